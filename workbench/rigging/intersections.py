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

from workbench._numba import NUMBA, njit, numba, prange

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


# --------------------------------------------------------------------------- numba kernels


@njit(cache=True, inline="always")
def _sep(ax0, ax1, ax2, V, ta, tb):  # pragma: no cover - compiled
    """Does the axis (ax0, ax1, ax2) separate triangles ``ta`` and ``tb`` (vertex ids; relative to ``V[ta[0]]``)?"""
    o0, o1, o2 = V[ta[0], 0], V[ta[0], 1], V[ta[0], 2]
    amin = 1e300
    amax = -1e300
    bmin = 1e300
    bmax = -1e300
    for v in range(3):
        p = ta[v]
        x = (V[p, 0] - o0) * ax0 + (V[p, 1] - o1) * ax1 + (V[p, 2] - o2) * ax2
        amin = min(amin, x)
        amax = max(amax, x)
        q = tb[v]
        y = (V[q, 0] - o0) * ax0 + (V[q, 1] - o1) * ax1 + (V[q, 2] - o2) * ax2
        bmin = min(bmin, y)
        bmax = max(bmax, y)
    return amax < bmin or bmax < amin


@njit(cache=True)
def _tri_tri(V, ta, tb):  # pragma: no cover - compiled
    """The separating-axis test of triangles ``ta`` and ``tb`` (vertex ids into ``V``; see :func:`triangles_intersect`)."""
    a0, a1, a2 = ta[0], ta[1], ta[2]
    b0, b1, b2 = tb[0], tb[1], tb[2]
    # edges i -> i + 1 of each triangle
    ea00, ea01, ea02 = V[a1, 0] - V[a0, 0], V[a1, 1] - V[a0, 1], V[a1, 2] - V[a0, 2]
    ea10, ea11, ea12 = V[a2, 0] - V[a1, 0], V[a2, 1] - V[a1, 1], V[a2, 2] - V[a1, 2]
    ea20, ea21, ea22 = V[a0, 0] - V[a2, 0], V[a0, 1] - V[a2, 1], V[a0, 2] - V[a2, 2]
    eb00, eb01, eb02 = V[b1, 0] - V[b0, 0], V[b1, 1] - V[b0, 1], V[b1, 2] - V[b0, 2]
    eb10, eb11, eb12 = V[b2, 0] - V[b1, 0], V[b2, 1] - V[b1, 1], V[b2, 2] - V[b1, 2]
    eb20, eb21, eb22 = V[b0, 0] - V[b2, 0], V[b0, 1] - V[b2, 1], V[b0, 2] - V[b2, 2]
    na0 = ea01 * ea12 - ea02 * ea11
    na1 = ea02 * ea10 - ea00 * ea12
    na2 = ea00 * ea11 - ea01 * ea10
    if _sep(na0, na1, na2, V, ta, tb):
        return False
    nb0 = eb01 * eb12 - eb02 * eb11
    nb1 = eb02 * eb10 - eb00 * eb12
    nb2 = eb00 * eb11 - eb01 * eb10
    if _sep(nb0, nb1, nb2, V, ta, tb):
        return False
    EA = ((ea00, ea01, ea02), (ea10, ea11, ea12), (ea20, ea21, ea22))
    EB = ((eb00, eb01, eb02), (eb10, eb11, eb12), (eb20, eb21, eb22))
    for i in range(3):
        x0, x1, x2 = EA[i]
        for j in range(3):
            y0, y1, y2 = EB[j]
            if _sep(x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0, V, ta, tb):
                return False
    for i in range(3):
        x0, x1, x2 = EA[i]
        if _sep(na1 * x2 - na2 * x1, na2 * x0 - na0 * x2, na0 * x1 - na1 * x0, V, ta, tb):
            return False
        y0, y1, y2 = EB[i]
        if _sep(nb1 * y2 - nb2 * y1, nb2 * y0 - nb0 * y2, nb0 * y1 - nb1 * y0, V, ta, tb):
            return False
    return True


@njit(cache=True, inline="always")
def _sep_gap(ax0, ax1, ax2, ref2, V, ta, tb):  # pragma: no cover - compiled
    """The gap between the projections of ``ta`` and ``tb`` on the axis, over its length (< 0: they overlap).

    An axis shorter than 1e-6 of the product of the lengths it was crossed
    from (``ref2``: their squared lengths' product) is not trusted: -1.
    """
    n2 = ax0 * ax0 + ax1 * ax1 + ax2 * ax2
    if not n2 > 1e-12 * ref2:
        return -1.0
    o0, o1, o2 = V[ta[0], 0], V[ta[0], 1], V[ta[0], 2]
    amin = np.inf
    amax = -np.inf
    bmin = np.inf
    bmax = -np.inf
    for v in range(3):
        p = ta[v]
        x = (V[p, 0] - o0) * ax0 + (V[p, 1] - o1) * ax1 + (V[p, 2] - o2) * ax2
        amin = min(amin, x)
        amax = max(amax, x)
        q = tb[v]
        y = (V[q, 0] - o0) * ax0 + (V[q, 1] - o1) * ax1 + (V[q, 2] - o2) * ax2
        bmin = min(bmin, y)
        bmax = max(bmax, y)
    return max(bmin - amax, amin - bmax) / np.sqrt(n2)


