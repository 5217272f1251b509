"""The per-triangle hot loop of §5.4 fused: blend the matched detail (eq. 4) and compose it with the input.

``J_t = R_t H_t R_tᵀ T_t`` with ``H_t = Σ_j c_tj H_{a_j, t}`` (or, for a database that
stores polar parts, the matrix of ``Σ_j c_tj P_{a_j, t}``, :mod:`workbench.enhance.polar`)
for every triangle ``t`` in one pass (numba, parallel over triangles): no (k, m, 3, 3) copy of the active
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


@njit(cache=True, inline="always")
def _compose(t, H, R, T, out):  # pragma: no cover - numba
    """``out[t] = R_t H R_tᵀ T_t``."""
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


@njit(parallel=True, cache=True)
def _blend_compose(C, active, detail, R, T, out):  # pragma: no cover - numba
    for t in prange(R.shape[0]):
        H = np.zeros((3, 3))
        for j in range(active.shape[0]):
            c = C[t, j]
            if c != 0.0:
                D = detail[active[j], t]
                for a in range(3):
                    for b in range(3):
                        H[a, b] += c * D[a, b]
        _compose(t, H, R, T, out)


@njit(parallel=True, cache=True)
def _blend_compose_polar(C, active, detail, R, T, out):  # pragma: no cover - numba
    for t in prange(R.shape[0]):
        p = np.zeros(9)
        for j in range(active.shape[0]):
            c = C[t, j]
            if c != 0.0:
                D = detail[active[j], t]
                for a in range(9):
                    p[a] += c * D[a]
        H = np.empty((3, 3))
        polar_matrix(p, H)
        _compose(t, H, R, T, out)


def blend_compose(
    C: NDArray[np.float32],
    active: NDArray[np.int64],
    detail: NDArray[np.float32],
    R: NDArray[np.float64],
    T: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Target Jacobians (m, 3, 3) from per-triangle weights of the active database frames (numba only).

    Parameters
    ----------
    C : (m, k) float32
        Weight of active frame ``j`` on triangle ``t`` (eq. 4's region-normalised sum).
    active : (k,) int64
        The frames ``C``'s columns refer to.
    detail : (D, m, 3, 3) or (D, m, 9) float32
        The database's detail ``H``: matrices, or polar parts (blended as such).
    R : (m, 3, 3) float64
        The input's low-frequency triangle frames.
    T : (m, 3, 3) float64
        The input's low-frequency gradients from ``f(d0)``.
    """
    if not NUMBA:
        raise RuntimeError("blend_compose needs numba (the 'fast' extra); use blend_detail + compose")
    out = np.empty(R.shape, np.float64)
    kernel = _blend_compose_polar if detail.ndim == 3 else _blend_compose
    kernel(np.ascontiguousarray(C, np.float32), np.ascontiguousarray(active, np.int64), detail,
           np.ascontiguousarray(R), np.ascontiguousarray(T), out)
    return out
