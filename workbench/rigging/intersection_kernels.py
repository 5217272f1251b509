"""The numba kernels of :mod:`workbench.rigging.intersections`: the grid broad phase and the separating-axis test.

Compiled loops (numba is the optional ``fast`` extra; without it
:mod:`workbench._numba` makes them plain Python and the intersections module
takes its numpy path instead). The entry points:

* :func:`grid` — each triangle's bounding box (grown by ``pad``) into the
  buckets of the grid cells it spans (Morton-coded cells, a counting sort);
* :func:`grid_pairs` — per bucket, every queried triangle against every
  other entry: boxes first, then the 17-axis separating-axis test; with
  ``gaps`` it keeps each triangle's clearance instead;
* :func:`moving_triangles` — ``V = V0 + D`` and the triangles a displacement
  moves far enough to meet another.

How and why are in the intersections module's docstring.
"""

from __future__ import annotations

import numpy as np

from workbench._numba import njit, prange

__all__ = ["grid", "grid_pairs", "moving_triangles"]


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
def grid(V, F, query, h, pad):  # pragma: no cover - compiled
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
def grid_pairs(V, F, query, lo, hi, clo, start, tri, mask, most, hit, gaps):  # pragma: no cover - compiled
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
def moving_triangles(V0, D, F, clearance, tol, V, query):  # pragma: no cover - compiled
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
