"""A folder of same-topology OBJ files: one neutral plus one file per expression.

This is how many sculptors hand over blendshapes (one posed mesh per shape,
absolute positions). Each expression becomes ``delta = V_expression - V_neutral``.
The files must share the neutral's vertex count and polygon list exactly, since
the deltas are matched vertex by vertex. Built on :mod:`workbench.io.obj`; no
library reads shape folders.

Speed: the neutral is parsed in full once. An expression file whose face lines
are byte-identical to the neutral's (the usual case: one exporter, one
topology) has its faces known to be the neutral's; of its ``v`` lines only
those that differ from the neutral's are converted (a blendshape moves part of
the face), and only the position-dependent zero-area test is run on it. Any
other file is parsed in full and compared polygon by polygon, so errors and
results are those of :func:`~workbench.io.obj.read_obj`. Files are read by a
small thread pool; the result and the first error (in file-name order) do not
depend on it.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, check_faces
from workbench.io.base import ImportedFace, check_shape_names
from workbench.io.obj import read_obj, read_obj_with_template, read_positions_if_same_faces

__all__ = ["DESCRIPTION", "NEUTRAL_STEMS", "detect", "read", "read_obj_folder"]

DESCRIPTION = (
    "a folder of .obj files with one topology: neutral.obj (or base.obj) + one file per shape"
)
NEUTRAL_STEMS = ("neutral", "base")


def _obj_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() == ".obj")


def detect(path: Path) -> bool:
    return path.is_dir() and len(_obj_files(path)) >= 2


def read(path: Path) -> ImportedFace:
    return read_obj_folder(path)


def read_obj_folder(
    folder: str | Path, neutral: str | Path | None = None, *, workers: int | None = None
) -> ImportedFace:
    """Read a neutral OBJ and expression OBJs from one folder.

    Parameters
    ----------
    folder : str or Path
        Folder holding the .obj files (sub-folders are not searched).
    neutral : str or Path, optional
        File name (or stem) of the neutral; default ``neutral.obj`` or ``base.obj``.
    workers : int, optional
        Threads reading expression files; default ``min(4, os.cpu_count())``; 1 reads
        them one after the other.

    Returns
    -------
    ImportedFace
        The neutral mesh and one shape per other file, named by file stem,
        sorted by file name; ``source_files`` starts with the neutral.

    Raises
    ------
    MeshFormatError
        No or ambiguous neutral (the message lists candidates), an expression
        whose vertex count or polygons differ from the neutral, two files whose
        names collide (same ignoring case, or same ARKit shape), or any OBJ error.
        When several files are bad, the first by file name is reported.
    """
    root = Path(folder)
    if not root.is_dir():
        raise MeshFormatError(root, "path", "expected a folder of .obj files")
    files = _obj_files(root)
    if not files:
        raise MeshFormatError(root, "path", "folder has no .obj files")
    names = ", ".join(p.name for p in files)

    if neutral is not None:
        want = Path(neutral).name
        hits = [p for p in files if p.name == want or p.stem == want]
        if not hits:
            raise MeshFormatError(
                root, "neutral", f"neutral {want!r} not found; .obj files: {names}"
            )
    else:
        hits = [p for p in files if p.stem.lower() in NEUTRAL_STEMS]
        if not hits:
            raise MeshFormatError(
                root,
                "neutral",
                "no neutral mesh: name it neutral.obj or base.obj, or pass neutral=<file>; "
                f"candidates: {names}",
            )
    if len(hits) > 1:
        raise MeshFormatError(
            root,
            "neutral",
            f"ambiguous neutral: {', '.join(p.name for p in hits)}; pass neutral=<file>",
        )
    neutral_path = hits[0]
    base, template = read_obj_with_template(neutral_path)
    others = [p for p in files if p != neutral_path]
    check_shape_names([p.stem for p in others], [str(p) for p in others], str(root))

    area = _AreaTest(base.polygons, base.vertices)

    def delta(p: Path) -> NDArray[np.float32]:
        V = None
        if template is not None:
            V = read_positions_if_same_faces(p, template)
            if V is not None and not area.clearly_nonzero(V):
                V = None
        if V is None:
            V = _read_full(p, base, neutral_path.name)
        return (V - base.vertices).astype(np.float32)

    n_workers = max(1, min(4, os.cpu_count() or 1) if workers is None else workers)
    if n_workers == 1 or len(others) < 2:
        deltas = [delta(p) for p in others]
    else:
        with ThreadPoolExecutor(n_workers, thread_name_prefix="obj-folder") as pool:
            futures = [pool.submit(delta, p) for p in others]
            try:
                deltas = [f.result() for f in futures]  # the first error in name order
            finally:
                for f in futures:
                    f.cancel()

    shapes = [(p.stem, d) for p, d in zip(others, deltas, strict=True)]
    return ImportedFace(
        vertices=base.vertices,
        polygons=base.polygons,
        face_groups=base.face_groups,
        group_names=base.group_names,
        shapes=shapes,
        source_files=[str(neutral_path)] + [str(p) for p in others],
        units=None,
        up_axis=None,
    )


def _read_full(p: Path, base: ImportedFace, neutral_name: str) -> NDArray[np.float64]:
    """Parse ``p`` in full and check it has the neutral's topology (errors name ``p``)."""
    face = read_obj(p)
    if face.n_vertices != base.n_vertices:
        raise MeshFormatError(
            p,
            "v",
            f"has {face.n_vertices} vertices but the neutral {neutral_name} has "
            f"{base.n_vertices}; every shape must have the neutral's topology",
        )
    if not face.polygons.equals(base.polygons):
        first = _first_difference(face, base)
        raise MeshFormatError(
            p,
            "f",
            f"faces differ from the neutral {neutral_name} ({first}); "
            "every shape must have the neutral's topology",
        )
    return face.vertices


