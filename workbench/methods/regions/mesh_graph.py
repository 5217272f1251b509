"""Per-vertex labels on a triangle mesh's edge graph: adjacency, pieces, morphology, smoothing.

The graph operations the region segmentation and the region edits share: the
vertex adjacency of a mesh, connected pieces of equal labels and the edge
counts between them, a morphological close of a vertex mask, absorbing small
pieces into a neighbour, a one-ring mode filter of labels, and the one-ring
averaging that turns disjoint cores into overlapping blend weights
(Joshi et al. 2003, §2 "Segmentation"; the reasons for each choice are in
:mod:`workbench.methods.regions.segmentation`).

Hand-written on scipy's sparse matrices and ``csgraph.connected_components``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

__all__ = [
    "absorb_small_pieces",
    "dilate",
    "label_pieces",
    "mesh_adjacency",
    "mode_filter",
    "morphological_close",
    "piece_adjacency",
    "smooth_weights",
]


def mesh_adjacency(faces: NDArray[Any], n: int) -> sp.csr_matrix:
    """Vertex adjacency of a triangle mesh.

    Parameters
    ----------
    faces : (m, 3) int
    n : int
        Number of vertices.

    Returns
    -------
    A : (n, n) sparse CSR int8, symmetric, 1 where two vertices share an edge, 0 diagonal.
    """
    F = np.asarray(faces, dtype=np.int64)
    i = np.concatenate([F[:, 0], F[:, 1], F[:, 2], F[:, 1], F[:, 2], F[:, 0]])
    j = np.concatenate([F[:, 1], F[:, 2], F[:, 0], F[:, 0], F[:, 1], F[:, 2]])
    A = sp.csr_matrix((np.ones(i.size, np.int8), (i, j)), shape=(n, n))
    A.data[:] = 1  # duplicates (an edge in two triangles) summed to 2
    A.setdiag(0)
    A.eliminate_zeros()
    return A


def dilate(A: sp.csr_matrix, mask: NDArray[np.bool_], rings: int) -> NDArray[np.bool_]:
    m = mask.copy()
    for _ in range(rings):
        m = m | (A @ m.astype(np.int32) > 0)
    return m


def morphological_close(A: sp.csr_matrix, mask: NDArray[np.bool_], domain: NDArray[np.bool_], rings: int) -> NDArray[np.bool_]:
    """Morphological close (dilate, then erode) inside ``domain``."""
    m = dilate(A, mask, rings) & domain
    for _ in range(rings):
        # erode: keep v if no neighbour (inside the domain) is outside the mask
        outside = (domain & ~m).astype(np.int32)
        m = m & ~(A @ outside > 0)
    return m


def label_pieces(A: sp.csr_matrix, labels: NDArray[np.int64]) -> NDArray[np.int64]:
    """Connected components of equal non-negative labels; -1 stays -1."""
    n = labels.size
    coo = A.tocoo()
    keep = (labels[coo.row] >= 0) & (labels[coo.row] == labels[coo.col])
    G = sp.csr_matrix((np.ones(int(keep.sum()), np.int8), (coo.row[keep], coo.col[keep])), shape=(n, n))
    _, comp = connected_components(G, directed=False)
    out = np.full(n, -1, np.int64)
    fg = labels >= 0
    _, out[fg] = np.unique(comp[fg], return_inverse=True)
    return out


def piece_adjacency(A: sp.csr_matrix, labels: NDArray[np.int64], R: int) -> NDArray[np.float64]:
    """(R, R) number of mesh edges between pieces (diagonal zeroed)."""
    fg = np.flatnonzero(labels >= 0)
    P = sp.csr_matrix((np.ones(fg.size), (fg, labels[fg])), shape=(labels.size, R))
    C = np.asarray((P.T @ A.astype(np.float64) @ P).todense())
    np.fill_diagonal(C, 0.0)
    return C


def absorb_small_pieces(
    A: sp.csr_matrix,
    labels: NDArray[np.int64],
    area: NDArray[np.float64],
    min_area: float,
    side: NDArray[np.int8] | None = None,
) -> NDArray[np.int64]:
    """Merge pieces below ``min_area`` into the neighbour sharing most edges (else background).

    ``labels`` must be connected pieces 0..R-1; returns relabelled connected pieces.
    With ``side`` (per vertex: 0 = -x, 1 = on the mid-plane, 2 = +x; pieces must
    not mix sides), a neighbour on the same side is preferred (cross-side edges
    count 1/1000) and mid-plane pieces are merged last, into the neighbour they
    share most edges with, so a mirror-symmetric input gives mirror-symmetric
    regions apart from the mid-plane column itself.
    """
    R = int(labels.max()) + 1 if (labels >= 0).any() else 0
    if R == 0:
        return labels
    C = piece_adjacency(A, labels, R)
    fg = labels >= 0
    center = np.zeros(R, bool)
    if side is not None:
        pside = np.zeros(R, np.int8)
        pside[labels[fg]] = side[fg]
        center = pside == 1
        C = C * np.where(pside[:, None] == pside[None, :], 1.0, 1e-3)
    sizes = np.bincount(labels[fg], weights=area[fg], minlength=R)
    target = np.arange(R)
    alive = np.ones(R, bool)

    def merge(i: int, allowed: NDArray[np.bool_]) -> None:
        alive[i] = False
        row = np.where(allowed & alive, C[i], 0.0)
        if row.max() > 0:
            j = int(np.argmax(row))
            target[target == i] = j
            sizes[j] += sizes[i]
            C[j] += C[i]
            C[:, j] += C[:, i]
            C[j, j] = 0.0
        else:
            target[target == i] = -1
        C[i] = 0.0
        C[:, i] = 0.0

    while True:
        cand = np.flatnonzero(alive & ~center & (sizes < min_area))
        if cand.size == 0:
            break
        merge(int(cand[np.argmin(sizes[cand])]), ~center)
    for i in np.flatnonzero(center):
        merge(int(i), ~center)
    out = np.where(fg, target[np.maximum(labels, 0)], -1)
    return label_pieces(A, out)


def mode_filter(A1: sp.csr_matrix, labels: NDArray[np.int64], iterations: int) -> NDArray[np.int64]:
    """Each foreground vertex takes the most frequent foreground label of its closed one-ring."""
    lab = labels.copy()
    fg = np.flatnonzero(lab >= 0)
    if fg.size == 0:
        return lab
    sub = A1[fg][:, fg]
    for _ in range(iterations):
        _, inv = np.unique(lab[fg], return_inverse=True)
        R = int(inv.max()) + 1
        H = sp.csr_matrix((np.ones(fg.size), (np.arange(fg.size), inv)), shape=(fg.size, R))
        counts = np.asarray((sub @ H).todense())
        counts[np.arange(fg.size), inv] += 0.5  # ties keep the current label
        new = np.argmax(counts, axis=1)
        uniq = np.unique(lab[fg])
        changed = uniq[new] != lab[fg]
        if not changed.any():
            break
        lab[fg] = uniq[new]
    return lab


def smooth_weights(
    S: sp.csr_matrix, labels: NDArray[np.int64], R: int, domain: NDArray[np.bool_], rings: int
) -> sp.csr_matrix:
    """(n, R + 1) weights ``S^rings χ`` on ``domain`` rows (last column = background)."""
    n = labels.size
    idx = np.flatnonzero(domain)
    col = np.where(labels[idx] >= 0, labels[idx], R)
    X = sp.csr_matrix((np.ones(idx.size), (idx, col)), shape=(n, R + 1))
    for _ in range(rings):
        X = S @ X
    return sp.csr_matrix(X)
