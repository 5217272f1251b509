"""A :class:`Track`: the keys of one animated quantity, checked, and its curve evaluated.

The segment starting at each key is evaluated by that key's interpolation
(:mod:`~workbench.animation.curves.keys`: step, linear or the cubic Hermite
form of a Bézier segment), with auto-clamped tangents resolved when the track
is built.

Head-pose rotation is always interpolated by spherical linear interpolation
(shortest arc; ``step`` holds) — Bézier/tangents apply to its translation only —
so it exports exactly as glTF ``LINEAR`` rotation.

Outside the keyed range a track holds its first/last value (constant
extrapolation). Times are seconds.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves.keys import Key, _readonly, auto_clamped_slopes
from workbench.animation.curves.names import HEAD_POSE, WEIGHTS_PREFIX, TrackError
from workbench.animation.curves.rotations import quat_slerp

_CODE = {"step": 0, "linear": 1, "bezier": 2}


#: a method family's own track: a name (``"mouth_gain"``), or one under its
#: prefix (``"my_family/0/upper lip"``); the model checks that a registered
#: family keys it and the value shape (:func:`workbench.core.families.track_value_shape`)
_FAMILY_TRACK = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(/.*[^/])?", re.DOTALL)

@dataclass(frozen=True, eq=False)
class Track:
    """Keys of one animated quantity, sorted by strictly increasing time (immutable).

    Parameters
    ----------
    name : str
        ``"weights/<shape>"``, ``"head_pose"`` or a method family's own track
        (see :mod:`~workbench.animation.curves.names`).
    keys : sequence of Key
        At least one key; times strictly increasing; all values the same shape
        (scalar for weights, ``(7,)`` for the head pose; a family's tracks have
        the shape it registers, checked against the model by
        :meth:`Timeline.check_model <workbench.animation.tracks.Timeline.check_model>`).

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
            (name.startswith(WEIGHTS_PREFIX) and len(name) > len(WEIGHTS_PREFIX))
            or (_FAMILY_TRACK.fullmatch(name) is not None and not name.startswith(WEIGHTS_PREFIX))
        ):
            raise TrackError(
                "track name must be 'weights/<shape>', 'head_pose' or a method family's own "
                f"track name (a name, or '<prefix>/<...>'), got {name!r}"
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
    def shape_name(self) -> str | None:
        """The blendshape name of a weight track, else None."""
        return self.name[len(WEIGHTS_PREFIX) :] if self.name.startswith(WEIGHTS_PREFIX) else None

    @property
    def is_family_track(self) -> bool:
        """Neither a weight nor the head pose: a method family's own track."""
        return self.name != HEAD_POSE and not self.name.startswith(WEIGHTS_PREFIX)

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
            Flattened values (``d = 1`` for weights, 7 for the head pose with unit
            quaternions, the size of a family track's values).
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
