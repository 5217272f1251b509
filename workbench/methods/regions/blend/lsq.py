"""Bounded linear least squares with a ridge term, exact where it can be (NNLS), BVLS otherwise.

The solver of region sculpting (:mod:`~workbench.methods.regions.blend.sculpt`)
and marker fitting: ``scipy.optimize.nnls``
(compiled Lawson–Hanson active set) on ``w - slider_min`` with a small outer
active set for the upper bounds, KKT-checked, falling back to
``scipy.optimize.lsq_linear(method="bvls")`` — both maintained in scipy, already
a core dependency. NNLS is exact and ~100–500× faster than BVLS when many
weights sit at 0 (the usual case); ``benchmarks/bench_regions.py`` compares it
with OSQP through qpsolvers on the same problems.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import lsq_linear, nnls


def bounded_lsq(
    J: NDArray[np.float64],
    b: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    reg: float,
    *,
    lam: float | None = None,
) -> NDArray[np.float64]:
    """``argmin |J x - b|² + λ|x|²`` s.t. ``lo <= x <= hi``, ``λ = reg · mean(|J_col|²)``.

    Parameters
    ----------
    J : (m, u) float
    b : (m,) float
    lo, hi : (u,) float
        With ``lo <= 0 <= hi``.
    reg : float
    lam : float, optional
        Use this absolute ``λ`` instead (``reg`` is then ignored).

    Returns
    -------
    x : (u,) float64
    """
    u = J.shape[1]
    if lam is None:
        lam = reg * float(np.mean(np.einsum("ij,ij->j", J, J))) if u else 0.0
    if lam > 0:
        A = np.vstack([J, np.sqrt(lam) * np.eye(u)])
        rhs = np.concatenate([b, np.zeros(u)])
    else:
        A, rhs = J, b
    x = _box_nnls(A, rhs, lo, hi)
    if x is not None:
        return x
    # lsq_linear needs lo < hi strictly; pin fixed unknowns by a tiny box
    hi = np.where(hi <= lo, lo + 1e-12, hi)
    res = lsq_linear(A, rhs, bounds=(lo, hi), method="bvls", lsmr_tol=None)
    return np.asarray(res.x, dtype=np.float64)


def _box_nnls(
    A: NDArray[np.float64], b: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Exact box-constrained least squares by NNLS on ``x - lo``, upper bounds by an active set.

    ``scipy.optimize.nnls`` (Lawson–Hanson, compiled) is ~100–500× faster than
    ``lsq_linear(method="bvls")`` on these problems when many weights sit at 0.
    Variables above ``hi`` are fixed there and the rest re-solved; a fixed
    variable whose gradient asks to decrease is released. The result is returned
    only if it satisfies the KKT conditions of the box problem (so it is the
    optimum); otherwise None (the caller falls back to BVLS).
    """
    u = A.shape[1]
    if u == 0:
        return np.zeros(0)
    at_hi = np.zeros(u, bool)
    x = lo.copy()
    for _ in range(2 * u + 2):
        free = ~at_hi
        x = np.where(at_hi, hi, lo)
        r = b - A[:, at_hi] @ hi[at_hi] - A[:, free] @ lo[free]
        if free.any():  # scipy 1.17's nnls aborts the process (double free) on a 0-column matrix
            try:
                y, _ = nnls(A[:, free], r, maxiter=max(50, 6 * u))
            except RuntimeError:
                return None
            x[free] = lo[free] + y
        g = A.T @ (A @ x - b)  # gradient / 2
        over = free & (x > hi)
        release = at_hi & (g > 1e-12 * (1.0 + np.abs(g).max()))
        if not over.any() and not release.any():
            tol = 1e-9 * (1.0 + np.abs(g).max())
            ok_lo = np.all(g[(x <= lo) & free] >= -tol)
            ok_mid = np.all(np.abs(g[(x > lo) & (x < hi) & free]) <= 1e-6 * (1.0 + np.abs(A.T @ b).max()))
            return x if ok_lo and ok_mid else None
        at_hi = (at_hi | over) & ~release
    return None
