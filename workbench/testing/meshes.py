"""Mesh surgery with a known answer: re-triangulate, renumber, add a bust, cut holes.

Array level (``V``, ``F``), no :class:`~workbench.model.FaceModel`:

* :func:`split_remesh` — a new triangulation of the same surface, every new
  vertex on it and none where an old one was, with the exact interpolation
  matrix ``W`` (``V2 == W @ V``);
* :func:`permute_vertices` — the same mesh in another vertex order;
* :func:`add_bust` — rings of vertices below an open neck, flaring into shoulders;
* :func:`cut_hole` / :func:`keep_vertices` — remove a ball of the surface, or
  keep a set of vertices and the triangles among them.

:mod:`workbench.testing.faces` builds generated faces from these.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

__all__ = ["add_bust", "cut_hole", "keep_vertices", "permute_vertices", "split_remesh"]


def _unique_edges(F: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Unique undirected edges ``(e, 2)`` and ``(m, 3)``: column ``k`` is the id of edge ``(F[:, k], F[:, k + 1])``."""
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(he, axis=1)
    edges, inv = np.unique(key, axis=0, return_inverse=True)
    m = F.shape[0]
    return edges, inv.reshape(3, m).T  # column k: edge (F[:, k], F[:, k+1])


def split_remesh(
    V: ArrayLike, F: ArrayLike, *, seed: int = 0, slide: float = 0.2, flips: float = 0.3
) -> tuple[NDArray[np.float64], NDArray[np.int64], sp.csr_matrix]:
    """A new triangulation of the same surface: every vertex on it, none where one was.

    Every triangle is split in four through a point on each edge (at a random
    0.35-0.65 of the edge), every old vertex slides along one of its edges by
    up to ``slide`` of it, and a share ``flips`` of the new edges inside the old
    triangles is flipped. All new vertices lie on the old piecewise-linear
    surface, so a per-vertex field ``f`` of the old mesh is exactly ``W @ f``
    on the new one.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    seed : int
    slide : float
        Largest slide of an old vertex along an edge, as a share of the edge (< 0.35).
    flips : float
        Share of the interior edges of the split triangles that are flipped.

    Returns
    -------
    V2 : (n2, 3) float
    F2 : (m2, 3) int
        Counter-clockwise like ``F``.
    W : (n2, n) sparse
        ``V2 == W @ V``; the same rows interpolate any per-vertex field.
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = V.shape[0]
    rng = np.random.default_rng(seed)
    edges, fe = _unique_edges(F)
    ne = edges.shape[0]
    t = np.asarray(rng.uniform(0.35, 0.65, ne), np.float64)
    # old vertices slide toward a random neighbour along their edge
    rows: list[NDArray[np.int64]] = [np.arange(n), np.arange(n)]
    cols: list[NDArray[np.int64]] = [np.arange(n), np.arange(n)]
    vals: list[NDArray[np.float64]] = [np.ones(n), np.zeros(n)]
    ends = np.concatenate([edges, edges[:, ::-1]])  # (2e, 2): (vertex, neighbour)
    order = rng.permutation(ends.shape[0])
    first = np.full(n, -1, np.int64)
    first[ends[order[::-1], 0]] = order[::-1]  # one random incident edge per vertex
    has = first >= 0
    s = np.where(has, rng.uniform(0.05, min(slide, 0.3), n), 0.0)
    vals[0] = 1.0 - s
    cols[1] = np.where(has, ends[np.maximum(first, 0), 1], np.arange(n))
    vals[1] = s
    # edge points
    rows += [n + np.arange(ne), n + np.arange(ne)]
    cols += [edges[:, 0], edges[:, 1]]
    vals += [1.0 - t, t]
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    ab, bc, ca = n + fe[:, 0], n + fe[:, 1], n + fe[:, 2]
    F2 = np.concatenate(
        [np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1), np.stack([ab, bc, ca], 1)]
    )
    parent = np.tile(np.arange(F.shape[0]), 4)
    n_old = np.cross(V[b] - V[a], V[c] - V[a])[parent]
    for it in range(8):  # an old vertex that slid across its own corner triangle slides half as far
        W = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n + ne, n)
        )
        W.sum_duplicates()
        W.eliminate_zeros()
        V2 = np.asarray(W @ V)
        n_new = np.cross(V2[F2[:, 1]] - V2[F2[:, 0]], V2[F2[:, 2]] - V2[F2[:, 0]])
        cos = (n_new * n_old).sum(1) / np.maximum(
            np.linalg.norm(n_new, axis=1) * np.linalg.norm(n_old, axis=1), 1e-300
        )
        bad = F2[cos < 0.2]
        back = np.unique(bad[bad < n])
        if back.size == 0:
            break
        vals[1][back] = 0.0 if it == 6 else 0.5 * vals[1][back]
        vals[0][back] = 1.0 - vals[1][back]
    if flips > 0:
        F2 = _flip_inner_edges(V2, F2, n_old[: F.shape[0]], flips, rng)
    return V2, F2, W


def _flip_inner_edges(
    V: NDArray[np.float64], F: NDArray[np.int64], parent_normal: NDArray[np.float64], share: float,
    rng: np.random.Generator,
) -> NDArray[np.int64]:
    """Flip a share of the edges between a corner triangle and the middle one (each middle edge once)."""
    F = F.copy()
    m = parent_normal.shape[0]
    # corner triangle k of face i (row k * m + i) shares an edge with the middle one (row 3 * m + i)
    used = np.zeros(m, bool)
    for corner in rng.permutation(3):
        pick = (rng.random(m) < share / 3.0) & ~used
        idx = np.flatnonzero(pick)
        c = corner * m + idx
        mid = 3 * m + idx
        # corner 0: (a, ab, ca) shares (ab, ca) with mid (ab, bc, ca); apex a, opposite bc
        # corner 1: (ab, b, bc) shares (bc, ab); apex b, opposite ca
        # corner 2: (ca, bc, c) shares (ca, bc); apex c, opposite ab
        apex = F[c, corner]
        opp = F[mid, (corner + 1) % 3]  # bc, ca, ab
        e0, e1 = {0: (F[c, 1], F[c, 2]), 1: (F[c, 2], F[c, 0]), 2: (F[c, 0], F[c, 1])}[corner]
        new1 = np.stack([apex, e0, opp], 1)
        new2 = np.stack([apex, opp, e1], 1)
        old_n = parent_normal[idx]
        ok = np.ones(idx.size, bool)
        for tri in (new1, new2):
            nn = np.cross(V[tri[:, 1]] - V[tri[:, 0]], V[tri[:, 2]] - V[tri[:, 0]])
            ok &= (nn * old_n).sum(1) > 0.2 * np.linalg.norm(nn, axis=1) * np.linalg.norm(old_n, axis=1)
        F[c[ok]] = new1[ok]
        F[mid[ok]] = new2[ok]
        used[idx[ok]] = True
    return F


def add_bust(
    V: ArrayLike, F: ArrayLike, loop: Sequence[int], *, rings: int = 12, drop: float = 0.25, flare: float = 1.6,
    up: ArrayLike = (0.0, 1.0, 0.0),
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Extend an open neck by ``rings`` rings of vertices below the boundary ``loop``, flaring into shoulders.

    Parameters
    ----------
    V, F
        The mesh; ``loop`` is an ordered boundary loop of it (``igl.boundary_loop_all``).
    rings : int
    drop : float
        How far the last ring is below the loop, as a share of the loop's width.
    flare : float
        Width of the last ring over the loop's (it widens smoothly).
    up : (3,) float
        The up direction.

    Returns
    -------
    V2, F2
        The old vertices first (same ids), the new rings after them; the new
        triangles continue the loop's orientation.
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    lp = np.asarray(loop, np.int64)
    u = np.asarray(up, np.float64)
    u = u / np.linalg.norm(u)
    P = V[lp]
    c = P.mean(0)
    radial = (P - c) - np.outer((P - c) @ u, u)
    width = 2.0 * float(np.linalg.norm(radial, axis=1).max())
    L = lp.size
    out = [V]
    ids: list[NDArray[np.int64]] = [lp]
    nxt = V.shape[0]
    for k in range(1, rings + 1):
        f = k / rings
        grow = 1.0 + (flare - 1.0) * f**2
        ring = c + radial * grow + np.outer(np.full(L, -drop * width * f), u)
        ring += np.outer(((P - c) @ u), u) * (1 - f)  # the loop's own height fades out
        out.append(ring)
        ids.append(np.arange(nxt, nxt + L))
        nxt += L
    V2 = np.concatenate(out)
    # orientation: the boundary edge (loop[i], loop[i+1]) runs one way in its face
    a, b = lp[0], lp[1]
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    forward = bool(((he[:, 0] == a) & (he[:, 1] == b)).any())
    tris = []
    for k in range(rings):
        r0, r1 = ids[k], ids[k + 1]
        r0n, r1n = np.roll(r0, -1), np.roll(r1, -1)
        t1 = np.stack([r0n, r0, r1], 1)
        t2 = np.stack([r0n, r1, r1n], 1)
        if not forward:
            t1, t2 = t1[:, ::-1], t2[:, ::-1]
        tris += [t1, t2]
    return V2, np.concatenate([F, *tris])


def cut_hole(
    V: ArrayLike, F: ArrayLike, centre: ArrayLike, radius: float
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Remove the triangles with a corner within ``radius`` of ``centre`` and the vertices left unused.

    Returns
    -------
    V2, F2
        The mesh with the hole.
    kept : (n2,) int
        Old id of every new vertex.
    """
    Vf = np.asarray(V, np.float64)
    near = np.linalg.norm(Vf - np.asarray(centre, np.float64), axis=1) < radius
    return keep_vertices(Vf, F, ~near)