class _AreaTest:
    """A conservative version of ``check_faces``' zero-area test, for faces whose corners moved.

    :meth:`clearly_nonzero` is True when every polygon that has a corner where
    ``V`` differs from the neutral has a vector area far above ``check_faces``'
    threshold (1e-12 x its longest edge squared); the other polygons are the
    neutral's, which passed the exact test. A polygon near the threshold sends
    the file to the full parse, which applies the exact test.
    """

    def __init__(self, polygons: Polygons, neutral: NDArray[np.float64]) -> None:
        self.neutral = neutral
        sizes = polygons.sizes
        self.by_size: list[NDArray[np.int32]] = []  # (m, k) corners of the k-gons, k = 3, 4
        for k in (3, 4):
            rows = np.flatnonzero(sizes == k)
            if rows.size:
                self.by_size.append(polygons.indices[polygons.offsets[rows, None] + np.arange(k)])
        big = np.flatnonzero(sizes > 4)
        self.ngons = [polygons[int(i)].tolist() for i in big]

    def clearly_nonzero(self, V: NDArray[np.float64]) -> bool:
        moved = (V != self.neutral).any(axis=1)
        X = np.ascontiguousarray(V.T)  # x, y, z rows: the gathers below are one-dimensional
        for corners in self.by_size:
            k = corners.shape[1]
            touched = moved[corners[:, 0]]
            for j in range(1, k):
                touched |= moved[corners[:, j]]
            if not touched.any():
                continue
            P = [X[:, corners[touched, j]] for j in range(k)]  # k corners, each (3, m)
            # vector area: of a triangle, of a quad (half the cross product of its diagonals)
            u, w = (P[1] - P[0], P[2] - P[0]) if k == 3 else (P[2] - P[0], P[3] - P[1])
            area2 = (
                (u[1] * w[2] - u[2] * w[1]) ** 2
                + (u[2] * w[0] - u[0] * w[2]) ** 2
                + (u[0] * w[1] - u[1] * w[0]) ** 2
            )
            edge2 = np.zeros(area2.shape)
            for j in range(k):
                d = P[(j + 1) % k] - P[j]
                np.maximum(edge2, d[0] ** 2 + d[1] ** 2 + d[2] ** 2, out=edge2)
            if not (area2 > 1e-18 * edge2**2).all():
                return False
        if self.ngons:
            try:
                check_faces(Polygons.from_lists(self.ngons), V.shape[0], "", vertices=V)
            except MeshFormatError:
                return False
        return True


def _first_difference(a: ImportedFace, b: ImportedFace) -> str:
    pa, pb = a.polygons, b.polygons
    if len(pa) != len(pb):
        return f"{len(pa)} faces vs {len(pb)}"
    for i in range(len(pa)):
        if not np.array_equal(pa[i], pb[i]):
            return f"face {i} is {pa[i].tolist()} vs {pb[i].tolist()}"
    return "same faces"  # pragma: no cover - equals() said they differ
