"""Validation of imported meshes, and naming of connected components.

Every importer runs its arrays through :func:`check_vertices` and
:func:`check_faces` so a bad file fails at load time with a message naming the
file, the field and the first bad row, instead of producing NaNs or an index
error deep inside a solver. trimesh's ``process``/``validate`` repair meshes
silently (merge, drop faces) and report nothing, so the checks are hand-written;
component labelling uses ``scipy.sparse.csgraph``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components

from workbench.core.polygons import Polygons

__all__ = ["MeshFormatError", "check_faces", "check_vertices", "label_components"]


class MeshFormatError(ValueError):
    """A mesh or shape file is malformed.

    Attributes
    ----------
    source : str
        Path of the offending file (or a description of the in-memory source).
    field : str
        What was wrong, e.g. "v", "f", "accessors[3]", "header".
    """

    def __init__(self, source: str | Path, field: str, message: str) -> None:
        self.source = str(source)
        self.field = field
        self.detail = message
        super().__init__(f"{Path(self.source).name}: {message}")


def _prefix(row: int, line_numbers: ArrayLike | None, field: str) -> str:
    """ "line 12: " for text formats (line known), else "<field>: "."""
    if line_numbers is not None:
        return f"line {int(np.asarray(line_numbers)[row])}: "
    return f"{field}: "


def check_vertices(
    V: ArrayLike,
    source: str | Path,
    field: str,
    line_numbers: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Check vertex positions (or deltas) are an (n, 3) array of finite numbers.

    Parameters
    ----------
    V : (n, 3) float
        Positions or deltas.
    source : str or Path
        File the array came from (used in the error message).
    field : str
        Name of the field in that file ("v", "POSITION", "targets[2].POSITION").
    line_numbers : (n,) int, optional
        Source line of each row, for text formats.

    Returns
    -------
    V : (n, 3) float64
        The input as a contiguous float64 array.

    Raises
    ------
    MeshFormatError
        Wrong shape, or a NaN/inf; names the first bad row.
    """
    try:
        arr = np.asarray(V, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MeshFormatError(source, field, f"{field}: not numeric ({exc})") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise MeshFormatError(
            source, field, f"{field}: expected an (n, 3) array, got shape {arr.shape}"
        )
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        row = int(np.argmax(bad))
        raise MeshFormatError(
            source,
            field,
            f"{_prefix(row, line_numbers, field)}row {row} is not finite "
            f"({', '.join(map(str, arr[row]))})",
        )
    return np.ascontiguousarray(arr)


def _as_polygons(faces: ArrayLike | Polygons, source: str | Path) -> Polygons:
    if isinstance(faces, Polygons):
        return faces
    F = np.asarray(faces)
    if F.ndim != 2 or F.shape[1] < 3:
        raise MeshFormatError(
            source, "faces", f"faces: expected an (m, k>=3) array, got shape {F.shape}"
        )
    if not np.issubdtype(F.dtype, np.integer):
        raise MeshFormatError(source, "faces", f"faces: expected integer indices, got {F.dtype}")
    return Polygons(
        F.reshape(-1).astype(np.int32), np.arange(0, F.size + 1, F.shape[1], dtype=np.int64)
    )


def _padded_sorted(P: Polygons) -> NDArray[np.int64]:
    """(p, k_max) corner ids of each polygon, sorted, padded with -1 at the front."""
    sizes = P.sizes
    k = int(sizes.max())
    rows = np.repeat(np.arange(len(P)), sizes)
    cols = (
        np.arange(P.indices.size) - np.repeat(P.offsets[:-1], sizes) + (k - np.repeat(sizes, sizes))
    )
    out = np.full((len(P), k), -1, dtype=np.int64)
    out[rows, cols] = P.indices
    # sort each row; the -1 padding stays in front
    out.sort(axis=1)
    return out


def check_faces(
    faces: ArrayLike | Polygons,
    n_vertices: int,
    source: str | Path,
    vertices: ArrayLike | None = None,
    line_numbers: ArrayLike | None = None,
    field: str = "f",
) -> Polygons:
    """Check face connectivity (and, given positions, that no face has zero area).

    Parameters
    ----------
    faces : (m, k) int or Polygons
        Triangles/quads or general polygons.
    n_vertices : int
        Number of vertices the indices refer to.
    source : str or Path
        File the faces came from.
    vertices : (n, 3) float, optional
        Positions; when given, polygons with zero area are rejected. A polygon's
        area is the length of its vector area, compared with its longest edge
        squared (scale invariant).
    line_numbers : (m,) int, optional
        Source line of each face, for text formats.
    field : str
        Field name used in messages.

    Returns
    -------
    Polygons
        The faces as Polygons.

    Raises
    ------
    MeshFormatError
        Index out of range, fewer than 3 corners, a corner repeated inside a
        polygon, two faces with the same vertex set, or a zero-area face; the
        message names the first offending face.
    """
    P = _as_polygons(faces, source)
    n_poly = len(P)
    if n_poly == 0:
        raise MeshFormatError(source, field, "no faces")

    def where(i: int) -> str:
        return _prefix(i, line_numbers, field)

    idx = P.indices
    bad = (idx < 0) | (idx >= n_vertices)
    if bad.any():
        corner = int(np.argmax(bad))
        face = int(np.searchsorted(P.offsets, corner, side="right") - 1)
        raise MeshFormatError(
            source,
            field,
            f"{where(face)}face {face} index {int(idx[corner])} out of range "
            f"(file has {n_vertices} vertices)",
        )

    if int(P.sizes.max()) * n_poly > 50_000_000:
        # a giant n-gon would make the padded table huge: check corner sets in Python
        _check_repeats_slow(P, source, field, where)
        return _check_area(P, vertices, source, field, where)
    rows = _padded_sorted(P)
    rep = (rows[:, 1:] == rows[:, :-1]) & (rows[:, 1:] >= 0)
    if rep.any():
        face = int(np.argmax(rep.any(axis=1)))
        raise MeshFormatError(
            source,
            field,
            f"{where(face)}face {face} uses vertex {int(rows[face][1:][rep[face]][0])} "
            f"more than once ({P[face].tolist()})",
        )

    _, first, inverse, counts = np.unique(
        rows, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    inverse = inverse.reshape(-1)
    dup = counts[inverse] > 1
    dup &= first[inverse] != np.arange(n_poly)
    if dup.any():
        face = int(np.argmax(dup))
        other = int(first[inverse[face]])
        raise MeshFormatError(
            source,
            field,
            f"{where(face)}face {face} {P[face].tolist()} duplicates face {other} (same vertices)",
        )

    return _check_area(P, vertices, source, field, where)


def _check_repeats_slow(
    P: Polygons, source: str | Path, field: str, where: Callable[[int], str]
) -> None:
    seen: dict[tuple[int, ...], int] = {}
    for i in range(len(P)):
        corners = P[i].tolist()
        key = tuple(sorted(corners))
        if len(set(key)) != len(key):
            raise MeshFormatError(source, field, f"{where(i)}face {i} uses a vertex more than once")
        if key in seen:
            raise MeshFormatError(
                source, field, f"{where(i)}face {i} duplicates face {seen[key]} (same vertices)"
            )
        seen[key] = i


def _check_area(
    P: Polygons,
    vertices: ArrayLike | None,
    source: str | Path,
    field: str,
    where: Callable[[int], str],
) -> Polygons:
    n_poly = len(P)
    idx = P.indices
    if vertices is not None:
        V = np.asarray(vertices, dtype=np.float64)
        tris, poly_of_tri = P.triangulate()
        a, b, c = V[tris[:, 0]], V[tris[:, 1]], V[tris[:, 2]]
        # vector area of the polygon = sum of its fan triangles' vector areas
        cross = np.cross(b - a, c - a)
        varea = np.zeros((n_poly, 3))
        np.add.at(varea, poly_of_tri, cross)
        # longest edge of each polygon, squared
        nxt = np.arange(idx.size) + 1
        last = P.offsets[1:] - 1
        nxt[last] = P.offsets[:-1]
        edge2 = ((V[idx[nxt]] - V[idx]) ** 2).sum(axis=1)
        longest = np.maximum.reduceat(edge2, P.offsets[:-1])
        area2 = np.linalg.norm(varea, axis=1)
        zero = area2 <= 1e-12 * longest
        if zero.any():
            face = int(np.argmax(zero))
            raise MeshFormatError(
                source, field, f"{where(face)}face {face} {P[face].tolist()} has zero area"
            )
    return P


def label_components(
    faces: ArrayLike | Polygons,
    n_vertices: int,
    group_of_face: ArrayLike | None = None,
    group_names: Sequence[str] | None = None,
) -> tuple[NDArray[np.int32], list[str]]:
    """Label connected mesh pieces (skin, eyes, teeth, ...) and name them.

    Parameters
    ----------
    faces : (m, k) int or Polygons
        Connectivity.
    n_vertices : int
        Number of vertices.
    group_of_face : (m,) int, optional
        Group id of each face (e.g. from OBJ ``g`` lines); negative = no group.
    group_names : sequence of str, optional
        Name of each group id.

    Returns
    -------
    labels : (n,) int32
        Part id of each vertex, in ``0..len(names)-1``.
    names : list of str
        Name of each part.

    Notes
    -----
    A connected component whose faces all lie in one named group takes the
    group's name; components sharing a name are merged into one part (an
    eyelash made of many strands is one part "eyelashes_left"). Of the rest, the
    largest is "skin" (unless a group is already called that) and the others
    "component_<k>". Vertices used by no face form their own components. Parts
    are ordered by decreasing vertex count, ties by lowest vertex id.
    """
    P = _as_polygons(faces, "faces")
    idx = P.indices.astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= n_vertices):
        raise ValueError(f"label_components: face index out of range for {n_vertices} vertices")
    # connect every corner to the polygon's first corner: enough for connectivity
    first = np.repeat(idx[P.offsets[:-1]], P.sizes)
    A = sp.coo_matrix(
        (np.ones(idx.size, dtype=np.int8), (first, idx)), shape=(n_vertices, n_vertices)
    ).tocsr()
    n_comp, comp = connected_components(A, directed=False)

    comp_name: list[str | None] = [None] * n_comp
    if group_of_face is not None and group_names is not None and len(P):
        g = np.asarray(group_of_face, dtype=np.int64).reshape(-1)
        if g.size != len(P):
            raise ValueError(
                f"label_components: group_of_face has {g.size} entries for {len(P)} faces"
            )
        comp_of_face = comp[idx[P.offsets[:-1]]]
        for c in range(n_comp):
            gs = np.unique(g[comp_of_face == c])
            if gs.size == 1 and 0 <= gs[0] < len(group_names):
                comp_name[c] = str(group_names[int(gs[0])])

    sizes = np.bincount(comp, minlength=n_comp)
    first_vertex = np.full(n_comp, n_vertices, dtype=np.int64)
    np.minimum.at(first_vertex, comp, np.arange(n_vertices))
    taken = {n for n in comp_name if n is not None}
    unnamed = [c for c in range(n_comp) if comp_name[c] is None]
    if unnamed and "skin" not in taken:
        biggest = max(unnamed, key=lambda c: (sizes[c], -first_vertex[c]))
        comp_name[biggest] = "skin"

    # merge by name, then order parts by size
    part_of_name: dict[str, list[int]] = {}
    anon: list[list[int]] = []
    for c in range(n_comp):
        name = comp_name[c]
        if name is None:
            anon.append([c])
        else:
            part_of_name.setdefault(name, []).append(c)
    parts: list[tuple[str | None, list[int]]] = [(n, cs) for n, cs in part_of_name.items()]
    parts += [(None, cs) for cs in anon]
    parts.sort(key=lambda p: (-int(sizes[p[1]].sum()), int(first_vertex[p[1]].min())))

    labels_of_comp = np.empty(n_comp, dtype=np.int32)
    names: list[str] = []
    k = 0
    for label, (name, cs) in enumerate(parts):
        labels_of_comp[cs] = label
        if name is None:
            k += 1
            name = f"component_{k}"
            while name in taken:
                k += 1
                name = f"component_{k}"
        names.append(name)
    return labels_of_comp[comp].astype(np.int32), names
