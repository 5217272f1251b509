"""The timeline front end's messages and the model calls they make.

One function per message ``{"type": kind, ...}`` in :data:`HANDLERS`, called
by :meth:`TimelineWidget.handle_message
<widgets.timeline.widget.TimelineWidget.handle_message>` after it ended the
interactions other widgets hold open (except for :data:`NOT_EDITS`). Every
edit is one named method of the ``model.timeline`` facet (one undo step each:
``move_key``, ``delete_keys``, ``add_key`` / ``key_weights`` / ``handles.key``,
``set_interpolations``, ``set_tangents``, ``set_fps``, ...) or
``model.set_time``; the widget never builds timelines nor touches the history.

The playhead drag is a "scrub" gesture of the project's gesture protocol
(``widgets/js/src/viewport/gestures.js``: ``phase`` "start" / "move" / "end" /
"cancel", one message in flight, each acked with ``scrub_ack``); a message
without a phase (the Start button, the arrow keys) sets the time once. Changing
the time is not an undo step, so the gesture holds no model interaction.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from widgets.timeline.state import track_label

if TYPE_CHECKING:
    from widgets.timeline.widget import TimelineWidget

Handler = Callable[["TimelineWidget", dict[str, Any]], None]

#: message type -> handler(widget, content)
HANDLERS: dict[str, Handler] = {}

#: messages that do not edit the model (every other one first ends the interactions
#: other widgets hold open, e.g. a slider drag waiting for its idle time)
NOT_EDITS = frozenset({"frame_ack", "pause"})

#: messages after which the error line is kept (they are sent continuously)
KEEP_ERROR = frozenset({"scrub", "frame_ack"})


def handles(kind: str) -> Callable[[Handler], Handler]:
    def register(fn: Handler) -> Handler:
        HANDLERS[kind] = fn
        return fn

    return register


def _keys(c: dict[str, Any]) -> list[tuple[str, int]]:
    return [(str(tn), int(i)) for tn, i in c["keys"]]


def _select(w: TimelineWidget, track: str, when: float) -> None:
    """Select the key of ``track`` at ``when`` (none if there is none)."""
    i = w.model.timeline.value.tracks[track].index_at(when)
    w.selected_keys = [[track, i]] if i is not None else []


# ------------------------------------------------------------------ transport
@handles("scrub")
def scrub(w: TimelineWidget, c: dict[str, Any]) -> None:
    try:
        phase = c.get("phase")
        if phase == "start":
            w.pause()  # scrubbing takes the playhead from playback
        if phase != "cancel" and c.get("time") is not None:
            w.model.set_time(float(c["time"]))
    finally:
        # ack even after an error: the front end keeps one scrub in flight
        w.send({"type": "scrub_ack", "seq": c.get("seq")})


@handles("play")
def play(w: TimelineWidget, c: dict[str, Any]) -> None:
    w.play()


@handles("pause")
def pause(w: TimelineWidget, c: dict[str, Any]) -> None:
    w.pause()


@handles("frame_ack")
def frame_ack(w: TimelineWidget, c: dict[str, Any]) -> None:
    w.playback.on_ack(int(c["seq"]))


# ----------------------------------------------------------------------- keys
@handles("move_key")
def move_key(w: TimelineWidget, c: dict[str, Any]) -> None:
    track, index, when = str(c["track"]), int(c["index"]), float(c["time"])
    w.model.timeline.move_key(track, index, when)
    _select(w, track, when)
    w.status = f"moved key of {track_label(track)} to {when:.2f} s"


@handles("delete_keys")
def delete_keys(w: TimelineWidget, c: dict[str, Any]) -> None:
    keys = _keys(c)
    if not keys:
        return
    n = w.model.timeline.delete_keys(keys)
    w.selected_keys = []
    w.status = f"deleted {n} key{'s' if n > 1 else ''}"


@handles("add_key")
def add_key(w: TimelineWidget, c: dict[str, Any]) -> None:
    track, when = str(c["track"]), float(c["time"])
    m = w.model
    m.timeline.key_track(track, when)  # what the track shows now: weight, layer state, or value at the playhead
    _select(w, track, when)
    w.status = f"keyed {track_label(track)} at {when:.2f} s"


@handles("key")
def key(w: TimelineWidget, c: dict[str, Any]) -> None:
    m = w.model
    when = float(c.get("time", m.time))
    with m.lock:
        keyed = set(m.timeline.value.weight_tracks)
        names = [n for n in m.shape_names if m.weights[n] != 0.0 or n in keyed]
    if not names:
        w.status = "nothing to key: every weight is 0 (move a slider or drop an expression)"
        return
    m.timeline.key_weights(when)
    w.status = f"keyed {len(names)} weights at {when:.2f} s"


@handles("key_handles")
def key_handles(w: TimelineWidget, c: dict[str, Any]) -> None:
    m = w.model
    when = float(c.get("time", m.time))
    m.handles.key(when)
    w.status = f"keyed handles at {when:.2f} s"


@handles("key_head_pose")
def key_head_pose(w: TimelineWidget, c: dict[str, Any]) -> None:
    yaw, pitch, roll = (float(c[k]) for k in ("yaw", "pitch", "roll"))
    if not all(math.isfinite(a) for a in (yaw, pitch, roll)):
        raise ValueError(f"yaw, pitch and roll must be finite degrees, got {[yaw, pitch, roll]}")
    when = float(c.get("time", w.model.time))
    w.key_head_pose(yaw, pitch, roll, time=when)


@handles("key_expression")
def key_expression(w: TimelineWidget, c: dict[str, Any]) -> None:
    name, when = str(c["name"]), float(c["time"])
    w.model.expressions.key(when, name)
    w.status = f"keyed {name} at {when:.2f} s"


@handles("key_gallery")
def key_gallery(w: TimelineWidget, c: dict[str, Any]) -> None:
    w.key_selected_expression()


# ------------------------------------------------------- interpolation, tangents
@handles("set_interpolation")
def set_interpolation(w: TimelineWidget, c: dict[str, Any]) -> None:
    interp = str(c["interpolation"])
    keys = _keys(c)
    if not keys:
        return
    w.model.timeline.set_interpolations(keys, interp)
    w.status = f"{len(keys)} key{'s' if len(keys) > 1 else ''} → {interp}"


@handles("set_tangent")
def set_tangent(w: TimelineWidget, c: dict[str, Any]) -> None:
    track, index, side = str(c["track"]), int(c["index"]), str(c["side"])
    slope = float(c["slope"])
    if not math.isfinite(slope):
        raise ValueError(f"tangent slope must be finite, got {slope}")
    if side not in ("in", "out"):
        raise ValueError(f"tangent side must be 'in' or 'out', got {side!r}")
    aligned = bool(c.get("aligned", True))
    in_t = slope if (aligned or side == "in") else None
    out_t = slope if (aligned or side == "out") else None
    w.model.timeline.set_tangents(track, index, in_tangent=in_t, out_tangent=out_t)
    w.status = f"tangent of {track_label(track)} key {index}: {slope:.3g}/s"


@handles("auto_tangent")
def auto_tangent(w: TimelineWidget, c: dict[str, Any]) -> None:
    track, index = str(c["track"]), int(c["index"])
    w.model.timeline.set_tangents(track, index, mode="auto_clamped")
    w.status = f"{track_label(track)} key {index}: auto-clamped tangents"


@handles("set_fps")
def set_fps(w: TimelineWidget, c: dict[str, Any]) -> None:
    fps = float(c["fps"])
    w.model.timeline.set_fps(fps)
    w.status = f"{fps:g} fps"
