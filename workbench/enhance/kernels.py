"""The per-triangle hot loop of §5.4 fused: blend the matched detail (eq. 4) and compose it with the input.

``J_t = R_t H_t R_tᵀ T_t`` with ``H_t = Σ_j c_tj H_{a_j, t}`` (or the matrix of the
blended polar parts ``Σ_j c_tj P_{a_j, t}``, :mod:`workbench.enhance.polar`) for every
triangle ``t`` in one pass (numba, parallel over triangles): no (k, m, 3, 3) copy of the active
database frames and no three batched 3×3 products through numpy temporaries —
together 60 % of a frame at 318k before. Without numba the numpy path of
:meth:`PerformanceDatabase.blend_detail` and :meth:`~PerformanceDatabase.compose`
is used (the same numbers; a test pins both).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from workbench._numba import NUMBA, njit, prange
from workbench.enhance.polar import polar_matrix

__all__ = ["NUMBA", "blend_compose"]


@njit(parallel=True, cache=True)
def _blend_compose(C, active, detail, R, T, polar, out):  # pragma: no cover - numba
    m = R.shape[0]
    k = active.shape[0]
    for t in prange(m):
        H = np.zeros((3, 3))
        p = np.zeros(9)
        Hj = np.empty((3, 3))
        for j in range(k):
            c = C[t, j]
            if c != 0.0:
                D = detail[active[j], t]
                if polar:
                    for a in range(9):
                        p[a] += c * D[a]
                else:
                    polar_matrix(D, Hj)
                    for a in range(3):
                        for b in range(3):
                            H[a, b] += c * Hj[a, b]
        if polar:
            polar_matrix(p, H)
        RH = np.zeros((3, 3))
        for a in range(3):
            for b in range(3):
                s = 0.0
                for q in range(3):
                    s += R[t, a, q] * H[q, b]
                RH[a, b] = s
        M = np.zeros((3, 3))
        for a in range(3):
            for b in range(3):
                s = 0.0
                for q in range(3):
                    s += RH[a, q] * R[t, b, q]
                M[a, b] = s
        for a in range(3):
            for b in range(3):
                s = 0.0
                for q in range(3):
                    s += M[a, q] * T[t, q, b]
                out[t, a, b] = s


def blend_compose(
    C: NDArray[np.float32],
    active: NDArray[np.int64],
    detail: NDArray[np.float32],
    R: NDArray[np.float64],
    T: NDArray[np.float64],
    *,
    polar: bool = False,
) -> NDArray[np.float64]:
    """Target Jacobians (m, 3, 3) from per-triangle weights of the active database frames (numba only).

    Parameters
    ----------
    C : (m, k) float32
        Weight of active frame ``j`` on triangle ``t`` (eq. 4's region-normalised sum).
    active : (k,) int64
        The frames ``C``'s columns refer to.
    detail : (D, m, 9) float32
        The database's detail ``H`` in polar parts.
    R : (m, 3, 3) float64
        The input's low-frequency triangle frames.
    T : (m, 3, 3) float64
        The input's low-frequency gradients from ``f(d0)``.
    polar : bool
        Blend the polar parts (``detail_blend="polar"``), else the matrices they stand for.
    """
    if not NUMBA:
        raise RuntimeError("blend_compose needs numba (the 'fast' extra); use blend_detail + compose")
    out = np.empty(R.shape, np.float64)
    _blend_compose(np.ascontiguousarray(C, np.float32), np.ascontiguousarray(active, np.int64), detail,
                   np.ascontiguousarray(R), np.ascontiguousarray(T), bool(polar), out)
    return out
