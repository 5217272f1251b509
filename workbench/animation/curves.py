"""Keyframes and animation curves: :class:`Key`, :class:`Track`, tangents, interpolation, head rotations.

A :class:`Track` holds the keys of one animated quantity and evaluates its
curve; a :class:`~workbench.animation.tracks.Timeline` holds the tracks.
Track names say what a track animates:

* ``"weights/<shape>"`` — scalar tracks, one per keyed blendshape weight;
* ``"handles"`` — a vector track whose values are the handle-layer offsets,
  ``(h, 3)`` in model units (the "pose keys" of the handle layer);
* ``"head_pose"`` — a rigid head transform, value ``(7,)`` =
  translation ``(tx, ty, tz)`` in model units + unit quaternion ``(qx, qy, qz, qw)``
  (glTF order). The transform maps a model point ``p`` to ``R(q) p + t``;
  :func:`head_rotation_from_euler` / :func:`head_euler_from_rotation` convert
  yaw/pitch/roll about the model's axes;
* ``"regions/<level>/<region>"`` — per-region blend weights (Joshi et al. 2003
  §3/§4), a vector track whose value is ``(k,)``: the weight of every model
  shape (in the model's shape order, as a row of
  :class:`workbench.methods.regions.blend.RegionWeights`) inside region ``<region>`` of
  hierarchy level ``<level>`` (the rules for a timeline's region tracks are
  in :mod:`workbench.animation.tracks`).

Interpolation (per key; a key's interpolation governs the segment that *starts*
at it, as in Blender):

``step``
    hold the key's value until the next key.
``linear``
    straight line to the next key.
``bezier``
    cubic Bézier whose inner control points sit at 1/3 and 2/3 of the segment
    *in time*, so the value is a cubic polynomial of ``t`` — exactly the cubic
    Hermite curve of glTF's ``CUBICSPLINE``. With key values ``v0, v1`` at times
    ``t0 < t1``, ``Δ = t1 - t0``, ``u = (t - t0) / Δ``, the key's *out* slope
    ``m0`` and the next key's *in* slope ``m1`` (value units per second)::

        v(t) = (2u³ - 3u² + 1) v0 + (u³ - 2u² + u) Δ m0 + (-2u³ + 3u²) v1 + (u³ - u²) Δ m1

    i.e. Bézier control values ``v0, v0 + m0 Δ/3, v1 - m1 Δ/3, v1``.

Tangents are slopes (``dv/dt``), stored on every key (``in_tangent``,
``out_tangent``). ``tangent_mode="auto_clamped"`` keys get them computed by the
track (Blender's "Auto Clamped" rule, ``BKE_nurb_handle_calc`` for F-curves),
``"user"`` keys keep what :func:`set_tangents` gave them. The auto-clamped
slope at key ``k`` with neighbour secants ``s_a = (v_k - v_{k-1}) / (t_k - t_{k-1})``
and ``s_b = (v_{k+1} - v_k) / (t_{k+1} - t_k)`` is::

    m_k = 0                                  if k is the first or last key
                                             (flat ends, constant extrapolation),
    m_k = 0                                  if s_a * s_b <= 0 (a local extreme
                                             or a plateau: flat, no overshoot),
    m_k = sign(s) * min(|s_a + s_b| / 2, 3|s_a|, 3|s_b|)   otherwise.

``(s_a + s_b) / 2`` is Blender's direction for F-curve auto handles (the sum of
the two unit-x-length neighbour vectors); the ``3|s|`` caps are Blender's
"clamped" overshoot rule for handles at 1/3 of the interval: they keep the
inner Bézier control values between the two key values, so by the convex-hull
property a segment never leaves ``[min(v0, v1), max(v0, v1)]`` (and with both
``α = m/s <= 3`` it is monotone, Fritsch–Carlson). Both in and out slopes of an
auto key are ``m_k``. Vector tracks apply the rule per component (each
component is one F-curve, as in Blender). Differences from Blender: Blender's
handle *time* length is not exactly 1/3 of the interval for uneven key spacing;
we fix it at 1/3 so each segment is an exact cubic in ``t`` (and exports to
glTF without resampling).

Head-pose rotation is always interpolated by spherical linear interpolation
(shortest arc; ``step`` holds) — Bézier/tangents apply to its translation only —
so it exports exactly as glTF ``LINEAR`` rotation.

Outside the keyed range a track holds its first/last value (constant
extrapolation). Times are seconds.

Hand-written because no kept dependency has keyframe curves; scipy's
``CubicHermiteSpline`` would evaluate the segments but not the per-key
interpolation modes or clamping rules.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "HANDLES",
    "HEAD_POSE",
    "IDENTITY_POSE",
    "INTERPOLATIONS",
    "REGIONS_PREFIX",
    "TANGENT_MODES",
    "WEIGHTS_PREFIX",
    "Interpolation",
    "Key",
    "TangentMode",
    "Track",
    "TrackError",
    "auto_clamped_slopes",
    "head_euler_from_rotation",
    "head_rotation_from_euler",
    "parse_region_track",
    "quat_slerp",
    "quaternion_to_matrix",
    "region_track_name",
    "weight_track_name",
]


Interpolation = Literal["step", "linear", "bezier"]
TangentMode = Literal["auto_clamped", "user"]
INTERPOLATIONS: tuple[str, ...] = ("step", "linear", "bezier")
TANGENT_MODES: tuple[str, ...] = ("auto_clamped", "user")
_CODE = {"step": 0, "linear": 1, "bezier": 2}

WEIGHTS_PREFIX = "weights/"
HANDLES = "handles"
HEAD_POSE = "head_pose"
REGIONS_PREFIX = "regions/"

#: identity head pose: no translation, quaternion (0, 0, 0, 1)
IDENTITY_POSE = np.array([0, 0, 0, 0, 0, 0, 1], np.float64)


class TrackError(ValueError):
    """A key, track or timeline that cannot be built or edited as asked."""


def weight_track_name(shape: str) -> str:
    """``"weights/<shape>"``: the track name of a blendshape weight."""
    return WEIGHTS_PREFIX + shape


def region_track_name(level: int, region: str) -> str:
    """``"regions/<level>/<region>"``: the track name of one region's blend weights."""
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        raise TrackError(f"region track level must be an int >= 0, got {level!r}")
    if not isinstance(region, str) or not region:
        raise TrackError(f"region track region must be a non-empty name, got {region!r}")
    return f"{REGIONS_PREFIX}{int(level)}/{region}"


