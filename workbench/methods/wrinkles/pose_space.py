"""Fine-scale detail in a strain pose space: fitting PSD and weighted PSD (Bickel et al. 2008, §5.2–5.3).

A :class:`PoseSpace` maps the strain features of a pose (the feature graph of
:mod:`workbench.methods.wrinkles.features`) to per-vertex values — fine-scale
details in local frames — learned from a few detailed example poses:

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
is numpy's batched ``eigh`` and scipy's sparse products. Per-frame evaluation
on a deforming mesh is in :mod:`workbench.methods.wrinkles.hybrid_deformer`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.methods.wrinkles.features import EdgeWeights, FloatArray

__all__ = [
    "FitMode",
    "PoseSpace",
    "fit_pose_space",
    "greedy_fit",
]


FitMode = Literal["interp", "lsq"]


_RCOND = 1e-3
_MISS = 1e-4


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
