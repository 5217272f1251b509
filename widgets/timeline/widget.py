"""``TimelineWidget``: keyframe timeline of a :class:`workbench.FaceModel` (Pighin et al. 1998 §5).

The widget draws ``model.tracks`` (a :class:`workbench.animation.tracks.Timeline`): a time
ruler with frame ticks at the timeline's fps, a playhead, one row per track with
its keys as diamonds (squares for step keys), and a curve view of the selected
weight track with the Bézier tangent handles of its keys. Region-weight tracks
(a keyed marker fit) and the head pose are vector tracks: rows without a
curve view. Three sliders give the head's yaw, pitch and roll (degrees about
the model's up, side and front axes, :func:`workbench.animation.tracks.head_rotation_from_euler`);
they show the pose keyed at the playhead and "Key head pose" keys what they
say there (the face turns at once: the model shows the keyed head pose). It only *observes*
the model (``events.tracks``, ``events.time``, ``events.expressions``,
``events.shapes``) and edits it only through model methods, so undo, other
views and Python cells stay in agreement:

=============================  ==========================================================
front end                      model call
=============================  ==========================================================
drag the playhead / ruler      ``set_time(t)`` (one message in flight, acked)
drag a key diamond, release    ``move_key(track, i, t)`` — one undo step per drag
Delete / Backspace / button    ``delete_key`` (several keys: one ``set_timeline``)
double-click a row             ``key_weights(t, [shape])`` / ``key_handles(t)``
"Key" / "Key handles"          ``key_weights(time)`` / ``key_handles(time)``
yaw/pitch/roll, "Key head pose" ``key_head_pose(time, rotation)`` (translation kept)
interpolation selector         ``set_timeline(tl.set_interpolation(...))``
drag a tangent handle          ``set_timeline(tl.set_tangents(...))`` (user tangents)
drop an expression chip        ``key_expression(t, name)`` (HTML5 drag and drop)
"Key selected expression"      ``key_expression(time, gallery.selected)``
fps field                      ``set_timeline(tl.replace(fps=...))``
Play / Pause / Loop            kernel-side asyncio task calling ``set_time``
=============================  ==========================================================

Playback runs in the kernel, not the browser: every frame must evaluate the
model (weights, handle layer) and the viewport ships the new vertices, which
only Python can do. An asyncio task on the kernel's event loop computes the
frame due from the wall clock, calls ``model.set_time`` for it and sleeps until
the next frame; when a frame takes longer than ``1/fps`` the frames that fell
due meanwhile are *dropped* (never queued), so playback keeps real time and the
kernel stays responsive (Pause is a comm message handled between frames).
Dropping in the kernel is not enough: a browser drawing with software WebGL can
render fewer frames per second than the kernel sends, and the geometry messages
would then pile up in the websocket (the view lags further and further behind,
and Pause takes effect seconds late). So after each frame the kernel sends a
small ``{"type": "frame", "seq"}`` message; the front end answers
``frame_ack`` from its next animation frame (after the viewport drew the
geometry that arrived before it), and playback sends a new frame only while
fewer than :data:`FRAMES_IN_FLIGHT` frames are unanswered (waiting at most
:data:`FRAME_ACK_TIMEOUT_S`). When no view answers at
all (nothing displayed, a headless run), playback stops waiting after the
first timeout. The achieved rate is shown in the status label and kept in
:attr:`playback_stats`.

The expression chips (one per saved expression and blendshape) are a small
gallery: with a ``gallery`` (:class:`widgets.gallery.ExpressionGallery`) each
chip shows that gallery's PNG thumbnail of the expression (nothing is rendered
twice: the timeline observes ``gallery.thumbnails`` and follows it, e.g. when an
expression is saved). The PNGs travel as binary message buffers (the
``_thumbnails`` dict of bytes), never as JSON. Without thumbnails the chips
are text. Dragging a chip onto the tracks or the ruler keys that expression at
the drop time.

Why hand-written: ipywidgets has no timeline/dope-sheet widget, and the
available anywidget/ipywidget timeline components (e.g. vis-timeline wrappers)
edit their own event lists rather than calling a model, have no Bézier
tangent view and would need a CDN or a large bundle. The front end is plain
DOM + a 2D canvas (``widgets/js/src/timeline.js``), bundled by esbuild to
``widgets/static/timeline.js``; it has no imports, so the source file itself
is loaded when it is newer than the bundle (or the bundle was not built).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import anywidget
import ipywidgets
import numpy as np
import traitlets as t

from widgets._threading import ErrorSink, close_interactions
from workbench.animation.curves import (
    HANDLES,
    HEAD_POSE,
    IDENTITY_POSE,
    WEIGHTS_PREFIX,
    head_euler_from_rotation,
    head_rotation_from_euler,
    parse_region_track,
)
from workbench.animation.tracks import Timeline
from workbench.model import ModelError

__all__ = ["TimelineWidget", "load_timeline_bundle"]

_JS = Path(__file__).resolve().parent / "js" / "src" / "timeline.js"
_BUNDLE = Path(__file__).resolve().parent / "static" / "timeline.js"

#: samples of the curve view over the visible range (plus two per key for steps)
CURVE_SAMPLES = 240

#: seconds between status-label updates during playback
STATUS_PERIOD_S = 0.5

#: playback waits at most this long for the browser to show an earlier frame
FRAME_ACK_TIMEOUT_S = 0.5

#: frames sent but not yet drawn by the browser: 2 lets the kernel prepare the next
#: frame while the browser draws the current one, and still bounds the backlog
FRAMES_IN_FLIGHT = 2

#: front-end messages that do not touch the model (every other one first ends the
#: interactions other widgets hold open, e.g. a slider drag waiting for its idle time)
_NOT_EDITS = frozenset({"frame_ack", "pause", "scrub_end"})


def load_timeline_bundle() -> str:
    """The front end's ESM text: the esbuild bundle, or the source when newer/unbuilt."""
    candidates = [p for p in (_BUNDLE, _JS) if p.exists()]
    if not candidates:
        raise FileNotFoundError(
            f"the timeline front end is missing: neither {_BUNDLE} nor {_JS} exists"
        )
    newest = max(candidates, key=lambda p: p.stat().st_mtime_ns)
    return newest.read_text(encoding="utf-8")