def parse_region_track(name: str) -> tuple[int, str] | None:
    """``(level, region)`` of a ``"regions/<level>/<region>"`` name, else None."""
    if not isinstance(name, str) or not name.startswith(REGIONS_PREFIX):
        return None
    level, sep, region = name[len(REGIONS_PREFIX) :].partition("/")
    if not sep or not region or not level.isdigit() or not level.isascii():
        return None
    return int(level), region


def _readonly(a: NDArray[Any]) -> NDArray[Any]:
    a.setflags(write=False)
    return a


def _as_value(value: ArrayLike, what: str) -> NDArray[np.float64]:
    v = np.array(value, dtype=np.float64)
    if not np.isfinite(v).all():
        raise TrackError(f"{what}: value must be finite, got NaN/inf")
    return _readonly(v)


# ---------------------------------------------------------------------------- keys
@dataclass(frozen=True, eq=False, init=False)
class Key:
    """One keyframe (immutable).

    Parameters
    ----------
    time : float
        Seconds.
    value : float or (h, 3) or (7,) or (k,) array
        Scalar for weight tracks, ``(h, 3)`` offsets for the handle track,
        ``(7,)`` translation + quaternion (x, y, z, w) for the head pose,
        ``(k,)`` shape weights for a region track.
        Stored as a read-only float64 array (0-d for scalars).
    interpolation : {"step", "linear", "bezier"}
        How the segment starting at this key is interpolated.
    in_tangent, out_tangent : float or array like ``value``, optional
        Slopes (value units per second) arriving at / leaving this key. Only
        used by Bézier segments; computed by the track for auto-clamped keys.
    tangent_mode : {"auto_clamped", "user"}
        ``auto_clamped``: the track computes the slopes (see module docstring);
        ``user``: the given slopes are kept.
    """

    time: float
    value: NDArray[np.float64]
    interpolation: Interpolation
    in_tangent: NDArray[np.float64]
    out_tangent: NDArray[np.float64]
    tangent_mode: TangentMode

    def __init__(
        self,
        time: float,
        value: ArrayLike,
        interpolation: Interpolation = "bezier",
        in_tangent: ArrayLike | None = None,
        out_tangent: ArrayLike | None = None,
        tangent_mode: TangentMode = "auto_clamped",
    ) -> None:
        t = float(time)
        if not math.isfinite(t):
            raise TrackError(f"key time must be finite, got {time!r}")
        object.__setattr__(self, "time", t)
        v = _as_value(value, f"key at t={t:g}")
        object.__setattr__(self, "value", v)
        if interpolation not in INTERPOLATIONS:
            raise TrackError(
                f"key at t={t:g}: interpolation must be one of {INTERPOLATIONS}, "
                f"got {interpolation!r}"
            )
        object.__setattr__(self, "interpolation", interpolation)
        if tangent_mode not in TANGENT_MODES:
            raise TrackError(
                f"key at t={t:g}: tangent_mode must be one of {TANGENT_MODES}, "
                f"got {tangent_mode!r}"
            )
        object.__setattr__(self, "tangent_mode", tangent_mode)
        for name, tan in (("in_tangent", in_tangent), ("out_tangent", out_tangent)):
            arr = np.zeros_like(v) if tan is None else np.asarray(tan, np.float64)
            try:
                arr = np.broadcast_to(arr, v.shape)
            except ValueError:
                raise TrackError(
                    f"key at t={t:g}: {name} has shape {arr.shape}, the value has {v.shape}"
                ) from None
            object.__setattr__(self, name, _as_value(arr, f"key at t={t:g}: {name}"))

    @property
    def scalar(self) -> float:
        """The value as a float (scalar tracks only)."""
        return float(self.value)

    def replace(self, **changes: Any) -> Key:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


