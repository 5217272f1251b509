"""MakeHuman ``.target`` files: sparse per-vertex deltas on a base OBJ.

A target is a text file of ``vertex_index dx dy dz`` lines (``#`` comments),
indexed on the base mesh's vertices (0-based, in file order), in decimetres
with y up. The format is a few lines of text and MakeHuman's own loader is
not a dependency (and is lenient), so it is parsed here, strictly: every line
must have four fields, indices must be in range and appear once.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError, check_vertices
from workbench.io.base import ImportedFace, check_shape_names
from workbench.io.obj import read_obj

__all__ = ["DESCRIPTION", "detect", "parse_target", "read", "read_targets"]

DESCRIPTION = (
    "MakeHuman: a folder with one .obj and a targets/ folder of .target files "
    "(or call read_targets(obj, targets))"
)


def _target_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() == ".target")


def detect(path: Path) -> bool:
    if not path.is_dir():
        return False
    objs = [p for p in path.iterdir() if p.is_file() and p.suffix.lower() == ".obj"]
    t = path / "targets"
    return len(objs) == 1 and t.is_dir() and bool(_target_files(t))


def read(path: Path) -> ImportedFace:
    objs = [p for p in path.iterdir() if p.is_file() and p.suffix.lower() == ".obj"]
    return read_targets(objs[0])


def parse_target(path: str | Path, n_vertices: int) -> NDArray[np.float32]:
    """Read one .target file as a dense delta.

    Parameters
    ----------
    path : str or Path
        The .target file.
    n_vertices : int
        Vertex count of the base mesh.

    Returns
    -------
    delta : (n_vertices, 3) float32
        Zero except at the listed vertices.

    Raises
    ------
    MeshFormatError
        Empty file, a line without exactly ``index dx dy dz``, a non-integer or
        out-of-range index, an index listed twice, NaN/inf; with line number.
    """
    p = Path(path)
    data = p.read_bytes()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    rows: list[list[str]] = []
    linenos: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line[0] == "#":
            continue
        parts = line.split()
        if len(parts) != 4:
            raise MeshFormatError(
                p, "delta", f"line {lineno}: expected 'vertex_index dx dy dz', got {line[:80]!r}"
            )
        rows.append(parts)
        linenos.append(lineno)
    if not rows:
        raise MeshFormatError(p, "file", "empty target (no 'vertex_index dx dy dz' lines)")

    idx = np.empty(len(rows), dtype=np.int64)
    for k, (parts, lineno) in enumerate(zip(rows, linenos, strict=True)):
        try:
            idx[k] = int(parts[0])
        except (ValueError, OverflowError):
            raise MeshFormatError(
                p, "index", f"line {lineno}: vertex index {parts[0][:40]!r} is not an integer"
            ) from None
    bad = (idx < 0) | (idx >= n_vertices)
    if bad.any():
        k = int(np.argmax(bad))
        raise MeshFormatError(
            p,
            "index",
            f"line {linenos[k]}: vertex index {int(idx[k])} out of range "
            f"(base mesh has {n_vertices} vertices)",
        )
    order = np.argsort(idx, kind="stable")
    same = idx[order][1:] == idx[order][:-1]
    if same.any():
        j = int(np.argmax(same))
        a, b = sorted((int(order[j]), int(order[j + 1])))
        raise MeshFormatError(
            p,
            "index",
            f"line {linenos[b]}: vertex index {int(idx[b])} already given on line {linenos[a]}",
        )
    try:
        d = np.array([r[1:] for r in rows], dtype=np.float64)
    except ValueError:
        for r, lineno in zip(rows, linenos, strict=True):
            try:
                [float(t) for t in r[1:]]
            except ValueError:
                raise MeshFormatError(
                    p, "delta", f"line {lineno}: delta is not a number: {' '.join(r[1:])[:80]!r}"
                ) from None
        raise MeshFormatError(p, "delta", "deltas are not numbers") from None
    d = check_vertices(d, p, "delta", line_numbers=linenos)
    delta = np.zeros((n_vertices, 3), dtype=np.float32)
    delta[idx] = d
    return delta


def read_targets(
    obj_path: str | Path,
    targets: str | Path | Sequence[str | Path] | None = None,
) -> ImportedFace:
    """Read a base OBJ and MakeHuman targets on it.

    Parameters
    ----------
    obj_path : str or Path
        Base mesh.
    targets : folder, or sequence of .target paths, optional
        Default: the ``targets/`` folder next to ``obj_path``.

    Returns
    -------
    ImportedFace
        Shapes named by target file stem, in the given order (folder: sorted by
        name); units "dm", up axis "+y" (MakeHuman conventions).

    Raises
    ------
    MeshFormatError
        Any OBJ or target error, no targets found, or colliding shape names.
    """
    obj = Path(obj_path)
    base = read_obj(obj)
    if targets is None:
        targets = obj.parent / "targets"
    if isinstance(targets, (str, Path)):
        folder = Path(targets)
        if not folder.is_dir():
            raise MeshFormatError(folder, "targets", "targets folder not found")
        paths = _target_files(folder)
        if not paths:
            raise MeshFormatError(folder, "targets", "no .target files in folder")
    else:
        paths = [Path(t) for t in targets]
    check_shape_names([p.stem for p in paths], [str(p) for p in paths], str(obj.parent))
    shapes = [(p.stem, parse_target(p, base.n_vertices)) for p in paths]
    return ImportedFace(
        vertices=base.vertices,
        polygons=base.polygons,
        face_groups=base.face_groups,
        group_names=base.group_names,
        shapes=shapes,
        source_files=[str(obj)] + [str(p) for p in paths],
        units="dm",
        up_axis="+y",
    )
