"""``CapturePanel``: the Capture tab — drive the face from a performance (Bouaziz et al. 2013, issue 17).

Load a take (C3D or CSV markers with a marker → vertex map, NPZ marker arrays,
a folder of PLY point clouds or an NPZ of clouds; from code,
:meth:`CapturePanel.set_take`), then *Track*: rigid head pose and blendshape
weights per frame (:func:`workbench.capture.track`) with a progress bar. The
input points of the current frame are drawn over the face
(:meth:`widgets.Viewport.set_overlay_points`); the frame slider scrubs them and
the plot under it shows the busiest shapes' weights and the fit error, with the
current frame marked and held frames shaded. The *sparsity* (λ₁) and
*smoothness* (λ₂) sliders re-track the frames around the current one as soon as
they are released (the rest of the take keeps its values until the next
*Track*). *Apply to timeline* keys the result (reduced linear keys + head-pose
keys, ``model.capture.apply``: one undo step); from then on, scrubbing the
timeline also scrubs the input points.
"""

from __future__ import annotations

import html
import time
from pathlib import Path
from typing import Any

import ipywidgets as W
import numpy as np

from widgets.capture.plots import take_plot_png
from widgets.panels.base import ModelPanel, button
from widgets.panels.progress import ProgressRow

__all__ = ["CapturePanel"]

#: frames re-tracked around the current one when a λ slider moves
WINDOW = 60
#: point-cloud points drawn over the face per frame at most
MAX_DRAWN_POINTS = 3000
MARKER_COLOR = (0.2, 1.0, 0.6)
CLOUD_COLOR = (0.35, 0.75, 1.0)


