"""Similarity transforms ``p -> s R p + t`` and their least-squares fit (Umeyama 1991)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Similarity", "fit_similarity"]


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
    X = np.asarray(X, np.float64)
    Y = np.asarray(Y, np.float64)
    w = np.ones(X.shape[0]) if w is None else np.asarray(w, np.float64)
    ws = w.sum()
    if ws <= 0:
        raise ValueError("fit_similarity: all weights are zero")
    mx = (w[:, None] * X).sum(0) / ws
    my = (w[:, None] * Y).sum(0) / ws
    Xc, Yc = X - mx, Y - my
    C = (w[:, None] * Yc).T @ Xc / ws
    U, S, Vt = np.linalg.svd(C)
    D = np.eye(3)
    if np.linalg.det(U @ Vt) < 0:
        D[2, 2] = -1.0
    R = U @ D @ Vt
    var = float((w * (Xc**2).sum(1)).sum() / ws)
    s = float(np.trace(np.diag(S) @ D) / var) if scale and var > 0 else 1.0
    return Similarity(s, R, my - s * (mx @ R.T))