def _has_trait(obj: Any, name: str) -> bool:
    return isinstance(obj, t.HasTraits) and obj.has_trait(name)


def _track_label(name: str) -> str:
    if name.startswith(WEIGHTS_PREFIX):
        return name[len(WEIGHTS_PREFIX) :]
    region = parse_region_track(name)
    if region is not None:
        return f"region {region[1]} (L{region[0]})"
    return {HANDLES: "handles (pose)", HEAD_POSE: "head pose"}.get(name, name)


def view_range(tl: Timeline) -> tuple[float, float]:
    """Visible time range: from min(0, start) past the end, so keys can be dragged later."""
    v0 = min(0.0, tl.start)
    v1 = max(tl.end, v0 + 1.0)
    return v0, v1 + max(0.25, 0.1 * (v1 - v0))


def timeline_state(tl: Timeline) -> dict[str, Any]:
    """JSON the front end draws: fps, range, visible range and every track's keys.

    Scalar (weight) tracks carry values and tangent slopes; vector tracks
    (handles, head pose, region weights) only times and interpolations (no
    curve view).
    """
    tracks = []
    for name, tr in tl.tracks.items():
        scalar = tr.kind == "weight"
        tracks.append(
            {
                "name": name,
                "label": _track_label(name),
                "kind": tr.kind,
                "times": [float(x) for x in tr.times],
                "values": [float(k.value) for k in tr.keys] if scalar else None,
                "in": [float(k.in_tangent) for k in tr.keys] if scalar else None,
                "out": [float(k.out_tangent) for k in tr.keys] if scalar else None,
                "interp": list(tr.interpolations),
                "mode": [k.tangent_mode for k in tr.keys],
            }
        )
    # weights first (alphabetical, as Timeline sorts them), then handles, head pose
    tracks.sort(key=lambda d: (d["kind"] != "weight", d["name"]))
    return {
        "fps": tl.fps,
        "start": tl.start,
        "end": tl.end,
        "view": list(view_range(tl)),
        "tracks": tracks,
    }


