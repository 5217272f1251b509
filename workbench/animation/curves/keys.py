"""Keyframes (:class:`Key`): interpolation modes, tangents and Blender's auto-clamped slopes.

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
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves.names import TrackError

Interpolation = Literal["step", "linear", "bezier"]
TangentMode = Literal["auto_clamped", "user"]
INTERPOLATIONS: tuple[str, ...] = ("step", "linear", "bezier")
TANGENT_MODES: tuple[str, ...] = ("auto_clamped", "user")


def _readonly(a: NDArray[Any]) -> NDArray[Any]:
    a.setflags(write=False)
    return a


def _as_value(value: ArrayLike, what: str) -> NDArray[np.float64]:
    v = np.array(value, dtype=np.float64)
    if not np.isfinite(v).all():
        raise TrackError(f"{what}: value must be finite, got NaN/inf")
    return _readonly(v)


@dataclass(frozen=True, eq=False, init=False)
class Key:
    """One keyframe (immutable).

    Parameters
    ----------
    time : float
        Seconds.
    value : float or array
        Scalar for weight tracks, ``(7,)`` translation + quaternion (x, y, z, w)
        for the head pose, the shape a method family registers for its tracks.
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