@njit(cache=True)
def _gap(V, ta, tb, enough):  # pragma: no cover - compiled
    """A lower bound on the distance between triangles ``ta`` and ``tb``: the widest gap over the 17 axes (0: they meet).

    Stops at the first axis whose gap reaches ``enough``.
    """
    a0, a1, a2 = ta[0], ta[1], ta[2]
    b0, b1, b2 = tb[0], tb[1], tb[2]
    EA = ((V[a1, 0] - V[a0, 0], V[a1, 1] - V[a0, 1], V[a1, 2] - V[a0, 2]),
          (V[a2, 0] - V[a1, 0], V[a2, 1] - V[a1, 1], V[a2, 2] - V[a1, 2]),
          (V[a0, 0] - V[a2, 0], V[a0, 1] - V[a2, 1], V[a0, 2] - V[a2, 2]))
    EB = ((V[b1, 0] - V[b0, 0], V[b1, 1] - V[b0, 1], V[b1, 2] - V[b0, 2]),
          (V[b2, 0] - V[b1, 0], V[b2, 1] - V[b1, 1], V[b2, 2] - V[b1, 2]),
          (V[b0, 0] - V[b2, 0], V[b0, 1] - V[b2, 1], V[b0, 2] - V[b2, 2]))
    la = (EA[0][0] ** 2 + EA[0][1] ** 2 + EA[0][2] ** 2, EA[1][0] ** 2 + EA[1][1] ** 2 + EA[1][2] ** 2,
          EA[2][0] ** 2 + EA[2][1] ** 2 + EA[2][2] ** 2)
    lb = (EB[0][0] ** 2 + EB[0][1] ** 2 + EB[0][2] ** 2, EB[1][0] ** 2 + EB[1][1] ** 2 + EB[1][2] ** 2,
          EB[2][0] ** 2 + EB[2][1] ** 2 + EB[2][2] ** 2)
    x0, x1, x2 = EA[0]
    y0, y1, y2 = EA[1]
    na0, na1, na2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    x0, x1, x2 = EB[0]
    y0, y1, y2 = EB[1]
    nb0, nb1, nb2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    lna = na0 * na0 + na1 * na1 + na2 * na2
    lnb = nb0 * nb0 + nb1 * nb1 + nb2 * nb2
    g = max(0.0, _sep_gap(na0, na1, na2, la[0] * la[1], V, ta, tb))
    if g >= enough:
        return g
    g = max(g, _sep_gap(nb0, nb1, nb2, lb[0] * lb[1], V, ta, tb))
    for i in range(3):
        x0, x1, x2 = EA[i]
        g = max(g, _sep_gap(na1 * x2 - na2 * x1, na2 * x0 - na0 * x2, na0 * x1 - na1 * x0, lna * la[i], V, ta, tb))
        y0, y1, y2 = EB[i]
        g = max(g, _sep_gap(nb1 * y2 - nb2 * y1, nb2 * y0 - nb0 * y2, nb0 * y1 - nb1 * y0, lnb * lb[i], V, ta, tb))
        if g >= enough:
            return g
    for i in range(3):
        x0, x1, x2 = EA[i]
        for j in range(3):
            y0, y1, y2 = EB[j]
            g = max(g, _sep_gap(x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0, la[i] * lb[j], V, ta, tb))
        if g >= enough:
            return g
    return g


@njit(cache=True, inline="always")
def _spread(v):  # pragma: no cover - compiled
    """The low 10 bits of ``v`` spread to every third bit (for a Morton code)."""
    v &= 1023
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


@njit(cache=True, inline="always")
def _bucket(x, y, z, mask):  # pragma: no cover - compiled
    """The hash bucket of grid cell (x, y, z): its Morton code (neighbour cells, neighbour buckets)."""
    return (_spread(x) | (_spread(y) << 1) | (_spread(z) << 2)) & mask


