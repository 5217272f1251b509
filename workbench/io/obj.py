"""Strict Wavefront OBJ reader that keeps polygons and groups.

Why hand-written: trimesh (and most loaders) triangulate on load and drop the
polygon list, merge or drop vertices, and skip lines they cannot parse. Face
editing needs the artist's quads (exports write them back), vertex ids that
match the file exactly (MakeHuman targets and OBJ shape folders index them),
the ``g``/``o`` groups (eyes, teeth, tongue become named parts) and an error
with a line number on a damaged file rather than a silently different mesh.

Accepted statements: ``v x y z [w]`` (or ``v x y z r g b`` vertex colours; only
x y z are kept), ``f`` with ``v``, ``v/vt``, ``v/vt/vn``, ``v//vn`` corners and
negative (relative) indices, ``g``, ``o``. Ignored: ``vt vn vp usemtl mtllib s l
p`` and comments. Free-form geometry and unknown statements are errors.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, check_faces, check_vertices
from workbench.io.base import ImportedFace

__all__ = ["DESCRIPTION", "detect", "parse_obj_text", "read", "read_obj"]

DESCRIPTION = "a .obj file (neutral mesh only; polygons and g/o groups kept)"

_IGNORED = frozenset(
    {"vt", "vn", "vp", "usemtl", "mtllib", "s", "l", "p", "mg", "usemap", "maplib"}
)
_FREEFORM = frozenset(
    {
        "cstype",
        "deg",
        "bmat",
        "step",
        "curv",
        "curv2",
        "surf",
        "parm",
        "trim",
        "hole",
        "scrv",
        "sp",
        "end",
        "con",
    }
)
# one face corner: v, v/vt, v/vt/vn, v//vn (indices may be negative)
_CORNER_RE = r"(-?\d+)(?:/-?\d+(?:/-?\d+)?|//-?\d+)?"
_CORNER = re.compile(_CORNER_RE, re.ASCII)
# all corners of all faces joined by single spaces, checked in one call
_CORNERS = re.compile(
    f"{_CORNER_RE.replace('(-', '(?:-')}(?: {_CORNER_RE.replace('(-', '(?:-')})*", re.ASCII
)


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() == ".obj"


def read(path: Path) -> ImportedFace:
    return read_obj(path)


def _decode(data: bytes) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        # group names from old tools may be Latin-1; every byte decodes, and any
        # binary garbage in v/f lines is then reported as a parse error
        return data.decode("latin-1")


def read_obj(path: str | Path) -> ImportedFace:
    """Read one OBJ file.

    Parameters
    ----------
    path : str or Path
        The .obj file.

    Returns
    -------
    ImportedFace
        ``vertices`` (n, 3) float64, ``polygons`` as in the file, ``face_groups``
        from ``g``/``o`` lines (None if the file has none), no shapes, unknown
        units and up axis.

    Raises
    ------
    MeshFormatError
        Empty file, garbled line, NaN/inf coordinate, face index out of range,
        face with fewer than 3 corners or a repeated corner, duplicate or
        zero-area face. The message gives the file name and line number.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except IsADirectoryError:
        raise MeshFormatError(p, "path", "is a folder, expected an .obj file") from None
    return parse_obj_text(_decode(data), p)


