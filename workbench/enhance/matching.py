"""Convex least squares on the simplex for the shape-space matching (Bermano et al. 2014, §5.3, eq. 2–3).

``min_w  wᵀ G w − 2 bᵀ w   s.t.  w ≥ 0, Σ w = 1`` with a precomputed normal
matrix ``G = D̃ᵀ diag(ω) D̃`` (D × D, D the database frames) and ``b = D̃ᵀ diag(ω) ã``.

Solved as a non-negative least-squares problem (``scipy.optimize.nnls``,
Lawson–Hanson active set): ``G = V S Vᵀ`` gives ``A = S^½ Vᵀ`` and
``y = S^-½ Vᵀ b`` (directions with ``s ≈ 0`` dropped), plus one heavily weighted
row ``√ρ 1ᵀ w = √ρ`` for the sum; the result is renormalised to sum to one.
Hand-written because scipy has no QP solver and the paper's (MOSEK) is not a
dependency; the active-set solve is scipy's.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import nnls

__all__ = ["SimplexLSQ", "simplex_lsq"]


class SimplexLSQ:
    """The matching of one region, factored once: ``G = V S Vᵀ`` (eq. 3's normal matrix is fixed per database).

    Parameters
    ----------
    G : (D, D) float
        Symmetric positive semi-definite normal matrix.
    rho : float
        Weight of the sum-to-one row relative to the mean eigenvalue of ``G``.
    """

    def __init__(self, G: ArrayLike, *, rho: float = 1e4) -> None:
        g = np.asarray(G, np.float64)
        D = g.shape[0]
        if g.ndim != 2 or g.shape != (D, D):
            raise ValueError(f"G must be (D, D), got {g.shape}")
        self.D = D
        if D == 1:
            return
        s, V = np.linalg.eigh(0.5 * (g + g.T))
        keep = s > 1e-12 * max(float(s.max()), 1e-300)
        self._sq = np.sqrt(s[keep])
        self._Vt = np.ascontiguousarray(V[:, keep].T)
        w_sum = np.sqrt(rho * max(float(s.mean()), 1e-300))
        self._A = np.vstack([self._sq[:, None] * self._Vt, np.full((1, D), w_sum)])
        self._w_sum = w_sum

    def solve(self, b: ArrayLike) -> NDArray[np.float64]:
        """Convex weights (D,) minimising ``wᵀGw − 2bᵀw`` on the probability simplex."""
        r = np.asarray(b, np.float64)
        if r.shape != (self.D,):
            raise ValueError(f"b must be ({self.D},), got {r.shape}")
        if self.D == 1:
            return np.ones(1)
        y = np.concatenate([(self._Vt @ r) / self._sq, [self._w_sum]])
        w, _ = nnls(self._A, y, maxiter=50 * self.D)
        total = w.sum()
        return w / total if total > 0 else np.full(self.D, 1.0 / self.D)


def simplex_lsq(G: ArrayLike, b: ArrayLike, *, rho: float = 1e4) -> NDArray[np.float64]:
    """Convex weights (D,) minimising ``wᵀGw − 2bᵀw`` on the probability simplex (:class:`SimplexLSQ` once).

    Parameters
    ----------
    G : (D, D) float
        Symmetric positive semi-definite normal matrix.
    b : (D,) float
    rho : float
        Weight of the sum-to-one row relative to the mean eigenvalue of ``G``.
    """
    g = np.asarray(G, np.float64)
    r = np.asarray(b, np.float64)
    D = g.shape[0]
    if g.shape != (D, D) or r.shape != (D,):
        raise ValueError(f"G must be (D, D) and b (D,), got {g.shape} and {r.shape}")
    return SimplexLSQ(g, rho=rho).solve(r)
