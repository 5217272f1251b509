"""The region hierarchy: adjacent fine pieces merged level by level, those moving most alike first.

Step 5 of :mod:`workbench.methods.regions.segmentation`: every fine piece has a
per-shape motion energy (area-weighted squared relative motion);
:func:`merge_by_motion` merges the adjacent pair with the smallest
dissimilarity times Ward's size factor until each coarser level has about
``coarsen`` times the regions of the one below, so levels nest by construction.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from workbench.methods.regions.fine_pieces import FinePieces
from workbench.methods.regions.mesh_graph import piece_adjacency

__all__ = ["level_maps", "merge_by_motion"]


def level_maps(A: sp.csr_matrix, fine: FinePieces, area: NDArray[np.float64], levels: int, coarsen: float
               ) -> list[NDArray[np.int64]]:
    """Per level, the region of every fine piece: ``levels`` arrays, level 0 the identity.

    Parameters
    ----------
    A : (n, n) sparse
        The mesh adjacency.
    fine : FinePieces
    area : (n,) float
        Vertex areas.
    levels : int
        Levels of the hierarchy (>= 1).
    coarsen : float
        Each level has about ``coarsen`` times the regions of the next finer one.
    """
    lab0, rel = fine.labels, fine.rel
    R0 = fine.count
    # motion energy per shape of every piece: E[r, k] = sum_v area_v rel_k(v)^2
    fidx = np.flatnonzero(lab0 >= 0)
    P = sp.csr_matrix((area[fidx], (lab0[fidx], np.arange(fidx.size))), shape=(R0, fidx.size))
    feats = np.asarray(P @ (rel[:, fidx] ** 2).T)
    wpiece = np.asarray(P.sum(axis=1)).ravel()
    C = piece_adjacency(A, lab0, R0)
    counts: list[int] = []
    c = R0
    for _ in range(levels - 1):
        c = max(1, round(c * coarsen))
        counts.append(c)
    pmirror = None
    if fine.mirror is not None and R0:
        # mirror piece = the piece holding the mirror images of most of its vertices
        M = sp.csr_matrix((area[fidx], (lab0[fidx], np.maximum(lab0[fine.mirror[0][fidx]], 0))), shape=(R0, R0))
        pmirror = np.asarray(M.argmax(axis=1)).ravel().astype(np.int64)
    merges = merge_by_motion(C, feats, wpiece, counts, pmirror) if R0 else [np.zeros(0, np.int64) for _ in counts]
    return [np.arange(R0, dtype=np.int64), *merges]


def merge_by_motion(
    C: NDArray[np.float64],
    energy: NDArray[np.float64],
    w: NDArray[np.float64],
    counts: Sequence[int],
    mirror: NDArray[np.int64] | None = None,
) -> list[NDArray[np.int64]]:
    """Greedy merging of adjacent regions whose motion is most alike.

    The cost of merging ``A`` and ``B`` is ``(1 - cos(E_A, E_B)) w_A w_B / (w_A + w_B)``:
    the dissimilarity of their per-shape motion energies (the same shapes move
    both → near 0) times Ward's size factor (small regions go first, so one region
    does not snowball). A merged region's energy and area are the sums. Ties go
    to the lower index.

    Parameters
    ----------
    C : (R, R) float
        Edge counts between pieces (adjacency).
    energy : (R, k) float
        Non-negative motion energy of each piece per shape.
    w : (R,) float
        Piece areas.
    counts : sequence of int
        Decreasing target numbers of regions, one per coarser level.
    mirror : (R,) int, optional
        Mirror piece of each piece; when given, the mirror pair of every merge is
        merged in the same step, so a symmetric input stays symmetric (a level
        may then end one region below its target).

    Returns
    -------
    list of (R,) int64
        Per target, the cluster id (0..count-1, compact) of every piece.
    """
    R = C.shape[0]
    adj = C > 0
    E = energy.astype(np.float64).copy()
    wt = w.astype(np.float64).copy()
    cluster = np.arange(R)
    alive = np.ones(R, bool)
    out: list[NDArray[np.int64]] = []
    n_alive = R

    def merge(i: int, j: int) -> None:
        E[i] += E[j]
        wt[i] += wt[j]
        adj[i] |= adj[j]
        adj[:, i] |= adj[:, j]
        adj[i, i] = False
        alive[j] = False
        adj[j] = False
        adj[:, j] = False
        cluster[cluster == j] = i

    for target in counts:
        while n_alive > target:
            ii, jj = np.nonzero(np.triu(adj & alive[:, None] & alive[None, :], 1))
            if ii.size == 0:
                break  # no adjacent pair left: the level keeps more regions
            nrm = np.maximum(np.linalg.norm(E, axis=1), 1e-300)
            dissim = 1.0 - np.einsum("ij,ij->i", E[ii], E[jj]) / (nrm[ii] * nrm[jj])
            cost = dissim * wt[ii] * wt[jj] / (wt[ii] + wt[jj])
            b = int(np.argmin(cost))
            i, j = int(ii[b]), int(jj[b])
            mi = mj = -1
            if mirror is not None:
                mi, mj = int(cluster[mirror[i]]), int(cluster[mirror[j]])
            merge(i, j)
            n_alive -= 1
            if mirror is not None:
                mi, mj = int(cluster[mi]), int(cluster[mj])
                if mi != mj and adj[mi, mj]:
                    merge(min(mi, mj), max(mi, mj))
                    n_alive -= 1
        _, compact = np.unique(cluster, return_inverse=True)
        out.append(compact.astype(np.int64))
    return out
