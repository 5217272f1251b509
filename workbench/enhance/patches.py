"""Seed-and-grow patches of ~``patch_size`` vertices for the compressed shape space (Bermano 2014, §4.2).

Seeds: per connected piece of the mesh, ``max(1, round(n_piece / patch_size))``
random vertices (the paper's "random seed-and-grow"; uniform over *vertices*,
so denser parts get more seeds). Growth: every vertex joins the seed nearest in
hops along the edge graph (multi-source Dijkstra, ``scipy.sparse.csgraph.dijkstra``
with ``min_only``) — a graph Voronoi partition, so each vertex is in exactly one
patch and each patch is connected (a vertex's shortest-path predecessor belongs
to the same seed). Then ``relax`` Lloyd-style rounds even the sizes out (each
seed moves to the vertex of its patch nearest the patch centroid; a patch over
twice the target gets a second seed at its farthest vertex). Triangles take the
patch most of their corners are in (ties: the first corner's).

Why not Euclidean farthest-point seeds and edge-length distances: they give
patches of equal *area*, and the sample head's vertex density varies by ~10x
(dense face, coarse scalp), so vertex counts ranged 5–1100 for a target of 100;
random seeds with hop distances give ~35–165 (median ~95) after 5 rounds.

Hand-written because it is a few lines around scipy's Dijkstra; the paper's
"random seed-and-grow" has no library implementation.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components, dijkstra

__all__ = ["face_patches", "grow_patches"]


def _edge_graph(V: NDArray[np.float64], F: NDArray[np.int64]) -> sp.csr_matrix:
    """The vertex graph with unit edge weights (hop counts)."""
    n = V.shape[0]
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = np.ones(len(e))
    A = sp.csr_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n))
    return sp.csr_matrix(A + A.T)


def grow_patches(
    V: ArrayLike, F: ArrayLike, patch_size: int = 100, *, seed: int = 0, relax: int = 5
) -> NDArray[np.int32]:
    """Patch label per vertex, (n,) int32 in ``[0, n_patches)``.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    patch_size : int
        Target vertices per patch (>= 1).
    seed : int
        Random start of the farthest-point sampling in each piece.
    relax : int
        Lloyd-style rounds (move seeds to patch centroids, split patches over twice the target).
    """
    v = np.asarray(V, np.float64)
    f = np.asarray(F, np.int64)
    if int(patch_size) != patch_size or patch_size < 1:
        raise ValueError(f"patch_size must be an integer >= 1, got {patch_size!r}")
    graph = _edge_graph(v, f)
    n_pieces, piece = connected_components(graph, directed=False)
    rng = np.random.default_rng(seed)
    seeds: list[int] = []
    for p in range(n_pieces):
        ids = np.flatnonzero(piece == p)
        k = max(1, round(len(ids) / patch_size))
        seeds.extend(rng.choice(ids, k, replace=False).tolist())
    seed_ids = np.asarray(seeds, np.int64)
    for _ in range(int(relax)):
        seed_ids = _relax(v, graph, seed_ids, patch_size)
    return _grow(graph, seed_ids)[0]


def _grow(graph: sp.csr_matrix, seeds: NDArray[np.int64]) -> tuple[NDArray[np.int32], NDArray[np.float64]]:
    """Label of the graph-nearest seed per vertex and the distance to it."""
    dist, _, sources = dijkstra(graph, directed=False, indices=seeds, min_only=True, return_predecessors=True)
    lookup = np.full(graph.shape[0], -1, np.int64)
    lookup[seeds] = np.arange(len(seeds))
    return lookup[sources].astype(np.int32), dist


def _relax(
    v: NDArray[np.float64], graph: sp.csr_matrix, seeds: NDArray[np.int64], patch_size: int
) -> NDArray[np.int64]:
    """One Lloyd-style round: each seed moves to the vertex of its patch nearest the patch centroid;
    patches over twice the target get a second seed at their farthest vertex."""
    lab, dist = _grow(graph, seeds)
    k = len(seeds)
    count = np.bincount(lab, minlength=k)
    cen = np.zeros((k, 3))
    np.add.at(cen, lab, v)
    cen /= np.maximum(count, 1)[:, None]
    d = np.linalg.norm(v - cen[lab], axis=1)
    order = np.lexsort((d, lab))  # by patch, nearest to its centroid first
    first = np.ones(len(order), bool)
    first[1:] = lab[order][1:] != lab[order][:-1]
    moved = np.full(k, -1, np.int64)
    moved[lab[order][first]] = order[first]
    new = np.where(moved >= 0, moved, seeds)
    big = np.flatnonzero(count > 2 * patch_size)
    if len(big):
        order = np.lexsort((-dist, lab))
        first = np.ones(len(order), bool)
        first[1:] = lab[order][1:] != lab[order][:-1]
        far = np.full(k, -1, np.int64)
        far[lab[order][first]] = order[first]
        new = np.concatenate([new, far[big]])
    return np.unique(new)


def face_patches(F: ArrayLike, vertex_patch: ArrayLike) -> NDArray[np.int32]:
    """Patch of each triangle: the label most of its corners carry (ties: the first corner's), (m,) int32."""
    lab = np.asarray(vertex_patch)[np.asarray(F, np.int64)]
    out = lab[:, 0].copy()
    two = (lab[:, 1] == lab[:, 2]) & (lab[:, 1] != lab[:, 0])
    out[two] = lab[two, 1]
    return out.astype(np.int32)


