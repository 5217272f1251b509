"""Polar form of per-triangle detail gradients: a rotation vector and a symmetric stretch (Bermano 2014 §4, §5.4).

Bermano et al. define their shape space "using the polar decompositions of the
deformation gradients [...] and thus effectively represents the stretching and
rotation of each triangle", and blend the high-frequency detail in that space
before "converting the stretching and rotation vectors [...] back to the
deformation gradients' matrices". A detail matrix ``H = Q S`` (``Q`` a
rotation, ``S`` symmetric) is stored as nine numbers
``[r_x, r_y, r_z, S_00, S_01, S_02, S_11, S_12, S_22]`` with ``r`` the rotation
vector of ``Q`` (axis × angle); blending is linear in those nine numbers.

Why not blend the matrices: the weighted mean of two rotations is not a
rotation — two folds of a wrinkle turning a triangle by ±θ blend into a
triangle shrunk by ``cos θ`` — while the mean of their rotation vectors is a
rotation by the mean angle. For one frame at weight 1 both give ``H`` back.

Hand-written because the decomposition and its inverse run per triangle inside
the enhancement's hot loop (numba, no temporaries); scipy's ``polar`` and
``Rotation`` work one matrix or one batch at a time through numpy. The
decomposition is Higham's Newton iteration ``Q ← (Q + Q⁻ᵀ)/2`` from ``H``
(quadratic convergence; detail matrices are close to the identity), with an
SVD where ``det H ≤ 0``.

Shapes: ``H : (m, 3, 3)``; polar parts ``P : (m, 9)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench._numba import NUMBA, njit, prange

__all__ = ["from_polar", "polar_matrix", "to_polar"]

_SMALL = 1e-7  # below this angle (radians) the series of Rodrigues' formula is exact in float64
_NEAR_PI = np.pi - 1e-3  # above it the axis comes from the symmetric part


@njit(cache=True)
def _inv3(A, out):  # pragma: no cover - numba
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    d, e, f = A[1, 0], A[1, 1], A[1, 2]
    g, h, i = A[2, 0], A[2, 1], A[2, 2]
    c0, c1, c2 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c0 + b * c1 + c * c2
    if det == 0.0:
        return 0.0
    s = 1.0 / det
    out[0, 0], out[0, 1], out[0, 2] = c0 * s, (c * h - b * i) * s, (b * f - c * e) * s
    out[1, 0], out[1, 1], out[1, 2] = c1 * s, (a * i - c * g) * s, (c * d - a * f) * s
    out[2, 0], out[2, 1], out[2, 2] = c2 * s, (b * g - a * h) * s, (a * e - b * d) * s
    return det


@njit(cache=True)
def _rotation_of(H, Q):  # pragma: no cover - numba
    """The rotation of ``H``'s polar decomposition into ``Q`` (3, 3)."""
    Qi = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            Q[a, b] = H[a, b]
    if _inv3(Q, Qi) > 0.0:
        for _ in range(30):
            change = 0.0
            for a in range(3):
                for b in range(3):
                    v = 0.5 * (Q[a, b] + Qi[b, a])
                    change += (v - Q[a, b]) ** 2
                    Q[a, b] = v
            if change < 1e-26:
                return
            if _inv3(Q, Qi) <= 0.0:
                break
    # det H <= 0 (or no convergence): the closest rotation from the SVD
    U, _s, Vt = np.linalg.svd(H)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0.0:
        for a in range(3):
            U[a, 2] = -U[a, 2]
    for a in range(3):
        for b in range(3):
            Q[a, b] = U[a, 0] * Vt[0, b] + U[a, 1] * Vt[1, b] + U[a, 2] * Vt[2, b]