def keep_vertices(
    V: ArrayLike, F: ArrayLike, keep: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Keep the triangles whose three corners are in ``keep`` (a boolean mask), and the vertices they use.

    Returns
    -------
    V2, F2
        The kept part, vertices in their old order.
    kept : (n2,) int
        Old id of every new vertex (``V2 == V[kept]``).
    """
    Vf = np.asarray(V, np.float64)
    Fi = np.asarray(F, np.int64)
    mask = np.asarray(keep, bool)
    Fi = Fi[mask[Fi].all(axis=1)]
    kept = np.unique(Fi)
    new = np.full(Vf.shape[0], -1, np.int64)
    new[kept] = np.arange(kept.size)
    return Vf[kept], new[Fi], kept


def permute_vertices(F: ArrayLike, n: int, *, seed: int = 0) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """A random new vertex order: ``order`` (new id -> old id) and the triangles renumbered.

    ``V[order]`` with the returned triangles is the same surface; any per-vertex
    field ``f`` of the old numbering is ``f[order]`` in the new one. The
    triangles are also listed in a random order (corners kept, so the
    orientation is too).
    """
    rng = np.random.default_rng(seed)
    order = rng.permutation(n).astype(np.int64)
    new = np.empty(n, np.int64)
    new[order] = np.arange(n)
    Fi = new[np.asarray(F, np.int64)]
    return order, Fi[rng.permutation(Fi.shape[0])]
