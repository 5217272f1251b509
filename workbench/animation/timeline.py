"""``model.timeline``: keying (Pighin et al. 1998 §5) — the undoable edits of the ``tracks`` slot.

Keys of weights, the rigid head pose and the method families' own tracks
(registered by each family, :class:`workbench.core.families.TrackSpec`). The
timeline itself is an immutable :class:`~workbench.animation.tracks.Timeline`;
sampling it (``set_time``, ``evaluate_at``) is the state's, through the hooks in
:mod:`.family`. What a family keys from its own state is its facet's (e.g. keying a saved
look, or a fit frame by frame).

Every edit a view makes has a named method here, each one undo step:
``key_weights`` / ``key_track`` / ``key_head_pose`` and ``add_key`` (any track,
a given value) add keys; ``move_key``, ``delete_key`` / ``delete_keys``,
``set_interpolation`` / ``set_interpolations``, ``set_tangents`` and
``set_fps`` edit them. Arguments are checked before anything changes, and
errors (:class:`ModelError`) name the method and the argument.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import (
    HEAD_POSE,
    IDENTITY_POSE,
    INTERPOLATIONS,
    TANGENT_MODES,
    WEIGHTS_PREFIX,
    Interpolation,
    TangentMode,
    Track,
    weight_track_name,
)
from workbench.animation.tracks import Timeline
from workbench.core.families import (
    family_track_title,
    track_names,
    track_owner,
    track_value_shape,
    weight_product_reads,
    weight_products,
)
from workbench.core.shapes import ModelError

if TYPE_CHECKING:
    from workbench.core.state import FaceState


def as_quaternion(rotation: ArrayLike, what: str) -> NDArray[np.float64]:
    """(4,) unit quaternion (x, y, z, w) from a quaternion or a (3, 3) rotation matrix."""
    r = np.asarray(rotation, np.float64)
    if r.shape == (4,) and np.isfinite(r).all() and np.linalg.norm(r) > 1e-12:
        return np.asarray(r / np.linalg.norm(r), np.float64)
    if r.shape == (3, 3) and np.isfinite(r).all():
        if np.allclose(r.T @ r, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0:
            from scipy.spatial.transform import Rotation

            return np.asarray(Rotation.from_matrix(r).as_quat(), np.float64)
        raise ModelError(f"{what}: rotation matrix must be orthonormal with determinant +1")
    raise ModelError(
        f"{what}: rotation must be a non-zero finite (4,) quaternion (x, y, z, w) or a (3, 3) "
        f"rotation matrix, got shape {r.shape}"
    )


def grow_range(tl: Timeline, time: float) -> Timeline:
    """``tl`` with its playback range grown to include ``time``."""
    return tl.replace(start=min(tl.start, time), end=max(tl.end, time))


def derived_shapes(model: FaceState) -> frozenset[str]:
    """Shapes whose weight is derived (correctives: the product of their drivers'); never keyed."""
    return frozenset(weight_products({r: model.slot(r) for r in weight_product_reads()}))


def track_title(track: str) -> str:
    """A short name of ``track`` for labels ("jawOpen", "head pose", a family's title of its track)."""
    if track.startswith(WEIGHTS_PREFIX):
        return track[len(WEIGHTS_PREFIX) :]
    if track == HEAD_POSE:
        return "head pose"
    return family_track_title(track)


def _finite(x: Any, what: str, name: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ModelError(f"{what}: {name} must be a number, got {x!r}") from None
    if not math.isfinite(v):
        raise ModelError(f"{what}: {name} must be finite, got {x!r}")
    return v


def _interpolation(kind: Any, what: str, name: str = "interpolation") -> Interpolation:
    if kind not in INTERPOLATIONS:
        raise ModelError(f"{what}: {name} must be one of {list(INTERPOLATIONS)}, got {kind!r}")
    return cast("Interpolation", kind)


class TimelineFacet:
    """The keyframe timeline of one model (see the module docstring)."""

    def __init__(self, model: FaceState) -> None:
        self._model = model

    @property
    def value(self) -> Timeline:
        return self._model.slot("tracks")

    def __repr__(self) -> str:
        return f"<timeline: {self.value!r}>"

    def set(self, timeline: Timeline, label: str = "Edit keys") -> None:
        """Replace the timeline (undoable); checked against the model (:meth:`Timeline.check_model`)."""
        self._model.set_slot("tracks", timeline, label)

    @property
    def head_pose(self) -> NDArray[np.float64] | None:
        """(7,) float: the head pose keyed at the model's time (translation + quaternion), or None."""
        m = self._model
        with m.lock:
            hp = self.value.head_pose
            return None if hp is None else hp.sample([m.time])[0]

    # -------------------------------------------------------------------- keys
    def key_weights(self, time: float, names: Iterable[str] | None = None,
                    interpolation: Interpolation = "bezier") -> None:
        """Key the current weights at ``time`` (one undo step).

        ``names`` default: every shape with a non-zero weight or already keyed,
        but no corrective (its weight is derived from its drivers' keys).
        """
        m = self._model
        with m.lock:
            tl = self.value
            w = m.weights
            if names is None:
                keyed, derived = set(tl.weight_tracks), derived_shapes(m)
                names = [n for n in m.shape_names if (w[n] != 0.0 or n in keyed) and n not in derived]
            names = list(names)
            for n in names:
                m.shape(n)
                tl = tl.add_key(weight_track_name(n), time, w[n], interpolation=interpolation)
            self.set(grow_range(tl, time), f"Key {len(names)} weights at {time:g}s")

    def key_track(self, track: str, time: float, interpolation: Interpolation = "bezier") -> None:
        """Key what ``track`` shows now at ``time`` (one undo step).

        A weight track keys the shape's current weight; the head pose its value
        at the model's time; a family's track what its family records now
        (:attr:`TrackSpec.current <workbench.core.families.TrackSpec.current>`,
        e.g. the current offsets of a layer), else its value at the model's time.
        """
        what = "key_track"
        m = self._model
        with m.lock:
            self._value_shape(what, track)  # names the track's problem before anything changes
            if track.startswith(WEIGHTS_PREFIX):
                self.key_weights(time, [track[len(WEIGHTS_PREFIX):]], interpolation)
                return
            owner = track_owner(track)
            if owner is not None and owner[1].current is not None:
                value = owner[1].current(m, track)
            elif track in self.value.tracks:
                value = self.value.tracks[track].evaluate(m.time)
            elif track == HEAD_POSE:
                value = IDENTITY_POSE
            else:
                raise ModelError(f"{what}: track {track!r} has no keys to take a value from")
            self.add_key(track, time, value, interpolation)

    def key_head_pose(self, time: float, rotation: ArrayLike | None = None,
                      translation: ArrayLike | None = None, interpolation: Interpolation = "bezier") -> None:
        """Key the rigid head transform ``p -> R p + t`` at ``time`` (one undo step).

        ``rotation``: unit quaternion (x, y, z, w) or (3, 3) matrix (default: the
        rotation the timeline has at ``time``); ``translation`` (3,) in model units
        (default: the keyed one). The rotation is always slerped between keys;
        ``interpolation`` shapes the translation.
        """
        t = float(time)
        if not math.isfinite(t):
            raise ModelError(f"key_head_pose: time must be finite, got {time!r}")
        with self._model.lock:
            tl = self.value
            hp = tl.head_pose
            current = IDENTITY_POSE if hp is None else hp.evaluate(t)
            q = current[3:] if rotation is None else as_quaternion(rotation, "key_head_pose")
            if translation is None:
                tr = current[:3]
            else:
                tr = np.asarray(translation, np.float64).reshape(-1)
                if tr.shape != (3,) or not np.isfinite(tr).all():
                    raise ModelError(
                        "key_head_pose: translation must be 3 finite numbers (model units), "
                        f"got {np.asarray(translation).tolist()!r}"
                    )
            tl = tl.add_key(HEAD_POSE, t, np.concatenate([tr, q]), interpolation=interpolation)
            self.set(grow_range(tl, t), f"Key head pose at {t:g}s")

    def add_key(self, track: str, time: float, value: ArrayLike,
                interpolation: Interpolation = "bezier") -> None:
        """Key ``value`` on ``track`` at ``time`` (one undo step); extends the range to ``time``.

        For any track, with the value given: ``"weights/<shape>"`` a number,
        ``"head_pose"`` (7,) translation + quaternion (x, y, z, w), a family's
        track the shape its family gives it. A key already at ``time`` is
        replaced. (``key_weights``, ``key_track`` and ``key_head_pose`` key the
        model's current values.)
        """
        what = "add_key"
        t = _finite(time, what, "time")
        kind = _interpolation(interpolation, what)
        m = self._model
        with m.lock:
            try:
                v = np.asarray(value, np.float64)
            except (TypeError, ValueError):
                raise ModelError(f"{what}: value must be numbers, got {value!r}") from None
            want = self._value_shape(what, track)
            if v.shape != want:
                raise ModelError(
                    f"{what}: value for track {track!r} must have shape {want}, got {v.shape}"
                )
            if not np.isfinite(v).all():
                raise ModelError(f"{what}: value for track {track!r} must be finite, got NaN/inf")
            if track == HEAD_POSE and np.linalg.norm(v[3:]) < 1e-12:
                raise ModelError(f"{what}: value for 'head_pose' has a zero quaternion (x, y, z, w)")
            tl = self.value.add_key(track, t, v, interpolation=kind)
            self.set(grow_range(tl, t), f"Key {track_title(track)} at {t:g}s")

    def delete_key(self, track: str, index: int) -> None:
        """Delete key ``index`` of ``track`` (undoable)."""
        with self._model.lock:
            tr = self._track("delete_key", track)
            i = self._index("delete_key", tr, index)
            self.set(self.value.delete_key(track, i), f"Delete key {index} of {track}")

    def delete_keys(self, keys: Iterable[tuple[str, int]]) -> int:
        """Delete several keys ``[(track, index), ...]`` in one undo step; returns how many.

        Every key is checked before any is deleted; a key named twice (also as
        ``-1`` and its positive index) is deleted once; no keys: no step.
        """
        what = "delete_keys"
        with self._model.lock:
            tl = self.value
            chosen: set[tuple[str, int]] = set()
            for item in keys:
                try:
                    track, index = item
                except (TypeError, ValueError):
                    raise ModelError(
                        f"{what}: keys must be (track, index) pairs, got {item!r}"
                    ) from None
                tr = self._track(what, track)
                chosen.add((track, self._index(what, tr, index)))
            if not chosen:
                return 0
            if len(chosen) == 1:
                track, i = next(iter(chosen))
                self.set(tl.delete_key(track, i), f"Delete key {i} of {track}")
                return 1
            # highest index first, so earlier deletions do not shift later ones
            for track, i in sorted(chosen, key=lambda k: (k[0], -k[1])):
                tl = tl.delete_key(track, i)
            self.set(tl, f"Delete {len(chosen)} keys")
            return len(chosen)

    def move_key(self, track: str, index: int, time: float, value: ArrayLike | None = None) -> None:
        """Move key ``index`` of ``track`` to ``time`` (and ``value``), undoable."""
        with self._model.lock:
            tl = self.value.move_key(track, index, time, value)
            self.set(grow_range(tl, time), f"Move key of {track}")

    def set_interpolation(self, track: str, index: int | None, interpolation: Interpolation) -> None:
        """Interpolation of key ``index`` of ``track`` (None: every key of it); one undo step.

        ``interpolation`` shapes the segment that starts at the key: "step",
        "linear" or "bezier". No change: no step.
        """
        what = "set_interpolation"
        kind = _interpolation(interpolation, what)
        with self._model.lock:
            tr = self._track(what, track)
            i = None if index is None else self._index(what, tr, index)
            self._set_interpolations(
                [(track, i)], kind, f"Set interpolation {kind} ({track_title(track)})"
            )

    def set_interpolations(self, keys: Iterable[tuple[str, int]], interpolation: Interpolation) -> int:
        """Interpolation of several keys ``[(track, index), ...]`` in one undo step; returns how many."""
        what = "set_interpolations"
        kind = _interpolation(interpolation, what)
        with self._model.lock:
            chosen: list[tuple[str, int | None]] = []
            for item in keys:
                try:
                    track, index = item
                except (TypeError, ValueError):
                    raise ModelError(
                        f"{what}: keys must be (track, index) pairs, got {item!r}"
                    ) from None
                chosen.append((track, self._index(what, self._track(what, track), index)))
            if chosen:
                self._set_interpolations(chosen, kind, f"Set interpolation {kind}")
            return len(set(chosen))

    def _set_interpolations(self, keys: list[tuple[str, int | None]], kind: Interpolation,
                            label: str) -> None:
        old = tl = self.value
        for track, i in keys:
            tr = tl.tracks[track]
            idx = range(len(tr)) if i is None else [i]
            if any(tr.keys[j].interpolation != kind for j in idx):
                tl = tl.set_interpolation(track, i, kind)
        if tl is not old:
            self.set(tl, label)

    def set_tangents(self, track: str, index: int, in_tangent: ArrayLike | None = None,
                     out_tangent: ArrayLike | None = None, mode: TangentMode = "user") -> None:
        """Bézier slopes (value units per second) of key ``index`` of ``track``; one undo step.

        ``mode="user"``: the given slopes are kept (a side not given keeps its
        current slope); ``mode="auto_clamped"``: the key's slopes are computed
        again from its neighbours (no slope may be given then).
        """
        what = "set_tangents"
        if mode not in TANGENT_MODES:
            raise ModelError(f"{what}: mode must be one of {list(TANGENT_MODES)}, got {mode!r}")
        if mode == "auto_clamped" and (in_tangent is not None or out_tangent is not None):
            raise ModelError(f"{what}: mode 'auto_clamped' computes the slopes; give no in/out_tangent")
        with self._model.lock:
            tr = self._track(what, track)
            i = self._index(what, tr, index)
            shape = tr.value_shape
            slopes: list[NDArray[np.float64] | None] = []
            for name, tan in (("in_tangent", in_tangent), ("out_tangent", out_tangent)):
                if tan is None:
                    slopes.append(None)
                    continue
                a = np.asarray(tan, np.float64)
                if a.shape not in ((), shape):
                    raise ModelError(
                        f"{what}: {name} for track {track!r} must be a number or shape {shape}, "
                        f"got {a.shape}"
                    )
                if not np.isfinite(a).all():
                    raise ModelError(f"{what}: {name} must be finite, got {tan!r}")
                slopes.append(np.broadcast_to(a, shape))
            label = (f"Auto tangent of {track_title(track)}" if mode == "auto_clamped"
                     else f"Edit tangent of {track_title(track)}")
            self.set(self.value.set_tangents(track, i, slopes[0], slopes[1], mode), label)

    def set_fps(self, fps: float) -> None:
        """Frames per second of playback and baking (> 0); one undo step (none if unchanged)."""
        what = "set_fps"
        f = _finite(fps, what, "fps")
        if f <= 0:
            raise ModelError(f"{what}: fps must be a positive number, got {fps!r}")
        with self._model.lock:
            tl = self.value
            if f != tl.fps:
                self.set(tl.replace(fps=f), f"Set fps {f:g}")

    # ------------------------------------------------------------- checks
    def _track(self, what: str, track: Any) -> Track:
        tracks = self.value.tracks
        if not isinstance(track, str) or track not in tracks:
            names = list(tracks)
            have = f"{names[:8]}{'...' if len(names) > 8 else ''}" if names else "none"
            raise ModelError(f"{what}: track {track!r} has no keys; the keyed tracks are {have}")
        return tracks[track]

    @staticmethod
    def _index(what: str, tr: Track, index: Any) -> int:
        if isinstance(index, bool) or not isinstance(index, int | np.integer):
            raise ModelError(f"{what}: index must be an int, got {index!r}")
        n = len(tr)
        if not -n <= int(index) < n:
            raise ModelError(
                f"{what}: index {int(index)} is out of range for track {tr.name!r} ({n} keys)"
            )
        return int(index) % n

    def _value_shape(self, what: str, track: Any) -> tuple[int, ...]:
        """The value shape a key of ``track`` has on this model (raises for an unknown track)."""
        m = self._model
        if isinstance(track, str) and track.startswith(WEIGHTS_PREFIX):
            shape = track[len(WEIGHTS_PREFIX) :]
            if shape not in m.shape_names:
                raise ModelError(
                    f"{what}: track {track!r} names no shape of the model; its shapes are "
                    f"{m.shape_names[:8]}{'...' if len(m.shape_names) > 8 else ''}"
                )
            return ()
        if track == HEAD_POSE:
            return (7,)
        if isinstance(track, str):
            own = track_value_shape(m, track)  # the families' own tracks
            if own is not None:
                return own
        names = ", ".join(repr(n + "<...>" if n.endswith("/") else n) for n in track_names())
        raise ModelError(f"{what}: track must be 'weights/<shape>', 'head_pose' or one of the "
                         f"families' tracks ({names}), got {track!r}")
