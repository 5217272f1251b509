"""Regions from how the face moves, and the four voluntary ones among them (Bermano et al. 2014, §4.3).

Bermano et al. take their regions from Tena et al. (2011), "which clusters the
vertices according to their correlation in movement" (13 regions), and call
four of them *voluntary*: the left and right halves of the mouth and the left
and right eyebrows; the eyes they leave out on purpose (§7). Here:

1. **Motion.** A vertex's motion is its displacement in every frame (or shape)
   stacked into one ``(3T,)`` vector. Vertices moving less than ``still`` of
   the 99th percentile are still and belong to no region; of the moving ones
   only the largest edge-connected piece is clustered (the skin: eyeballs,
   teeth and lashes are other pieces, rigid or attached).
2. **Affinity.** Every mesh edge between two clustered vertices weighs
   ``exp(−(1 − c) / tau)`` with ``c`` the cosine of their motion vectors (Tena's
   correlation without the mean: the neutral is the reference). Neighbours
   that move alike are tightly bound; the edge between the upper and the lower
   lip (jawOpen moves one, not the other) nearly vanishes.
3. **Spectral clustering.** The ``n_regions`` smallest eigenvectors of the
   normalised graph Laplacian ``I − D^-½ W D^-½`` (scipy's shift-invert Lanczos),
   rows scaled to unit length, grouped by k-means++ (scipy, fixed seed) — Ng,
   Jordan & Weiss's recipe. k-means works in the embedding, so a region can
   come out in pieces (a stray vertex or two): every region keeps its largest
   edge-connected piece and the rest joins the region of its neighbours.
4. **Voluntary regions**, by position on the face (``axes``: left, up, front)
   and motion, never by shape names: with the clustered skin's height
   normalised to [0, 1] (2nd to 98th percentile), the *brow* of each side is
   its highest region among those centred in the top third that move at least
   ``active`` of the most moving region's median (so a still forehead is not
   a brow, and the lids below it are left out, as in the paper); the *mouth*
   is the union of the regions centred in the bottom 40 % that move that
   much, split into halves at the face's midline (the median of the mouth's left
   coordinate, which the brows share). A group the face does not have (no moving brow) is left out.

Hand-written because it is a few lines around scipy (``eigsh``, ``kmeans2``,
``connected_components``); scikit-learn's ``SpectralClustering`` would do step 3
but is not a dependency of the core, and the graph of step 2 is ours anyway.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.cluster.vq import kmeans2
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import eigsh

from workbench.enhance.voluntary import checked_mesh, mesh_edges

__all__ = ["MotionRegions", "motion_regions", "voluntary_cores_from_motion"]


@dataclass(frozen=True)
class MotionRegions:
    """Vertices clustered by their motion (:func:`motion_regions`).

    Attributes
    ----------
    labels : (n,) int64
        Region of every vertex, ``-1`` for still vertices and moving ones off the clustered piece.
    motion : (n,) float64
        Norm of each vertex's stacked displacements (model units).
    n_regions : int
    """

    labels: NDArray[np.int64]
    motion: NDArray[np.float64]
    n_regions: int

    def vertices(self, region: int) -> NDArray[np.int64]:
        """Indices of the vertices of one region."""
        return np.flatnonzero(self.labels == int(region))


def _in_one_piece(lab: NDArray[np.int64], a: NDArray[np.int64], b: NDArray[np.int64], k: int) -> NDArray[np.int64]:
    """Give every stray piece of a region (k-means works in the embedding, not on the mesh) to the neighbours' region.

    Each region keeps its largest edge-connected piece; a vertex of another
    piece takes the region most of its neighbours outside the strays have.
    Repeated until every region is one piece (a few rounds).
    """
    n = len(lab)
    lab = lab.copy()
    for _ in range(50):
        same = lab[a] == lab[b]
        G = sp.csr_matrix((np.ones(int(same.sum())), (a[same], b[same])), shape=(n, n))
        _, comp = connected_components(G, directed=False)
        size = np.bincount(comp)
        main = np.full(k, -1, np.int64)
        order = np.argsort(size[comp], kind="stable")  # ascending: the largest piece of a region writes last
        main[lab[order]] = comp[order]
        stray = comp != main[lab]
        if not stray.any():
            break
        src = np.concatenate([a, b])
        dst = np.concatenate([b, a])
        vote = stray[src] & ~stray[dst]
        counts = sp.csr_matrix((np.ones(int(vote.sum())), (src[vote], lab[dst[vote]])), shape=(n, k)).toarray()
        take = stray & (counts.sum(axis=1) > 0)
        lab[take] = counts[take].argmax(axis=1)
    return lab


def motion_regions(
    neutral: ArrayLike,
    faces: ArrayLike,
    frames: ArrayLike,
    n_regions: int = 13,
    *,
    tau: float = 0.05,
    still: float = 0.05,
    seed: int = 0,
) -> MotionRegions:
    """Cluster a face's moving vertices by the correlation of their motion (steps 1–3 of the module docstring).

    Parameters
    ----------
    neutral : (n, 3) float
    faces : (m, 3) int
    frames : (T, n, 3) float
        Poses of the face (a performance, or the neutral plus each shape's delta); T >= 1.
    n_regions : int
        Number of regions (Tena et al. and Bermano et al. use 13).
    tau : float
        Width of the affinity in ``1 − cosine`` (smaller: sharper borders between differently moving parts).
    still : float
        Vertices moving less than this fraction of the 99th-percentile motion are in no region.
    seed : int
        Seed of the k-means initialisation (deterministic for a given seed).

    Returns
    -------
    MotionRegions

    Raises
    ------
    ValueError
        Shapes that do not match, nothing moves, or fewer moving vertices than ``n_regions``.
    """
    V, F = checked_mesh(neutral, faces, "motion_regions: ")
    P = np.asarray(frames, np.float64)
    if P.ndim != 3 or P.shape[1:] != V.shape or len(P) == 0:
        raise ValueError(f"motion_regions: frames must be (T, {len(V)}, 3) with T >= 1, got {P.shape}")
    if int(n_regions) < 2:
        raise ValueError(f"motion_regions: n_regions must be >= 2, got {n_regions!r}")
    if not (np.isfinite(tau) and tau > 0) or not (0 <= still < 1):
        raise ValueError(f"motion_regions: tau must be > 0 and still in [0, 1), got tau={tau!r}, still={still!r}")
    n, k = len(V), int(n_regions)
    X = (P - V).transpose(1, 0, 2).reshape(n, -1)
    motion = np.linalg.norm(X, axis=1)
    top = float(np.percentile(motion, 99))
    if not top > 0:
        raise ValueError("motion_regions: no vertex moves in frames")
    moving = motion >= still * top
    e = mesh_edges(F)
    e = e[moving[e[:, 0]] & moving[e[:, 1]]]
    A = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, piece = connected_components(A + A.T, directed=False)
    largest = np.argmax(np.bincount(piece[moving]))
    keep = moving & (piece == largest)
    idx = np.flatnonzero(keep)
    if len(idx) < 4 * k:
        raise ValueError(f"motion_regions: only {len(idx)} connected moving vertices for {k} regions")
    e = e[keep[e[:, 0]] & keep[e[:, 1]]]
    pos = np.full(n, -1, np.int64)
    pos[idx] = np.arange(len(idx))
    unit = X[idx] / motion[idx, None]
    a, b = pos[e[:, 0]], pos[e[:, 1]]
    w = np.exp(-(1.0 - np.einsum("ij,ij->i", unit[a], unit[b])) / tau)
    W = sp.csr_matrix((w, (a, b)), shape=(len(idx), len(idx)))
    W = (W + W.T).tocsr()
    d = np.asarray(W.sum(axis=1)).ravel()
    s = sp.diags(1.0 / np.sqrt(np.maximum(d, 1e-300)))
    L = (sp.identity(len(idx)) - s @ W @ s).tocsc()
    # shift just below 0: L is singular (its constant-like null vector), L − σI is not
    _, vecs = eigsh(L, k=k, sigma=-1e-3, which="LM")
    Y = vecs / np.maximum(np.linalg.norm(vecs, axis=1, keepdims=True), 1e-300)
    _, lab = kmeans2(Y, k, minit="++", seed=np.random.default_rng(seed))
    lab = _in_one_piece(lab.astype(np.int64), a, b, k)
    # number the regions by their size (largest first) so labels do not depend on k-means' order
    order = np.argsort(-np.bincount(lab, minlength=k), kind="stable")
    rank = np.empty(k, np.int64)
    rank[order] = np.arange(k)
    labels = np.full(n, -1, np.int64)
    labels[idx] = rank[lab]
    return MotionRegions(labels, motion, k)


def voluntary_cores_from_motion(
    neutral: ArrayLike, regions: MotionRegions, axes: ArrayLike, *, active: float = 0.1
) -> dict[str, NDArray[np.int64]]:
    """The four voluntary regions (mouth and brow, left and right) among motion regions (step 4 of the docstring).

    Parameters
    ----------
    neutral : (n, 3) float
    regions : MotionRegions
    axes : (3, 3) float
        Rows: the subject's left, up and front in model coordinates
        (:func:`workbench.geometry.axes.face_axes`).
    active : float
        A region takes part when its median motion is at least this fraction of the most moving region's.

    Returns
    -------
    dict name -> (k,) int64
        ``brow_left``, ``brow_right``, ``mouth_left``, ``mouth_right`` in this order — the groups found
        (at least the mouth).

    Raises
    ------
    ValueError
        No moving region in the lower part of the face (no mouth).
    """
    V = np.asarray(neutral, np.float64) @ np.asarray(axes, np.float64).T
    lab = regions.labels
    clustered = lab >= 0
    lo, hi = np.percentile(V[clustered, 1], [2, 98])
    med = np.array([np.median(regions.motion[lab == r]) for r in range(regions.n_regions)])
    height = np.array([(V[lab == r, 1].mean() - lo) / max(hi - lo, 1e-300) for r in range(regions.n_regions)])
    moves = med >= active * med.max()
    out: dict[str, NDArray[np.int64]] = {}
    mouth = np.flatnonzero(moves & (height <= 0.4))
    if mouth.size == 0:
        raise ValueError("voluntary_cores_from_motion: no moving region in the lower 40 % of the face (no mouth)")
    ids = np.flatnonzero(np.isin(lab, mouth))
    # the face's midline: the mouth's (the skin's median is off where a turned head shows more of one cheek)
    mid = float(np.median(V[ids, 0]))
    out["mouth_left"] = ids[V[ids, 0] >= mid]
    out["mouth_right"] = ids[V[ids, 0] < mid]
    for name, this_side in (("brow_left", V[:, 0] >= mid), ("brow_right", V[:, 0] < mid)):
        halves = []
        for r in np.flatnonzero(moves & (height >= 2.0 / 3.0)):
            members = regions.vertices(int(r))
            here = members[this_side[members]]
            # a brow region may cross the midline (a face whose brows move together): take its half
            if here.size >= 0.25 * members.size:
                halves.append((members.size, float(V[here, 1].mean()), here))
        # the highest, among regions not much smaller than the largest (a sliver of a crease is no brow)
        big = [h for h in halves if h[0] >= 0.25 * max((h[0] for h in halves), default=0)]
        if big:
            out[name] = max(big, key=lambda h: h[1])[2]
    # the order of face_voluntary_cores: brows, then mouth
    return {k: out[k] for k in ("brow_left", "brow_right", "mouth_left", "mouth_right") if k in out and out[k].size}