def parse_obj_text(text: str, source: str | Path = "<string>") -> ImportedFace:
    """Parse OBJ text (see :func:`read_obj`); ``source`` is used in messages."""
    src = str(source)
    if not text.strip():
        raise MeshFormatError(src, "file", "empty file")

    v_tokens: list[list[str]] = []
    v_lines: list[int] = []
    f_tokens: list[str] = []  # every face corner token, all faces concatenated
    f_sizes: list[int] = []
    f_lines: list[int] = []
    f_nv: list[int] = []  # vertices defined before each face (for negative indices)
    f_group: list[int] = []
    group_names: list[str] = []
    group_ids: dict[str, int] = {}
    current_group = -1
    any_group = False

    def fail(lineno: int, field: str, msg: str) -> MeshFormatError:
        return MeshFormatError(src, field, f"line {lineno}: {msg}")

    # The loop only splits and sorts lines; numbers are converted in bulk below
    # (this keeps a 100k-vertex file well under a second).
    for lineno, raw in enumerate(text.splitlines(), start=1):
        parts = raw.split()
        if not parts:
            continue
        key = parts[0]
        if key == "v":
            n = len(parts) - 1
            if n not in (3, 4, 6, 7):
                raise fail(
                    lineno,
                    "v",
                    f"vertex needs 3 coordinates (x y z [w] or x y z r g b), got {n}: "
                    f"{raw.strip()[:80]!r}",
                )
            v_tokens.append(parts[1:4])
            v_lines.append(lineno)
        elif key == "f":
            if len(parts) < 4:
                raise fail(
                    lineno,
                    "f",
                    f"face needs at least 3 corners, got {len(parts) - 1}: {raw.strip()[:80]!r}",
                )
            f_tokens.extend(parts[1:])
            f_sizes.append(len(parts) - 1)
            f_lines.append(lineno)
            f_nv.append(len(v_tokens))
            f_group.append(current_group)
        elif key[0] == "#" or key in _IGNORED:
            continue
        elif key in ("g", "o"):
            any_group = True
            name = " ".join(parts[1:]) or "default"
            if name not in group_ids:
                group_ids[name] = len(group_names)
                group_names.append(name)
            current_group = group_ids[name]
        elif key in _FREEFORM:
            raise fail(lineno, key, f"free-form geometry ('{key}') is not supported")
        else:
            raise fail(lineno, "line", f"unknown statement {key[:40]!r}")

    if not v_tokens:
        raise MeshFormatError(src, "v", "no vertices ('v' lines)")
    if not f_sizes:
        raise MeshFormatError(src, "f", "no faces ('f' lines)")

    try:
        V = np.array(v_tokens, dtype=np.float64)
    except ValueError:
        # find the first bad line for the message
        for toks, lineno in zip(v_tokens, v_lines, strict=True):
            try:
                [float(t) for t in toks]
            except ValueError:
                raise fail(
                    lineno, "v", f"vertex coordinate is not a number: {' '.join(toks)[:80]!r}"
                ) from None
        raise MeshFormatError(src, "v", "vertex coordinates are not numbers") from None
    V = check_vertices(V, src, "v", line_numbers=v_lines)
    n = V.shape[0]

    sizes = np.asarray(f_sizes, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    def line_of_corner(c: int) -> int:
        return f_lines[int(np.searchsorted(offsets, c, side="right") - 1)]

    ids: np.ndarray | None = None
    if _CORNERS.fullmatch(" ".join(f_tokens)) is not None:
        try:
            ids = np.array([t.split("/", 1)[0] for t in f_tokens], dtype=np.int64)
        except (ValueError, OverflowError):
            ids = None  # e.g. a 30-digit index: the slow path below reports it
    if ids is None:
        for c, tok in enumerate(f_tokens):
            m = _CORNER.fullmatch(tok)
            if m is None:
                raise fail(
                    line_of_corner(c),
                    "f",
                    f"bad face corner {tok[:40]!r} (expected v, v/vt, v/vt/vn or v//vn)",
                )
            if abs(int(m.group(1))) > n:
                raise fail(
                    line_of_corner(c),
                    "f",
                    f"face index {m.group(1)[:40]} out of range (file has {n} vertices)",
                )
        raise MeshFormatError(src, "f", "unreadable face indices")  # pragma: no cover

    zero = ids == 0
    if zero.any():
        raise fail(
            line_of_corner(int(np.argmax(zero))), "f", "face index 0 (OBJ indices start at 1)"
        )
    # negative indices count back from the last vertex defined before the face line
    nv = np.repeat(np.asarray(f_nv, dtype=np.int64), sizes)
    corners = np.where(ids > 0, ids - 1, nv + ids)
    bad = (corners < 0) | (corners >= n)
    if bad.any():
        c = int(np.argmax(bad))
        raise fail(
            line_of_corner(c),
            "f",
            f"face index {int(ids[c])} out of range (file has {n} vertices"
            + (f", {int(nv[c])} before this line)" if ids[c] < 0 else ")"),
        )
    polygons = Polygons(corners.astype(np.int32), offsets)
    check_faces(polygons, n, src, vertices=V, line_numbers=f_lines)

    face_groups = np.asarray(f_group, dtype=np.int32) if any_group else None
    return ImportedFace(
        vertices=V,
        polygons=polygons,
        face_groups=face_groups,
        group_names=group_names if any_group else [],
        shapes=[],
        source_files=[src],
        units=None,
        up_axis=None,
    )
