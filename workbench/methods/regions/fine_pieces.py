"""Fine blend regions: the foreground split into quasi-rigid pieces that keep features whole.

Step 4 of :mod:`workbench.methods.regions.segmentation`: each foreground vertex
is labelled by the shape that moves it most (relative to that shape's peak)
and by its side of the mid-plane; pieces are connected runs of equal labels,
smoothed by a one-ring mode filter, with small ones absorbed; then the piece
borders move so that every local one-sided feature lies in one piece
(:func:`keep_features_whole`). On a mirror-symmetric face the vertex and shape
mirror maps (:func:`mirror_maps`) make both sides break ties alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.methods.regions.mesh_graph import absorb_small_pieces, label_pieces, mode_filter

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = ["FinePieces", "fine_pieces", "keep_features_whole", "mirror_maps"]


@dataclass
class FinePieces:
    """The finest level's skin pieces and what they were cut by.

    Attributes
    ----------
    labels : (n,) int64
        Piece of every vertex, 0..R-1 (-1: background or not skin).
    rel : (k, n) float
        Each shape's displacement relative to its largest on the skin.
    side3 : (n,) int8
        Side of the mid-plane: 0 = -x, 1 = on it, 2 = +x.
    mirror : ((n,) int, (k,) int) or None
        Vertex and shape mirror maps when the skin is mirror-symmetric.
    """

    labels: NDArray[np.int64]
    rel: NDArray[np.float32] | NDArray[np.float64]
    side3: NDArray[np.int8]
    mirror: tuple[NDArray[np.intp], NDArray[np.intp]] | None

    @property
    def count(self) -> int:
        return int(self.labels.max()) + 1 if (self.labels >= 0).any() else 0


def fine_pieces(
    model: FaceModel,
    A: sp.csr_matrix,
    A1: sp.csr_matrix,
    fg: NDArray[np.bool_],
    skin: NDArray[np.bool_],
    mags: NDArray[np.float32],
    area: NDArray[np.float64],
    act_area: float,
    min_area: float,
    mid: float,
    diag: float,
    *,
    split_midline: bool,
    keep_features: bool,
) -> FinePieces:
    """Cut the foreground ``fg`` into the finest pieces (the module docstring).

    Parameters
    ----------
    A, A1 : (n, n) sparse
        The mesh adjacency, without and with the diagonal.
    fg, skin : (n,) bool
        Foreground and skin vertices.
    mags : (k, n) float
        Each shape's displacement length times its slider range.
    area : (n,) float
        Vertex areas; ``act_area`` that of the moving skin, ``min_area`` the smallest piece kept.
    mid, diag : float
        The mid-plane's x and the moving skin's diagonal.
    """
    V = model.vertices
    # relative motion: each shape scaled to its own peak, so broad strong shapes
    # (jawOpen) do not swallow the local ones (mouthSmile) that peak elsewhere
    rel = mags / np.maximum(mags[:, skin].max(axis=1, initial=0.0), 1e-30)[:, None]
    mirror = mirror_maps(model, skin, mid, diag) if split_midline else None
    if mirror is not None:
        # a mirror-symmetric face: average each vertex with its mirror image so
        # near-ties between shapes (the targets are symmetric only to ~1e-2 dm)
        # break the same way on both sides
        vmap, kmap = mirror
        rel = 0.5 * (rel + rel[kmap][:, vmap])
    dom = np.argmax(rel, axis=0).astype(np.int64)
    # side of the mid-plane: 0 = -x, 1 = on it (within 1e-4 of the face size), 2 = +x
    side3 = (np.sign(np.where(np.abs(V[:, 0] - mid) <= 1e-4 * diag, 0.0, V[:, 0] - mid)) + 1).astype(np.int8)
    key = dom * 3 + (side3 if split_midline else 0)
    lab0 = label_pieces(A, np.where(fg, key, -1))
    lab0 = mode_filter(A1, lab0, 2)
    if split_midline:
        lab0 = label_pieces(A, np.where(lab0 >= 0, lab0 * 3 + side3, -1))
    lab0 = absorb_small_pieces(A, lab0, area, min_area, side3 if split_midline else None)
    if keep_features:
        lab0 = keep_features_whole(A, lab0, rel, skin, side3, area, act_area, min_area)
    return FinePieces(lab0, rel, side3, mirror)


def mirror_maps(
    model: FaceModel, skin: NDArray[np.bool_], mid: float, diag: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]] | None:
    """Vertex and shape mirror permutations if the skin is mirror-symmetric about x = mid.

    Returns ``(vmap (n,), kmap (k,))`` with ``vmap[v]`` the vertex nearest to the
    reflection of ``v`` (identity off the skin) and ``kmap[k]`` the shape named as
    the mirror of shape ``k`` (itself if unsided), or None if any skin vertex has no
    mirror partner within ``1e-3 * diag`` or a sided shape has no partner.
    """
    from workbench.arkit import mirror_name

    V = model.vertices
    idx = np.flatnonzero(skin)
    refl = V[idx].copy()
    refl[:, 0] = 2.0 * mid - refl[:, 0]
    d, j = cKDTree(V[idx]).query(refl)
    if idx.size == 0 or float(np.max(d)) > 1e-3 * diag:
        return None
    vmap = np.arange(model.n_vertices)
    vmap[idx] = idx[np.asarray(j)]
    names = model.shape_names
    pos = {nm: i for i, nm in enumerate(names)}
    kmap = np.arange(len(names))
    for i, nm in enumerate(names):
        mn = mirror_name(nm)
        if mn is not None:
            if mn not in pos:
                return None
            kmap[i] = pos[mn]
    return vmap, kmap


def keep_features_whole(
    A: sp.csr_matrix,
    lab0: NDArray[np.int64],
    rel: NDArray[np.float32] | NDArray[np.float64],
    skin: NDArray[np.bool_],
    side3: NDArray[np.int8],
    area: NDArray[np.float64],
    act_area: float,
    min_area: float,
    *,
    strong: float = 0.5,
    max_support: float = 0.1,
    nested: float = 0.6,
    rounds: int = 2,
) -> NDArray[np.int64]:
    """Move fine-piece borders so that every local one-sided feature lies in one piece.

    A *feature* is a shape whose strong support ``S_k = {v on the skin: rel_k(v) >=
    strong}`` covers at most ``max_support`` of the moving skin area, at least 80 %
    of it on one side of the mid-plane. A feature whose support lies at least
    ``nested`` inside a larger feature's support (the outer brow inside the brow)
    belongs to that feature's family; the family's *home* is the piece of its side
    holding most of the largest member's support. Every vertex of some ``S_k``
    (background ones included, the mid-plane column excluded) moves to the home
    of the most local feature that holds it (the smallest support: the inner
    brow goes with the brow, whose support it is half of, not with the nose
    wrinkler, whose support it is a quarter of). Two rounds, the homes
    recomputed in between; pieces left disconnected split, and splinters below
    ``min_area`` are absorbed as in step 4.

    Returns
    -------
    (n,) int64
        Connected pieces 0..R-1, -1 background.
    """
    sided = skin & (side3 != 1)
    sup = (rel >= strong) & sided[None, :]
    areas = sup.astype(np.float64) @ area
    left = (sup & (side3 == 2)[None, :]).astype(np.float64) @ area
    one_sided = np.maximum(left, areas - left) >= 0.8 * areas
    feats = np.flatnonzero((areas > 0) & (areas <= max_support * act_area) & one_sided)
    lab = lab0.copy()
    if feats.size == 0 or not (lab >= 0).any():
        return lab
    S = sup[feats]
    fa = areas[feats]
    fside = np.where(left[feats] * 2 >= fa, 2, 0)
    # families: each feature points to the larger feature containing most of it
    inter = (S.astype(np.float64) * area[None, :]) @ S.T.astype(np.float64)
    contain = inter / fa[:, None]  # share of row's support inside column's
    np.fill_diagonal(contain, 0.0)
    contain[fa[:, None] >= fa[None, :]] = 0.0  # only into larger features
    parent = np.where(contain.max(axis=1) >= nested, np.argmax(contain, axis=1), np.arange(feats.size))
    root = parent.copy()
    for _ in range(feats.size):
        root = parent[root]
    order = np.argsort(fa, kind="stable")  # most local first
    rank = np.empty(feats.size, np.int64)
    rank[order] = np.arange(feats.size)
    for _ in range(rounds):
        R = int(lab.max()) + 1
        pside = np.full(R, 1, np.int64)
        fgv = np.flatnonzero((lab >= 0) & (side3 != 1))
        for sd in (0, 2):
            cnt = np.bincount(lab[fgv], weights=(side3[fgv] == sd).astype(np.float64), minlength=R)
            pside[cnt > 0] = sd
        home = np.full(feats.size, -1, np.int64)
        for i in np.unique(root):
            vv = np.flatnonzero(S[i] & (lab >= 0))
            vv = vv[pside[lab[vv]] == fside[i]]
            if vv.size:
                home[i] = int(np.argmax(np.bincount(lab[vv], weights=area[vv], minlength=R)))
        fhome = home[root]
        claim = np.where(S & (fhome >= 0)[:, None] & (side3[None, :] == fside[:, None]), rank[:, None], np.iinfo(np.int64).max)
        best = np.argmin(claim, axis=0)
        cols = np.flatnonzero(claim[best, np.arange(claim.shape[1])] < np.iinfo(np.int64).max)
        lab[cols] = fhome[best[cols]]
        lab = label_pieces(A, lab)
    # as in step 4: pieces keyed by side, the mid-plane column absorbed last
    lab = label_pieces(A, np.where(lab >= 0, lab * 3 + side3, -1))
    return absorb_small_pieces(A, lab, area, min_area, side3)
