"""The timeline: an immutable :class:`Timeline` of named tracks, sampling, and pure edit functions.

A :class:`Timeline` holds a frame rate, a playback range and named
:class:`~workbench.animation.curves.Track` objects (the track names, keys,
interpolation and tangents are in :mod:`workbench.animation.curves`);
:class:`TimelineSample` is what it gives at one time. The timeline knows two
kinds of track, blendshape weights and the rigid head pose; every other track
belongs to a method family, which registers its name, value shape and checks
(:class:`workbench.core.families.TrackSpec`) and reads its values from the
sample (``sample.others``) in its ``animate``.

Everything is immutable: the edit functions (:func:`add_key`,
:func:`add_keys`, :func:`delete_key`, :func:`move_key`,
:func:`set_interpolation`, :func:`set_tangents`, in
:mod:`workbench.animation.key_edits`) return *new* objects, so the model can
keep old timelines on its undo stack
(``model.set_slot("tracks", new_timeline, label)``).

Times are seconds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import (
    HEAD_POSE,
    Interpolation,
    Key,
    TangentMode,
    Track,
    TrackError,
    quaternion_to_matrix,
)
from workbench.animation.key_edits import (
    add_key,
    add_keys,
    delete_key,
    move_key,
    set_interpolation,
    set_tangents,
)
from workbench.core.families import check_family_tracks, track_names, track_value_shape

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = [
    "Timeline",
    "TimelineSample",
    "add_key",
    "add_keys",
    "delete_key",
    "move_key",
    "set_interpolation",
    "set_tangents",
]


@dataclass(frozen=True)
class TimelineSample:
    """What a timeline gives at one time.

    Attributes
    ----------
    weights : dict of str to float
        Weight of every keyed shape.
    head_translation : (3,) float or None
        Model units.
    head_rotation : (4,) float or None
        Unit quaternion (x, y, z, w).
    others : dict of str to ndarray
        Every family track's value by track name (its ``animate`` reads them;
        see :mod:`workbench.core.families`).
    """

    weights: dict[str, float]
    head_translation: NDArray[np.float64] | None
    head_rotation: NDArray[np.float64] | None
    others: dict[str, NDArray[np.float64]] = field(default_factory=dict)

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
        By track name (``"weights/<shape>"``, ``"head_pose"`` and the method
        families' own tracks; :meth:`check_model` checks them against a model).
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
    def head_pose(self) -> Track | None:
        return self.tracks.get(HEAD_POSE)

    @property
    def family_tracks(self) -> dict[str, Track]:
        """Every track that is neither a weight nor the head pose, by name: the families' own."""
        return {n: tr for n, tr in self.tracks.items() if tr.is_family_track}

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

        Every weight track names a shape of the model; every other track (but
        the head pose) is keyed by a registered method family, has the value
        shape that family gives it on this model, and the family's tracks pass
        its ``check_tracks`` together.
        """
        for name, tr in self.family_tracks.items():
            try:
                want = track_value_shape(model, name)
            except ValueError as exc:
                raise TrackError(f"track {name!r}: {exc}") from None
            if want is None:
                raise TrackError(f"track {name!r}: no method family of this model keys it "
                                 f"(their tracks: {track_names()})")
            if tr.value_shape != want:
                raise TrackError(f"track {name!r}: values must have shape {want}, got {tr.value_shape}")
        names = set(model.shape_names)
        unknown = sorted(s for s in self.weight_tracks if s not in names)
        if unknown:
            raise TrackError(
                f"timeline keys unknown shape names {unknown}; the model's shapes are "
                f"{sorted(names)[:8]}{'...' if len(names) > 8 else ''}"
            )
        try:
            check_family_tracks(model, self.family_tracks)
        except ValueError as exc:  # ModelError: the family says what is expected
            raise TrackError(str(exc)) from None

    # ------------------------------------------------------------ evaluation
    def evaluate(self, time: float) -> TimelineSample:
        """Weights, head transform and every family track's value at ``time`` (seconds)."""
        pre = self.__dict__.get("_prefetched")
        hit = None if pre is None else pre.get(float(time))
        if hit is not None:
            weights = dict(hit)
        else:
            weights = {s: float(tr.sample([time])[0, 0]) for s, tr in self.weight_tracks.items()}
        hp = self.head_pose
        tr_, rot = None, None
        if hp is not None:
            p = hp.sample([time])[0]
            tr_, rot = p[:3].copy(), p[3:].copy()
        others = {name: tr.evaluate(time) for name, tr in self.family_tracks.items()}
        return TimelineSample(weights, tr_, rot, others)

    def prefetch_weights(self, times: ArrayLike) -> None:
        """Sample every weight track at all ``times`` in one go; :meth:`evaluate` then looks them up.

        For exporters, which evaluate every frame: one vectorised pass per track
        instead of one call per track and frame. The values are the same bits,
        because curve sampling is elementwise arithmetic (no reductions), so a
        time sampled alone or among others gives one result. Dropped by
        :meth:`forget_prefetched`; edits make new timelines without it.
        """
        ts = np.asarray(times, np.float64).reshape(-1)
        cols = {s: tr.sample(ts)[:, 0] for s, tr in self.weight_tracks.items()}
        table = {float(t): {s: float(c[i]) for s, c in cols.items()} for i, t in enumerate(ts)}
        object.__setattr__(self, "_prefetched", table)

    def forget_prefetched(self) -> None:
        """Drop what :meth:`prefetch_weights` stored."""
        self.__dict__.pop("_prefetched", None)

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