def auto_clamped_slopes(times: ArrayLike, values: ArrayLike) -> NDArray[np.float64]:
    """Blender-like auto-clamped slopes at every key (formula in the module docstring).

    Parameters
    ----------
    times : (K,) float
        Strictly increasing key times.
    values : (K, d) float
        Key values, one column per independent component.

    Returns
    -------
    (K, d) float
        Slope ``dv/dt`` at each key; 0 at the first and last key and at extremes.
    """
    t = np.asarray(times, np.float64)
    v = np.asarray(values, np.float64).reshape(t.size, -1)
    m = np.zeros_like(v)
    if t.size < 3:
        return m
    s = np.diff(v, axis=0) / np.diff(t)[:, None]  # (K-1, d) secants
    sa, sb = s[:-1], s[1:]
    same_sign = sa * sb > 0
    mag = np.minimum(np.abs(sa + sb) / 2.0, np.minimum(3.0 * np.abs(sa), 3.0 * np.abs(sb)))
    m[1:-1] = np.where(same_sign, np.sign(sa) * mag, 0.0)
    return m


# --------------------------------------------------------------------- quaternions
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


# -------------------------------------------------------------------------- tracks
@dataclass(frozen=True, eq=False)
class Track:
    """Keys of one animated quantity, sorted by strictly increasing time (immutable).

    Parameters
    ----------
    name : str
        ``"weights/<shape>"``, ``"handles"``, ``"head_pose"`` or
        ``"regions/<level>/<region>"``.
    keys : sequence of Key
        At least one key; times strictly increasing; all values the same shape
        (scalar for weights, ``(h, 3)`` for handles, ``(7,)`` for the head pose,
        ``(k,)`` with ``k >= 1`` for a region).

    Raises
    ------
    TrackError
        Unknown track name, no keys, non-increasing times, mismatched value shapes.
    """

    name: str
    keys: tuple[Key, ...]
    _times: NDArray[np.float64] = field(init=False, repr=False)
    _values: NDArray[np.float64] = field(init=False, repr=False)
    _in: NDArray[np.float64] = field(init=False, repr=False)
    _out: NDArray[np.float64] = field(init=False, repr=False)
    _codes: NDArray[np.int8] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        name = self.name
        if not isinstance(name, str) or not (
            name in (HANDLES, HEAD_POSE)
            or (name.startswith(WEIGHTS_PREFIX) and len(name) > len(WEIGHTS_PREFIX))
            or parse_region_track(name) is not None
        ):
            raise TrackError(
                "track name must be 'weights/<shape>', 'handles', 'head_pose' or "
                f"'regions/<level>/<region>', got {name!r}"
            )
        keys = tuple(self.keys)
        if not keys:
            raise TrackError(f"track {name!r}: needs at least one key")
        for k in keys:
            if not isinstance(k, Key):
                raise TrackError(f"track {name!r}: keys must be Key objects, got {type(k).__name__}")
        times = np.array([k.time for k in keys], np.float64)
        bad = np.flatnonzero(np.diff(times) <= 0)
        if bad.size:
            i = int(bad[0])
            raise TrackError(
                f"track {name!r}: key times must be strictly increasing, but key {i + 1} "
                f"(t={times[i + 1]:g}) does not come after key {i} (t={times[i]:g})"
            )
        shape = keys[0].value.shape
        expect: tuple[int, ...] | None = {HEAD_POSE: (7,)}.get(name)
        if name.startswith(WEIGHTS_PREFIX):
            expect = ()
        if expect is not None and shape != expect:
            raise TrackError(f"track {name!r}: values must have shape {expect}, got {shape}")
        if name == HANDLES and (len(shape) != 2 or shape[1] != 3):
            raise TrackError(f"track 'handles': values must be (h, 3) offsets, got shape {shape}")
        if name.startswith(REGIONS_PREFIX) and (len(shape) != 1 or shape[0] < 1):
            raise TrackError(
                f"track {name!r}: values must be (k,) shape weights, one per model shape, "
                f"got shape {shape}"
            )
        for i, k in enumerate(keys):
            if k.value.shape != shape:
                raise TrackError(
                    f"track {name!r}: key {i} (t={k.time:g}) has value shape {k.value.shape}, "
                    f"key 0 has {shape}"
                )
        if name == HEAD_POSE:
            keys = tuple(_normalized_pose_key(k, name, i) for i, k in enumerate(keys))
        values = np.stack([k.value.reshape(-1) for k in keys])
        auto = auto_clamped_slopes(times, values)
        resolved = []
        for i, k in enumerate(keys):
            if k.tangent_mode == "auto_clamped":
                m = _readonly(auto[i].reshape(shape).copy())
                k = dataclasses.replace(k, in_tangent=m, out_tangent=m)
            resolved.append(k)
        keys = tuple(resolved)
        object.__setattr__(self, "keys", keys)
        object.__setattr__(self, "_times", _readonly(times))
        object.__setattr__(self, "_values", _readonly(values))
        object.__setattr__(
            self, "_in", _readonly(np.stack([k.in_tangent.reshape(-1) for k in keys]))
        )
        object.__setattr__(
            self, "_out", _readonly(np.stack([k.out_tangent.reshape(-1) for k in keys]))
        )
        object.__setattr__(
            self, "_codes", _readonly(np.array([_CODE[k.interpolation] for k in keys], np.int8))
        )

    # ---------------------------------------------------------------- access
    def __len__(self) -> int:
        return len(self.keys)

    @property
    def times(self) -> NDArray[np.float64]:
        """(K,) float, read-only: key times in seconds."""
        return self._times

    @property
    def values(self) -> NDArray[np.float64]:
        """(K, d) float, read-only: key values flattened to ``d`` components."""
        return self._values

    @property
    def value_shape(self) -> tuple[int, ...]:
        return self.keys[0].value.shape

    @property
    def kind(self) -> str:
        """"weight", "handles", "head_pose" or "region"."""
        if self.name.startswith(WEIGHTS_PREFIX):
            return "weight"
        return "region" if self.name.startswith(REGIONS_PREFIX) else self.name

    @property
    def region(self) -> tuple[int, str] | None:
        """``(level, region name)`` of a region track, else None."""
        return parse_region_track(self.name)

    @property
    def shape_name(self) -> str | None:
        """The blendshape name of a weight track, else None."""
        return self.name[len(WEIGHTS_PREFIX) :] if self.kind == "weight" else None

    @property
    def interpolations(self) -> tuple[str, ...]:
        return tuple(k.interpolation for k in self.keys)

    def index_at(self, time: float, tol: float = 1e-9) -> int | None:
        """Index of the key at ``time`` (within ``tol`` seconds), or None."""
        i = int(np.argmin(np.abs(self._times - time)))
        return i if abs(self._times[i] - time) <= tol else None

    # ------------------------------------------------------------ evaluation
    def sample(self, times: ArrayLike) -> NDArray[np.float64]:
        """Values at many times.

        Parameters
        ----------
        times : (F,) float
            Seconds (any order).

        Returns
        -------
        (F, d) float
            Flattened values (``d = 1`` for weights, ``3h`` for handles, 7 for the
            head pose with unit quaternions, ``k`` for a region).
        """
        ts = np.asarray(times, np.float64).reshape(-1)
        out, _ = self._eval(ts, derivative=False)
        return out

    def evaluate(self, time: float) -> NDArray[np.float64]:
        """Value at one time, shaped like a key value (a 0-d array for weights)."""
        return self.sample([time])[0].reshape(self.value_shape)

    def derivatives(self, times: ArrayLike, side: Literal["left", "right"] = "right") -> NDArray[np.float64]:
        """(F, d) one-sided time derivatives ``dv/dt`` (rotation components: 0).

        ``side="right"`` uses the segment starting at ``t`` (the out-tangent at a
        key), ``"left"`` the segment ending at ``t`` (the in-tangent). Used to
        split Bézier segments exactly when exports merge key times.
        """
        ts = np.asarray(times, np.float64).reshape(-1)
        _, d = self._eval(ts, derivative=True, side=side)
        assert d is not None
        return d

    def _eval(
        self, ts: NDArray[np.float64], derivative: bool, side: str = "right"
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        T, V = self._times, self._values
        K = T.size
        if K == 1:
            val = np.broadcast_to(V[0], (ts.size, V.shape[1])).copy()
            return val, (np.zeros_like(val) if derivative else None)
        # segment index: key i governs [T[i], T[i+1]); for left derivatives at a
        # key time, use the segment that ends there.
        if side == "left":
            seg = np.searchsorted(T, ts, side="left") - 1
        else:
            seg = np.searchsorted(T, ts, side="right") - 1
        before = seg < 0
        after = seg >= K - 1
        s = np.clip(seg, 0, K - 2)
        t0, t1 = T[s], T[s + 1]
        dt = t1 - t0
        u = np.clip((ts - t0) / dt, 0.0, 1.0)[:, None]
        v0, v1 = V[s], V[s + 1]
        m0, m1 = self._out[s], self._in[s + 1]
        code = self._codes[s][:, None]
        dtc = dt[:, None]
        u2, u3 = u * u, u * u * u
        lin = v0 + (v1 - v0) * u
        herm = (
            (2 * u3 - 3 * u2 + 1) * v0
            + (u3 - 2 * u2 + u) * dtc * m0
            + (-2 * u3 + 3 * u2) * v1
            + (u3 - u2) * dtc * m1
        )
        # a step segment holds v0 until the next key, which then takes over
        step = np.where(u >= 1.0, v1, v0)
        val = np.where(code == 0, step, np.where(code == 1, lin, herm))
        dv: NDArray[np.float64] | None = None
        if derivative:
            dlin = (v1 - v0) / dtc
            dherm = (
                (6 * u2 - 6 * u) * v0
                + (3 * u2 - 4 * u + 1) * dtc * m0
                + (-6 * u2 + 6 * u) * v1
                + (3 * u2 - 2 * u) * dtc * m1
            ) / dtc
            dv = np.where(code == 0, 0.0, np.where(code == 1, dlin, dherm))
        if self.name == HEAD_POSE:
            q0, q1 = v0[:, 3:], v1[:, 3:]
            uq = np.where(code[:, 0] == 0, (u[:, 0] >= 1.0).astype(np.float64), u[:, 0])
            val[:, 3:] = quat_slerp(q0, q1, uq)
            if dv is not None:
                dv[:, 3:] = 0.0
        # constant extrapolation outside the keyed range
        val[before] = V[0]
        val[after] = V[-1]
        if dv is not None:
            dv[before] = 0.0
            dv[after] = 0.0
        return val, dv


def _normalized_pose_key(k: Key, name: str, i: int) -> Key:
    q = k.value[3:]
    n = float(np.linalg.norm(q))
    if n < 1e-12:
        raise TrackError(f"track {name!r}: key {i} (t={k.time:g}) has a zero quaternion")
    v = k.value.copy()
    v[3:] = q / n
    return dataclasses.replace(k, value=_readonly(v))