def curve_samples(tl: Timeline, track: str, n: int = CURVE_SAMPLES) -> dict[str, Any]:
    """``{"track", "times", "values"}``: the scalar track sampled over the visible range.

    Sampled with the model's own evaluation (the front end never re-implements
    the interpolation); each key time is added, and a time just before it, so
    step keys draw as vertical jumps.
    """
    tr = tl.tracks.get(track)
    if tr is None or tr.kind != "weight":
        return {"track": track, "times": [], "values": []}
    v0, v1 = view_range(tl)
    ts = np.linspace(v0, v1, n)
    eps = 1e-6 * max(v1 - v0, 1.0)
    ts = np.unique(np.concatenate([ts, tr.times, tr.times - eps]))
    vals = tr.sample(ts)[:, 0]
    return {"track": track, "times": ts.tolist(), "values": vals.tolist()}


class TimelineWidget(anywidget.AnyWidget):
    """Keyframe timeline: scrub, play, key, move/delete keys, edit tangents, drop expressions.

    Parameters
    ----------
    model : workbench.FaceModel
    gallery : widgets.gallery.ExpressionGallery, optional
        Its ``selected`` shape is keyed at the playhead by the "Key selected
        expression at playhead" button (:meth:`key_selected_expression`), and
        its ``thumbnails`` (name -> PNG bytes, followed as they change) are
        the pictures of the chips. See :meth:`set_gallery`.
    chips : sequence of str, optional
        Expression names shown as draggable chips. Default: the saved
        expressions (``model.expressions``) then every blendshape.
    errors : ipywidgets.Output, optional
        Where callback tracebacks go (the status label shows a one-line summary).
    before_edit : iterable of callables, optional
        Called before each editing message (a key, a key move, a scrub, Play),
        after :func:`widgets._threading.close_interactions` ended the
        interactions other widgets hold open on the model: a Key pressed right
        after a slider drag is an undo step of its own, not part of the drag's.

    Attributes
    ----------
    time : float
        The model's current time (read-only mirror of ``model.time``).
    playing : bool
        True while the playback task runs.
    loop : bool
        Playback wraps from the end of the range to its start.
    selected_keys : list of [track, index]
        Keys selected in the front end (synced both ways).
    selected_track : str
        Track shown in the curve view.
    status : str
        The status label (achieved playback fps, last action).
    frames_shown, frames_dropped : int
        Live counters of the current (or last) playback.
    head_pose_angles : tuple of float
        (yaw, pitch, roll) in degrees of the head pose keyed at the playhead.
    playback_stats : dict
        After/while playing: ``frames``, ``dropped``, ``fps`` (achieved),
        ``target_fps``, ``set_time_ms`` (median), ``seconds``.
    """

    _esm = t.Unicode("").tag(sync=True)
    _tracks = t.Dict().tag(sync=True)
    _curve = t.Dict().tag(sync=True)
    _error = t.Unicode("").tag(sync=True)
    _saved_expressions = t.List(t.Unicode()).tag(sync=True)
    _gallery_selected = t.Unicode("").tag(sync=True)
    #: chip name -> PNG bytes (from the gallery; sent as binary buffers, not JSON)
    _thumbnails = t.Dict(value_trait=t.Bytes()).tag(sync=True)
    _has_handles = t.Bool(False).tag(sync=True)
    #: [yaw, pitch, roll] in degrees of the head pose keyed at the playhead
    _head_pose = t.List(t.Float(), default_value=[0.0, 0.0, 0.0]).tag(sync=True)

    time = t.Float(0.0).tag(sync=True)
    playing = t.Bool(False).tag(sync=True)
    loop = t.Bool(False).tag(sync=True)
    selected_keys: t.List[Any] = t.List().tag(sync=True)
    selected_track = t.Unicode("").tag(sync=True)
    expressions = t.List(t.Unicode()).tag(sync=True)
    status = t.Unicode("").tag(sync=True)

    def __init__(
        self,
        model: Any,
        gallery: Any = None,
        *,
        chips: Sequence[str] | None = None,
        errors: ipywidgets.Output | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
        **kwargs: Any,
    ) -> None:
        super().__init__(_esm=load_timeline_bundle(), **kwargs)
        self._model = model
        self._before_edit = list(before_edit)
        self.gallery: Any = None
        self._chips = None if chips is None else list(chips)
        self.errors = ErrorSink(errors, on_error=self._show_error)
        self.frontend_msg_count = 0
        self.playback_stats: dict[str, Any] = {}
        #: live counters of the current/last playback (updated every frame)
        self.frames_shown = 0
        self.frames_dropped = 0
        #: playback waits for the front end to draw each frame (see the module docstring)
        self.frame_ack_timeout = FRAME_ACK_TIMEOUT_S
        self._frame_seq = 0
        self._ack_seq = 0
        self._ack_event: asyncio.Event | None = None
        self._ack_loop: asyncio.AbstractEventLoop | None = None
        self._task: Any = None
        self._play_lock = threading.RLock()
        try:
            # the kernel's loop, for playback started from a non-loop thread
            self._loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            self._loop = None
        g = self.errors.guard
        self._on_tracks = g("Timeline update")(self._refresh_tracks)
        self._on_time = g("Timeline time")(self._refresh_time)
        self._on_metadata = g("Timeline head pose")(self._refresh_head_pose)
        self._on_expr = g("Timeline expressions")(self._refresh_chips)
        self._on_handles = g("Timeline handles")(self._refresh_handles)
        model.events.tracks.connect(self._on_tracks)
        model.events.time.connect(self._on_time)
        model.events.expressions.connect(self._on_expr)
        model.events.shapes.connect(self._on_expr)
        model.events.handles.connect(self._on_handles)
        model.events.metadata.connect(self._on_metadata)
        self._on_thumbs = g("Timeline thumbnails")(self._refresh_thumbnails)
        self.set_gallery(gallery)
        self.on_msg(self._on_frontend_msg)
        self.observe(self._on_selected_track, "selected_track")
        self._refresh_tracks()
        self._refresh_time(model.time)
        self._refresh_chips()
        self._refresh_handles()

    # ------------------------------------------------------------------ public
    @property
    def model(self) -> Any:
        return self._model

    def close(self) -> None:
        self.pause()
        m = self._model
        for sig, cb in (
            (m.events.tracks, self._on_tracks),
            (m.events.time, self._on_time),
            (m.events.expressions, self._on_expr),
            (m.events.shapes, self._on_expr),
            (m.events.handles, self._on_handles),
            (m.events.metadata, self._on_metadata),
        ):
            sig.disconnect(cb)
        self.set_gallery(None)
        super().close()

    def set_gallery(self, gallery: Any) -> None:
        """Use ``gallery`` (or ``None``) for the "Key selected" button and the chip pictures.

        The chips show ``gallery.thumbnails[name]`` where it has one (followed
        when the gallery's ``thumbnails`` trait changes); chips without a
        picture, or all of them without a gallery, are text.
        """
        old = self.gallery
        if old is gallery:
            return
        if old is not None:
            old.unobserve(self._on_gallery, "selected")
            if _has_trait(old, "thumbnails"):
                old.unobserve(self._on_thumbs, "thumbnails")
        self.gallery = gallery
        if gallery is not None:
            gallery.observe(self._on_gallery, "selected")
            if _has_trait(gallery, "thumbnails"):
                gallery.observe(self._on_thumbs, "thumbnails")
        with self.hold_sync():
            self._gallery_selected = getattr(gallery, "selected", None) or ""
            self._refresh_thumbnails()

    def handle_message(self, content: dict[str, Any]) -> None:
        """Apply one front-end message (what a click or drag sends); errors go to the status."""
        kind = content.get("type")
        handler = getattr(self, f"_msg_{kind}", None)
        if handler is None:
            self._fail(f"unknown timeline message {kind!r}")
            return
        try:
            if kind not in _NOT_EDITS:
                self._flush()
            handler(content)
        except Exception as exc:
            self.errors.report(f"timeline {kind}", exc)
        else:
            if kind not in ("scrub", "scrub_start", "scrub_end", "frame_ack"):
                self._error = ""

    def key_selected_expression(self) -> None:
        """Key the gallery's selected expression at the playhead (``model.key_expression``)."""
        name = getattr(self.gallery, "selected", None)
        if not name:
            raise ValueError("no expression is selected in the gallery")
        self._flush()
        self._model.key_expression(self._model.time, name)
        self.status = f"keyed {name} at {self._model.time:.2f} s"

    @property
    def head_pose_angles(self) -> tuple[float, float, float]:
        return (float(self._head_pose[0]), float(self._head_pose[1]), float(self._head_pose[2]))

    def key_head_pose(self, yaw: float, pitch: float, roll: float, time: float | None = None) -> None:
        """Key the head turned by ``yaw``, ``pitch``, ``roll`` degrees at ``time`` (default: playhead).

        The rotation is about the model's axes (``metadata.up_axis`` /
        ``front_axis``, see :func:`workbench.animation.tracks.head_rotation_from_euler`);
        the translation keeps the one keyed at ``time`` (0 when the head pose
        is not keyed). One undo step (``model.key_head_pose``).
        """
        m = self._model
        meta = m.metadata
        q = head_rotation_from_euler(
            float(yaw), float(pitch), float(roll), up_axis=meta.up_axis, front_axis=meta.front_axis
        )
        when = float(m.time if time is None else time)
        self._flush()
        m.timeline.key_head_pose(when, rotation=q)
        self.status = f"keyed head pose (yaw {yaw:.0f}°, pitch {pitch:.0f}°, roll {roll:.0f}°) at {when:.2f} s"

    def _flush(self) -> None:
        """End open slider/handle interactions so the next edit is an undo step of its own."""
        close_interactions(self._model)
        for fn in self._before_edit:
            fn()

    # ---------------------------------------------------------------- playback
    def play(self, loop: bool | None = None) -> Any:
        """Start kernel-side playback from the playhead; return its task.

        In a notebook ``await widget.play(loop=False)`` plays the range once and
        returns :attr:`playback_stats`. Called where no asyncio loop runs (a plain
        script), playback runs on a daemon thread and a
        :class:`concurrent.futures.Future` is returned.
        """
        if loop is not None:
            self.loop = bool(loop)
        with self._play_lock:
            if self._task is not None and not self._task.done():
                return self._task
            self.playing = True
            try:
                running = asyncio.get_running_loop()
            except RuntimeError:
                running = None
            if running is not None:
                self._task = running.create_task(self._run())
            elif self._loop is not None and self._loop.is_running():
                self._task = asyncio.run_coroutine_threadsafe(self._run(), self._loop)
            else:
                fut: concurrent.futures.Future[dict[str, Any]] = concurrent.futures.Future()

                def runner() -> None:
                    try:
                        fut.set_result(asyncio.run(self._run()))
                    except BaseException as exc:  # handed to the future
                        fut.set_exception(exc)

                threading.Thread(target=runner, name="timeline-playback", daemon=True).start()
                self._task = fut
            return self._task

    def pause(self) -> None:
        """Stop playback after the current frame (the playhead stays where it is)."""
        self.playing = False

    async def _run(self) -> dict[str, Any]:
        model = self._model
        frames = dropped = 0
        set_ms: deque[float] = deque(maxlen=600)
        done_at: deque[float] = deque()
        started = time.perf_counter()
        last_status = started
        self._ack_loop = asyncio.get_running_loop()
        self._ack_event = asyncio.Event()
        # None: no front end has acknowledged a frame of this run yet
        acks_seen: bool | None = None
        seq0 = self._frame_seq  # acks above this belong to this run
        # frames of an earlier run that were never answered must not stall this one
        self._ack_seq = max(self._ack_seq, seq0)
        try:
            tl = model.tracks
            fps, start, end = tl.fps, tl.start, tl.end
            if not end > start:
                self.status = "nothing to play: key at two different times first"
                return self._stats(0, 0, fps, set_ms, 0.0, done_at)
            t_now = model.time
            media0 = t_now if start <= t_now < end - 0.5 / fps else start
            clock0 = time.perf_counter()
            next_f = 0
            while self.playing:
                now = time.perf_counter()
                tl = model.tracks
                if tl.fps != fps or tl.start != start or tl.end != end:
                    # fps/range edited while playing: continue from the current time
                    fps, start, end = tl.fps, tl.start, tl.end
                    media0 = min(max(model.time, start), end)
                    clock0, next_f = now, 0
                f = max(next_f, math.floor((now - clock0) * fps + 1e-6))
                dropped += f - next_f  # frames that fell due while the last one ran
                t_media = media0 + f / fps
                if t_media > end + 1e-9:
                    if not self.loop or not end > start:
                        if model.time != end:
                            model.set_time(end)
                            frames += 1
                        break
                    media0, clock0, f, t_media = start, now, 0, start
                t0 = time.perf_counter()
                try:
                    model.set_time(t_media)
                except ModelError:  # a slider/handle drag is open: skip this frame
                    dropped += 1
                else:
                    frames += 1
                    self._frame_seq += 1
                    self.send({"type": "frame", "seq": self._frame_seq})
                t1 = time.perf_counter()
                set_ms.append((t1 - t0) * 1e3)
                if acks_seen is not False and self.frame_ack_timeout > 0:
                    # Flow control: the next frame goes out once the browser has drawn
                    # all but FRAMES_IN_FLIGHT - 1 of the frames sent, so geometry never
                    # queues up in the websocket; frames that fall due meanwhile are
                    # dropped by the wall-clock rule above.
                    ok = await self._wait_ack(
                        self._frame_seq - (FRAMES_IN_FLIGHT - 1), self.frame_ack_timeout
                    )
                    if ok:
                        if self._ack_seq > seq0:
                            acks_seen = True
                    elif acks_seen is None:
                        acks_seen = False  # nobody draws this widget (e.g. headless run)
                    t1 = time.perf_counter()
                done_at.append(t1)
                while done_at and t1 - done_at[0] > 1.0:
                    done_at.popleft()
                next_f = f + 1
                self.frames_shown, self.frames_dropped = frames, dropped
                if t1 - last_status >= STATUS_PERIOD_S:
                    last_status = t1
                    st = self._stats(frames, dropped, fps, set_ms, t1 - started, done_at)
                    self.playback_stats = st
                    self.status = f"playing {st['fps']:.1f}/{fps:g} fps, {dropped} dropped"
                # always yield to the loop, so Pause and other comm messages get in
                await asyncio.sleep(max(clock0 + next_f / fps - time.perf_counter(), 0.0))
            st = self._stats(frames, dropped, fps, set_ms, time.perf_counter() - started, done_at)
            self.playback_stats = st
            self.status = (
                f"played {frames} frames at {st['mean_fps']:.1f}/{fps:g} fps, {dropped} dropped"
            )
            return st
        except Exception as exc:
            self.errors.report("timeline playback", exc)
            raise
        finally:
            self.playing = False

    async def _wait_ack(self, seq: int, timeout: float) -> bool:
        """Wait until the front end acknowledged frame ``seq`` (False on timeout or pause)."""
        event = self._ack_event
        assert event is not None
        deadline = time.perf_counter() + timeout
        while self._ack_seq < seq:
            remaining = deadline - time.perf_counter()
            if remaining <= 0 or not self.playing:
                return False
            event.clear()
            if self._ack_seq >= seq:
                break
            try:
                await asyncio.wait_for(event.wait(), remaining)
            except TimeoutError:
                return False
        return True

    @staticmethod
    def _stats(
        frames: int,
        dropped: int,
        fps: float,
        set_ms: deque[float],
        seconds: float,
        done_at: deque[float],
    ) -> dict[str, Any]:
        recent = (
            (len(done_at) - 1) / (done_at[-1] - done_at[0])
            if len(done_at) > 1 and done_at[-1] > done_at[0]
            else 0.0
        )
        return {
            "frames": frames,
            "dropped": dropped,
            "target_fps": fps,
            "fps": recent,  # over the last second
            "mean_fps": frames / seconds if seconds > 0 else 0.0,
            "seconds": seconds,
            "set_time_ms": float(np.median(set_ms)) if set_ms else 0.0,
        }

    # -------------------------------------------------------- model -> front end
    def _show_error(self, text: str) -> None:
        self._error = text

    def _fail(self, text: str) -> None:
        self._error = text

    def _refresh_tracks(self, *_args: Any) -> None:
        tl = self._model.tracks
        state = timeline_state(tl)
        names = [d["name"] for d in state["tracks"]]
        sel = [
            [tn, i]
            for tn, i in self.selected_keys
            if tn in tl.tracks and 0 <= int(i) < len(tl.tracks[tn])
        ]
        with self.hold_sync():
            self._tracks = state
            if sel != list(self.selected_keys):
                self.selected_keys = sel
            if self.selected_track not in names:
                weights = [n for n in names if n.startswith(WEIGHTS_PREFIX)]
                self.selected_track = weights[0] if weights else (names[0] if names else "")
            self._curve = curve_samples(tl, self.selected_track)
            self._refresh_head_pose()

    def _on_selected_track(self, _change: Any) -> None:
        self._curve = curve_samples(self._model.tracks, self.selected_track)

    def _refresh_time(self, t_: float, *_args: Any) -> None:
        with self.hold_sync():
            self.time = float(t_)
            self._refresh_head_pose()

    def _refresh_head_pose(self, *_args: Any) -> None:
        m = self._model
        pose = m.timeline.head_pose
        q = IDENTITY_POSE[3:] if pose is None else pose[3:]
        meta = m.metadata
        angles = head_euler_from_rotation(q, up_axis=meta.up_axis, front_axis=meta.front_axis)
        rounded = [round(a, 6) + 0.0 for a in angles]  # + 0.0: no "-0" in the sliders
        if rounded != list(self._head_pose):
            self._head_pose = rounded

    def _refresh_chips(self, *_args: Any) -> None:
        m = self._model
        saved = list(m.expressions)
        with self.hold_sync():
            self._saved_expressions = saved
            if self._chips is not None:
                self.expressions = list(self._chips)
            else:
                self.expressions = saved + [n for n in m.shape_names if n not in saved]
            self._refresh_thumbnails()

    def _refresh_thumbnails(self, *_args: Any) -> None:
        # only the chips' pictures, as bytes (ipywidgets sends them as binary buffers);
        # an unchanged dict is not sent again (traitlets compares old and new)
        thumbs = getattr(self.gallery, "thumbnails", None) or {}
        self._thumbnails = {n: bytes(thumbs[n]) for n in self.expressions if n in thumbs}

    def _refresh_handles(self, *_args: Any) -> None:
        self._has_handles = len(self._model.handles) > 0

    def _on_gallery(self, change: Any) -> None:
        self._gallery_selected = change["new"] or ""

    # --------------------------------------------------------- front end -> model
    def _handle_msg(self, msg: dict[str, Any]) -> None:
        self.frontend_msg_count += 1
        super()._handle_msg(msg)

    def _on_frontend_msg(self, _widget: Any, content: Any, _buffers: Any) -> None:
        if isinstance(content, dict):
            self.handle_message(content)

    def _msg_scrub_start(self, c: dict[str, Any]) -> None:
        self.pause()  # scrubbing takes the playhead from playback

    def _msg_scrub_end(self, c: dict[str, Any]) -> None:
        pass

    def _msg_scrub(self, c: dict[str, Any]) -> None:
        try:
            self._model.set_time(float(c["time"]))
        finally:
            # ack even after an error: the front end keeps one scrub in flight
            self.send({"type": "scrub_ack", "seq": c.get("seq")})

    def _msg_frame_ack(self, c: dict[str, Any]) -> None:
        self._ack_seq = max(self._ack_seq, int(c["seq"]))
        loop, event = self._ack_loop, self._ack_event
        if loop is None or event is None:
            return
        try:
            same_thread = asyncio.get_running_loop() is loop
        except RuntimeError:
            same_thread = False
        if same_thread:
            event.set()
        elif not loop.is_closed():
            loop.call_soon_threadsafe(event.set)

    def _msg_play(self, c: dict[str, Any]) -> None:
        self.play()

    def _msg_pause(self, c: dict[str, Any]) -> None:
        self.pause()

    def _msg_move_key(self, c: dict[str, Any]) -> None:
        track, index, when = str(c["track"]), int(c["index"]), float(c["time"])
        self._model.timeline.move_key(track, index, when)
        i = self._model.tracks.tracks[track].index_at(when)
        self.selected_keys = [[track, i]] if i is not None else []
        self.status = f"moved key of {_track_label(track)} to {when:.2f} s"

    def _msg_delete_keys(self, c: dict[str, Any]) -> None:
        keys = [(str(tn), int(i)) for tn, i in c["keys"]]
        if not keys:
            return
        if len(keys) == 1:
            self._model.timeline.delete_key(*keys[0])
        else:
            tl = self._model.tracks
            # highest index first, so earlier deletions do not shift later ones
            for tn, i in sorted(set(keys), key=lambda k: (k[0], -k[1])):
                tl = tl.delete_key(tn, i)
            self._model.timeline.set(tl, f"Delete {len(keys)} keys")
        self.selected_keys = []
        self.status = f"deleted {len(keys)} key{'s' if len(keys) > 1 else ''}"

    def _msg_add_key(self, c: dict[str, Any]) -> None:
        track, when = str(c["track"]), float(c["time"])
        m = self._model
        if track.startswith(WEIGHTS_PREFIX):
            m.timeline.key_weights(when, [track[len(WEIGHTS_PREFIX) :]])
        elif track == HANDLES:
            m.timeline.key_handles(when)
        else:
            tl = m.tracks
            value = tl.tracks[track].evaluate(m.time)
            m.timeline.set(
                tl.add_key(track, when, value), f"Key {_track_label(track)} at {when:g}s"
            )
        i = m.tracks.tracks[track].index_at(when)
        self.selected_keys = [[track, i]] if i is not None else []
        self.status = f"keyed {_track_label(track)} at {when:.2f} s"

    def _msg_key(self, c: dict[str, Any]) -> None:
        m = self._model
        when = float(c.get("time", m.time))
        with m.lock:
            keyed = set(m.tracks.weight_tracks)
            names = [n for n in m.shape_names if m.weights[n] != 0.0 or n in keyed]
        if not names:
            self.status = "nothing to key: every weight is 0 (move a slider or drop an expression)"
            return
        m.timeline.key_weights(when)
        self.status = f"keyed {len(names)} weights at {when:.2f} s"

    def _msg_key_handles(self, c: dict[str, Any]) -> None:
        m = self._model
        when = float(c.get("time", m.time))
        m.timeline.key_handles(when)
        self.status = f"keyed handles at {when:.2f} s"

    def _msg_key_head_pose(self, c: dict[str, Any]) -> None:
        yaw, pitch, roll = (float(c[k]) for k in ("yaw", "pitch", "roll"))
        if not all(math.isfinite(a) for a in (yaw, pitch, roll)):
            raise ValueError(f"yaw, pitch and roll must be finite degrees, got {[yaw, pitch, roll]}")
        when = float(c.get("time", self._model.time))
        self.key_head_pose(yaw, pitch, roll, time=when)

    def _msg_key_expression(self, c: dict[str, Any]) -> None:
        name, when = str(c["name"]), float(c["time"])
        self._model.key_expression(when, name)
        self.status = f"keyed {name} at {when:.2f} s"

    def _msg_key_gallery(self, c: dict[str, Any]) -> None:
        self.key_selected_expression()

    def _msg_set_interpolation(self, c: dict[str, Any]) -> None:
        interp = str(c["interpolation"])
        keys = [(str(tn), int(i)) for tn, i in c["keys"]]
        if not keys:
            return
        tl = self._model.tracks
        for tn, i in keys:
            tl = tl.set_interpolation(tn, i, interp)
        self._model.timeline.set(tl, f"Set interpolation {interp}")
        self.status = f"{len(keys)} key{'s' if len(keys) > 1 else ''} → {interp}"

    def _msg_set_tangent(self, c: dict[str, Any]) -> None:
        track, index, side = str(c["track"]), int(c["index"]), str(c["side"])
        slope = float(c["slope"])
        if not math.isfinite(slope):
            raise ValueError(f"tangent slope must be finite, got {slope}")
        if side not in ("in", "out"):
            raise ValueError(f"tangent side must be 'in' or 'out', got {side!r}")
        aligned = bool(c.get("aligned", True))
        tl = self._model.tracks
        in_t = slope if (aligned or side == "in") else None
        out_t = slope if (aligned or side == "out") else None
        self._model.timeline.set(
            tl.set_tangents(track, index, in_tangent=in_t, out_tangent=out_t),
            f"Edit tangent of {_track_label(track)}",
        )
        self.status = f"tangent of {_track_label(track)} key {index}: {slope:.3g}/s"

    def _msg_auto_tangent(self, c: dict[str, Any]) -> None:
        track, index = str(c["track"]), int(c["index"])
        tl = self._model.tracks
        self._model.timeline.set(
            tl.set_tangents(track, index, mode="auto_clamped"),
            f"Auto tangent of {_track_label(track)}",
        )
        self.status = f"{_track_label(track)} key {index}: auto-clamped tangents"

    def _msg_set_fps(self, c: dict[str, Any]) -> None:
        fps = float(c["fps"])
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {c['fps']!r}")
        tl = self._model.tracks
        if fps != tl.fps:
            self._model.timeline.set(tl.replace(fps=fps), f"Set fps {fps:g}")
        self.status = f"{fps:g} fps"
