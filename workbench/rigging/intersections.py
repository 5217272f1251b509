"""Self-intersections of a triangle mesh: the triangles that cross another triangle of the same mesh.

Two triangles *intersect* when they share a point, boundary included (a
vertex resting on the other triangle counts); pairs that share a vertex
index are never tested (neighbours always touch, and a fold between
neighbours shows as a flipped triangle instead).
:func:`self_intersecting_triangles` checks one mesh;
:class:`SelfIntersections` holds a rest mesh and answers, per displacement,
which triangles intersect the surface that did not at rest: a mesh may
already touch itself at rest (closed lips, seams left unwelded), and only
what a shape adds is news. Per displacement it tests only the pairs with a
triangle that moves, by more than ``tol`` and by at least half its
*clearance* (a lower bound, found once at rest, on its distance to the
triangles around it): two triangles apart at rest can only meet if their
displacements add up to their distance, so one of them moves by half its
clearance. The answer is that of two full checks (the tests compare them);
on a face, where a transferred shape moves half the skin a little, ~12 %
of the triangles are tested instead of ~50 %.

How
---
*Broad phase*: each triangle's bounding box goes into the buckets of the
grid cells it spans (cell: the median box size of the rest mesh; bucket:
the cell's Morton code, so neighbour cells share cache lines; a counting
sort). Per bucket, every moving triangle is compared with every other entry,
boxes first in a branch-free pass; a pair is kept only in the bucket of the
low corner of the two boxes' cell ranges, so it is looked at once.
*Narrow phase*: the separating-axis test of two triangles over 17 axes (both
normals, the 9 cross products of an edge of each, the 6 in-plane edge
normals, which decide the coplanar case), stopping at the first axis that
separates. The clearance is the same pass over boxes grown by an eighth of
the cell, keeping per triangle the smallest of the widest normalised gaps
over those axes. All are numba loops, the buckets dealt to numba's threads.

numba is an optional speed-up of the workbench (the ``fast`` extra). Without
it the broad phase is a :class:`scipy.spatial.cKDTree` per triangle size
class and the narrow phase the same test vectorised over pairs
(:func:`triangles_intersect`), with no clearance: same answers, ~100x
slower (~0.5 s per shape on a 24k-vertex face against ~4 ms), which is why
the rig transfer's report only counts self-intersections with numba.

Why by hand: libigl's ``tri_tri_overlap_test_3d`` (Guigue-Devillers) takes
one pair per Python call (~2.4 µs each; a face has ~3e5 box-overlapping
pairs per shape, and a rig 52 shapes), the Python bindings of its ``AABB``
have no tree-against-tree or box query, and trimesh's collision manager needs
python-fcl (not a dependency) and reports pairs of meshes, not triangles of
one. The tests check the narrow phase against libigl's on random pairs,
and both backends against all pairs on small meshes.

Shapes: ``V : (n, 3) float``, ``F : (m, 3) int``, ``D : (n, 3) float``
(displacements); results are ``(m,) bool`` per triangle.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench._numba import NUMBA, numba
from workbench.rigging.intersection_kernels import grid, grid_pairs, moving_triangles

__all__ = ["NUMBA", "SelfIntersections", "self_intersecting_triangles", "triangles_intersect"]

Backend = Literal["auto", "numba", "numpy"]

#: :attr:`SelfIntersections.clearance` is capped at this share of the grid cell (the median triangle size):
#: a wider reach costs more at set-up than it saves per shape
_REACH = 0.25


# --------------------------------------------------------------------------- narrow phase, numpy


def _axis(k: int, EA: NDArray[np.float64], EB: NDArray[np.float64], nA: NDArray[np.float64],
          nB: NDArray[np.float64]) -> NDArray[np.float64]:
    """Candidate separating axis ``k`` (0..16) per pair: normals, edge x edge, in-plane edge normals."""
    if k == 0:
        return nA
    if k == 1:
        return nB
    if k < 11:
        i, j = divmod(k - 2, 3)
        return np.cross(EA[:, i], EB[:, j])
    if k < 14:
        return np.cross(nA, EA[:, k - 11])
    return np.cross(nB, EB[:, k - 14])


def triangles_intersect(A: NDArray[np.floating[Any]], B: NDArray[np.floating[Any]]) -> NDArray[np.bool_]:
    """Whether triangles ``A[p]`` and ``B[p]`` share a point (boundary included), per pair.

    Parameters
    ----------
    A, B : (p, 3, 3) float
        Pairs of triangles (vertex, coordinate).

    Returns
    -------
    (p,) bool

    Notes
    -----
    The separating-axis test: two triangles are disjoint iff one of 17 axes
    separates their projections (both normals, the 9 cross products of an
    edge of each, the 6 edge normals in each plane, which decide the coplanar
    case). A pair leaves the work at the first axis that separates it.
    Coordinates are taken relative to ``A``'s first vertex.
    """
    A = np.asarray(A, np.float64)
    B = np.asarray(B, np.float64)
    if A.ndim != 3 or A.shape[1:] != (3, 3) or B.shape != A.shape:
        raise ValueError(f"A and B must both be (p, 3, 3), got {A.shape} and {B.shape}")
    o = A[:, :1]
    A, B = A - o, B - o
    live = np.arange(A.shape[0])
    EA = np.roll(A, -1, axis=1) - A  # (p, edge, 3): edge i runs from vertex i to i + 1
    EB = np.roll(B, -1, axis=1) - B
    nA = np.cross(EA[:, 0], EA[:, 1])
    nB = np.cross(EB[:, 0], EB[:, 1])
    for k in range(17):
        if live.size == 0:
            break
        ax = _axis(k, EA, EB, nA, nB)
        pa = np.einsum("pvc,pc->pv", A, ax)
        pb = np.einsum("pvc,pc->pv", B, ax)
        keep = (pa.max(1) >= pb.min(1)) & (pb.max(1) >= pa.min(1))
        live, A, B, EA, EB, nA, nB = live[keep], A[keep], B[keep], EA[keep], EB[keep], nA[keep], nB[keep]
    out = np.zeros(o.shape[0], np.bool_)
    out[live] = True
    return out


# --------------------------------------------------------------------------- drivers


def _cell_size(V: NDArray[np.float64], F: NDArray[np.int64]) -> float:
    """The grid cell: the median extent of the triangles' boxes (bounded below by 1e-5 of the mesh's)."""
    T = V[F]
    ext = (T.max(1) - T.min(1)).max(1)
    span = float((V.max(0) - V.min(0)).max()) if V.size else 0.0
    pos = ext[ext > 0]
    return max(float(np.median(pos)) if pos.size else span, span * 1e-5, 1e-300)


def _stripes() -> int:
    return max(1, min(numba.get_num_threads(), 8))


def _hits_numba(V: NDArray[np.float64], F: NDArray[np.int64], query: NDArray[np.bool_], h: float
                ) -> NDArray[np.bool_]:
    lo, hi, clo, start, tri, mask, most = grid(V, F, query, h, 0.0)
    hit = np.zeros((_stripes(), F.shape[0]), np.bool_)
    grid_pairs(V, F, query, lo, hi, clo, start, tri, mask, most, hit, np.zeros((hit.shape[0], 0)))
    return np.any(hit, axis=0)


def _clearance_numba(V: NDArray[np.float64], F: NDArray[np.int64], reach: float, h: float) -> NDArray[np.float64]:
    """Per triangle, a lower bound on its distance to the triangles sharing no vertex with it, capped at ``reach``."""
    query = np.ones(F.shape[0], np.bool_)
    lo, hi, clo, start, tri, mask, most = grid(V, F, query, h, reach / 2)
    hit = np.zeros((_stripes(), F.shape[0]), np.bool_)
    gaps = np.full((hit.shape[0], F.shape[0]), reach)
    grid_pairs(V, F, query, lo, hi, clo, start, tri, mask, most, hit, gaps)
    return gaps.min(0)


def _candidate_pairs(V: NDArray[np.float64], F: NDArray[np.int64], query: NDArray[np.bool_]
                     ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """numpy broad phase: the pairs ``(i, j)`` with ``i`` in ``query`` whose boxes overlap and that share no vertex.

    Each pair once (a pair of query triangles with ``i < j``). Balls around
    the boxes in a :class:`scipy.spatial.cKDTree` per size class (radii within
    2x), queried with the class's largest radius.
    """
    T = V[F]
    lo, hi = T.min(1), T.max(1)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo, axis=1) / 2
    q = np.flatnonzero(query)
    med = max(float(np.median(r[r > 0])) if (r > 0).any() else 1.0, 1e-300)
    size_class = np.maximum(np.floor(np.log2(np.maximum(r, 1e-300) / med)), -1).astype(np.int64)
    ii, jj = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for k in np.unique(size_class):
        members = np.flatnonzero(size_class == k)
        near = cKDTree(c[members]).query_ball_point(c[q], r[q] + r[members].max(), return_sorted=False)
        counts = np.fromiter((len(x) for x in near), np.int64, len(near))
        if counts.sum():
            ii.append(np.repeat(q, counts))
            jj.append(members[np.concatenate([np.asarray(x, np.int64) for x in near])])
    i, j = np.concatenate(ii), np.concatenate(jj)
    keep = (i != j) & ~(query[j] & (j < i))
    i, j = i[keep], j[keep]
    keep = ((lo[i] <= hi[j]) & (lo[j] <= hi[i])).all(1)
    i, j = i[keep], j[keep]
    keep = ~(F[i][:, :, None] == F[j][:, None, :]).any((1, 2))
    return i[keep], j[keep]


def _hits_numpy(V: NDArray[np.float64], F: NDArray[np.int64], query: NDArray[np.bool_]) -> NDArray[np.bool_]:
    i, j = _candidate_pairs(V, F, query)
    yes = triangles_intersect(V[F[i]], V[F[j]])
    hit = np.zeros(F.shape[0], np.bool_)
    hit[i[yes]] = True
    hit[j[yes]] = True
    return hit


def _check(V: NDArray[Any], F: NDArray[Any]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"V must be (n, 3), got {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"F must be (m, 3) triangles, got {F.shape}")
    if F.size and (F.min() < 0 or F.max() >= V.shape[0]):
        raise ValueError(f"F indexes vertices outside 0..{V.shape[0] - 1}")
    if not np.isfinite(V).all():
        raise ValueError("V has coordinates that are not finite")
    return V, F


def _hits(V: NDArray[np.float64], F: NDArray[np.int64], query: NDArray[np.bool_], backend: Backend,
          h: float | None = None) -> NDArray[np.bool_]:
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}")
    if backend == "numba" and not NUMBA:
        raise ValueError("backend='numba': numba is not installed")
    if not query.any():
        return np.zeros(F.shape[0], np.bool_)
    if backend == "numpy" or not NUMBA:
        return _hits_numpy(V, F, query)
    return _hits_numba(V, F, query, _cell_size(V, F) if h is None else h)


def self_intersecting_triangles(
    V: NDArray[np.floating[Any]],
    F: NDArray[np.integer[Any]],
    *,
    only: NDArray[np.bool_] | NDArray[np.integer[Any]] | None = None,
    backend: Backend = "auto",
) -> NDArray[np.bool_]:
    """The triangles of ``(V, F)`` that intersect another triangle of it (pairs sharing a vertex never count).

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    only : (m,) bool or int array, optional
        Test only pairs with a triangle among these (a mask or triangle
        indices); a triangle outside them is True only when it meets one of
        them. Default: all pairs.
    backend : {"auto", "numba", "numpy"}
        The numba kernels (default when numba is installed) or numpy and scipy.

    Returns
    -------
    (m,) bool
    """
    V, F = _check(V, F)
    query = np.zeros(F.shape[0], np.bool_)
    if only is None:
        query[:] = True
    else:
        sel = np.asarray(only)
        if sel.dtype == np.bool_:
            if sel.shape != (F.shape[0],):
                raise ValueError(f"only: a mask must be ({F.shape[0]},), got {sel.shape}")
            query[:] = sel
        else:
            query[sel.astype(np.int64)] = True
    return _hits(V, F, query, backend)


class SelfIntersections:
    """Self-intersections that displacements of one rest mesh add (the rest pose is looked at once).

    Parameters
    ----------
    V0 : (n, 3) float
        The rest mesh.
    F : (m, 3) int
    tol : float, optional
        Vertices moving by at most this much are taken as still; default
        1e-6 of the rest mesh's bounding-box diagonal.
    backend : {"auto", "numba", "numpy"}

    Attributes
    ----------
    rest : (m,) bool
        The triangles that intersect the rest mesh.
    clearance : (m,) float
        Per triangle, a lower bound on its distance at rest to every triangle
        sharing no vertex with it (the widest gap over the separating axes of
        the pairs within reach), capped at a quarter of the median triangle
        size; 0 for the ``rest`` triangles. With the numpy backend, zeros.
    """

    def __init__(
        self,
        V0: NDArray[np.floating[Any]],
        F: NDArray[np.integer[Any]],
        *,
        tol: float | None = None,
        backend: Backend = "auto",
    ) -> None:
        self.V0, self.F = _check(V0, F)
        self.backend: Backend = backend
        diag = float(np.linalg.norm(self.V0.max(0) - self.V0.min(0))) if self.V0.size else 0.0
        self.tol = 1e-6 * diag if tol is None else float(tol)
        self._h = _cell_size(self.V0, self.F) if self.F.size else 1.0
        self.rest = _hits(self.V0, self.F, np.ones(self.F.shape[0], np.bool_), backend, self._h)
        self._numba = backend != "numpy" and NUMBA
        if self._numba and self.F.size:
            self.clearance = _clearance_numba(self.V0, self.F, _REACH * self._h, self._h)
        else:
            self.clearance = np.zeros(self.F.shape[0])

    def new(self, D: NDArray[np.floating[Any]]) -> NDArray[np.bool_]:
        """(m,) bool: the triangles that intersect the mesh displaced by ``D`` (n, 3) and did not at rest.

        Only pairs with a triangle that moves (a vertex by more than
        ``tol``) by at least half its ``clearance`` are tested: for two
        triangles apart at rest to meet, their largest vertex displacements
        must add up to their distance, which is at least either one's
        clearance, so one of them moves by half its own. Every other pair is
        as it was at rest (or too far apart to have met), so the answer is
        that of two full checks.
        """
        D = np.asarray(D, np.float64)
        if D.shape != self.V0.shape:
            raise ValueError(f"D must be {self.V0.shape} like the rest mesh, got {D.shape}")
        if not np.isfinite(D).all():
            raise ValueError("D has displacements that are not finite")
        m = self.F.shape[0]
        if self._numba:
            V = np.empty_like(self.V0)
            query = np.empty(m, np.bool_)
            moving_triangles(self.V0, np.ascontiguousarray(D), self.F, self.clearance, self.tol, V, query)
            hit = _hits_numba(V, self.F, query, self._h) if query.any() else np.zeros(m, np.bool_)
        else:
            step = np.sqrt(np.einsum("ij,ij->i", D, D))[self.F].max(1) if m else np.zeros(0)
            hit = _hits(self.V0 + D, self.F, (step > self.tol) & (step >= self.clearance / 2), self.backend)
        return hit & ~self.rest

    def count_new(self, D: NDArray[np.floating[Any]]) -> int:
        """How many triangles :meth:`new` finds."""
        return int(self.new(D).sum())
