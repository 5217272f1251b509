"""The line-by-line OBJ parser: the reference grammar, and the one that words the errors.

Accepted statements: ``v x y z [w]`` (or ``v x y z r g b`` vertex colours; only
x y z are kept), ``f`` with ``v``, ``v/vt``, ``v/vt/vn``, ``v//vn`` corners and
negative (relative) indices, ``g``, ``o``. Ignored: ``vt vn vp usemtl mtllib s l
p`` and comments. Free-form geometry and unknown statements are errors.
"""

from __future__ import annotations

import re

import numpy as np

from workbench.geometry.mesh_checks import MeshFormatError, check_vertices
from workbench.io.base import ImportedFace
from workbench.io.obj.assemble import _assemble, _Tokens

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


def _parse_lines(text: str, src: str) -> ImportedFace:
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
    n = V.shape[0]
    sizes = np.asarray(f_sizes, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    ids: np.ndarray | None = None
    if _CORNERS.fullmatch(" ".join(f_tokens)) is not None:
        try:
            ids = np.array([t.split("/", 1)[0] for t in f_tokens], dtype=np.int64)
        except (ValueError, OverflowError):
            ids = None  # e.g. a 30-digit index: the slow path below reports it
    if ids is None:
        check_vertices(V, src, "v", line_numbers=v_lines)
        for c, tok in enumerate(f_tokens):
            line = f_lines[int(np.searchsorted(offsets, c, side="right") - 1)]
            m = _CORNER.fullmatch(tok)
            if m is None:
                raise fail(
                    line, "f", f"bad face corner {tok[:40]!r} (expected v, v/vt, v/vt/vn or v//vn)"
                )
            if abs(int(m.group(1))) > n:
                raise fail(
                    line, "f", f"face index {m.group(1)[:40]} out of range (file has {n} vertices)"
                )
        raise MeshFormatError(src, "f", "unreadable face indices")  # pragma: no cover

    tokens = _Tokens(
        V=V,
        v_lines=np.asarray(v_lines, dtype=np.int64),
        ids=ids,
        sizes=sizes,
        f_lines=np.asarray(f_lines, dtype=np.int64),
        f_nv=np.asarray(f_nv, dtype=np.int64),
        f_group=np.asarray(f_group, dtype=np.int32),
        group_names=group_names,
        any_group=any_group,
    )
    return _assemble(tokens, src)
