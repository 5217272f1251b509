"""Fine-scale detail in a strain pose space: PSD and weighted PSD (Bickel et al. 2008, §5–6).

The large-scale motion of a face comes from a linear shell driven by ``H``
handle vertices (:mod:`workbench.methods.handles.shell`). What the shell misses — wrinkles,
bulges — is learned from a few detailed example poses as a function of skin
*strain*:

* **Feature graph** (§5.1): edges between handle vertices (each handle to its
  ``k`` nearest handles, deduplicated; edges may cross, ``F ≈ 2–3·H``), with
  rest lengths ``l_i``. The feature vector of a pose is the relative stretch
  ``f_i = (‖p_i1 − p_i2‖ − l_i) / l_i`` — invariant under rigid motions.
* **Details** (§3): ``d = example − large-scale`` per vertex, stored in a local
  frame of the large-scale surface (normal + the direction to a fixed one-ring
  neighbour projected to the tangent plane), so they are rotation invariant.
* **PSD** (§5.2): ``d(f) = Σ_j w_j φ(‖f − f_j‖)`` with ``φ(r) = r``; exact
  interpolation of ``P`` poses or least squares over ``T`` poses with a greedy
  basis (start from the rest pose, add the pose with the largest error until
  the error is below a threshold).
* **WPSD** (§5.3): per-vertex distance ``‖f − f_j‖_v² = Σ_i α_{v,i}(f_i − f_{j,i})²``
  with ``ᾱ_{v,i} = exp(−β(L_{v,i} − l_i))`` normalized, small weights dropped,
  at most 16 edges per vertex; one ``P × P`` system per vertex (batched solves).

Documented choices (each pinned by ``tests/test_pose_space.py``):

* The rest pose is always basis pose 0 with zero features and zero detail,
  and zero strain gives exactly zero detail (up to float32 rounding) in both
  fit modes: ``Σ_j w_j φ(‖f_j‖) = 0`` is a linear constraint on the weights.
  ``lsq`` solves the equality-constrained least-squares problem (null-space
  projection, :func:`_rest_constrained_lstsq`), not a fit followed by a
  projection, so a larger basis never fits the training poses worse and the
  greedy error never rises. A consequence of ``φ(r) = r``: with one pose
  besides the rest pose the constraint forces that pose's weight to 0, so the
  two-pose ``lsq`` fit equals the rest-only one.
* The 0.025 cut-off is applied to ``ᾱ`` *relative to the vertex's largest*
  ``ᾱ`` (identical to the paper for vertices near an edge, where the largest
  ``ᾱ`` is ≈ 1; vertices far from every edge — the neck, the scalp — keep
  their nearest edges instead of losing all of them). ``β`` defaults to
  ``ln(1/0.025) / q`` where ``q`` is the 10th percentile, over vertices near the
  graph, of the gap between their nearest and 17th-nearest edge excess
  ``L_{v,i} − l_i``: ≥ 90 % of those vertices see ≤ 16 edges naturally, the
  rest are truncated to their 16 strongest edges (then renormalized).
* Basis poses are tested in order, per vertex (one shared test for PSD): a
  distance column whose part orthogonal to the columns kept before it is at
  most ``rcond = 1e-3`` of its norm is dropped (weight 0) — the vertex's metric
  cannot tell that basis pose from earlier ones. The test only looks at
  earlier columns, so growing the basis never drops a column kept before.
  Why ``1e-3``: weights are stored and evaluated in float32 (the kernels too),
  which costs about ``eps32 / rcond ≈ 6e-5`` of a vertex's detail through the
  cancelling weights of nearly coincident poses (``1e-4`` allowed 6e-4 on the
  sample head's examples); and poses closer than ``1e-3`` of a vertex's
  pose-space extent (median 0.18 on the sample head) differ by RMS strains of
  ~2e-4 — a 0.02 % stretch, within two orders of magnitude of the few-1e-6
  noise of strain measured from float32 positions. :attr:`PoseSpace.singular` marks
  the vertices where a dropped pose makes the fit miss a basis pose's values
  by more than ``1e-4`` of that pose's largest value (in ``interp`` mode: the
  vertices not reproduced exactly); elsewhere dropping loses nothing.

Hand-written because no library offers strain pose spaces; the linear algebra
is numpy's batched ``eigh`` and scipy's sparse products. Per-frame kernels for
large meshes are in :mod:`workbench.methods.wrinkles.kernels` (numba, optional).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from workbench.methods.handles.shell import ShellDeformer
from workbench.methods.wrinkles import kernels as _kernels

FloatArray = NDArray[np.float64]
FitMode = Literal["interp", "lsq"]

#: paper values (§5.3)
DEFAULT_WEIGHT_THRESHOLD = 0.025
DEFAULT_MAX_EDGES = 16
_RCOND = 1e-3
_MISS = 1e-4


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


def vertex_normals(X: ArrayLike, faces: ArrayLike) -> NDArray[np.float64]:
    """Area-weighted unit vertex normals, (n, 3) float64 (numpy; zero for unused vertices)."""
    P = np.asarray(X, dtype=np.float64).reshape(-1, 3)
    Fa = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    fn = np.cross(P[Fa[:, 1]] - P[Fa[:, 0]], P[Fa[:, 2]] - P[Fa[:, 0]])
    N = np.zeros_like(P)
    for c in range(3):
        for k in range(3):
            N[:, k] += np.bincount(Fa[:, c], fn[:, k], minlength=P.shape[0])
    ln = np.linalg.norm(N, axis=1, keepdims=True)
    return np.divide(N, ln, out=np.zeros_like(N), where=ln > 0)


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


# --------------------------------------------------------------------------- RBF pose space


def _distances_global(FA: FloatArray, FB: FloatArray) -> FloatArray:
    """(A, B) Euclidean feature distances."""
    d = FA[:, None, :] - FB[None, :, :]
    return np.sqrt(np.einsum("abf,abf->ab", d, d))


def _distances_weighted(alpha: sp.csr_matrix, FA: FloatArray, fb: FloatArray) -> FloatArray:
    """(n, A) per-vertex weighted distances ``‖f_a − fb‖_v`` (eq. 3) to one pose ``fb``."""
    sq = (FA - fb[None, :]) ** 2  # (A, F)
    r2 = alpha @ sq.T  # (n, A): a sparse x dense product, no cancellation
    return np.sqrt(np.maximum(np.asarray(r2), 0.0))


@dataclass(frozen=True, eq=False)
class PoseSpace:
    """A fitted PSD / WPSD map from features to per-vertex values (Bickel et al. 2008, eqs. 2, 5).

    The values are whatever was fitted: fine-scale details in local frames (PSD,
    WPSD) or full displacements (the paper's blend-shape comparisons).

    Attributes
    ----------
    basis_features : (P, F) float64
        ``f_j`` of the basis poses (pose 0 is the rest pose).
    weights : (P, n, 3) float32 (global) or (n, P, 3) float32 (weighted)
        RBF weights ``w_j`` / ``w_{v,j}``.
    alpha : EdgeWeights or None
        WPSD edge weights; None for global PSD.
    basis : tuple of int
        Indices of the basis poses in the training set (the rest pose is -1).
    mode : {"interp", "lsq"}
    train_features : (T, F) float64
    train_values : (T, n, 3) float32
        Kept so examples can be edited and refitted.
    rcond : float
        Column cut-off of the fit (module docstring).
    errors : tuple of float
        RMS training errors per basis size (greedy fits).
    singular : (n,) bool or None
        Vertices whose metric cannot tell a basis pose from an earlier one
        where that costs more than ``1e-4`` of a basis pose's largest value;
        in ``interp`` mode exactly the vertices not reproduced.
    """

    basis_features: FloatArray
    weights: NDArray[np.float32]
    alpha: EdgeWeights | None
    basis: tuple[int, ...]
    mode: FitMode
    train_features: FloatArray
    train_values: NDArray[np.float32]
    rcond: float = _RCOND
    errors: tuple[float, ...] = field(default=())
    singular: NDArray[np.bool_] | None = None

    @property
    def weighted(self) -> bool:
        return self.alpha is not None

    @property
    def n_vertices(self) -> int:
        return int(self.train_values.shape[1])

    def distances(self, features: ArrayLike) -> FloatArray:
        """φ of one pose to every basis pose: (P,) for PSD, (n, P) for WPSD."""
        f = np.asarray(features, dtype=np.float64).reshape(-1)
        if self.alpha is None:
            return _distances_global(f[None], self.basis_features)[0]
        r2 = self.alpha.matrix @ ((self.basis_features - f[None]) ** 2).T
        return np.sqrt(np.maximum(np.asarray(r2), 0.0))

    def evaluate(self, features: ArrayLike) -> NDArray[np.float32]:
        """Values for one pose, (n, 3) float32 (numpy path; see :mod:`workbench.methods.wrinkles.kernels`)."""
        phi = self.distances(features)
        if self.alpha is None:
            P = self.weights.shape[0]
            return np.tensordot(phi.astype(np.float32), self.weights.reshape(P, -1), 1).reshape(-1, 3)
        return np.einsum("np,npc->nc", phi.astype(np.float32), self.weights)

    def evaluate_many(self, features: ArrayLike) -> NDArray[np.float32]:
        """Values for T poses, (T, n, 3) float32."""
        Fs = np.asarray(features, dtype=np.float64).reshape(-1, self.basis_features.shape[1])
        if self.alpha is None:
            R = _distances_global(Fs, self.basis_features)
            P = self.weights.shape[0]
            return (R.astype(np.float32) @ self.weights.reshape(P, -1)).reshape(len(Fs), -1, 3)
        out = np.zeros((len(Fs), self.n_vertices, 3), np.float32)
        for j in range(self.basis_features.shape[0]):
            r = _distances_weighted(self.alpha.matrix, Fs, self.basis_features[j]).astype(np.float32)  # (n, T)
            out += np.einsum("nt,nc->tnc", r, self.weights[:, j, :])
        return out

    def edited(
        self,
        example: int,
        *,
        scale: float | ArrayLike = 1.0,
        mask: ArrayLike | None = None,
        values: ArrayLike | None = None,
    ) -> PoseSpace:
        """Edit the stored values of one training pose and refit with the same basis.

        Parameters
        ----------
        example : int
            Index into the training set.
        scale : float or (n,) float
            Multiply the pose's values (per vertex if an array).
        mask : (n,) float or bool, optional
            Paint-out mask: values are multiplied by ``1 − mask`` (1 removes).
        values : (n, 3) float, optional
            Replace the values outright (applied before ``scale`` and ``mask``).

        The change propagates through the RBFs to every pose near this one.
        """
        T, n = self.train_values.shape[:2]
        if not 0 <= example < T:
            raise IndexError(f"edited: example must be in 0..{T - 1}, got {example}")
        D = self.train_values.copy()
        v = D[example].astype(np.float64) if values is None else np.asarray(values, np.float64).reshape(n, 3)
        s = np.asarray(scale, dtype=np.float64)
        v = v * (s.reshape(n, 1) if s.ndim else float(s))
        if mask is not None:
            m = np.asarray(mask, dtype=np.float64).reshape(n)
            v = v * (1.0 - np.clip(m, 0.0, 1.0))[:, None]
        D[example] = v
        return fit_pose_space(
            self.train_features,
            D,
            alpha=self.alpha,
            basis=[b for b in self.basis if b >= 0],
            mode=self.mode,
            rcond=self.rcond,
        )


def _nested_columns(A: FloatArray, rcond: float) -> NDArray[np.bool_]:
    """(n, P) bool: the columns of A (n, R, P) that ordered Gram–Schmidt keeps.

    Column ``j`` is kept when its component orthogonal to the kept columns
    before it is more than ``rcond`` times its norm; otherwise (a basis pose the
    vertex's metric cannot tell from earlier ones, or an all-zero column) its
    weight is 0. The decision for column ``j`` depends on columns ``0..j`` only,
    so adding basis poses never drops a column kept before: fit spaces are
    nested and a least-squares error cannot rise as the basis grows.
    """
    n, R, P = A.shape
    Q = np.zeros((n, R, P))
    keep = np.zeros((n, P), bool)
    for j in range(P):
        c = A[:, :, j]
        r = c.copy()
        if j:
            Qj = Q[:, :, :j]
            for _ in range(2):  # twice is enough (Kahan, Parlett)
                r -= np.einsum("nrk,nk->nr", Qj, np.einsum("nrk,nr->nk", Qj, r))
        nr = np.linalg.norm(r, axis=1)
        k = nr > rcond * np.linalg.norm(c, axis=1)
        keep[:, j] = k
        Q[k, :, j] = r[k] / nr[k, None]
    return keep


def _rest_constrained_lstsq(A: FloatArray, b: FloatArray, rcond: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Batched ``min ‖A w − b‖`` subject to ``A[:, 0, :] · w = 0`` (row 0 is the rest pose).

    A (n, R, P) distance columns, b (n, R, m) values -> w (n, P, m) and the
    (n, P) mask of kept columns. Columns are selected by
    :func:`_nested_columns` (dropped ones get weight 0). The rest-pose
    constraint ``aᵀ w = 0`` (``a`` = row 0 restricted to the kept columns) is
    eliminated with the projector ``Π = I − â âᵀ``: ``w = (A Π)⁺ b`` is the
    constrained least-squares solution (its range lies in ``â⊥``). It is
    computed from the eigendecomposition of ``Π AᵀA Π``, whose null space is
    known exactly — ``â`` and the dropped coordinates — so exactly that many
    smallest eigenvalues are discarded and every other one is inverted (the
    kept columns are independent by construction). With ``R = P`` and nothing
    dropped this is exact interpolation, which reproduces row 0 anyway.
    """
    P = A.shape[2]
    keep = _nested_columns(A, rcond)
    AK = A * keep[:, None, :]
    a = AK[:, 0, :]
    na = np.linalg.norm(a, axis=1)
    ah = np.divide(a, na[:, None], out=np.zeros_like(a), where=na[:, None] > 0)
    M = AK - np.einsum("nr,np->nrp", np.einsum("nrp,np->nr", AK, ah), ah)  # A Π
    lam, V = np.linalg.eigh(np.einsum("nrp,nrq->npq", M, M))
    null = (~keep).sum(axis=1) + (na > 0)  # dimension of the known null space
    use = (np.arange(P)[None, :] >= null[:, None]) & (lam > 0)
    inv = np.where(use, 1.0 / np.where(use, lam, 1.0), 0.0)
    rhs = np.einsum("nrp,nrm->npm", M, b, optimize=True)
    w = np.einsum("npk,nk,nqk,nqm->npm", V, inv, V, rhs, optimize=True)
    w -= ah[:, :, None] * np.einsum("np,npm->nm", ah, w)[:, None, :]  # exactly in â⊥ (up to rounding)
    w *= keep[:, :, None]
    return w, keep


def _miss_thresholds(values: NDArray) -> FloatArray:
    """(P,) per basis pose: ``_MISS`` times its largest value norm over all vertices (values (P, n, 3)).

    The rest pose (row 0) is exact by construction and is not checked.
    """
    scale = np.linalg.norm(np.asarray(values, np.float64), axis=2).max(axis=1)
    thr = _MISS * np.maximum(scale, 1e-9 * max(float(scale.max(initial=0.0)), 1e-300))
    thr[0] = np.inf
    return thr


def _missed(pred: NDArray[np.floating], target: NDArray[np.floating], thr: FloatArray) -> NDArray[np.bool_]:
    """(n,) vertices whose pred and target (n, P, 3) differ by more than ``thr[p]`` at some basis pose p."""
    return np.any(np.linalg.norm(pred - target, axis=2) > thr[None, :], axis=1)


def _fit_global(
    rows_F: FloatArray, rows_D: NDArray[np.float32], basis_rows: Sequence[int], mode: FitMode, rcond: float
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Global PSD weights (P, n, 3): one system shared by every vertex (rows_F[0] is the rest pose).

    Also returns the (n,) :attr:`PoseSpace.singular` mask (all False unless a
    basis pose duplicates an earlier one).
    """
    n = rows_D.shape[1]
    FS = rows_F[basis_rows]
    P = len(FS)
    rows = list(basis_rows) if mode == "interp" else list(range(rows_F.shape[0]))
    A = _distances_global(rows_F[rows], FS)
    b = rows_D[rows].reshape(len(rows), -1).astype(np.float64)
    w, keep = _rest_constrained_lstsq(A[None], b[None], rcond)
    W = w[0]
    singular = np.zeros(n, bool)
    if P > 1 and not keep.all():
        target = rows_D[basis_rows]
        pred = (_distances_global(FS, FS) @ W).reshape(P, n, 3)
        singular = _missed(pred.transpose(1, 0, 2), target.transpose(1, 0, 2), _miss_thresholds(target))
    return W.reshape(P, n, 3).astype(np.float32), singular


def _weighted_columns(alpha: sp.csr_matrix, rows_F: FloatArray, FS: FloatArray) -> FloatArray:
    """(n, R, P) float64: ``‖rows_F[r] − FS[p]‖_v`` for every vertex."""
    return np.stack([_distances_weighted(alpha, rows_F, FS[j]) for j in range(len(FS))], 2)


def _solve_weighted(
    C: NDArray[np.float64],
    rows_D: NDArray,
    basis_rows: Sequence[int],
    mode: FitMode,
    rcond: float,
    chunk: int = 8192,
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Per-vertex RBF weights (n, P, 3) from distance columns C (n, R, P) and values (R, n, 3).

    Row 0 of C must be the rest pose. ``interp`` uses the rows ``basis_rows``
    (a ``P × P`` system per vertex), ``lsq`` every row; both are solved by
    :func:`_rest_constrained_lstsq`. Also returns :attr:`PoseSpace.singular`:
    vertices that dropped a basis pose their metric cannot tell from an
    earlier one *and* miss a basis pose's values by more than ``_MISS``.
    """
    n, _, P = C.shape
    W = np.empty((n, P, 3), np.float32)
    singular = np.zeros(n, bool)
    br = np.asarray(basis_rows, dtype=np.int64)
    rows = br if mode == "interp" else np.arange(C.shape[1])
    thr = _miss_thresholds(rows_D[br])
    for s in range(0, n, chunk):
        e = min(n, s + chunk)
        A = np.asarray(C[s:e][:, rows, :], np.float64)
        b = np.asarray(rows_D[rows, s:e], np.float64).transpose(1, 0, 2)
        w, keep = _rest_constrained_lstsq(A, b, rcond)
        W[s:e] = w
        if P > 1:
            Cb = np.asarray(C[s:e][:, br, :], np.float64)
            target = np.asarray(rows_D[br, s:e], np.float64).transpose(1, 0, 2)
            singular[s:e] = ~keep.all(axis=1) & _missed(np.einsum("nrp,npc->nrc", Cb, w), target, thr)
    return W, singular


def _check_training(features: ArrayLike, values: ArrayLike) -> tuple[FloatArray, NDArray[np.float32]]:
    Ft = np.asarray(features, dtype=np.float64)
    D = np.asarray(values, dtype=np.float32)
    if Ft.ndim != 2 or D.ndim != 3 or D.shape[0] != Ft.shape[0] or D.shape[2] != 3:
        raise ValueError(
            f"pose_space: need features (T, F) and values (T, n, 3) with the same T, got {Ft.shape}, {D.shape}"
        )
    return Ft, D


def _rows(Ft: FloatArray, D: NDArray[np.float32]) -> tuple[FloatArray, NDArray[np.float32]]:
    """Training rows with the rest pose (zero features, zero values) prepended as row 0."""
    rows_F = np.vstack([np.zeros((1, Ft.shape[1])), Ft])
    rows_D = np.concatenate([np.zeros((1, *D.shape[1:]), np.float32), D], 0)
    return rows_F, rows_D


def fit_pose_space(
    features: ArrayLike,
    values: ArrayLike,
    *,
    alpha: EdgeWeights | None = None,
    basis: Sequence[int] | None = None,
    mode: FitMode = "interp",
    rcond: float = _RCOND,
) -> PoseSpace:
    """Fit PSD (``alpha=None``) or WPSD weights.

    Parameters
    ----------
    features : (T, F) float
        Feature vectors of the training poses.
    values : (T, n, 3) float
        Values to reproduce (details in local frames, or displacements).
    alpha : EdgeWeights, optional
        WPSD edge weights (per-vertex metric); None = global PSD metric.
    basis : sequence of int, optional
        Training poses forming the basis (default: all). The rest pose (zero
        features, zero values) is always basis pose 0 and is not listed;
        training poses with exactly zero strain are skipped.
    mode : {"interp", "lsq"}
        ``interp``: reproduce the basis poses exactly (``P × P`` systems).
        ``lsq``: least squares over all ``T`` poses (``T × P`` systems).
    rcond : float
        Relative cut-off of the ordered column test (module docstring): a basis
        pose closer than this to the earlier ones in a vertex's metric gets weight 0.

    Both modes keep the rest pose exact: ``Σ_j w_j φ(‖f_j‖) = 0`` is imposed as
    a constraint (``interp`` reproduces it anyway), see :func:`_rest_constrained_lstsq`.
    """
    Ft, D = _check_training(features, values)
    if mode not in ("interp", "lsq"):
        raise ValueError(f"fit_pose_space: mode must be 'interp' or 'lsq', got {mode!r}")
    T, n = D.shape[:2]
    sel = list(range(T)) if basis is None else [int(b) for b in basis]
    if any(not 0 <= b < T for b in sel) or len(set(sel)) != len(sel):
        raise ValueError(f"fit_pose_space: basis must be distinct indices in 0..{T - 1}, got {sel}")
    sel = [b for b in sel if np.any(Ft[b] != 0.0)]
    rows_F, rows_D = _rows(Ft, D)
    basis_rows = [0] + [b + 1 for b in sel]
    FS = rows_F[basis_rows]
    P = len(basis_rows)
    if alpha is None:
        weights, singular = _fit_global(rows_F, rows_D, basis_rows, mode, rcond)
    else:
        if alpha.matrix.shape != (n, Ft.shape[1]):
            raise ValueError(
                f"fit_pose_space: alpha is {alpha.matrix.shape}, expected ({n}, {Ft.shape[1]}) (vertices, edges)"
            )
        used = basis_rows if mode == "interp" else list(range(T + 1))
        C = _weighted_columns(alpha.matrix, rows_F[used], FS)
        local_basis = list(range(P)) if mode == "interp" else basis_rows
        weights, singular = _solve_weighted(C, rows_D[used], local_basis, mode, rcond)
    return PoseSpace(
        basis_features=FS,
        weights=weights,
        alpha=alpha,
        basis=(-1, *sel),
        mode=mode,
        train_features=Ft,
        train_values=D,
        rcond=rcond,
        singular=singular,
    )


def greedy_fit(
    features: ArrayLike,
    values: ArrayLike,
    *,
    alpha: EdgeWeights | None = None,
    mode: FitMode = "lsq",
    max_basis: int | None = None,
    tolerance: float = 0.0,
    vertex_mask: ArrayLike | None = None,
    rcond: float = _RCOND,
    callback: Callable[[int, float, PoseSpace], None] | None = None,
) -> tuple[PoseSpace, list[float]]:
    """Greedy basis selection (Bickel et al. 2008, §5.2, after Carr et al. 2001).

    Start with the rest pose; repeatedly add the training pose with the largest
    error and refit, until the RMS error over all poses and vertices is at most
    ``tolerance`` or the basis has ``max_basis`` poses (rest pose included).

    In ``lsq`` mode the errors never rise (up to float32 rounding of the
    weights): each fit is the rest-constrained least-squares optimum over a
    basis that contains the previous one, with the same columns kept
    (:func:`_nested_columns`). They can stay flat: a second pose alone gets
    weight 0 (module docstring), and the next pose picked is then the
    second-largest error of the rest-only fit.

    Parameters
    ----------
    features : (T, F), values : (T, n, 3)
    alpha, mode, rcond : see :func:`fit_pose_space`
    max_basis : int, optional
        Default: every pose (``T + 1`` with the rest pose).
    tolerance : float
        RMS per-vertex error (model units) at which to stop.
    vertex_mask : (n,) bool, optional
        Vertices that count for the error (default all).
    callback : callable, optional
        ``callback(basis_size, rms_error, pose_space)`` after every fit (for
        error-vs-basis-size curves).

    Returns
    -------
    (PoseSpace, errors) where ``errors[k]`` is the RMS training error with ``k + 1`` basis poses.
    """
    Ft, D = _check_training(features, values)
    if mode not in ("interp", "lsq"):
        raise ValueError(f"greedy_fit: mode must be 'interp' or 'lsq', got {mode!r}")
    T, n = D.shape[:2]
    limit = T + 1 if max_basis is None else max(1, int(max_basis))
    mask = np.ones(n, bool) if vertex_mask is None else np.asarray(vertex_mask, bool).reshape(n)
    rows_F, rows_D = _rows(Ft, D)
    target = rows_D[:, mask].astype(np.float64)  # (R, nm, 3)
    nm = int(mask.sum())
    basis_rows = [0]
    cols: list[FloatArray] = []  # per basis pose: (n, R) weighted distances
    errors: list[float] = []
    singular: NDArray[np.bool_] | None = None
    while True:
        FS = rows_F[basis_rows]
        P = len(basis_rows)
        if alpha is None:
            weights, singular = _fit_global(rows_F, rows_D, basis_rows, mode, rcond)
            pred = (_distances_global(rows_F, FS) @ weights.reshape(P, -1)).reshape(T + 1, n, 3)[:, mask]
        else:
            cols.append(_distances_weighted(alpha.matrix, rows_F, rows_F[basis_rows[-1]]))
            C = np.stack(cols, 2)  # (n, R, P)
            weights, singular = _solve_weighted(C, rows_D, basis_rows, mode, rcond)
            pred = np.einsum("nrp,npc->rnc", C[mask], weights[mask], optimize=True)
        per_pose = np.sum((pred - target) ** 2, axis=(1, 2))
        errors.append(float(np.sqrt(per_pose[1:].sum() / max(T * nm, 1))))
        sel = [r - 1 for r in basis_rows[1:]]
        ps = PoseSpace(FS, weights, alpha, (-1, *sel), mode, Ft, D, rcond, tuple(errors), singular)
        if callback is not None:
            callback(P, errors[-1], ps)
        # candidates: poses not (numerically) equal to a basis pose — duplicates make the system singular
        dmin = _distances_global(rows_F, FS).min(axis=1)
        scale = max(float(np.abs(rows_F).max()), 1e-30)
        remaining = [r for r in range(1, T + 1) if dmin[r] > 1e-9 * scale]
        if errors[-1] <= tolerance or P >= limit or not remaining:
            return ps, errors
        basis_rows.append(max(remaining, key=lambda r: per_pose[r]))


# --------------------------------------------------------------------------- hybrid deformer


class DetailEvaluator:
    """Per-frame evaluation of a fitted pose space on a deforming mesh: frames + details.

    Holds float32, contiguous copies of everything a frame needs and reuses its
    buffers, so a frame allocates nothing. Uses the numba kernels of
    :mod:`workbench.methods.wrinkles.kernels` when available (``backend="auto"``), else numpy.

    Parameters
    ----------
    pose_space : PoseSpace
        Values must be details in local frames.
    faces : (m, 3) int
    neighbours : (n,) int
        Tangent neighbours (:func:`tangent_neighbours`).
    backend : {"auto", "numba", "numpy"}
    """

    def __init__(self, pose_space: PoseSpace, faces: ArrayLike, neighbours: ArrayLike, backend: str = "auto") -> None:
        if backend not in ("auto", "numba", "numpy"):
            raise ValueError(f"DetailEvaluator: backend must be auto, numba or numpy, got {backend!r}")
        if backend == "numba" and not _kernels.AVAILABLE:
            raise RuntimeError("DetailEvaluator: backend='numba' but numba is not installed")
        self.backend = "numba" if backend != "numpy" and _kernels.AVAILABLE else "numpy"
        self.pose_space = pose_space
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)
        n = pose_space.n_vertices
        self.neighbours = np.ascontiguousarray(neighbours, dtype=np.int32)
        if self.neighbours.shape != (n,):
            raise ValueError(f"DetailEvaluator: neighbours must be ({n},), got {self.neighbours.shape}")
        self.FS = np.ascontiguousarray(pose_space.basis_features, np.float32)
        self.W = np.ascontiguousarray(pose_space.weights, np.float32)
        if pose_space.alpha is not None:
            # edge ids fit in int16 (F is a few hundred): less memory traffic per frame
            idx_type = np.int16 if self.FS.shape[1] < np.iinfo(np.int16).max else np.int32
            self.a_idx = np.ascontiguousarray(pose_space.alpha.index, idx_type)
            self.a_val = np.ascontiguousarray(pose_space.alpha.value, np.float32)
        self.vf_ptr, self.vf_idx = _kernels.vertex_face_csr(self.faces, n)
        self._fbuf = np.empty((self.faces.shape[0], 3), np.float32)
        self._normals = np.zeros((n, 3), np.float32)
        self._all_rows = np.arange(n, dtype=np.int32)
        self._all_faces = np.arange(self.faces.shape[0], dtype=np.int32)
        # vertices with details (non-zero RBF weights; the rest of the head has none)
        # and the faces around them: a frame only touches these
        Wv = np.abs(self.W).max(axis=(1, 2)) if pose_space.alpha is not None else np.abs(self.W).max(axis=(0, 2))
        self.rows = np.flatnonzero(Wv > 0).astype(np.int32)
        touched = np.zeros(n, bool)
        touched[self.rows] = True
        self.face_rows = np.flatnonzero(touched[self.faces].any(axis=1)).astype(np.int32)
        if pose_space.alpha is not None:
            self._W8 = _kernels.pad_poses(self.W)  # WPSD weights in groups of 8 poses
            self._D = np.empty((self.FS.shape[1], self._W8.shape[1]), np.float32)

    def normals(self, X: NDArray[np.float32]) -> NDArray[np.float32]:
        """Unit area-weighted normals of X (n, 3) float32 (an internal buffer; copy to keep)."""
        if self.backend == "numba":
            _kernels.vertex_normals(
                X, self.faces, self.vf_ptr, self.vf_idx, self._all_faces, self._all_rows, self._fbuf, self._normals
            )
        else:
            self._normals[:] = vertex_normals(X, self.faces)
        return self._normals

    def apply(
        self,
        X: ArrayLike,
        features: ArrayLike,
        strength: float = 1.0,
        *,
        add_base: bool = True,
        out: NDArray[np.float32] | None = None,
    ) -> NDArray[np.float32]:
        """``X + strength · R_v d_v(f)`` (or only the detail displacement with ``add_base=False``).

        Parameters
        ----------
        X : (n, 3) float
            Large-scale positions (frames are taken from this surface).
        features : (F,) float
            Strain of the current pose.
        """
        X32 = np.ascontiguousarray(X, np.float32)
        f = np.ascontiguousarray(features, np.float32).reshape(-1)
        if out is None:
            out = np.empty_like(X32)
        ps = self.pose_space
        if self.backend == "numba":
            if ps.alpha is not None:
                # normals and details only where there are details; elsewhere out = X (or 0)
                N = self._normals
                _kernels.vertex_normals(
                    X32, self.faces, self.vf_ptr, self.vf_idx, self.face_rows, self.rows, self._fbuf, N
                )
                if out is not X32:
                    if add_base:
                        np.copyto(out, X32)
                    else:
                        out.fill(0.0)
                D = _kernels.wpsd_pose_table(self.FS, f, self._D)
                _kernels.wpsd_apply(
                    X32, N, self.neighbours, self.rows, self.a_idx, self.a_val, D, self._W8,
                    np.float32(strength), add_base, out,
                )
            else:
                N = self.normals(X32)
                phi = np.ascontiguousarray(ps.distances(f), np.float32)
                _kernels.psd_apply(X32, N, self.neighbours, phi, self.W, np.float32(strength), add_base, out)
            return out
        fr = local_frames(X32, self.faces, self.neighbours)
        d = to_world(fr, ps.evaluate(f)) * strength
        out[:] = X32 + d if add_base else d
        return out


@dataclass
class DetailSet:
    """Training data for a pose space: features and local details of T poses."""

    features: FloatArray  # (T, F)
    details: NDArray[np.float32]  # (T, n, 3) local frames
    large_scale: NDArray[np.float32] | None = None  # (T, n, 3) if kept


class HybridDeformer:
    """Large-scale shell + fine-scale pose-space details in one call (Bickel et al. 2008, Fig. 2).

    Parameters
    ----------
    shell : ShellDeformer
        Built on the rest mesh with the handle vertices.
    graph : FeatureGraph, optional
        Default: :meth:`FeatureGraph.from_handles` on the rest handle positions.
    weighted : bool
        WPSD (True) or global PSD (False).
    beta : float, optional
        WPSD decay (see :func:`edge_weights`).
    neighbours : int
        Nearest handles per handle for the automatic feature graph.
    active : (n,) bool, optional
        Vertices that carry details (others get exactly zero). Default: skin
        vertices (when the shell knows component names) within ``reach`` mean
        feature-edge lengths of the graph (``L_{v,i} − l_i`` of the nearest
        edge) — the face, not the back of the head, the tongue or the eyes,
        whose "details" would only be the shell's large-scale mismatch.
    reach : float
        See ``active``.
    """

    def __init__(
        self,
        shell: ShellDeformer,
        graph: FeatureGraph | None = None,
        *,
        weighted: bool = True,
        beta: float | None = None,
        neighbours: int = 4,
        active: ArrayLike | None = None,
        reach: float = 4.0,
    ) -> None:
        self.shell = shell
        self.rest = shell.vertices
        self.faces = shell.faces
        self.handles = shell.handles
        rest_h = self.rest[self.handles]
        self.graph = graph if graph is not None else FeatureGraph.from_handles(rest_h, neighbours)
        n = self.rest.shape[0]
        ew = edge_weights(self.rest, rest_h, self.graph, beta=beta)
        self.alpha = ew if weighted else None
        self.neighbours = tangent_neighbours(self.faces, n)
        if active is not None:
            self.active = np.asarray(active, bool).reshape(n)
        else:
            self.active = ew.nearest_excess <= reach * float(np.mean(self.graph.rest_lengths))
            names = list(shell.component_names or [])
            if "skin" in names and shell.component_labels is not None:
                self.active &= np.asarray(shell.component_labels).reshape(n) == names.index("skin")
        self.pose_space: PoseSpace | None = None

    def large_scale(self, handle_positions: ArrayLike) -> NDArray[np.float32]:
        """Shell deformation for (H, 3) handle positions, (n, 3) float32."""
        return self.shell.deform(handle_positions)

    def details_of(self, examples: ArrayLike) -> DetailSet:
        """Features and local details of detailed example meshes (T, n, 3) (paper mode)."""
        X = _positions(examples, "examples")
        if X.ndim == 2:
            X = X[None]
        T, n = X.shape[:2]
        feats = np.empty((T, len(self.graph)))
        det = np.empty((T, n, 3), np.float32)
        ls = np.empty((T, n, 3), np.float32)
        for t in range(T):
            p = X[t, self.handles]
            ls[t] = self.large_scale(p)
            feats[t] = self.graph.strain(p)
            det[t] = extract_details(X[t], ls[t], local_frames(ls[t], self.faces, self.neighbours))
        det[:, ~self.active] = 0.0
        return DetailSet(feats, det, ls)

    def fit(
        self,
        examples: ArrayLike | DetailSet,
        *,
        mode: FitMode = "interp",
        max_basis: int | None = None,
        tolerance: float = 0.0,
    ) -> PoseSpace:
        """Fit the pose space to detailed example meshes (T, n, 3) or a :class:`DetailSet`.

        ``interp`` with no ``max_basis`` uses every example; otherwise the basis is
        chosen greedily.
        """
        ds = examples if isinstance(examples, DetailSet) else self.details_of(examples)
        if mode == "interp" and max_basis is None and tolerance == 0.0:
            self.pose_space = fit_pose_space(ds.features, ds.details, alpha=self.alpha, mode="interp")
        else:
            self.pose_space, _ = greedy_fit(
                ds.features, ds.details, alpha=self.alpha, mode=mode, max_basis=max_basis, tolerance=tolerance
            )
        return self.pose_space

    def evaluator(self, backend: str = "auto") -> DetailEvaluator:
        """A per-frame :class:`DetailEvaluator` of the fitted pose space (cached per backend)."""
        if self.pose_space is None:
            raise RuntimeError("HybridDeformer: fit() first")
        cache = self.__dict__.setdefault("_evaluators", {})
        key = (id(self.pose_space), backend)
        if key not in cache:
            cache.clear()
            cache[key] = DetailEvaluator(self.pose_space, self.faces, self.neighbours, backend)
        return cache[key]

    def frame(
        self, handle_positions: ArrayLike, strength: float = 1.0, *, backend: str = "auto",
        out: NDArray[np.float32] | None = None,
    ) -> NDArray[np.float32]:
        """Fast path of :meth:`deform`: ``B·u_H`` + normals + frames + (W)PSD, (n, 3) float32.

        With numba every step is a fused two-thread kernel (no BLAS in the loop).
        """
        p = np.asarray(handle_positions, dtype=np.float64).reshape(-1, 3)
        if p.shape[0] != self.handles.size:
            raise ValueError(f"frame: expected {self.handles.size} handle positions, got {p.shape[0]}")
        if not hasattr(self, "_rest32"):
            self._rest32 = np.ascontiguousarray(self.rest, np.float32)
            self._uniq, self._col = np.unique(self.handles, return_inverse=True)
            self._count = np.bincount(self._col, minlength=self._uniq.size).astype(np.float64)[:, None]
            self._X = np.empty_like(self._rest32)
        d = p - self.rest[self.handles]
        uH = np.zeros((self._uniq.size, 3))
        np.add.at(uH, self._col, d)
        uH = np.ascontiguousarray(uH / self._count, np.float32)
        ev = self.evaluator(backend) if self.pose_space is not None else None
        use_numba = (ev.backend if ev is not None else ("numba" if _kernels.AVAILABLE and backend != "numpy" else "numpy")) == "numba"
        if use_numba:
            _kernels.bmul_add(self.shell.basis_, uH, self._rest32, self._X)
        else:
            np.add(self._rest32, self.shell.basis_ @ uH, out=self._X)
        if ev is None or strength == 0.0:
            if out is None:
                return self._X.copy()
            np.copyto(out, self._X)
            return out
        return ev.apply(self._X, self.graph.strain(p), strength, out=out)

    def deform(self, handle_positions: ArrayLike, strength: float = 1.0) -> NDArray[np.float32]:
        """Large-scale + fine-scale positions for (H, 3) handle positions, (n, 3) float32 (numpy reference)."""
        p = np.asarray(handle_positions, dtype=np.float64).reshape(-1, 3)
        X = self.large_scale(p)
        if self.pose_space is None or strength == 0.0:
            return X
        d = self.pose_space.evaluate(self.graph.strain(p))
        fr = local_frames(X, self.faces, self.neighbours)
        return (X + strength * to_world(fr, d)).astype(np.float32)


# --------------------------------------------------------------------------- comparison (§6.1, Fig. 4/5)

#: method name -> (values are details in local frames?, weighted metric?)
COMPARISON_METHODS: dict[str, tuple[bool, bool]] = {
    "global blend shapes": (False, False),
    "local blend shapes": (False, True),
    "PSD": (True, False),
    "WPSD": (True, True),
}


def compare_methods(
    hybrid: HybridDeformer,
    train: ArrayLike,
    test: ArrayLike | None = None,
    *,
    max_basis: int = 10,
    modes: Sequence[FitMode] = ("interp", "lsq"),
    methods: Sequence[str] | None = None,
) -> list[dict[str, float | int | str]]:
    """L2 error vs basis size for blend shapes, PSD and WPSD (Bickel et al. 2008, §6.1, Fig. 4).

    * **global blend shapes**: RBF (φ(r) = r) interpolation of the *full*
      displacements ``example − rest`` with the global feature distance; no shell.
    * **local blend shapes**: the same with the per-vertex weighted distance (eq. 3).
    * **PSD** / **WPSD**: shell ``B·u_H`` + details in local frames (§5.2 / §5.3).

    Each method is fitted with greedy basis selection from the rest pose, with
    exact interpolation of the chosen poses (``"interp"``) and with least squares
    over the whole training sequence (``"lsq"``).

    Parameters
    ----------
    hybrid : HybridDeformer
        Gives the shell, the feature graph, the edge weights and the face
        region (``hybrid.active``) over which errors are measured.
    train : (T, n, 3) float
        Detailed training frames (ground truth).
    test : (T', n, 3) float, optional
        Held-out frames, evaluated with each fit.
    max_basis : int
        Largest basis (rest pose included).

    Returns
    -------
    list of dict
        One row per (method, mode, basis size): ``method``, ``mode``, ``basis``,
        ``train_rms`` and ``test_rms`` (RMS per-vertex position error over the
        face region, model units), ``test_handle_max`` (largest error at a
        handle vertex on the test frames).
    """
    rest = hybrid.rest
    alpha = hybrid.alpha or edge_weights(rest, rest[hybrid.handles], hybrid.graph)
    mask = hybrid.active
    handle_mask = np.zeros(rest.shape[0], bool)
    handle_mask[hybrid.handles] = True
    sets = {"train": hybrid.details_of(train)}
    full = {"train": (np.asarray(train, np.float64) - rest[None]).astype(np.float32)}
    if test is not None:
        sets["test"] = hybrid.details_of(test)
        full["test"] = (np.asarray(test, np.float64) - rest[None]).astype(np.float32)
        # world error of details at handle vertices: the shell is exact there
        gt_test = np.asarray(test, np.float32)
    rows: list[dict[str, float | int | str]] = []
    for name in methods or list(COMPARISON_METHODS):
        is_detail, weighted = COMPARISON_METHODS[name]
        values = sets["train"].details if is_detail else full["train"]
        for mode in modes:

            def record(P: int, err: float, ps: PoseSpace, name: str = name, mode: str = mode, is_detail: bool = is_detail) -> None:
                row: dict[str, float | int | str] = {"method": name, "mode": mode, "basis": P, "train_rms": err}
                if test is not None:
                    ds = sets["test"]
                    pred = ps.evaluate_many(ds.features)
                    if is_detail:
                        err_v = pred - ds.details
                        assert ds.large_scale is not None
                        hmax = np.abs(ds.large_scale[:, handle_mask] - gt_test[:, handle_mask]).max()
                        hmax = max(hmax, float(np.abs(pred[:, handle_mask]).max()))
                    else:
                        err_v = pred - full["test"]
                        hmax = float(np.linalg.norm(err_v[:, handle_mask], axis=2).max())
                    row["test_rms"] = float(np.sqrt(np.mean(np.sum(err_v[:, mask] ** 2, axis=2))))
                    row["test_handle_max"] = float(hmax)
                rows.append(row)

            greedy_fit(
                sets["train"].features,
                values,
                alpha=alpha if weighted else None,
                mode=mode,
                max_basis=max_basis,
                vertex_mask=mask,
                callback=record,
            )
    return rows
