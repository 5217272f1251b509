"""Pure edit functions on a :class:`~workbench.animation.tracks.Timeline`'s keys.

Each returns a *new* timeline (the model keeps the old one on its undo stack);
:class:`~workbench.animation.tracks.Timeline` has a method of the same name
for each, which delegates here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from workbench.animation.curves import (
    INTERPOLATIONS,
    TANGENT_MODES,
    Interpolation,
    Key,
    TangentMode,
    Track,
    TrackError,
)

if TYPE_CHECKING:
    from workbench.animation.tracks import Timeline

__all__ = [
    "add_key",
    "add_keys",
    "delete_key",
    "move_key",
    "set_interpolation",
    "set_tangents",
]


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
        One key value per time (``(K,)`` for a weight track, ``(K, 7)`` for the
        head pose, ``(K, *shape)`` for a family track of that value shape).
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
