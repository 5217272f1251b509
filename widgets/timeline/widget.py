"""The ``TimelineWidget`` anywidget: traits, the model -> front end refresh, message dispatch.

What each front-end message does is in :mod:`widgets.timeline.messages`,
playback in :mod:`widgets.timeline.playback`, the JSON the front end draws in
:mod:`widgets.timeline.state`.

The expression chips (one per saved expression and blendshape) are a small
gallery: with a ``gallery`` (:class:`widgets.gallery.ExpressionGallery`) each
chip shows that gallery's PNG thumbnail of the expression (nothing is rendered
twice: the timeline observes ``gallery.thumbnails`` and follows it, e.g. when an
expression is saved). The PNGs travel as binary message buffers (the
``_thumbnails`` dict of bytes), never as JSON. Without thumbnails the chips
are text. Dragging a chip onto the tracks or the ruler keys that expression at
the drop time.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

import anywidget
import ipywidgets
import traitlets as t

from widgets._threading import ErrorSink, close_interactions
from widgets.timeline.bundle import load_timeline_bundle
from widgets.timeline.messages import HANDLERS, KEEP_ERROR, NOT_EDITS
from widgets.timeline.playback import FRAME_ACK_TIMEOUT_S, Playback
from widgets.timeline.state import curve_samples, timeline_state
from widgets.viewport.common import scene_key
from workbench.animation.curves import (
    IDENTITY_POSE,
    WEIGHTS_PREFIX,
    head_euler_from_rotation,
    head_rotation_from_euler,
)

__all__ = ["TimelineWidget"]


def _has_trait(obj: Any, name: str) -> bool:
    return isinstance(obj, t.HasTraits) and obj.has_trait(name)


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
    frame_ack_timeout : float
        Seconds playback waits for the browser to draw a frame (0: never waits).
    head_pose_angles : tuple of float
        (yaw, pitch, roll) in degrees of the head pose keyed at the playhead.
    playback_stats : dict
        After/while playing: ``frames``, ``dropped``, ``fps`` (achieved),
        ``target_fps``, ``set_time_ms`` (median), ``seconds``.
    """

    _esm = t.Unicode("").tag(sync=True)
    #: the face model's key in the browser (widgets.viewport.common.scene_key): a playing
    #: timeline puts only the viewports of its own model in draft resolution
    _scene = t.Unicode("").tag(sync=True)
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
        super().__init__(_esm=load_timeline_bundle(), _scene=scene_key(model), **kwargs)
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
        #: playback waits for the front end to draw each frame (widgets.timeline.playback)
        self.frame_ack_timeout = FRAME_ACK_TIMEOUT_S
        self.playback = Playback(self)
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
        handler = HANDLERS.get(kind) if isinstance(kind, str) else None
        if handler is None:
            self._fail(f"unknown timeline message {kind!r}")
            return
        try:
            if kind not in NOT_EDITS:
                self._flush()
            handler(self, content)
        except Exception as exc:
            self.errors.report(f"timeline {kind}", exc)
        else:
            if kind not in KEEP_ERROR:
                self._error = ""

    def key_selected_expression(self) -> None:
        """Key the gallery's selected expression at the playhead (``model.expressions.key``)."""
        name = getattr(self.gallery, "selected", None)
        if not name:
            raise ValueError("no expression is selected in the gallery")
        self._flush()
        self._model.expressions.key(self._model.time, name)
        self.status = f"keyed {name} at {self._model.time:.2f} s"

    @property
    def head_pose_angles(self) -> tuple[float, float, float]:
        return (float(self._head_pose[0]), float(self._head_pose[1]), float(self._head_pose[2]))

    def key_head_pose(
        self, yaw: float, pitch: float, roll: float, time: float | None = None
    ) -> None:
        """Key the head turned by ``yaw``, ``pitch``, ``roll`` degrees at ``time`` (default: playhead).

        The rotation is about the model's axes (``metadata.up_axis`` /
        ``front_axis``, see :func:`workbench.animation.tracks.head_rotation_from_euler`);
        the translation keeps the one keyed at ``time`` (0 when the head pose
        is not keyed). One undo step (``model.timeline.key_head_pose``).
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

    def play(self, loop: bool | None = None) -> Any:
        """Start kernel-side playback from the playhead; return its task.

        In a notebook ``await widget.play(loop=False)`` plays the range once and
        returns :attr:`playback_stats`. Playback runs on the kernel's event loop
        (the UI thread); called where no loop runs (a plain script) it raises
        ``RuntimeError`` saying how to run one.
        """
        if loop is not None:
            self.loop = bool(loop)
        return self.playback.start()

    def pause(self) -> None:
        """Stop playback after the current frame (the playhead stays where it is)."""
        self.playing = False

    def _flush(self) -> None:
        """End open slider/handle interactions so the next edit is an undo step of its own."""
        close_interactions(self._model)
        for fn in self._before_edit:
            fn()

    # -------------------------------------------------------- model -> front end
    def _show_error(self, text: str) -> None:
        self._error = text

    def _fail(self, text: str) -> None:
        self._error = text

    def _refresh_tracks(self, *_args: Any) -> None:
        tl = self._model.timeline.value
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
        self._curve = curve_samples(self._model.timeline.value, self.selected_track)

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
