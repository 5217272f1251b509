"""The Live tab: the face follows the user's webcam, and Record keys a take (Bouaziz et al. 2013, online).

A view of :class:`workbench.capture.LiveTracker`: *Start camera* asks the page for the
webcam (:class:`~widgets.live.camera.CameraWidget`), each frame the kernel keeps up
with goes through the tracker, and the face shows the frame's weights at once — inside
one open interaction (``kind="live"``), so watching yourself adds nothing to the undo
history and *Stop* puts the sliders back as they were. *Record* / *Stop recording*
keys what was tracked in between onto the timeline as one undo step
(``model.capture.apply``, reduced to keys within the tolerance); *Save take* writes
the raw landmarks and timestamps (``.npz``) to re-track offline with other settings
(``track_video(model, "take.npz", ...)``). The first face the camera sees is taken as the
actor's neutral; *Neutral* takes the next frame instead (a start mid-smile reads every later
frame against the smile), and *Calibrate* takes it from its "relax" prompt.

With *show my head's turn* (on by default) the viewport draws the face under the
tracked head pose (:meth:`~widgets.viewport.Viewport.show_head_pose`, a view-only
preview: nothing is keyed until *Record*); *Stop* puts the model's pose back. The
recorded take keys the same poses (``head_pose``).
"""

from __future__ import annotations

import contextlib
import html
import time
from collections import deque
from pathlib import Path
from typing import Any

import ipywidgets as W
import numpy as np
from numpy.typing import NDArray

from widgets.live.camera import CameraWidget
from widgets.panels.base import ModelPanel, button
from widgets.viewport.common import scene_key
from workbench.blas import one_blas_thread
from workbench.capture.expression_calibration import DEFAULT_PROMPTS, SECONDS_PER_PROMPT

#: the guided calibration's length (its default prompts)
SESSION_SECONDS = SECONDS_PER_PROMPT * len(DEFAULT_PROMPTS)

__all__ = ["LivePanel"]