@njit(cache=True)
def _log(Q, r):  # pragma: no cover - numba
    """Rotation vector ``r`` (3,) of a rotation matrix ``Q``."""
    vx, vy, vz = Q[2, 1] - Q[1, 2], Q[0, 2] - Q[2, 0], Q[1, 0] - Q[0, 1]  # 2 sin θ · axis
    cos = 0.5 * (Q[0, 0] + Q[1, 1] + Q[2, 2] - 1.0)
    sin = 0.5 * np.sqrt(vx * vx + vy * vy + vz * vz)
    theta = np.arctan2(sin, cos)  # accurate at every angle (arccos loses half the digits near 0 and π)
    if theta < _SMALL:
        r[0], r[1], r[2] = 0.5 * vx, 0.5 * vy, 0.5 * vz
        return
    if theta < _NEAR_PI:
        k = theta / (2.0 * sin)
        r[0], r[1], r[2] = k * vx, k * vy, k * vz
        return
    # near π the skew part vanishes: the axis from (Q + Qᵀ)/2 = cos θ I + (1 − cos θ) a aᵀ
    j = 0
    for a in range(1, 3):
        if Q[a, a] > Q[j, j]:
            j = a
    ax = np.empty(3)
    for a in range(3):
        ax[a] = 0.5 * (Q[a, j] + Q[j, a]) - (cos if a == j else 0.0)
    norm = np.sqrt(ax[0] ** 2 + ax[1] ** 2 + ax[2] ** 2)
    sign = -1.0 if ax[0] * vx + ax[1] * vy + ax[2] * vz < 0.0 else 1.0
    for a in range(3):
        r[a] = sign * theta * ax[a] / norm


@njit(cache=True)
def _exp(r0, r1, r2, Q):  # pragma: no cover - numba
    """Rotation matrix ``Q`` of the rotation vector ``(r0, r1, r2)`` (Rodrigues)."""
    theta2 = r0 * r0 + r1 * r1 + r2 * r2
    theta = np.sqrt(theta2)
    if theta < _SMALL:
        a, b = 1.0, 0.5  # sin θ/θ and (1 − cos θ)/θ² to the order that matters in float64
    else:
        a, b = np.sin(theta) / theta, (1.0 - np.cos(theta)) / theta2
    Q[0, 0] = 1.0 - b * (r1 * r1 + r2 * r2)
    Q[1, 1] = 1.0 - b * (r0 * r0 + r2 * r2)
    Q[2, 2] = 1.0 - b * (r0 * r0 + r1 * r1)
    Q[0, 1] = -a * r2 + b * r0 * r1
    Q[1, 0] = a * r2 + b * r0 * r1
    Q[0, 2] = a * r1 + b * r0 * r2
    Q[2, 0] = -a * r1 + b * r0 * r2
    Q[1, 2] = -a * r0 + b * r1 * r2
    Q[2, 1] = a * r0 + b * r1 * r2


@njit(cache=True)
def polar_matrix(p, H):  # pragma: no cover - numba
    """``H = Q S`` (3, 3) from one row of polar parts ``p`` (9,)."""
    Q = np.empty((3, 3))
    _exp(p[0], p[1], p[2], Q)
    s00, s01, s02, s11, s12, s22 = p[3], p[4], p[5], p[6], p[7], p[8]
    for a in range(3):
        q0, q1, q2 = Q[a, 0], Q[a, 1], Q[a, 2]
        H[a, 0] = q0 * s00 + q1 * s01 + q2 * s02
        H[a, 1] = q0 * s01 + q1 * s11 + q2 * s12
        H[a, 2] = q0 * s02 + q1 * s12 + q2 * s22


@njit(parallel=True, cache=True)
def _to_polar(H, P):  # pragma: no cover - numba
    for t in prange(H.shape[0]):
        Q = np.empty((3, 3))
        r = np.empty(3)
        Ht = np.empty((3, 3))
        for a in range(3):
            for b in range(3):
                Ht[a, b] = H[t, a, b]
        _rotation_of(Ht, Q)
        _log(Q, r)
        S = np.empty((3, 3))  # Qᵀ H, symmetric up to round-off: keep its symmetric part
        for a in range(3):
            for b in range(3):
                S[a, b] = Q[0, a] * Ht[0, b] + Q[1, a] * Ht[1, b] + Q[2, a] * Ht[2, b]
        P[t, 0], P[t, 1], P[t, 2] = r[0], r[1], r[2]
        P[t, 3] = S[0, 0]
        P[t, 4] = 0.5 * (S[0, 1] + S[1, 0])
        P[t, 5] = 0.5 * (S[0, 2] + S[2, 0])
        P[t, 6] = S[1, 1]
        P[t, 7] = 0.5 * (S[1, 2] + S[2, 1])
        P[t, 8] = S[2, 2]


@njit(parallel=True, cache=True)
def _from_polar(P, H):  # pragma: no cover - numba
    for t in prange(P.shape[0]):
        p = np.empty(9)
        for a in range(9):
            p[a] = P[t, a]
        Ht = np.empty((3, 3))
        polar_matrix(p, Ht)
        for a in range(3):
            for b in range(3):
                H[t, a, b] = Ht[a, b]


