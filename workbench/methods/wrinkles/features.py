"""Strain features and local detail frames for pose-space deformation (Bickel et al. 2008, §3, §5.1, §5.3).

What a pose space is fitted on, measured on the mesh:

* **Feature graph** (§5.1): edges between handle vertices (each handle to its
  ``k`` nearest handles, deduplicated; edges may cross, ``F ≈ 2–3·H``), with
  rest lengths ``l_i``. The feature vector of a pose is the relative stretch
  ``f_i = (‖p_i1 − p_i2‖ − l_i) / l_i`` — invariant under rigid motions.
* **Details** (§3): ``d = example − large-scale`` per vertex, stored in a local
  frame of the large-scale surface (normal + the direction to a fixed one-ring
  neighbour projected to the tangent plane), so they are rotation invariant.
* **WPSD edge weights** (§5.3): the per-vertex weights ``α_{v,i}`` of the
  feature edges in the weighted distance ``‖f − f_j‖_v² = Σ_i α_{v,i}(f_i − f_{j,i})²``:
  ``ᾱ_{v,i} = exp(−β(L_{v,i} − l_i))`` normalized, small weights dropped, at
  most 16 edges per vertex.

Documented choices (each pinned by ``tests/test_pose_space.py``):

* The 0.025 cut-off is applied to ``ᾱ`` *relative to the vertex's largest*
  ``ᾱ`` (identical to the paper for vertices near an edge, where the largest
  ``ᾱ`` is ≈ 1; vertices far from every edge — the neck, the scalp — keep
  their nearest edges instead of losing all of them). ``β`` defaults to
  ``ln(1/0.025) / q`` where ``q`` is the 10th percentile, over vertices near the
  graph, of the gap between their nearest and 17th-nearest edge excess
  ``L_{v,i} − l_i``: ≥ 90 % of those vertices see ≤ 16 edges naturally, the
  rest are truncated to their 16 strongest edges (then renormalized).

The pose space fitted on these features is in
:mod:`workbench.methods.wrinkles.pose_space`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

# the one definition of vertex normals (area-weighted), re-exported for this module's callers
from workbench.geometry.normals import vertex_normals

__all__ = [
    "DEFAULT_MAX_EDGES",
    "DEFAULT_WEIGHT_THRESHOLD",
    "EdgeWeights",
    "FeatureGraph",
    "FloatArray",
    "edge_weights",
    "extract_details",
    "local_frames",
    "strain",
    "tangent_neighbours",
    "to_local",
    "to_world",
    "vertex_normals",
]


FloatArray = NDArray[np.float64]


#: paper values (§5.3)
DEFAULT_WEIGHT_THRESHOLD = 0.025
DEFAULT_MAX_EDGES = 16


def _positions(x: ArrayLike, what: str) -> FloatArray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 2 or a.shape[-1] != 3:
        raise ValueError(f"pose_space: {what} must be (..., 3) positions, got shape {a.shape}")
    return a


# --------------------------------------------------------------------------- feature graph


@dataclass(frozen=True, eq=False)
class FeatureGraph:
    """Edges between handles where strain is measured (Bickel et al. 2008, §5.1).

    Parameters
    ----------
    edges : (F, 2) int
        Handle indices (in handle order, not vertex ids), ``i < j``, unique.
    rest_lengths : (F,) float
        ``l_i``: edge lengths in the rest pose (> 0).
    """

    edges: NDArray[np.int32]
    rest_lengths: FloatArray

    def __post_init__(self) -> None:
        e = np.asarray(self.edges, dtype=np.int32).reshape(-1, 2)
        rl = np.asarray(self.rest_lengths, dtype=np.float64).reshape(-1)
        if e.shape[0] != rl.shape[0]:
            raise ValueError(f"FeatureGraph: {e.shape[0]} edges but {rl.shape[0]} rest lengths")
        if np.any(rl <= 0):
            raise ValueError("FeatureGraph: rest lengths must be > 0 (two handles on one vertex?)")
        e.setflags(write=False)
        rl.setflags(write=False)
        object.__setattr__(self, "edges", e)
        object.__setattr__(self, "rest_lengths", rl)

    def __len__(self) -> int:
        return int(self.edges.shape[0])

    @classmethod
    def from_handles(cls, rest_positions: ArrayLike, neighbours: int = 4) -> FeatureGraph:
        """Connect every handle to its ``neighbours`` nearest handles (rest pose), deduplicated.

        Parameters
        ----------
        rest_positions : (H, 3) float
            Handle positions in the rest pose, in handle order.
        neighbours : int
            Nearest handles per handle (3–5 gives ``F ≈ 2–3·H``).
        """
        P = _positions(rest_positions, "rest_positions").reshape(-1, 3)
        H = P.shape[0]
        if H < 2:
            raise ValueError(f"FeatureGraph.from_handles: need at least 2 handles, got {H}")
        k = min(int(neighbours), H - 1)
        if k < 1:
            raise ValueError(f"FeatureGraph.from_handles: neighbours must be >= 1, got {neighbours}")
        _, nn = cKDTree(P).query(P, k=k + 1)
        nn = np.asarray(nn).reshape(H, k + 1)[:, 1:]
        a = np.repeat(np.arange(H), k)
        b = nn.ravel()
        pairs = np.unique(np.sort(np.stack([a, b], 1), axis=1), axis=0)
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
        lengths = np.linalg.norm(P[pairs[:, 0]] - P[pairs[:, 1]], axis=1)
        keep = lengths > 0  # two handles on the same vertex measure no strain
        return cls(pairs[keep].astype(np.int32), lengths[keep])

    def with_edge(self, i: int, j: int, rest_positions: ArrayLike) -> FeatureGraph:
        """A new graph with edge ``(i, j)`` added (no-op if present); rest length from ``rest_positions``."""
        P = _positions(rest_positions, "rest_positions").reshape(-1, 3)
        a, b = sorted((int(i), int(j)))
        if a == b or a < 0 or b >= P.shape[0]:
            raise ValueError(f"FeatureGraph.with_edge: need two different handles in 0..{P.shape[0] - 1}, got {i}, {j}")
        if np.any((self.edges[:, 0] == a) & (self.edges[:, 1] == b)):
            return self
        e = np.vstack([self.edges, [[a, b]]])
        rl = np.append(self.rest_lengths, np.linalg.norm(P[a] - P[b]))
        order = np.lexsort((e[:, 1], e[:, 0]))
        return FeatureGraph(e[order], rl[order])

    def without_edge(self, i: int, j: int) -> FeatureGraph:
        """A new graph with edge ``(i, j)`` removed (KeyError if absent)."""
        a, b = sorted((int(i), int(j)))
        hit = (self.edges[:, 0] == a) & (self.edges[:, 1] == b)
        if not hit.any():
            raise KeyError(f"FeatureGraph.without_edge: no edge between handles {i} and {j}")
        return FeatureGraph(self.edges[~hit], self.rest_lengths[~hit])

    def strain(self, handle_positions: ArrayLike) -> FloatArray:
        """Feature vector ``f_i = (‖p_i1 − p_i2‖ − l_i) / l_i``.

        Parameters
        ----------
        handle_positions : (H, 3) or (T, H, 3) float

        Returns
        -------
        (F,) or (T, F) float64
        """
        P = _positions(handle_positions, "handle_positions")
        if P.shape[-2] <= int(self.edges.max(initial=-1)):
            raise ValueError(f"strain: graph uses handle {int(self.edges.max())}, got only {P.shape[-2]} positions")
        d = P[..., self.edges[:, 0], :] - P[..., self.edges[:, 1], :]
        return (np.linalg.norm(d, axis=-1) - self.rest_lengths) / self.rest_lengths


def strain(graph: FeatureGraph, handle_positions: ArrayLike) -> FloatArray:
    """Function form of :meth:`FeatureGraph.strain`."""
    return graph.strain(handle_positions)


# --------------------------------------------------------------------------- WPSD edge weights


@dataclass(frozen=True, eq=False)
class EdgeWeights:
    """Per-vertex feature-edge weights ``α_{v,i}`` of WPSD (rows sum to 1).

    Attributes
    ----------
    matrix : (n, F) scipy CSR float64
    index : (n, K) int32
        Edge ids per vertex, strongest first, padded with 0 (with weight 0); for kernels.
    value : (n, K) float32
    beta : float
        Decay used, in 1 / model units.
    """

    matrix: sp.csr_matrix
    index: NDArray[np.int32]
    value: NDArray[np.float32]
    beta: float
    nearest_excess: FloatArray = field(default_factory=lambda: np.zeros(0))


def edge_weights(
    rest_vertices: ArrayLike,
    rest_handle_positions: ArrayLike,
    graph: FeatureGraph,
    *,
    beta: float | None = None,
    threshold: float = DEFAULT_WEIGHT_THRESHOLD,
    max_edges: int = DEFAULT_MAX_EDGES,
) -> EdgeWeights:
    """WPSD weights ``α_{v,i} ∝ exp(−β (L_{v,i} − l_i))`` (Bickel et al. 2008, eq. 4).

    Parameters
    ----------
    rest_vertices : (n, 3) float
    rest_handle_positions : (H, 3) float
    graph : FeatureGraph
    beta : float, optional
        Decay (1 / model units). Default: chosen from the handle density (module docstring).
    threshold : float
        Drop ``ᾱ`` below this fraction of the vertex's largest ``ᾱ``.
    max_edges : int
        At most this many edges per vertex (the strongest).
    """
    V = _positions(rest_vertices, "rest_vertices").reshape(-1, 3)
    P = _positions(rest_handle_positions, "rest_handle_positions").reshape(-1, 3)
    n, Fn = V.shape[0], len(graph)
    if Fn == 0:
        raise ValueError("edge_weights: the feature graph has no edges")
    K = min(int(max_edges), Fn)
    a, b = P[graph.edges[:, 0]], P[graph.edges[:, 1]]
    # K+1 smallest excesses per vertex, in chunks to bound memory (n x F floats)
    near_e = np.empty((n, min(K + 1, Fn)))
    near_i = np.empty((n, min(K + 1, Fn)), np.int64)
    chunk = max(1, 4_000_000 // Fn)
    for s in range(0, n, chunk):
        x = V[s : s + chunk]
        L = np.linalg.norm(x[:, None] - a[None], axis=2) + np.linalg.norm(x[:, None] - b[None], axis=2)
        exc = np.maximum(L - graph.rest_lengths[None], 0.0)
        kk = near_e.shape[1]
        idx = np.argpartition(exc, kk - 1, axis=1)[:, :kk] if kk < Fn else np.tile(np.arange(Fn), (len(x), 1))
        e = np.take_along_axis(exc, idx, 1)
        o = np.argsort(e, axis=1, kind="stable")
        near_e[s : s + chunk] = np.take_along_axis(e, o, 1)
        near_i[s : s + chunk] = np.take_along_axis(idx, o, 1)
    if beta is None:
        if Fn <= K:
            beta = float(np.log(1.0 / threshold) / max(np.median(graph.rest_lengths), 1e-12))
        else:
            close = near_e[:, 0] <= np.median(graph.rest_lengths)
            gaps = (near_e[:, K] - near_e[:, 0])[close if close.any() else slice(None)]
            q = float(np.quantile(gaps, 0.1))
            beta = float(np.log(1.0 / threshold) / max(q, 1e-12))
    if not beta > 0:
        raise ValueError(f"edge_weights: beta must be > 0, got {beta}")
    rel = np.exp(-beta * (near_e[:, :K] - near_e[:, :1]))  # ᾱ / max ᾱ, first column is 1
    rel[rel < threshold] = 0.0
    rel /= rel.sum(axis=1, keepdims=True)
    index = near_i[:, :K].astype(np.int32)
    index[rel == 0] = 0
    rows = np.repeat(np.arange(n), K)
    M = sp.csr_matrix((rel.ravel(), (rows, index.ravel())), shape=(n, Fn))
    M.eliminate_zeros()
    M.sum_duplicates()
    return EdgeWeights(M, index, rel.astype(np.float32), float(beta), near_e[:, 0].copy())


# --------------------------------------------------------------------------- local frames


def tangent_neighbours(faces: ArrayLike, n_vertices: int) -> NDArray[np.int32]:
    """A fixed one-ring neighbour per vertex (its successor in the first face using it).

    Vertices used by no face get themselves (their tangent falls back to an axis).
    """
    Fa = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    nb = np.arange(n_vertices, dtype=np.int32)
    corner = Fa.ravel()
    succ = Fa[:, [1, 2, 0]].ravel()
    _, first = np.unique(corner, return_index=True)
    nb[corner[first]] = succ[first]
    return nb


def local_frames(
    X: ArrayLike, faces: ArrayLike, neighbours: ArrayLike, normals: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Per-vertex orthonormal frames ``R_v = [t, b, n]`` (columns), (n, 3, 3) float64.

    ``n`` is the area-weighted normal of ``X``, ``t`` the direction to the fixed
    neighbour projected to the tangent plane, ``b = n × t``. A local vector
    ``x`` maps to world ``R_v x``. Frames rotate with the surface, which makes
    details stored in them rotation invariant.
    """
    P = np.asarray(X, dtype=np.float64).reshape(-1, 3)
    N = vertex_normals(P, faces) if normals is None else np.asarray(normals, np.float64)
    nb = np.asarray(neighbours, dtype=np.int64)
    t = P[nb] - P
    t -= np.sum(t * N, axis=1, keepdims=True) * N
    ln = np.linalg.norm(t, axis=1)
    bad = ln < 1e-12
    if bad.any():  # isolated vertex or neighbour along the normal: any perpendicular axis
        axis = np.where(np.abs(N[bad, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        tb = axis - np.sum(axis * N[bad], axis=1, keepdims=True) * N[bad]
        t[bad] = tb
        ln[bad] = np.linalg.norm(tb, axis=1)
    t /= np.maximum(ln, 1e-300)[:, None]
    b = np.cross(N, t)
    return np.stack([t, b, N], axis=2)


def to_local(frames: ArrayLike, d: ArrayLike) -> FloatArray:
    """World vectors (n, 3) -> frame coordinates (n, 3): ``R_vᵀ d_v``."""
    return np.einsum("nij,ni->nj", np.asarray(frames), np.asarray(d, dtype=np.float64))


def to_world(frames: ArrayLike, d_local: ArrayLike) -> FloatArray:
    """Frame coordinates (n, 3) -> world vectors (n, 3): ``R_v x_v``."""
    return np.einsum("nij,nj->ni", np.asarray(frames), np.asarray(d_local, dtype=np.float64))


def extract_details(detailed: ArrayLike, large_scale: ArrayLike, frames: ArrayLike) -> FloatArray:
    """Fine-scale detail ``R_vᵀ (detailed − large_scale)`` in local frames, (n, 3)."""
    a = _positions(detailed, "detailed")
    b = _positions(large_scale, "large_scale")
    if a.shape != b.shape:
        raise ValueError(f"extract_details: detailed {a.shape} and large_scale {b.shape} differ")
    return to_local(frames, a - b)