class LivePanel(ModelPanel):
    """The Live tab's panel (see the module docstring).

    Attributes
    ----------
    camera : CameraWidget
    tracker : workbench.capture.LiveTracker or None
        The tracker of the current camera session.
    last : LiveFrame or None
        What the last frame gave.
    recorded : TrackResult or None
        The last take recorded (applied to the timeline).
    """

    def __init__(self, model: Any, viewport: Any = None, *, errors: Any = None, before_edit: Any = ()) -> None:
        super().__init__(model, errors=errors, before_edit=before_edit, layout=W.Layout(width="100%"))
        self.viewport = viewport
        self.tracker: Any = None
        self.last: Any = None
        self.recorded: Any = None
        self._token: Any = None
        self._record_from: int | None = None
        self._session: Any = None  # the calibration session running (ExpressionCalibration)
        #: the kernel's seconds for the last frames (the status line's median)
        self._seconds: deque[float] = deque(maxlen=30)
        self.camera = CameraWidget(on_frame=self.errors.guard("live frame")(self.push), _scene=scene_key(model))
        self.camera.on_state = self.errors.guard("camera state")(self._on_camera_state)
        self.start_button = button("Start camera", "fwb-live-start", "Open the webcam (the browser asks first)",
                                   "video-camera")
        self.record_button = button("Record", "fwb-live-record", "Record a take onto the timeline", "circle")
        self.calibrate_button = button("Calibrate", "fwb-live-calibrate",
                                       f"A {SESSION_SECONDS:.0f}-second guided session: relax, make each expression "
                                       "shown here and hold it, then turn and nod your head; the tracker then reads "
                                       "you better (press again to end early)",
                                       "sliders")
        self.neutral_button = button("Neutral", "fwb-live-neutral",
                                     "Relax your face, eyes open, and press: the tracker takes this face as your "
                                     "neutral (it took the first face it saw; Calibrate does it too)", "user")
        self.prompt = W.HTML("")
        self.prompt.add_class("fwb-live-prompt")
        self.adapt = W.Checkbox(value=False, description="adapt the rig to me while tracking", indent=False)
        self.adapt.add_class("fwb-live-adapt")
        self.follow_head = W.Checkbox(value=True, description="show my head's turn", indent=False,
                                      layout=W.Layout(width="auto"))
        self.follow_head.add_class("fwb-live-follow-head")
        self.tolerance = W.BoundedFloatText(value=0.01, min=0.0, max=0.5, step=0.005, description="key tolerance",
                                            style={"description_width": "90px"}, layout=W.Layout(width="190px"))
        self.take_path = W.Text(placeholder="take.npz", layout=W.Layout(width="200px"))
        self.save_button = button("Save take", "fwb-live-save", "Save the raw landmarks and timestamps", "save")
        self.status = W.HTML("<i>Camera off.</i>")
        self.status.add_class("fwb-live-status")
        g = self.guard
        self.follow_head.observe(g("show head pose")(lambda _c: self._show_pose(self._last_pose())), "value")
        self.start_button.on_click(g("camera")(lambda _b: self.toggle_camera()))
        self.record_button.on_click(g("record")(lambda _b: self.toggle_record()))
        self.calibrate_button.on_click(g("calibrate")(lambda _b: self.toggle_calibration()))
        self.neutral_button.on_click(g("neutral")(lambda _b: self.set_neutral()))
        self.save_button.on_click(g("save take")(lambda _b: self.save_take(self.take_path.value)))
        self.children = [
            W.HTML("<b>Live</b> — the face follows your webcam"), self.camera,
            W.HBox([self.start_button, self.adapt, self.follow_head]),
            W.HBox([self.neutral_button, self.calibrate_button, self.prompt]),
            W.HBox([self.record_button, self.tolerance]),
            W.HBox([self.take_path, self.save_button]), self.status,
        ]
        self.on_close(self.stop_camera)
        self.refresh()

    # ------------------------------------------------------------------ camera
    def toggle_camera(self) -> None:
        if self.camera.active:
            self.stop_camera()
        else:
            self.start_camera()

    def start_camera(self) -> None:
        """Ask the page for the webcam; frames then drive the face."""
        from workbench.capture import LiveTracker

        self.flush()
        self.tracker = LiveTracker(self.model, adapt=bool(self.adapt.value))
        self.last, self._session = None, None
        self.prompt.value = ""
        self._seconds.clear()
        self.camera.active = True
        self.status.value = "<i>asking the browser for the camera…</i>"
        self.refresh()

    def stop_camera(self) -> None:
        """Stop the webcam (a take being recorded is applied first); the sliders go back."""
        if self._record_from is not None:
            self.toggle_record()
        self.camera.active = False
        self._end_live()
        self._show_pose(None)
        if self.tracker is not None:
            self.tracker.close()
        self.refresh()

    def _end_live(self) -> None:
        tok, self._token = self._token, None
        if tok is not None and self.model.interaction_token == tok:
            self.model.cancel_interaction(tok)

    def _on_camera_state(self, state: str, message: str) -> None:
        if state == "error":
            recording = self._record_from is not None
            self.stop_camera()  # unplugged mid-take: stopping keys what was recorded
            kept = f"; the take so far is kept — {self.status.value}" if recording else ""
            self.status.value = f"<b>Camera:</b> {html.escape(message)}{kept}"
        elif state == "on":
            self.status.value = ("<i>camera on: looking for a face — relax, eyes open: the first face is taken as "
                                 "your neutral (press Neutral to take it again)</i>")
        self.refresh()

    def push(self, image: NDArray[np.uint8], t: float) -> Any:
        """One camera frame: track it and show its weights (the Live tab's frame callback)."""
        if self.tracker is None or not self.camera.active:
            return None  # a frame already on its way when the camera was stopped: dropped
        # small dense work many times a second: threaded BLAS workers would spin between frames
        # on the cores the browser needs (workbench.blas)
        with one_blas_thread():
            return self._push(image, t)

    def _push(self, image: NDArray[np.uint8], t: float) -> Any:
        t0 = time.perf_counter()
        frame = self.tracker.push(image, t)
        self.last = frame
        if frame.ok:
            m = self.model
            if self._token is None or m.interaction_token != self._token:
                self._token = m.begin_interaction("Live camera", on_close=self._lost_live, kind="live")
            with self._one_view_update():
                self._show_pose(frame.pose)
                m.set_weights(dict(zip(m.shape_names, frame.weights.tolist(), strict=True)))
        self._seconds.append(time.perf_counter() - t0)
        self._show_prompt(frame)
        n = self.tracker.n_frames_
        if n % 5 == 1 or not frame.ok or frame.note:
            ms = 1000 * float(np.median(self._seconds))
            rec = f"; recording {n - self._record_from} frames" if self._record_from is not None else ""
            cal = self.tracker.calibration_
            if frame.note:
                note = f" — {html.escape(frame.note)}"
            else:
                note = f" — {html.escape(cal.summary())}" if cal is not None else ""
            self.status.value = (f"{n} frames, {ms:.0f} ms each in the kernel (≤ {1000 / max(ms, 1e-3):.0f} "
                                 f"frames/s){rec}{note}")
        return frame

    def _one_view_update(self) -> Any:
        return contextlib.nullcontext() if self.viewport is None else self.viewport.batch()

    def _show_pose(self, pose: Any) -> None:
        """The viewport draws the tracked head pose while the camera runs and the box is ticked."""
        if self.viewport is None:
            return
        show = pose is not None and self.camera.active and bool(self.follow_head.value)
        self.viewport.show_head_pose(pose if show else None)

    def _last_pose(self) -> Any:
        return self.last.pose if self.last is not None and self.last.ok else None

    def _lost_live(self) -> None:
        """Another edit closed the live interaction (its weights stay); the next frame opens a new one."""
        self._token = None

    # ------------------------------------------------------------------ neutral and calibration
    def set_neutral(self) -> None:
        """Take the next camera frame as the actor's neutral (:meth:`workbench.capture.LiveTracker.set_neutral`)."""
        if self.tracker is None or not self.camera.active:
            raise ValueError("Neutral: start the camera first")
        self.tracker.set_neutral()
        self.status.value = "<i>taking your neutral from the next frame: relax, eyes open…</i>"

    def toggle_calibration(self) -> Any:
        """Start the guided calibration session, or end it early (fitted on the prompts reached)."""
        if self.tracker is None or not self.camera.active:
            raise ValueError("Calibrate: start the camera first")
        if not self.tracker.calibrating:
            self._session = self.tracker.begin_calibration()
            self.prompt.value = self._prompt_html(0)
            self.status.value = (f"<i>calibrating: do what is shown, {self._session.seconds:.0f} s each "
                                 f"({self._session.duration:.0f} s in all)</i>")
            self.refresh()
        else:
            try:
                cal = self.tracker.end_calibration()
            finally:  # a failed fit ends the session too (the tracker keeps the last map)
                self._session, self.prompt.value = None, ""
                self.refresh()
            self.status.value = html.escape(cal.summary())
        return self.tracker.calibration_

    def _prompt_html(self, i: int) -> str:
        cal = self._session
        p = cal.prompts_[i]
        return (f"<span style='font-size:1.5em'><b>{i + 1}/{len(cal.prompts_)}</b> · "
                f"{html.escape(p.instruction)}</span>")

    def _show_prompt(self, frame: Any) -> None:
        """The session's instruction beside the camera; its end note when it ends."""
        if self._session is None:
            return
        if frame.prompt:
            text = self._prompt_html(frame.prompt_index)
            if self.prompt.value != text:
                self.prompt.value = text
        elif not self.tracker.calibrating:  # the session ended with this frame
            self._session, self.prompt.value = None, ""
            self.refresh()

    # ------------------------------------------------------------------ record
    def toggle_record(self) -> Any:
        """Start recording, or stop and key the recorded frames on the timeline (one undo step)."""
        if self._record_from is None:
            if self.tracker is None or not self.camera.active:
                raise ValueError("Record: start the camera first")
            self._record_from = self.tracker.n_frames_
            self.refresh()
            return None
        a, self._record_from = self._record_from, None
        self.refresh()
        take = self.tracker.take() if self.tracker is not None else None
        if take is None or take.n_frames - a < 2:
            self.status.value = "<i>nothing recorded (fewer than two frames)</i>"
            return None
        part = _frames_from(take, a)
        self._end_live()
        self.flush()
        self.model.capture.apply(part, tolerance=float(self.tolerance.value),
                                 label=f"Record live take ({part.n_frames} frames)")
        self.recorded = part
        rate = float(part.info.get("rate", part.fps))
        self.status.value = (f"recorded {part.n_frames} frames ({rate:.1f} frames/s from the camera) onto the "
                             "timeline at their own times (undo: one step)")
        return part

    def save_take(self, path: str) -> Path:
        """Save the raw take (landmarks, timestamps, image size) as ``.npz``."""
        if self.tracker is None or self.tracker.n_frames_ == 0:
            raise ValueError("Save take: nothing was tracked yet")
        out = self.tracker.save_take(Path(str(path).strip() or "take.npz"))
        self.status.value = f"saved {self.tracker.n_frames_} frames to {html.escape(str(out))}"
        return Path(out)

    def refresh(self) -> None:
        on = bool(self.camera.active)
        self.start_button.description = "Stop camera" if on else "Start camera"
        self.record_button.description = "Stop recording" if self._record_from is not None else "Record"
        self.record_button.disabled = not on
        calibrating = self.tracker is not None and self.tracker.calibrating
        self.calibrate_button.disabled = not on
        self.neutral_button.disabled = not on
        self.calibrate_button.description = "End calibration" if calibrating else "Calibrate"
        self.adapt.disabled = on


def _frames_from(take: Any, a: int) -> Any:
    """The take from frame ``a`` on, starting at time 0."""
    from workbench.capture.result import TrackResult

    info = dict(take.info)
    if "timestamps" in info:
        ts = np.asarray(info["timestamps"])[a:]
        info["timestamps"] = ts - ts[0]
        info["rate"] = 1.0 / float(np.median(np.diff(ts))) if ts.size > 1 else float("nan")
    return TrackResult(take.weights[a:], take.poses[a:], take.errors[a:], take.flags[a:], take.fps,
                       take.shape_names, take.derived, take.head_size, take.kind, info)