class CapturePanel(ModelPanel):
    """The Capture tab (see the module docstring).

    Parameters
    ----------
    model : workbench.FaceModel
    viewport : widgets.Viewport
        Where the input points are drawn.
    errors : ipywidgets.Output or ErrorSink, optional
    before_edit : iterable of callables

    Attributes
    ----------
    take : dict or None
        ``kind`` ("markers" | "clouds"), ``frames`` (model units), ``vertex_ids``,
        ``fps``, ``name``.
    result : workbench.capture.TrackResult or None
    applied_start : float or None
        Timeline seconds of frame 0 after *Apply to timeline*.
    """

    def __init__(self, model: Any, viewport: Any, *, errors: Any = None, before_edit: Any = (),
                 selected_keys: Any = None) -> None:
        super().__init__(model, errors=errors, before_edit=before_edit, layout=W.Layout(width="100%"))
        self.viewport = viewport
        #: returns the timeline's selected keys as [(track, index), ...] (the Workbench's timeline)
        self.selected_keys = selected_keys
        self.take: dict[str, Any] | None = None
        self.result: Any = None
        self.applied_start: float | None = None
        self.path = W.Text(placeholder="take: .c3d / .csv / .npz markers, or a folder of .ply clouds",
                           layout=W.Layout(width="98%"))
        self.path.add_class("fwb-capture-path")
        self.map_path = W.Text(placeholder="marker → vertex map (.csv / .json), for markers",
                               layout=W.Layout(width="98%"))
        self.map_path.add_class("fwb-capture-map")
        self.units = W.Dropdown(options=[("as the file states", ""), ("m", "m"), ("dm", "dm"), ("cm", "cm"),
                                         ("mm", "mm"), ("in", "in")], value="", description="units",
                                layout=W.Layout(width="220px"))
        self.units.add_class("fwb-capture-units")
        self.load_button = button("Load take", "fwb-capture-load", "Read the take", "folder-open")
        self.info = W.HTML("<i>No take loaded.</i>")
        self.info.add_class("fwb-capture-info")
        self.frame = W.IntSlider(value=0, min=0, max=0, description="frame", continuous_update=True,
                                 layout=W.Layout(width="98%"))
        self.frame.add_class("fwb-capture-frame")
        from workbench.capture.track import DEFAULT_L1, DEFAULT_TEMPORAL

        self.l1 = W.FloatLogSlider(value=DEFAULT_L1, base=10, min=-4, max=0, step=0.1, description="sparsity λ₁",
                                   continuous_update=False, readout_format=".3g", style={"description_width": "90px"})
        self.l1.add_class("fwb-capture-l1")
        self.temporal = W.FloatLogSlider(value=DEFAULT_TEMPORAL, base=10, min=-3, max=1, step=0.1,
                                         description="smooth λ₂",
                                         continuous_update=False, readout_format=".3g",
                                         style={"description_width": "90px"})
        self.temporal.add_class("fwb-capture-temporal")
        self.auto = W.Checkbox(value=True, description="choose λ₁, λ₂ from the take (held-out markers)",
                               indent=False, layout=W.Layout(width="auto"))
        self.auto.add_class("fwb-capture-auto")
        self._syncing = False
        self.adapt = W.Checkbox(value=False, description="Adapt the rig to the actor (default: on for clouds)",
                                indent=False, layout=W.Layout(width="auto"))
        self.adapt.add_class("fwb-capture-adapt")
        self.mode = W.ToggleButtons(options=[("solve weights", "weights"), ("drive handles (shell)", "shell")],
                                    value="weights", description="markers",
                                    tooltips=["Blendshape weights + head pose per frame (Bouaziz et al. 2013)",
                                              "The markers drive the shell's handles over the rig's weights, "
                                              "with wrinkles from their strain (Bickel et al. 2008, Fig. 6)"],
                                    style={"description_width": "60px", "button_width": "170px"})
        self.mode.add_class("fwb-capture-mode")
        #: the marker replay of the take (mode "shell"), or None
        self.replayed: Any = None
        self.track_button = button("Track", "fwb-capture-track", "Track the whole take", "play")
        self.tolerance = W.BoundedFloatText(value=0.01, min=0.0, max=0.5, step=0.005, description="key tolerance",
                                            style={"description_width": "90px"}, layout=W.Layout(width="190px"))
        self.apply_button = button("Apply to timeline", "fwb-capture-apply",
                                   "Key the tracked weights and head pose (one undo step)", "check")
        self.retime_button = button("Retime selected keys from this take", "fwb-capture-retime",
                                    "Bermano et al. 2014 §6: key the in-betweens of the two selected key times "
                                    "with this take's timing (one undo step)", "clock-o")
        self.adapted_path = W.Text(placeholder="adapted_rig.fwb", layout=W.Layout(width="220px"))
        self.adapted_path.add_class("fwb-capture-adapted-path")
        self.save_adapted_button = button("Save adapted rig", "fwb-capture-save-adapted",
                                          "Save the rig adapted to the actor as a new model (.fwb)", "save")
        self.clone_path = W.Text(placeholder="performance: a face file whose timeline plays it (.fwb, .glb, .abc...)",
                                 layout=W.Layout(flex="1 1 auto", width="auto"))
        self.clone_path.add_class("fwb-capture-clone-path")
        self.clone_button = button("Clone onto this face", "fwb-capture-clone",
                                   "Expression cloning (Noh & Neumann 2001): the performance's motion carried onto "
                                   "this face through a dense correspondence, as a marker take to track or replay",
                                   "clone")
        self.progress = ProgressRow("fwb-capture-progress", "fwb-capture-status")
        # hidden until a tracked take has a plot (an empty Image draws as a broken picture)
        self.plot = W.Image(format="png", layout=W.Layout(width="100%", display="none"))
        self.plot.add_class("fwb-capture-plot")
        g = self.guard
        self.load_button.on_click(g("load take")(lambda _b: self.load(self.path.value, self.map_path.value or None)))
        self.clone_button.on_click(g("clone performance")(lambda _b: self.clone(self.clone_path.value)))
        self.track_button.on_click(g("track")(lambda _b: self.track()))
        self.apply_button.on_click(g("apply capture")(lambda _b: self.apply()))
        self.retime_button.on_click(g("retime from performance")(lambda _b: self.retime_selected()))
        self.save_adapted_button.on_click(g("save adapted rig")(lambda _b: self.save_adapted(self.adapted_path.value)))
        self.frame.observe(g("capture frame")(lambda _c: self.show_frame()), "value")
        for s in (self.l1, self.temporal):
            s.observe(g("retrack window")(lambda _c: self._on_lambda()), "value")
        self.listen(model.events.time, self._on_time, "capture time")
        self.children = [
            W.HTML("<b>Take</b>"), self.path, self.map_path, W.HBox([self.units, self.load_button]),
            W.HTML("<b>or a performance of another face</b>"), W.HBox([self.clone_path, self.clone_button]), self.info,
            self.frame, self.mode, W.HBox([self.l1, self.temporal]), self.auto, self.adapt,
            W.HBox([self.track_button, self.tolerance, self.apply_button]), self.progress, self.plot,
            self.retime_button,
            W.HBox([self.adapted_path, self.save_adapted_button]),
        ]
        self.on_close(self._clear_points)
        self.refresh()

    # ------------------------------------------------------------------ take
    def load(self, path: str, vertex_map: Any = None) -> dict[str, Any]:
        """Read a take from ``path`` (markers need ``vertex_map``); replaces the current take."""
        from workbench.capture import inputs

        p = Path(str(path).strip())
        if not str(path).strip():
            raise ValueError("Load take: type the path of a take first")
        units = self.units.value or None
        if p.is_dir() or p.suffix.lower() == ".ply":
            clouds = inputs.read_point_clouds(p, units=units)
            frames = inputs.to_model_units(clouds, self.model)
            return self.set_take(frames, fps=clouds.fps, name=p.name)
        seq = inputs.read_markers(p, units=units)
        if vertex_map is None:
            raise ValueError(f"Load take {p.name}: markers need a marker → vertex map (.csv or .json)")
        ids = inputs.read_vertex_map(vertex_map, seq.names, self.model.n_vertices)
        return self.set_take(inputs.to_model_units(seq, self.model), vertex_ids=ids, fps=seq.fps, name=p.name)

    def set_take(self, frames: Any, *, vertex_ids: Any = None, fps: float = 30.0, name: str = "take") -> dict[str, Any]:
        """Use ``frames`` (model units): (T, m, 3) markers with ``vertex_ids``, or a list of (p_t, 3) clouds."""
        if vertex_ids is not None:
            F = np.asarray(frames, np.float64)
            if F.ndim != 3 or F.shape[2] != 3:
                raise ValueError(f"set_take: markers must be (T, m, 3), got {F.shape}")
            ids = np.asarray(vertex_ids, np.int64).reshape(-1)
            if ids.size != F.shape[1]:
                raise ValueError(f"set_take: {F.shape[1]} markers but {ids.size} vertex ids")
            take = {"kind": "markers", "frames": F, "vertex_ids": ids, "fps": float(fps), "name": name}
            n = F.shape[0]
        else:
            clouds = [np.asarray(c, np.float64).reshape(-1, 3) for c in frames]
            take = {"kind": "clouds", "frames": clouds, "vertex_ids": None, "fps": float(fps), "name": name}
            n = len(clouds)
        if n == 0:
            raise ValueError("set_take: the take has no frames")
        self.take, self.result, self.replayed, self.applied_start = take, None, None, None
        self.frame.max = n - 1
        self.frame.value = 0
        self.adapt.value = take["kind"] == "clouds"
        self.refresh()
        self.show_frame()
        return take

    def clone(self, path: str, *, markers: int = 120) -> dict[str, Any]:
        """Clone the performance in ``path`` onto this face and use it as the take (progress bar).

        The performance is any face file whose timeline plays it; expression cloning carries its
        frames onto this face (any topology, order, units), and ``markers`` spread face vertices of
        the clone become a marker take: *Track* fits this face's rig to it, *drive handles* replays it.
        """
        from workbench.io import load
        from workbench.rigging import ExpressionCloner

        p = Path(str(path).strip())
        if not str(path).strip():
            raise ValueError("Clone: give the performance's file")
        if not p.exists():
            raise ValueError(f"Clone: {p}: no such file")

        def clone() -> tuple[Any, ...]:
            perf = load(p)
            timeline = perf.tracks
            if not timeline.tracks:
                raise ValueError(f"Clone: {p.name}: its timeline has no keys: nothing to clone")
            times = timeline.frame_times()
            frames = np.stack([perf.evaluate_at(float(t)) for t in times])
            cloner = ExpressionCloner(perf, self.model, progress=lambda f, m: self.progress(0.9 * f, m))
            return (timeline, times, cloner, *cloner.marker_take(frames, markers=markers))

        (timeline, times, cloner, ids, take), dt = self._timed(f"cloning {html.escape(p.name)}", clone)
        out = self.set_take(take, vertex_ids=ids, fps=float(timeline.fps), name=f"clone of {p.name}")
        self.progress.finish(f"cloned {len(times)} frames of {html.escape(p.name)} onto this face in "
                             f"{dt:.1f} s ({ids.size} markers); Track or drive handles next"
                             + "".join(f"<br>warning: {html.escape(w)}" for w in cloner.transfer_.warnings[:3]))
        return out

    # ------------------------------------------------------------------ tracking
    def _track(self, frames: Any, progress: Any = None, adapt: Any = None, auto: bool = False,
               **options: Any) -> Any:
        from workbench.capture import track

        t = self.take
        assert t is not None
        return track(self.model, frames, vertex_ids=t["vertex_ids"], fps=t["fps"],
                     l1="auto" if auto else float(self.l1.value),
                     temporal="auto" if auto else float(self.temporal.value),
                     adapt=bool(self.adapt.value) if adapt is None else adapt, progress=progress, **options)

    def _on_lambda(self) -> None:
        """A λ slider moved by the user: they take over from the take's choice; re-track the window."""
        if self._syncing:
            return
        self.auto.value = False
        self.retrack_window()

    def _chosen(self, res: Any) -> str:
        """The λ's used, for the status line; the sliders show them (without re-tracking)."""
        l1, tm = res.info.get("l1"), res.info.get("temporal")
        if l1 is None or tm is None:
            return ""
        self._syncing = True
        try:
            self.l1.value, self.temporal.value = max(float(l1), 10.0**self.l1.min), float(tm)
        finally:
            self._syncing = False
        ch = res.info.get("lambda_choice")
        how = (f" chosen by held-out markers (error {ch['heldout']:.3g} {html.escape(self.model.metadata.units)}, "
               f"{ch['seconds']:.1f} s)" if ch else "")
        return f"; λ₁ {float(l1):.3g}, λ₂ {float(tm):.3g}{how}"

    def track(self) -> Any:
        """Track the whole take (progress bar); returns the :class:`~workbench.capture.TrackResult`."""
        if self.take is None:
            raise ValueError("Track: load a take first")
        if self.mode.value == "shell" and self.take["kind"] == "markers":
            return self.replay()
        auto = bool(self.auto.value) and self.take["kind"] == "markers"
        res, dt = self._timed("tracking", lambda: self._track(self.take["frames"], self.progress, auto=auto))
        self.result, self.replayed = res, None
        held = int(np.asarray(res.held).sum())
        self._finished(
            f"{res.n_frames} frames in {dt:.2f} s ({res.n_frames / max(dt, 1e-9):.0f} frames/s); median error "
            f"{np.nanmedian(res.errors):.3g} {html.escape(self.model.metadata.units)}"
            + (f"; {held} frames held (too few points)" if held else "") + self._chosen(res)
        )
        return res

    def _timed(self, what: str, work: Any) -> tuple[Any, float]:
        """Run ``work()`` behind the progress bar; a failure says what failed. Returns (result, seconds)."""
        self.progress.start(f"<i>{what} ...</i>")
        t0 = time.perf_counter()
        try:
            out = work()
        except Exception as exc:
            self.progress.fail(f"{what} failed: {exc}")
            raise
        return out, time.perf_counter() - t0

    def _finished(self, message: str) -> None:
        self.progress.finish(message)
        self.refresh()
        self.show_frame()

    def replay(self) -> Any:
        """Replay the marker take through the shell with wrinkles (mode "drive handles"); progress bar.

        Returns the :class:`~workbench.capture.ReplayResult`; :attr:`result` becomes its blendshape
        tracking (None on a face without shapes), for the plot.
        """
        t = self.take
        if t is None or t["kind"] != "markers":
            raise ValueError("Drive handles: load a marker take first (point clouds have no marker vertices)")
        auto = bool(self.auto.value)
        rep, dt = self._timed("replaying the markers through the shell", lambda: self.model.capture.replay(
            t["frames"], vertex_ids=t["vertex_ids"], fps=t["fps"], l1="auto" if auto else float(self.l1.value),
            temporal="auto" if auto else float(self.temporal.value), progress=self.progress))
        self.replayed, self.result = rep, rep.tracked
        self._finished(
            f"{rep.n_frames} frames through the shell in {dt:.2f} s, {rep.vertex_ids.size} markers as handles; "
            f"wrinkles: {html.escape(str(rep.info.get('wrinkles')))}"
            + (self._chosen(rep.tracked) if rep.tracked is not None else ""))
        return rep

    def retrack_window(self) -> None:
        """Re-track the frames around the current one with the λ's as they are now."""
        if self.take is None or self.result is None or self.replayed is not None:
            return
        from workbench.capture.result import TrackResult

        f = int(self.frame.value)
        a, b = max(0, f - WINDOW), min(self.result.n_frames - 1, f + WINDOW)
        frames = self.take["frames"][a : b + 1]
        # the take's adapted rig carries on (a new one would redo its set-up for every slider move); its
        # identity came from the take's neutral start, which a window in the middle of the take does not have
        adapted = self.result.info.get("adapted")
        options = {"neutral_start": False} if adapted is not None and self.result.kind == "clouds" else {}
        part = self._track(frames, adapt=adapted if adapted is not None else False, **options)
        r = self.result
        W_, P_, E_ = np.array(r.weights), np.array(r.poses), np.array(r.errors)
        W_[a : b + 1], P_[a : b + 1], E_[a : b + 1] = part.weights, part.poses, part.errors
        flags = list(r.flags)
        flags[a : b + 1] = part.flags
        self.result = TrackResult(W_, P_, E_, tuple(flags), r.fps, r.shape_names, r.derived, r.head_size, r.kind,
                                  {**dict(r.info), "retracked": (a, b)})
        self.progress.finish(f"re-tracked frames {a}–{b} with λ₁ {self.l1.value:.3g}, λ₂ {self.temporal.value:.3g}")
        self.show_frame()

    def apply(self) -> float:
        """Key the result on the timeline (one undo step); returns the start time used (0).

        A replay (mode "drive handles") also makes the markers the handles and installs their wrinkles.
        """
        self.flush()
        if self.replayed is not None:
            rep = self.replayed
            self.model.capture.apply_replay(rep, tolerance=float(self.tolerance.value))
            self.applied_start = 0.0
            self.progress.finish(f"applied the replay of {rep.n_frames} frames: the markers are the handles, "
                                 "their offsets and the weights are keyed (undo: one step)")
            return 0.0
        if self.result is None:
            raise ValueError("Apply to timeline: track the take first")
        self.model.capture.apply(self.result, tolerance=float(self.tolerance.value))
        self.applied_start = 0.0
        self.progress.finish(f"applied {self.result.n_frames} frames to the timeline (undo: one step)")
        return 0.0

    def retime_selected(self) -> Any:
        """Retime the timeline between the two selected key times from the tracked take (one undo step)."""
        if self.result is None:
            raise ValueError("Retime: track a take first (it is the performance the timing comes from)")
        keys = list(self.selected_keys() if self.selected_keys is not None else [])
        tracks = self.model.slot("tracks").tracks
        times = sorted({float(tracks[tn].keys[int(i)].time) for tn, i in keys if tn in tracks})
        if len(times) != 2:
            raise ValueError(f"Retime: select keys at exactly two times on the timeline (selected: {times})")
        self.flush()
        res = self.model.enhance.retime(times[0], times[1], [self.result])
        self.progress.finish(f"retimed {times[0]:g}–{times[1]:g} s: {res.describe()} (undo: one step)")
        return res

    def save_adapted(self, path: str) -> Path:
        """Save the rig the cloud tracker adapted to the actor (a new ``.fwb``; this model is not changed)."""
        adapted = None if self.result is None else self.result.info.get("adapted")
        if adapted is None:
            raise ValueError("Save adapted rig: track with 'Adapt the rig' on first")
        out = Path(str(path).strip() or "adapted_rig.fwb")
        if out.suffix.lower() != ".fwb":
            raise ValueError(f"Save adapted rig: {out.name}: expected a .fwb path")
        adapted.to_model().save(out)
        self.progress.finish(f"saved the adapted rig to {html.escape(str(out))}")
        return out

    # ------------------------------------------------------------------ display
    def _on_time(self, t: float) -> None:
        if self.take is None or self.applied_start is None:
            return
        f = round((float(t) - self.applied_start) * self.take["fps"])
        if 0 <= f <= self.frame.max and f != self.frame.value:
            self.frame.value = f

    def _clear_points(self) -> None:
        self.viewport.set_overlay_points(None)

    def hide_points(self) -> None:
        """Stop drawing the take's points (the Workbench calls it when another tab is picked)."""
        self._clear_points()

    def frame_points(self, f: int) -> np.ndarray:
        """The input points of frame ``f`` as drawn (model units; clouds thinned)."""
        assert self.take is not None
        P = np.asarray(self.take["frames"][f], np.float64).reshape(-1, 3)
        if self.take["kind"] == "clouds" and len(P) > MAX_DRAWN_POINTS:
            P = P[np.linspace(0, len(P) - 1, MAX_DRAWN_POINTS).astype(int)]
        return P

    def show_frame(self) -> None:
        """Draw the current frame's input points and the plot."""
        if self.take is None:
            self._clear_points()
            self.plot.layout.display = "none"
            return
        f = int(self.frame.value)
        color = MARKER_COLOR if self.take["kind"] == "markers" else CLOUD_COLOR
        self.viewport.set_overlay_points(self.frame_points(f), colors=color)
        if self.result is not None:
            n = self.result.n_frames
            win = None if n <= 4 * WINDOW else (max(0, f - 2 * WINDOW), min(n - 1, f + 2 * WINDOW))
            self.plot.value = take_plot_png(self.result, frame=f, window=win, units=self.model.metadata.units)
            self.plot.layout.display = None
        else:
            self.plot.layout.display = "none"

    def refresh(self) -> None:
        t = self.take
        if t is None:
            self.info.value = "<i>No take loaded.</i>"
        else:
            n = t["frames"].shape[0] if t["kind"] == "markers" else len(t["frames"])
            what = (f"{t['frames'].shape[1]} markers" if t["kind"] == "markers"
                    else f"point clouds of ~{int(np.median([len(c) for c in t['frames']]))} points")
            self.info.value = f"<b>{html.escape(t['name'])}</b>: {n} frames at {t['fps']:g} fps, {what}"
        self.track_button.disabled = t is None
        self.apply_button.disabled = self.result is None and self.replayed is None
        self.retime_button.disabled = self.result is None
        self.mode.disabled = t is None or t["kind"] != "markers"
        self.adapt.disabled = t is None
        has_adapted = self.result is not None and self.result.info.get("adapted") is not None
        self.save_adapted_button.disabled = not has_adapted