def to_polar(H: ArrayLike) -> NDArray[np.float64]:
    """Polar parts (m, 9) of matrices (m, 3, 3): rotation vector, then the stretch's upper triangle.

    Parameters
    ----------
    H : (m, 3, 3) float
        Per-triangle matrices; rotations of up to π, any stretch. Where
        ``det H ≤ 0`` the rotation is the closest one (from the SVD) and the
        stretch is ``Qᵀ H``'s symmetric part.

    Returns
    -------
    P : (m, 9) float64
        ``[r_x, r_y, r_z, S_00, S_01, S_02, S_11, S_12, S_22]`` with ``H = exp([r]×) S``.
    """
    A = np.ascontiguousarray(H, np.float64)
    if A.ndim != 3 or A.shape[1:] != (3, 3):
        raise ValueError(f"H must be (m, 3, 3), got {A.shape}")
    if not NUMBA:
        return _to_polar_numpy(A)
    P = np.empty((A.shape[0], 9))
    _to_polar(A, P)
    return P


def from_polar(P: ArrayLike) -> NDArray[np.float64]:
    """Matrices ``H = exp([r]×) S`` (m, 3, 3) from polar parts (m, 9) (:func:`to_polar`'s layout)."""
    A = np.ascontiguousarray(P, np.float64)
    if A.ndim != 2 or A.shape[1] != 9:
        raise ValueError(f"P must be (m, 9), got {A.shape}")
    if not NUMBA:
        return _from_polar_numpy(A)
    H = np.empty((A.shape[0], 3, 3))
    _from_polar(A, H)
    return H


# ----------------------------------------------------------------- without numba: the same, in numpy
def _to_polar_numpy(A: NDArray[np.float64]) -> NDArray[np.float64]:
    U, _s, Vt = np.linalg.svd(A)
    flip = np.linalg.det(U) * np.linalg.det(Vt) < 0
    U[flip, :, 2] *= -1
    Q = U @ Vt
    S = Q.transpose(0, 2, 1) @ A
    S = 0.5 * (S + S.transpose(0, 2, 1))
    v = np.stack([Q[:, 2, 1] - Q[:, 1, 2], Q[:, 0, 2] - Q[:, 2, 0], Q[:, 1, 0] - Q[:, 0, 1]], axis=1)
    cos = 0.5 * (np.trace(Q, axis1=1, axis2=2) - 1.0)
    sin = 0.5 * np.linalg.norm(v, axis=1)
    theta = np.arctan2(sin, cos)
    small = theta < _SMALL
    k = np.where(small, 0.5, theta / (2.0 * np.where(small, 1.0, sin)))
    r = k[:, None] * v
    for t in np.flatnonzero(theta >= _NEAR_PI):  # rare: as the numba path, one matrix at a time
        j = int(np.argmax(np.diag(Q[t])))
        axis = 0.5 * (Q[t, :, j] + Q[t, j, :])
        axis[j] -= cos[t]
        axis /= np.linalg.norm(axis)
        r[t] = theta[t] * axis * (-1.0 if axis @ v[t] < 0 else 1.0)
    iu = np.triu_indices(3)
    return np.concatenate([r, S[:, iu[0], iu[1]]], axis=1)


def _from_polar_numpy(A: NDArray[np.float64]) -> NDArray[np.float64]:
    r = A[:, :3]
    theta2 = np.einsum("ij,ij->i", r, r)
    theta = np.sqrt(theta2)
    small = theta < _SMALL
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(safe) / safe)
    b = np.where(small, 0.5, (1.0 - np.cos(safe)) / (safe * safe))
    K = np.zeros((len(A), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -r[:, 2], r[:, 1], -r[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = r[:, 2], -r[:, 1], r[:, 0]
    Q = np.eye(3)[None] + a[:, None, None] * K + b[:, None, None] * (K @ K)
    S = np.empty((len(A), 3, 3))
    S[:, 0, 0], S[:, 1, 1], S[:, 2, 2] = A[:, 3], A[:, 6], A[:, 8]
    S[:, 0, 1] = S[:, 1, 0] = A[:, 4]
    S[:, 0, 2] = S[:, 2, 0] = A[:, 5]
    S[:, 1, 2] = S[:, 2, 1] = A[:, 7]
    return Q @ S
