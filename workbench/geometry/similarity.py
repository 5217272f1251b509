"""Similarity transforms ``p -> s R p + t`` and their least-squares fit (Umeyama 1991).

:func:`procrustes` is the one closed form (weighted Kabsch / Horn, Umeyama's
scale, reflections excluded) behind :func:`fit_similarity` (rig registration),
:func:`workbench.capture.pose.fit_rigid` (the head pose while tracking, which
adds its degeneracy checks and reweighting) and
:func:`workbench.enhance.gradients.rigid_align` (aligning frames before their
frequencies are split). Hand-written: a 3×3 SVD; ``scipy``'s
``Rotation.align_vectors`` has no translation, scale or weights normalised this way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Similarity", "fit_similarity", "procrustes"]


@dataclass(frozen=True)
class Similarity:
    """``p -> scale * p @ R.T + t`` (``R`` a rotation)."""

    scale: float
    R: NDArray[np.float64]
    t: NDArray[np.float64]

    def __call__(self, P: ArrayLike) -> NDArray[np.float64]:
        return self.scale * (np.asarray(P, np.float64) @ self.R.T) + self.t

    def linear(self, D: ArrayLike) -> NDArray[np.float64]:
        """Apply to vectors (displacements): ``scale * R d``."""
        return self.scale * (np.asarray(D, np.float64) @ self.R.T)

    def inverse_linear(self, D: ArrayLike) -> NDArray[np.float64]:
        """Vectors back: ``R^T d / scale``."""
        return (np.asarray(D, np.float64) @ self.R) / self.scale

    def then(self, other: Similarity) -> Similarity:
        """``other(self(p))``."""
        return Similarity(self.scale * other.scale, other.R @ self.R, other.scale * (self.t @ other.R.T) + other.t)

    @staticmethod
    def identity() -> Similarity:
        return Similarity(1.0, np.eye(3), np.zeros(3))


def fit_similarity(
    X: ArrayLike, Y: ArrayLike, w: ArrayLike | None = None, *, scale: bool = True
) -> Similarity:
    """Least-squares similarity ``Y ~ s R X + t`` (Umeyama 1991), optionally weighted.

    Parameters
    ----------
    X, Y : (p, 3) float
        Corresponding points (p >= 3, not collinear, for a unique rotation).
    w : (p,) float, optional
    scale : bool
        Fit the scale (else 1).
    """
    R, t, s, _ = procrustes(X, Y, w, scale=scale)
    return Similarity(s, R, t)


def procrustes(
    P: ArrayLike, Q: ArrayLike, w: ArrayLike | None = None, *, scale: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, NDArray[np.float64]]:
    """The weighted least-squares ``Q ≈ s R P + t`` in closed form (Kabsch / Horn; Umeyama's scale).

    Parameters
    ----------
    P, Q : (p, 3) float
        Corresponding points (finite; p >= 3 not on one line for a unique rotation).
    w : (p,) float, optional
        Weights >= 0 (default 1), not all zero.
    scale : bool
        Fit the scale ``s`` (else 1).

    Returns
    -------
    R : (3, 3) float64
        A rotation (det +1: reflections excluded).
    t : (3,) float64
    s : float
    singular_values : (3,) float64
        Of the weighted cross-covariance ``Σ w (p − p̄)(q − q̄)ᵀ``, descending: a second
        one near 0 relative to the first means the points are (nearly) collinear.

    Raises
    ------
    ValueError
        All weights are zero.
    """
    X = np.asarray(P, np.float64)
    Y = np.asarray(Q, np.float64)
    wv = np.ones(X.shape[0]) if w is None else np.asarray(w, np.float64)
    ws = float(wv.sum())
    if not ws > 0:
        raise ValueError("procrustes: all weights are zero")
    mx = wv @ X / ws
    my = wv @ Y / ws
    Xc = X - mx
    Xw = Xc * wv[:, None]
    U, S, Vt = np.linalg.svd(Xw.T @ (Y - my))  # Σ w x yᵀ = U S Vt; R = V D Uᵀ
    d = 1.0 if np.linalg.det(U) * np.linalg.det(Vt) >= 0 else -1.0
    R = (Vt.T * np.array([1.0, 1.0, d])) @ U.T
    s = 1.0
    if scale:
        var = float((Xw * Xc).sum())
        s = float((S[0] + S[1] + d * S[2]) / var) if var > 0 else 1.0
    return R, my - s * (R @ mx), s, S
