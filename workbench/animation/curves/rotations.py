"""Quaternions and head rotations: slerp, rotation matrices, yaw/pitch/roll about the model's axes.

A ``"head_pose"`` value is ``(7,)`` = translation ``(tx, ty, tz)`` in model
units + unit quaternion ``(qx, qy, qz, qw)`` (glTF order); the transform maps a
model point ``p`` to ``R(q) p + t``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves.names import TrackError

#: identity head pose: no translation, quaternion (0, 0, 0, 1)
IDENTITY_POSE = np.array([0, 0, 0, 0, 0, 0, 1], np.float64)


def _normalize_quats(q: NDArray[np.float64]) -> NDArray[np.float64]:
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    return np.asarray(q / n, np.float64)


def quat_slerp(q0: ArrayLike, q1: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
    """Shortest-arc spherical linear interpolation of unit quaternions (x, y, z, w).

    Parameters
    ----------
    q0, q1 : (..., 4) float
        Unit quaternions.
    u : (...) float
        Interpolation parameter in [0, 1].

    Returns
    -------
    (..., 4) float
        Unit quaternions; ``u=0`` gives ``q0``, ``u=1`` gives ``±q1``.
    """
    a = np.asarray(q0, np.float64)
    b = np.asarray(q1, np.float64)
    uu = np.asarray(u, np.float64)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)  # shortest arc (same rule as glTF/three.js slerp)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    near = sin_t < 1e-9
    safe = np.where(near, 1.0, sin_t)
    w0 = np.where(near, 1.0 - uu, np.sin((1.0 - uu) * theta) / safe)
    w1 = np.where(near, uu, np.sin(uu * theta) / safe)
    return _normalize_quats(w0 * a + w1 * b)


def quaternion_to_matrix(q: ArrayLike) -> NDArray[np.float64]:
    """(3, 3) rotation matrix of a unit quaternion ``(x, y, z, w)``."""
    x, y, z, w = (float(c) for c in _normalize_quats(np.asarray(q, np.float64).reshape(4)))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _axis_vector(axis: str, what: str) -> NDArray[np.float64]:
    names = {"x": 0, "y": 1, "z": 2}
    if not isinstance(axis, str) or len(axis) != 2 or axis[0] not in "+-" or axis[1] not in names:
        raise TrackError(f"{what} must be a signed axis name like '+y', got {axis!r}")
    v = np.zeros(3)
    v[names[axis[1]]] = 1.0 if axis[0] == "+" else -1.0
    return v


def _head_basis(up_axis: str, front_axis: str) -> NDArray[np.float64]:
    """(3, 3) rotation whose columns are the model's side, up and front axes."""
    up = _axis_vector(up_axis, "up_axis")
    front = _axis_vector(front_axis, "front_axis")
    if abs(float(up @ front)) > 0:
        raise TrackError(f"up_axis {up_axis!r} and front_axis {front_axis!r} must be perpendicular")
    return np.stack([np.cross(up, front), up, front], axis=1)


def head_rotation_from_euler(
    yaw: float, pitch: float, roll: float, *, up_axis: str = "+y", front_axis: str = "+z"
) -> NDArray[np.float64]:
    """Unit quaternion ``(x, y, z, w)`` of a head turned by yaw, pitch and roll (degrees).

    Intrinsic yaw-pitch-roll about the model's own axes (right-hand rule):
    ``R = R_up(yaw) R_side(pitch) R_front(roll)`` with ``side = up × front``.
    For the usual ``up = +y``, ``front = +z`` (``side = +x``, the subject's
    left): positive yaw turns the face toward the subject's left, positive
    pitch nods it down, positive roll tilts the top of the head toward the
    subject's right. Uses :class:`scipy.spatial.transform.Rotation`.

    Parameters
    ----------
    yaw, pitch, roll : float
        Degrees.
    up_axis, front_axis : str
        Signed axis names (``model.metadata.up_axis`` / ``front_axis``).

    Returns
    -------
    (4,) float
        Unit quaternion with ``w >= 0``.
    """
    from scipy.spatial.transform import Rotation

    angles = np.array([yaw, pitch, roll], np.float64)
    if not np.isfinite(angles).all():
        raise TrackError(f"yaw, pitch and roll must be finite degrees, got {angles.tolist()}")
    B = _head_basis(up_axis, front_axis)
    local = Rotation.from_euler("YXZ", angles, degrees=True).as_matrix()
    q = np.asarray(Rotation.from_matrix(B @ local @ B.T).as_quat(), np.float64)
    return q if q[3] >= 0 else -q


def head_euler_from_rotation(
    rotation: ArrayLike, *, up_axis: str = "+y", front_axis: str = "+z"
) -> tuple[float, float, float]:
    """Inverse of :func:`head_rotation_from_euler`: ``(yaw, pitch, roll)`` in degrees.

    Parameters
    ----------
    rotation : (4,) float
        Quaternion ``(x, y, z, w)`` (normalised here).

    Returns
    -------
    tuple of float
        Yaw and roll in (-180, 180], pitch in [-90, 90] (at pitch ±90 yaw and
        roll are not unique; scipy picks roll = 0).
    """
    import warnings

    from scipy.spatial.transform import Rotation

    q = np.asarray(rotation, np.float64).reshape(-1)
    if q.shape != (4,) or not np.isfinite(q).all() or not np.linalg.norm(q) > 0:
        raise TrackError(f"rotation must be a finite non-zero (4,) quaternion, got {q.tolist()}")
    B = _head_basis(up_axis, front_axis)
    local = B.T @ quaternion_to_matrix(q) @ B
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # gimbal lock at pitch = ±90
        yaw, pitch, roll = Rotation.from_matrix(local).as_euler("YXZ", degrees=True)
    return float(yaw), float(pitch), float(roll)
