"""Robust rigid pose: weighted Kabsch / Horn (optionally with scale), reweighted against outliers.

The rigid stage of tracking (Bouaziz et al. 2013, §3.1, "rigid motion
tracking": the head pose from points the expressions barely move). Given
model points ``P`` and observed points ``Q`` in correspondence, find ``s, R, t``
with ``Q ≈ s R P + t`` minimising ``Σ ρ(||s R p_i + t − q_i||)``:

* :func:`fit_rigid` — the weighted least-squares optimum in closed form (the SVD
  of the weighted cross-covariance, Kabsch 1976 / Horn 1987; with ``scale=True``
  Umeyama's 1991 scale), reflections excluded;
* :func:`fit_rigid_robust` — iteratively reweighted least squares (IRLS) with the
  Huber or Tukey biweight loss, the residual scale from the median absolute
  deviation; points with a NaN coordinate (occluded markers) are ignored.

Both are small numpy functions (a 3×3 SVD per iteration). Why not a library:
``scipy.spatial.transform.Rotation.align_vectors`` gives the weighted rotation
only (no translation, scale, reweighting or NaN handling), and a general
robust optimiser (``scipy.optimize.least_squares`` with a loss) iterates on a
parameterised rotation for what the closed form gives in one SVD. Shapes: ``P : (n, 3) float``, ``Q : (n, 3) float``,
``weights : (n,) float``; results are ``(4, 4)`` homogeneous matrices acting on
column vectors, ``q = M @ [p, 1]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.similarity import procrustes

__all__ = ["PoseError", "RigidPose", "fit_rigid", "fit_rigid_robust", "pose_matrix"]

Loss = Literal["huber", "tukey", "l2"]

#: tuning constants for 95 % efficiency under Gaussian noise (in units of the residual scale)
_HUBER_C = 1.345
_TUKEY_C = 4.685
#: a spread this small relative to the largest says the points are collinear (or all at one place)
_DEGENERATE = 1e-6


class PoseError(ValueError):
    """The points cannot define a rigid pose (too few, collinear, wrong shape)."""


@dataclass(frozen=True, eq=False)
class RigidPose:
    """A fitted similarity ``q ≈ scale · R p + t``.

    Attributes
    ----------
    matrix : (4, 4) float
        ``[[scale·R, t], [0, 1]]``.
    rotation : (3, 3) float
    translation : (3,) float
    scale : float
        1 unless fitted with ``scale=True``.
    weights : (n,) float
        Final robust weight of every point in [0, 1] (0 for points with NaN, Tukey outliers).
    rms : float
        Root-mean-square residual of the points with weight > 0.5 (the inliers), in the units of ``Q``.
    n_iter : int
        Reweighting iterations used.
    """

    matrix: NDArray[np.float64]
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    scale: float
    weights: NDArray[np.float64]
    rms: float
    n_iter: int

    def apply(self, P: ArrayLike) -> NDArray[np.float64]:
        """``(n, 3)`` points ``scale · R p + t``."""
        P_ = np.asarray(P, np.float64)
        return self.scale * P_ @ self.rotation.T + self.translation


def pose_matrix(rotation: ArrayLike, translation: ArrayLike, scale: float = 1.0) -> NDArray[np.float64]:
    """``(4, 4)`` homogeneous matrix of ``p -> scale · R p + t``."""
    M = np.eye(4)
    M[:3, :3] = float(scale) * np.asarray(rotation, np.float64)
    M[:3, 3] = np.asarray(translation, np.float64)
    return M


def _points(P: ArrayLike, Q: ArrayLike, weights: ArrayLike | None) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
]:
    P_ = np.asarray(P, np.float64)
    Q_ = np.asarray(Q, np.float64)
    if P_.ndim != 2 or P_.shape[1] != 3:
        raise PoseError(f"P must be (n, 3) points, got shape {P_.shape}")
    if Q_.shape != P_.shape:
        raise PoseError(f"Q must have the shape of P {P_.shape}, got {Q_.shape}")
    if weights is None:
        w = np.ones(P_.shape[0])
    else:
        w = np.asarray(weights, np.float64)
        if w.shape != (P_.shape[0],):
            raise PoseError(f"weights must have shape ({P_.shape[0]},), got {w.shape}")
        if not (np.isfinite(w).all() and (w >= 0).all()):
            raise PoseError("weights must be finite and ≥ 0")
    return P_, Q_, w


def _kabsch(P: NDArray[np.float64], Q: NDArray[np.float64], w: NDArray[np.float64], scale: bool,
            what: str, check: bool = True) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """:func:`~workbench.geometry.similarity.procrustes` on finite points with w ≥ 0, Σw > 0 (checked by the caller).

    ``check``: raise :class:`PoseError` when the weighted points are collinear (else the
    caller guards against it, e.g. by the singular values of the cross-covariance).
    """
    if check:
        sw = float(w.sum())
        Pc = P - w @ P / sw
        C = (Pc * w[:, None]).T @ Pc  # weighted covariance of P (times Σw)
        ev = np.linalg.eigvalsh(C)  # ascending
        if not ev[2] > 0 or ev[1] <= _DEGENERATE**2 * ev[2]:
            spread = np.sqrt(np.maximum(ev[::-1], 0.0) / sw)
            raise PoseError(
                f"{what}: the {P.shape[0]} points are collinear or coincide "
                f"(spread {spread[0]:.3g}, {spread[1]:.3g}): a rigid pose needs 3 points not on one line"
            )
    R, t, s, S = procrustes(P, Q, w, scale=scale)
    if not check and not S[1] > _DEGENERATE * S[0]:
        raise PoseError(f"{what}: the weighted points are collinear")
    return R, t, s


def fit_rigid(P: ArrayLike, Q: ArrayLike, weights: ArrayLike | None = None, *,
              scale: bool = False) -> NDArray[np.float64]:
    """The weighted least-squares rigid (or similarity) transform taking ``P`` onto ``Q``.

    Parameters
    ----------
    P, Q : (n, 3) float
        Corresponding points; rows with a NaN in either are ignored.
    weights : (n,) float, optional
        ≥ 0 per point (default 1).
    scale : bool
        Also fit a uniform scale (Umeyama).

    Returns
    -------
    (4, 4) float
        ``M`` with ``Q ≈ (M @ [P, 1]ᵀ)ᵀ`` minimising ``Σ w_i ||s R p_i + t − q_i||²``.

    Raises
    ------
    PoseError
        Fewer than 3 usable points, or all of them on one line.
    """
    P_, Q_, w = _points(P, Q, weights)
    ok = np.isfinite(P_).all(1) & np.isfinite(Q_).all(1) & (w > 0)
    if int(ok.sum()) < 3:
        raise PoseError(f"P, Q: need at least 3 points finite in both (with weight > 0), got {int(ok.sum())}")
    R, t, s = _kabsch(P_[ok], Q_[ok], w[ok], scale, "P")
    return pose_matrix(R, t, s)


def _median(r: NDArray[np.float64]) -> float:
    """The median (the upper one for an even count: a scale estimate needs no more)."""
    h = r.size // 2
    return float(np.partition(r, h)[h])


def _robust_weights(r: NDArray[np.float64], sigma: float, loss: Loss) -> NDArray[np.float64]:
    if loss == "l2":
        return np.ones_like(r)
    if loss == "huber":
        c = _HUBER_C * sigma
        return np.minimum(1.0, c / np.maximum(r, 1e-300))
    c = _TUKEY_C * sigma
    u = r / c
    return np.where(u < 1.0, (1.0 - u * u) ** 2, 0.0)


def fit_rigid_robust(
    P: ArrayLike,
    Q: ArrayLike,
    *,
    weights: ArrayLike | None = None,
    scale: bool = False,
    loss: Loss = "tukey",
    sigma: float | None = None,
    max_iter: int = 20,
    tol: float = 1e-9,
) -> RigidPose:
    """Rigid (or similarity) pose by iteratively reweighted least squares; robust to outliers.

    Parameters
    ----------
    P, Q : (n, 3) float
        Corresponding points (model, observed); rows with a NaN in either are ignored.
    weights : (n,) float, optional
        Prior weights ≥ 0 (multiplied by the robust ones).
    scale : bool
        Also fit a uniform scale.
    loss : {"tukey", "huber", "l2"}
        Tukey's biweight rejects points beyond ``4.685 σ`` outright; Huber down-weights
        beyond ``1.345 σ``; ``"l2"`` is :func:`fit_rigid`.
    sigma : float, optional
        Residual scale (the units of ``Q``). Default: re-estimated each iteration as
        ``1.4826 · median`` of the residual norms (MAD), floored at ``1e-9`` of the points' extent.
    max_iter : int
        Most reweighting iterations (≥ 1).
    tol : float
        Stop when the transform moves a point by less than ``tol`` × the points' extent.

    Returns
    -------
    RigidPose

    Raises
    ------
    PoseError
        Fewer than 3 usable points or collinear ones (before any reweighting).
    """
    if loss not in ("tukey", "huber", "l2"):
        raise PoseError(f"loss must be 'tukey', 'huber' or 'l2', got {loss!r}")
    if int(max_iter) < 1:
        raise PoseError(f"max_iter must be ≥ 1, got {max_iter!r}")
    P_, Q_, w0 = _points(P, Q, weights)
    ok = np.isfinite(P_).all(1) & np.isfinite(Q_).all(1) & (w0 > 0)
    n_ok = int(ok.sum())
    if n_ok < 3:
        raise PoseError(f"P, Q: need at least 3 points finite in both (with weight > 0), got {n_ok}")
    Pv, Qv, wv = P_[ok], Q_[ok], w0[ok]
    extent = float(np.ptp(Pv, axis=0).max()) or 1.0
    R, t, s = _kabsch(Pv, Qv, wv, scale, "P")
    rw = np.ones(n_ok)
    it = 0
    fixed_sigma = None if sigma is None else float(sigma)
    if fixed_sigma is not None and not (np.isfinite(fixed_sigma) and fixed_sigma > 0):
        raise PoseError(f"sigma must be a positive number, got {sigma!r}")
    X = s * Pv @ R.T + t
    if loss != "l2":
        floor = 1e-9 * extent
        for it in range(1, int(max_iter) + 1):  # noqa: B007 - `it` is reported
            r = np.sqrt(((X - Qv) ** 2).sum(1))
            sig = fixed_sigma if fixed_sigma is not None else max(1.4826 * _median(r), floor)
            new_rw = _robust_weights(r, sig, loss)
            wt = wv * new_rw
            if int(np.count_nonzero(wt)) < 3:
                break  # the loss would reject all but two points: keep the last pose
            try:
                R2, t2, s2 = _kabsch(Pv, Qv, wt, scale, "P", check=False)
            except PoseError:
                break
            rw = new_rw
            X2 = s2 * Pv @ R2.T + t2
            move = float(np.abs(X2 - X).max())
            R, t, s, X = R2, t2, s2, X2
            if move <= tol * extent:
                break
    weights_out = np.zeros(P_.shape[0])
    weights_out[ok] = rw
    r = np.sqrt(((X - Qv) ** 2).sum(1))
    inl = rw > 0.5
    rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else float(np.sqrt(np.mean(r**2)))
    return RigidPose(pose_matrix(R, t, s), R, t, s, weights_out, rms, it)