@njit(cache=True)
def _grid(V, F, query, h, pad):  # pragma: no cover - compiled
    """Boxes of the triangles and the hash grid of those whose box meets the query triangles' bounding box.

    Returns ``lo``, ``hi`` (m, 3) the boxes (grown by ``pad`` on every side), ``clo`` (m, 3) their low cells,
    ``start`` (buckets + 1,) and ``tri`` (entries,) the buckets' triangles
    (counting sort), the bucket mask and the largest bucket's size. The cell
    ``h`` grows 1.5x while the boxes span more than 12 cells per triangle.
    """
    m = F.shape[0]
    lo = np.empty((m, 3))
    hi = np.empty((m, 3))
    qlo = np.full(3, np.inf)
    qhi = np.full(3, -np.inf)
    for t in range(m):
        for c in range(3):
            a, b, d = V[F[t, 0], c], V[F[t, 1], c], V[F[t, 2], c]
            lo[t, c] = min(a, min(b, d)) - pad
            hi[t, c] = max(a, max(b, d)) + pad
            if query[t]:
                qlo[c] = min(qlo[c], lo[t, c])
                qhi[c] = max(qhi[c], hi[t, c])
    use = np.zeros(m, np.bool_)
    n_use = 0
    for t in range(m):
        use[t] = (lo[t, 0] <= qhi[0] and hi[t, 0] >= qlo[0] and lo[t, 1] <= qhi[1] and hi[t, 1] >= qlo[1]
                  and lo[t, 2] <= qhi[2] and hi[t, 2] >= qlo[2])
        n_use += use[t]
    clo = np.zeros((m, 3), np.int64)
    chi = np.zeros((m, 3), np.int64)
    while True:
        total = 0
        for t in range(m):
            if use[t]:
                n = 1
                for c in range(3):
                    clo[t, c] = np.int64(np.floor((lo[t, c] - qlo[c]) / h))
                    chi[t, c] = np.int64(np.floor((hi[t, c] - qlo[c]) / h))
                    n *= chi[t, c] - clo[t, c] + 1
                total += n
        if total <= 12 * n_use:
            break
        h *= 1.5
    nb = 1024
    while nb < total:
        nb *= 2
    mask = nb - 1
    start = np.zeros(nb + 1, np.int64)
    for t in range(m):
        if use[t]:
            for x in range(clo[t, 0], chi[t, 0] + 1):
                for y in range(clo[t, 1], chi[t, 1] + 1):
                    for z in range(clo[t, 2], chi[t, 2] + 1):
                        start[_bucket(x, y, z, mask) + 1] += 1
    most = 0
    for b in range(nb):
        most = max(most, start[b + 1])
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    tri = np.empty(total, np.int64)
    for t in range(m):
        if use[t]:
            for x in range(clo[t, 0], chi[t, 0] + 1):
                for y in range(clo[t, 1], chi[t, 1] + 1):
                    for z in range(clo[t, 2], chi[t, 2] + 1):
                        b = _bucket(x, y, z, mask)
                        tri[fill[b]] = t
                        fill[b] += 1
    return lo, hi, clo, start, tri, mask, most


