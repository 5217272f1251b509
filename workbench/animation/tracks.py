"""Keyframes, tracks and the timeline: immutable values and pure edit functions.

A :class:`Timeline` holds named :class:`Track` objects:

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
  hierarchy level ``<level>``. All region tracks of a timeline are on one
  level and have the same ``k``. While a timeline has region tracks, they
  define the region weights of that level: keyed regions take their keyed
  values and every other region of the level follows the global weights
  (no correction there), whatever static region weights the model holds.
  ``FaceModel.key_marker_fit`` writes them from a marker fit.

Everything is immutable: the edit functions (:func:`add_key`, :func:`delete_key`,
:func:`move_key`, :func:`set_interpolation`, :func:`set_tangents`) return *new*
objects, so the model can keep old timelines on its undo stack
(``model.set_slot("tracks", new_timeline, label)``).

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
interpolation modes, clamping rules or immutable edit operations.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = [
    "HANDLES",
    "HEAD_POSE",
    "INTERPOLATIONS",
    "REGIONS_PREFIX",
    "TANGENT_MODES",
    "WEIGHTS_PREFIX",
    "Key",
    "Timeline",
    "TimelineSample",
    "Track",
    "TrackError",
    "add_key",
    "add_keys",
    "auto_clamped_slopes",
    "delete_key",
    "head_euler_from_rotation",
    "head_rotation_from_euler",
    "move_key",
    "parse_region_track",
    "quat_slerp",
    "quaternion_to_matrix",
    "region_track_name",
    "set_interpolation",
    "set_tangents",
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


# ------------------------------------------------------------------------ timeline
@dataclass(frozen=True)
class TimelineSample:
    """What a timeline gives at one time.

    Attributes
    ----------
    weights : dict of str to float
        Weight of every keyed shape.
    handle_offsets : (h, 3) float or None
        Handle-layer offsets (model units), None if the handles are not keyed.
    head_translation : (3,) float or None
        Model units.
    head_rotation : (4,) float or None
        Unit quaternion (x, y, z, w).
    region_level : int or None
        Level of the region tracks, None without region tracks.
    region_weights : dict of str to (k,) float
        Shape weights of every keyed region (empty without region tracks).
    """

    weights: dict[str, float]
    handle_offsets: NDArray[np.float64] | None
    head_translation: NDArray[np.float64] | None
    head_rotation: NDArray[np.float64] | None
    region_level: int | None = None
    region_weights: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    def head_matrix(self) -> NDArray[np.float64]:
        """(4, 4) homogeneous head transform (identity when the head is not keyed)."""
        M = np.eye(4)
        if self.head_rotation is not None:
            M[:3, :3] = quaternion_to_matrix(self.head_rotation)
        if self.head_translation is not None:
            M[:3, 3] = self.head_translation
        return M


@dataclass(frozen=True, eq=False)
class Timeline:
    """Frame rate, playback range and tracks (immutable value object).

    Parameters
    ----------
    fps : float
        Frames per second (> 0) for playback and baking.
    start, end : float
        Playback/export range in seconds, ``start <= end``. :meth:`fit_range`
        sets it to the keyed range.
    tracks : mapping of str to Track
        By track name (``"weights/<shape>"``, ``"handles"``, ``"head_pose"``,
        ``"regions/<level>/<region>"``). Region tracks must all be on one
        level and hold the same number of shape weights.
    """

    fps: float = 30.0
    start: float = 0.0
    end: float = 0.0
    tracks: Mapping[str, Track] = field(default_factory=dict)

    def __post_init__(self) -> None:
        fps, start, end = float(self.fps), float(self.start), float(self.end)
        if not (math.isfinite(fps) and fps > 0):
            raise TrackError(f"timeline fps must be a positive number, got {self.fps!r}")
        if not (math.isfinite(start) and math.isfinite(end) and start <= end):
            raise TrackError(f"timeline range needs finite start <= end, got {start}, {end}")
        tracks = dict(self.tracks)
        for name, tr in tracks.items():
            if not isinstance(tr, Track):
                raise TrackError(f"tracks[{name!r}] must be a Track, got {type(tr).__name__}")
            if tr.name != name:
                raise TrackError(f"tracks[{name!r}] holds a track named {tr.name!r}")
        regions = [tr for tr in tracks.values() if tr.kind == "region"]
        levels = sorted({tr.region[0] for tr in regions if tr.region is not None})
        if len(levels) > 1:
            raise TrackError(
                f"region tracks must all be on one region level, got levels {levels}"
            )
        lengths = sorted({tr.value_shape[0] for tr in regions})
        if len(lengths) > 1:
            raise TrackError(
                f"region tracks must all hold one weight per model shape, got lengths {lengths}"
            )
        object.__setattr__(self, "fps", fps)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "end", end)
        object.__setattr__(self, "tracks", MappingProxyType(dict(sorted(tracks.items()))))

    # --------------------------------------------------------------- queries
    def __repr__(self) -> str:
        return (
            f"Timeline(fps={self.fps:g}, start={self.start:g}, end={self.end:g}, "
            f"tracks={list(self.tracks)})"
        )

    @property
    def weight_tracks(self) -> dict[str, Track]:
        """Weight tracks by *shape* name."""
        return {tr.shape_name: tr for tr in self.tracks.values() if tr.shape_name is not None}

    @property
    def handles(self) -> Track | None:
        return self.tracks.get(HANDLES)

    @property
    def head_pose(self) -> Track | None:
        return self.tracks.get(HEAD_POSE)

    @property
    def region_tracks(self) -> dict[str, Track]:
        """Region tracks by *region* name (all on :attr:`region_level`)."""
        out = {}
        for tr in self.tracks.values():
            r = tr.region
            if r is not None:
                out[r[1]] = tr
        return out

    @property
    def region_level(self) -> int | None:
        """The hierarchy level the region tracks key, None without region tracks."""
        for tr in self.tracks.values():
            r = tr.region
            if r is not None:
                return r[0]
        return None

    @property
    def key_range(self) -> tuple[float, float] | None:
        """(first, last) key time over all tracks, or None without keys."""
        if not self.tracks:
            return None
        return (
            min(float(t.times[0]) for t in self.tracks.values()),
            max(float(t.times[-1]) for t in self.tracks.values()),
        )

    def frame_times(self) -> NDArray[np.float64]:
        """(F,) float: ``start + i / fps`` for every frame in ``[start, end]``."""
        n = math.floor((self.end - self.start) * self.fps + 1e-9) + 1
        return self.start + np.arange(n, dtype=np.float64) / self.fps

    def replace(self, **changes: Any) -> Timeline:
        """A copy with fps/start/end/tracks changed."""
        return dataclasses.replace(self, **changes)

    def fit_range(self) -> Timeline:
        """A copy whose range is the keyed range (unchanged without keys)."""
        r = self.key_range
        return self if r is None else self.replace(start=r[0], end=r[1])

    def with_track(self, track: Track) -> Timeline:
        """A copy with ``track`` added or replaced."""
        return self.replace(tracks={**self.tracks, track.name: track})

    def without_track(self, name: str) -> Timeline:
        if name not in self.tracks:
            raise TrackError(f"no track {name!r}; tracks are {list(self.tracks)}")
        return self.replace(tracks={k: v for k, v in self.tracks.items() if k != name})

    def check_model(self, model: FaceModel) -> None:
        """Raise :class:`TrackError` if the tracks do not fit ``model``.

        Checks that every weight track names a shape of the model, that the
        handle track has one offset per model handle and that region tracks
        hold one weight per model shape. When the model has regions, region
        tracks must name a level and regions of them; a model without regions
        (yet) is not checked for that, because
        :func:`workbench.fileformat.load_model` checks the timeline before it
        installs the regions (``FaceModel.set_timeline`` and ``export`` require
        the regions).
        """
        names = set(model.shape_names)
        unknown = sorted(s for s in self.weight_tracks if s not in names)
        if unknown:
            raise TrackError(
                f"timeline keys unknown shape names {unknown}; the model's shapes are "
                f"{sorted(names)[:8]}{'...' if len(names) > 8 else ''}"
            )
        h = self.handles
        n_handles = len(model.slot("handles"))
        if h is not None and h.value_shape[0] != n_handles:
            raise TrackError(
                f"the 'handles' track keys {h.value_shape[0]} handles but the model has "
                f"{n_handles}"
            )
        rt = self.region_tracks
        if not rt:
            return
        k = len(model.shape_names)
        bad_k = sorted(n for n, tr in rt.items() if tr.value_shape != (k,))
        if bad_k:
            raise TrackError(
                f"region tracks {bad_k[:4]} hold {rt[bad_k[0]].value_shape[0]} shape weights "
                f"but the model has {k} shapes (shapes were added or removed after keying)"
            )
        state = model.slot("regions")
        regions = getattr(state, "regions", None)
        if regions is None:
            return
        level = self.region_level
        assert level is not None
        if level >= regions.n_levels:
            raise TrackError(
                f"region tracks key level {level} but the model's regions have "
                f"{regions.n_levels} levels"
            )
        names = set(regions.names[level])
        unknown = sorted(n for n in rt if n not in names)
        if unknown:
            raise TrackError(
                f"region tracks key regions {unknown[:4]} that level {level} does not have; "
                f"its regions are {sorted(names)[:8]}{'...' if len(names) > 8 else ''}"
            )

    # ------------------------------------------------------------ evaluation
    def evaluate(self, time: float) -> TimelineSample:
        """Weights, handle offsets, head transform and region weights at ``time`` (seconds)."""
        weights = {s: float(tr.sample([time])[0, 0]) for s, tr in self.weight_tracks.items()}
        h = self.handles
        offsets = None if h is None else h.evaluate(time)
        hp = self.head_pose
        tr_, rot = None, None
        if hp is not None:
            p = hp.sample([time])[0]
            tr_, rot = p[:3].copy(), p[3:].copy()
        regions = {r: tr.sample([time])[0] for r, tr in self.region_tracks.items()}
        return TimelineSample(weights, offsets, tr_, rot, self.region_level, regions)

    def weight_matrix(self, shape_names: Iterable[str], times: ArrayLike) -> NDArray[np.float64]:
        """(F, k) weights of ``shape_names`` (in that order) at ``times``; unkeyed shapes 0.

        Raises
        ------
        TrackError
            If a weight track names a shape not in ``shape_names``.
        """
        names = list(shape_names)
        ts = np.asarray(times, np.float64).reshape(-1)
        index = {n: i for i, n in enumerate(names)}
        W = np.zeros((ts.size, len(names)))
        for s, tr in self.weight_tracks.items():
            if s not in index:
                raise TrackError(f"timeline keys unknown shape name {s!r}")
            W[:, index[s]] = tr.sample(ts)[:, 0]
        return W

    # ---------------------------------------------------------- persistence
    def to_json(self) -> dict[str, Any]:
        """A JSON-able dict (for the workbench file); :meth:`from_json` reads it back exactly.

        Values and tangents are nested lists of floats (Python floats round-trip
        float64 exactly through JSON); auto-clamped tangents are stored too but
        recomputed on load.
        """
        return {
            "fps": self.fps,
            "start": self.start,
            "end": self.end,
            "tracks": {
                name: [
                    {
                        "time": k.time,
                        "value": k.value.tolist(),
                        "interpolation": k.interpolation,
                        "in_tangent": k.in_tangent.tolist(),
                        "out_tangent": k.out_tangent.tolist(),
                        "tangent_mode": k.tangent_mode,
                    }
                    for k in tr.keys
                ]
                for name, tr in self.tracks.items()
            },
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Timeline:
        """Inverse of :meth:`to_json`; raises :class:`TrackError` naming the bad field."""
        try:
            tracks = {}
            for name, keys in dict(data.get("tracks", {})).items():
                tracks[name] = Track(
                    name,
                    tuple(
                        Key(
                            k["time"],
                            k["value"],
                            k.get("interpolation", "bezier"),
                            k.get("in_tangent"),
                            k.get("out_tangent"),
                            k.get("tangent_mode", "auto_clamped"),
                        )
                        for k in keys
                    ),
                )
            return cls(
                fps=data.get("fps", 30.0),
                start=data.get("start", 0.0),
                end=data.get("end", 0.0),
                tracks=tracks,
            )
        except (KeyError, TypeError, AttributeError) as exc:
            raise TrackError(f"timeline JSON is malformed: {type(exc).__name__}: {exc}") from None

    # --------------------------------------------------- edits (delegating)
    def add_key(self, track: str, time: float, value: ArrayLike, **kw: Any) -> Timeline:
        return add_key(self, track, time, value, **kw)

    def delete_key(self, track: str, index: int) -> Timeline:
        return delete_key(self, track, index)

    def move_key(self, track: str, index: int, time: float, value: ArrayLike | None = None) -> Timeline:
        return move_key(self, track, index, time, value)

    def set_interpolation(self, track: str, index: int | None, interpolation: Interpolation) -> Timeline:
        return set_interpolation(self, track, index, interpolation)

    def set_tangents(
        self,
        track: str,
        index: int,
        in_tangent: ArrayLike | None = None,
        out_tangent: ArrayLike | None = None,
        mode: TangentMode = "user",
    ) -> Timeline:
        return set_tangents(self, track, index, in_tangent, out_tangent, mode)


# ----------------------------------------------------------------- pure edit functions
def _track(tl: Timeline, name: str) -> Track:
    if name not in tl.tracks:
        raise TrackError(f"no track {name!r}; tracks are {list(tl.tracks)}")
    return tl.tracks[name]


def _key_index(tr: Track, index: int) -> int:
    if not -len(tr) <= index < len(tr):
        raise TrackError(f"track {tr.name!r}: key index {index} out of range ({len(tr)} keys)")
    return index % len(tr)


def add_key(
    timeline: Timeline,
    track: str,
    time: float,
    value: ArrayLike,
    *,
    interpolation: Interpolation = "bezier",
    in_tangent: ArrayLike | None = None,
    out_tangent: ArrayLike | None = None,
    tangent_mode: TangentMode | None = None,
    tol: float = 1e-9,
) -> Timeline:
    """A new timeline with a key inserted (or replacing the key at the same time).

    Parameters
    ----------
    timeline : Timeline
    track : str
        Track name; the track is created if missing.
    time : float
        Seconds. A key within ``tol`` of an existing key replaces it (Blender's
        "insert keyframe" on an existing key).
    value : float or (h, 3) or (7,) array
    interpolation, in_tangent, out_tangent
        See :class:`Key`.
    tangent_mode : {"auto_clamped", "user"}, optional
        Default: "user" if a tangent is given, else "auto_clamped".
    """
    mode: TangentMode = tangent_mode or (
        "user" if in_tangent is not None or out_tangent is not None else "auto_clamped"
    )
    if mode == "user":
        # a user key with one tangent given gets the same slope on both sides
        in_tangent = out_tangent if in_tangent is None else in_tangent
        out_tangent = in_tangent if out_tangent is None else out_tangent
    key = Key(time, value, interpolation, in_tangent, out_tangent, mode)
    old = timeline.tracks.get(track)
    keys = [] if old is None else [k for k in old.keys if abs(k.time - key.time) > tol]
    keys.append(key)
    keys.sort(key=lambda k: k.time)
    return timeline.with_track(Track(track, tuple(keys)))


def add_keys(
    timeline: Timeline,
    track: str,
    times: ArrayLike,
    values: ArrayLike,
    *,
    interpolation: Interpolation = "bezier",
    tol: float = 1e-9,
) -> Timeline:
    """A new timeline with many auto-clamped keys added to one track at once.

    The same as calling :func:`add_key` for every ``(time, value)`` pair, but
    the track is built once (``add_key`` in a loop rebuilds it per key, which
    is quadratic in the number of keys).

    Parameters
    ----------
    timeline : Timeline
    track : str
        Track name; created if missing.
    times : (K,) float
        Seconds, distinct (more than ``tol`` apart).
    values : (K, ...) float
        One key value per time (``(K,)`` for a weight track, ``(K, k)`` for a
        region track, ...).
    interpolation : {"step", "linear", "bezier"}
    tol : float
        Existing keys within ``tol`` seconds of a new time are replaced.
    """
    ts = np.asarray(times, np.float64).reshape(-1)
    vs = np.asarray(values, np.float64)
    if vs.shape[:1] != ts.shape:
        raise TrackError(
            f"add_keys {track!r}: values must have one row per time ({ts.size}), got shape {vs.shape}"
        )
    order = np.argsort(ts, kind="stable")
    ts, vs = ts[order], vs[order]
    if ts.size > 1 and np.any(np.diff(ts) <= tol):
        i = int(np.flatnonzero(np.diff(ts) <= tol)[0])
        raise TrackError(f"add_keys {track!r}: times must be distinct, {ts[i]:g} is given twice")
    new = [Key(t, v, interpolation) for t, v in zip(ts.tolist(), vs, strict=True)]
    old = timeline.tracks.get(track)
    kept = []
    if old is not None:
        near = np.abs(old.times[:, None] - ts[None, :]).min(axis=1) <= tol if ts.size else None
        kept = [k for i, k in enumerate(old.keys) if near is None or not near[i]]
    keys = sorted([*kept, *new], key=lambda k: k.time)
    return timeline.with_track(Track(track, tuple(keys)))


def delete_key(timeline: Timeline, track: str, index: int) -> Timeline:
    """A new timeline without key ``index`` of ``track`` (the track goes when empty)."""
    tr = _track(timeline, track)
    i = _key_index(tr, index)
    keys = tr.keys[:i] + tr.keys[i + 1 :]
    if not keys:
        return timeline.without_track(track)
    return timeline.with_track(Track(track, keys))


def move_key(
    timeline: Timeline, track: str, index: int, time: float, value: ArrayLike | None = None
) -> Timeline:
    """A new timeline with key ``index`` moved to ``time`` (and optionally a new value).

    Raises
    ------
    TrackError
        If another key of the track already sits at ``time``.
    """
    tr = _track(timeline, track)
    i = _key_index(tr, index)
    t = float(time)
    for j, k in enumerate(tr.keys):
        if j != i and abs(k.time - t) <= 1e-9:
            raise TrackError(
                f"track {track!r}: cannot move key {i} to t={t:g}, key {j} is already there"
            )
    k = tr.keys[i]
    new = k.replace(time=t, value=k.value if value is None else np.asarray(value, np.float64))
    keys = sorted((*tr.keys[:i], new, *tr.keys[i + 1 :]), key=lambda kk: kk.time)
    return timeline.with_track(Track(track, tuple(keys)))


def set_interpolation(
    timeline: Timeline, track: str, index: int | None, interpolation: Interpolation
) -> Timeline:
    """A new timeline with the interpolation of key ``index`` (None: every key) changed."""
    if interpolation not in INTERPOLATIONS:
        raise TrackError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
    tr = _track(timeline, track)
    idx = range(len(tr)) if index is None else [_key_index(tr, index)]
    keys = list(tr.keys)
    for i in idx:
        keys[i] = keys[i].replace(interpolation=interpolation)
    return timeline.with_track(Track(track, tuple(keys)))


def set_tangents(
    timeline: Timeline,
    track: str,
    index: int,
    in_tangent: ArrayLike | None = None,
    out_tangent: ArrayLike | None = None,
    mode: TangentMode = "user",
) -> Timeline:
    """A new timeline with the slopes of key ``index`` set (mode "user").

    A missing side keeps its current slope. ``mode="auto_clamped"`` returns the
    key to automatic slopes (the given values are then ignored).
    """
    if mode not in TANGENT_MODES:
        raise TrackError(f"tangent mode must be one of {TANGENT_MODES}, got {mode!r}")
    tr = _track(timeline, track)
    i = _key_index(tr, index)
    k = tr.keys[i]
    new = k.replace(
        in_tangent=k.in_tangent if in_tangent is None else np.asarray(in_tangent, np.float64),
        out_tangent=k.out_tangent if out_tangent is None else np.asarray(out_tangent, np.float64),
        tangent_mode=mode,
    )
    keys = list(tr.keys)
    keys[i] = new
    return timeline.with_track(Track(track, tuple(keys)))