@njit(cache=True, parallel=True)
def _grid_pairs(V, F, query, lo, hi, clo, start, tri, mask, most, hit, gaps):  # pragma: no cover - compiled
    """Mark ``hit[s, t]`` for both triangles of every intersecting pair with a query triangle.

    Per bucket, every query triangle against every other entry: boxes first
    (a branch-free pass that lists the overlaps), then the pair is kept only
    in the bucket of the low corner of its two boxes' low cells (so in one
    cell), then shared vertices, then :func:`_tri_tri`. Buckets are dealt to
    the ``hit.shape[0]`` stripes round-robin; stripe ``s`` writes row ``s``.
    With ``gaps`` (m, 3) float of as many rows instead of none, each pair's
    :func:`_gap` lowers ``gaps[s, i]`` and ``gaps[s, j]`` instead.
    """
    nt = hit.shape[0]
    clearance = gaps.shape[1] > 0
    nb = start.size - 1
    for s in prange(nt):
        out = hit[s]
        L0 = np.empty(most)
        L1 = np.empty(most)
        L2 = np.empty(most)
        H0 = np.empty(most)
        H1 = np.empty(most)
        H2 = np.empty(most)
        ids = np.empty(most, np.int64)
        isq = np.empty(most, np.bool_)
        qs = np.empty(most, np.int64)
        cand = np.empty(most, np.int64)
        for b in range(s, nb, nt):
            e0 = start[b]
            n = start[b + 1] - e0
            if n < 2:
                continue
            nq = 0
            for k in range(n):
                t = tri[e0 + k]
                ids[k] = t
                L0[k] = lo[t, 0]
                L1[k] = lo[t, 1]
                L2[k] = lo[t, 2]
                H0[k] = hi[t, 0]
                H1[k] = hi[t, 1]
                H2[k] = hi[t, 2]
                isq[k] = query[t]
                if query[t]:
                    qs[nq] = k
                    nq += 1
            for a in range(nq):
                ka = qs[a]
                la0, la1, la2, ha0, ha1, ha2 = L0[ka], L1[ka], L2[ka], H0[ka], H1[ka], H2[ka]
                nc = 0
                for kb in range(n):
                    # boxes overlap, and a pair of query triangles is taken from its first entry
                    ov = ((la0 <= H0[kb]) & (L0[kb] <= ha0) & (la1 <= H1[kb]) & (L1[kb] <= ha1)
                          & (la2 <= H2[kb]) & (L2[kb] <= ha2) & (kb != ka) & ~(isq[kb] & (kb < ka)))
                    cand[nc] = kb
                    nc += ov
                i = ids[ka]
                for c in range(nc):
                    j = ids[cand[c]]
                    if _bucket(max(clo[i, 0], clo[j, 0]), max(clo[i, 1], clo[j, 1]),
                               max(clo[i, 2], clo[j, 2]), mask) != b:
                        continue  # the pair is looked at in another cell
                    if not clearance and out[i] and out[j]:
                        continue
                    if (F[i, 0] == F[j, 0] or F[i, 0] == F[j, 1] or F[i, 0] == F[j, 2]
                            or F[i, 1] == F[j, 0] or F[i, 1] == F[j, 1] or F[i, 1] == F[j, 2]
                            or F[i, 2] == F[j, 0] or F[i, 2] == F[j, 1] or F[i, 2] == F[j, 2]):
                        continue
                    if clearance:
                        enough = max(gaps[s, i], gaps[s, j])  # a gap this wide lowers neither
                        g = _gap(V, F[i], F[j], enough)
                        gaps[s, i] = min(gaps[s, i], g)
                        gaps[s, j] = min(gaps[s, j], g)
                    elif _tri_tri(V, F[i], F[j]):
                        out[i] = True
                        out[j] = True


@njit(cache=True)
def _moving(V0, D, F, clearance, tol, V, query):  # pragma: no cover - compiled
    """``V = V0 + D``; ``query[t]``: triangle ``t`` has a vertex moving by more than ``tol`` and half its clearance."""
    n = V0.shape[0]
    step = np.empty(n)
    for v in range(n):
        V[v, 0] = V0[v, 0] + D[v, 0]
        V[v, 1] = V0[v, 1] + D[v, 1]
        V[v, 2] = V0[v, 2] + D[v, 2]
        step[v] = np.sqrt(D[v, 0] * D[v, 0] + D[v, 1] * D[v, 1] + D[v, 2] * D[v, 2])
    for t in range(F.shape[0]):
        most = max(step[F[t, 0]], max(step[F[t, 1]], step[F[t, 2]]))
        query[t] = most > tol and most >= 0.5 * clearance[t]


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
    lo, hi, clo, start, tri, mask, most = _grid(V, F, query, h, 0.0)
    hit = np.zeros((_stripes(), F.shape[0]), np.bool_)
    _grid_pairs(V, F, query, lo, hi, clo, start, tri, mask, most, hit, np.zeros((hit.shape[0], 0)))
    return np.any(hit, axis=0)


def _clearance_numba(V: NDArray[np.float64], F: NDArray[np.int64], reach: float, h: float) -> NDArray[np.float64]:
    """Per triangle, a lower bound on its distance to the triangles sharing no vertex with it, capped at ``reach``."""
    query = np.ones(F.shape[0], np.bool_)
    lo, hi, clo, start, tri, mask, most = _grid(V, F, query, h, reach / 2)
    hit = np.zeros((_stripes(), F.shape[0]), np.bool_)
    gaps = np.full((hit.shape[0], F.shape[0]), reach)
    _grid_pairs(V, F, query, lo, hi, clo, start, tri, mask, most, hit, gaps)
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
            _moving(self.V0, np.ascontiguousarray(D), self.F, self.clearance, self.tol, V, query)
            hit = _hits_numba(V, self.F, query, self._h) if query.any() else np.zeros(m, np.bool_)
        else:
            step = np.sqrt(np.einsum("ij,ij->i", D, D))[self.F].max(1) if m else np.zeros(0)
            hit = _hits(self.V0 + D, self.F, (step > self.tol) & (step >= self.clearance / 2), self.backend)
        return hit & ~self.rest

    def count_new(self, D: NDArray[np.floating[Any]]) -> int:
        """How many triangles :meth:`new` finds."""
        return int(self.new(D).sum())
