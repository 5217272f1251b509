"""``RegionsPanel``: local blend regions, coarse-to-fine region sculpting (Joshi et al. 2003, §2–§4).

Paper: "Learning Controls for Blend Shape Based Realistic Facial Animation"
(``shared/papers/siggraph2006-course-performance-driven-facial-animation.md``).
The numerics live in the headless core (``model.regions``,
:mod:`workbench.methods.regions`); this panel is the notebook front of them:

* **Find regions** + a threshold ``t`` slider: segmentation runs again when the
  slider is released (``model.regions.segment``, undoable), with a progress bar
  and the time it took;
* a **level** slider (coarse ↔ fine; ``model.regions.set_level``, the weights
  carry over to the new level);
* a **colour overlay** on the viewport (:mod:`widgets.regions.colors`): each
  region its own colour, the background grey, overlaps blended. It replaces
  ``viewport.vertex_colors`` while the panel is active; the previous colours
  come back on :meth:`RegionsPanel.deactivate` / :meth:`RegionsPanel.close`;
* a **region** dropdown with the region's weight sliders
  (:mod:`widgets.regions.sliders`);
* **Drag to sculpt**: the viewport shows pin markers (the mocap-like default
  marker set plus the model's handles) in its sculpt tool, and dragging a pin
  solves the region weights under it (``model.regions.begin_drag``, bounded
  least squares with motion damping, paper §4; :mod:`widgets.regions.tools`);
  the face follows while dragging and the drag is one undo step. Optionally
  the other pins of the touched regions are held ("hold other pins");
* **Edit regions**: rename, merge, split, paint (:mod:`widgets.regions.edits`);
* a status line: regions per level, segmentation time, solve time per drag update.

Like the other panels it keeps no model state of its own: it edits the model
through ``model.regions`` and follows ``model.events``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

import ipywidgets as W
import numpy as np

from widgets._threading import InteractionGrouper
from widgets.panels.base import ModelPanel, button
from widgets.panels.progress import ProgressRow
from widgets.regions.colors import ColorSlots, region_colors
from widgets.regions.edits import RegionEdits
from widgets.regions.sliders import RegionSliders
from widgets.regions.tools import MarkerMode, RegionDragHandler

_HELP = (
    "<div style='line-height:1.35'>"
    "<b>Find regions</b> splits the face where its shapes bend the skin (Joshi et al. 2003). "
    "Move <b>t</b> for bigger/smaller regions and <b>level</b> for coarse/fine. "
    "In <b>Drag to sculpt</b> mode drag a marker: the weights of the region(s) under it are "
    "solved so the point follows the mouse; Shift-click the face to add a marker. "
    "<b>Edit regions</b>: rename, merge with a neighbour, split between two clicked markers, "
    "or paint the region with a brush (each one undo step).</div>"
)


class RegionsPanel(ModelPanel):
    """Blend-region controls for a FaceModel and its viewport (see the module docstring).

    Parameters
    ----------
    model : workbench.FaceModel
    viewport : widgets.Viewport, optional
        Gets the colour overlay and, in drag and edit modes, the markers and the
        ``drag_handler``.
    errors : ipywidgets.Output, optional
        Where callback errors are shown.
    threshold : float
        Initial ``t``.
    idle_s : float
        Idle time that ends a weight-slider drag's undo step.
    before_edit : iterable of callables
        Called before undo/redo and whole-model edits (e.g. another panel's
        ``grouper.flush``).

    Notes
    -----
    A host that shows this panel in a tab should call :meth:`activate` when the
    tab is shown and :meth:`deactivate` when it is hidden: the overlay and the
    drag mode then come and go with the tab.
    """

    def __init__(self, model: Any, viewport: Any = None, *, errors: W.Output | None = None,
                 threshold: float = 0.25, idle_s: float = 0.5,
                 before_edit: Iterable[Callable[[], Any]] = ()) -> None:
        if errors is None:
            errors = getattr(getattr(viewport, "errors", None), "output", None)
        super().__init__(model, errors=errors, before_edit=before_edit,
                         layout=W.Layout(width="100%", min_width="400px"))  # fmt: skip
        self.viewport = viewport
        self.grouper = InteractionGrouper(model, idle_s=idle_s, errors=self.errors)
        #: lends the viewport's marker drags to the pin drag, the seed picker or the brush
        self.marker_mode = MarkerMode(viewport)
        self.drag_handler = RegionDragHandler(model, self._pin_vertices)
        self.color_slots = ColorSlots()
        self.segment_ms: float | None = None
        self._default_pins: np.ndarray | None = None
        self._active = False
        self._saved_colors: Any = None
        self._overlay_key: Any = None
        self._shown_regions: Any = None
        self._syncing = False  # True while model -> UI updates set widget values

        self.find_button = button("Find regions", "fwb-find-regions", "Segment the face into blend regions",
                                  "search")  # fmt: skip
        self.threshold = W.FloatSlider(
            value=float(threshold), min=0.0, max=0.95, step=0.05, description="t (threshold)",
            continuous_update=False, readout_format=".2f",
            style={"description_width": "110px"}, layout=W.Layout(width="98%"),
        )  # fmt: skip
        self.threshold.add_class("fwb-region-threshold")
        #: the segmentation's progress (``model.regions.segment(progress=...)``)
        self.progress_row = ProgressRow("fwb-region-progress", "fwb-region-progress-label",
                                        template="<i>segmenting: {message}</i>")  # fmt: skip
        self.level = W.SelectionSlider(
            options=[("—", 0)], value=0, description="level", continuous_update=False,
            style={"description_width": "110px"}, layout=W.Layout(width="98%"), disabled=True,
        )  # fmt: skip
        self.level.add_class("fwb-region-level")
        self.overlay = W.Checkbox(value=True, description="region colours", indent=False,
                                  layout=W.Layout(width="150px"))  # fmt: skip
        self.overlay.add_class("fwb-region-overlay")
        self.region = W.Dropdown(options=[], description="region", style={"description_width": "60px"},
                                 layout=W.Layout(width="260px"), disabled=True)  # fmt: skip
        self.region.add_class("fwb-region-select")
        self.sliders = RegionSliders(model, self._selected_index, self.grouper, self.errors, self.flush)
        self.drag_mode = W.ToggleButton(value=False, description="Drag to sculpt", icon="hand-paper-o",
                                        tooltip="Drag a marker to solve the weights of the region(s) under it",
                                        layout=W.Layout(width="150px"))  # fmt: skip
        self.drag_mode.add_class("fwb-region-drag")
        self.damping = W.Checkbox(value=True, description="motion damping", indent=False,
                                  layout=W.Layout(width="140px"))  # fmt: skip
        self.damping.add_class("fwb-region-damping")
        self.hold = W.Checkbox(value=False, description="hold other pins", indent=False,
                               layout=W.Layout(width="140px"))  # fmt: skip
        self.hold.add_class("fwb-region-hold")
        self.edits = RegionEdits(self)
        self.history_buttons = self.undo_redo_buttons("fwb-region-undo", "fwb-region-redo")
        self.undo_button, self.redo_button = self.history_buttons.buttons
        self.status = W.HTML("")
        self.status.add_class("fwb-region-status")
        s = self.sliders
        self.children = [
            W.HTML(_HELP),
            W.HBox([self.find_button, self.overlay]),
            self.threshold,
            self.progress_row,
            self.level,
            W.HBox([self.region, s.reset_region_button, s.reset_all_button]),
            s.box,
            s.add_shape,
            W.HBox([self.drag_mode, self.damping, self.hold]),
            self.edits.box,
            W.HBox([self.undo_button, self.redo_button]),
            self.status,
        ]
        self.add_class("fwb-regions-panel")

        g = self.errors.guard
        self.find_button.on_click(g("find regions")(lambda _b: self.segment()))
        self.threshold.observe(g("threshold")(self._on_threshold), "value")
        self.level.observe(g("region level")(self._on_level), "value")
        self.overlay.observe(g("region overlay")(lambda _c: self._update_overlay()), "value")
        self.region.observe(g("region select")(self._on_region_select), "value")
        self.drag_mode.observe(g("drag mode")(self._on_drag_mode), "value")
        self.damping.observe(g("damping")(self._on_drag_options), "value")
        self.hold.observe(g("hold pins")(self._on_drag_options), "value")
        self.add_listener(self.drag_handler.listeners, self._on_drag_end, "region drag stats")
        self.on_close(self.sliders.close)
        ev = model.events
        self.listen(ev.regions, self._on_model_regions, "RegionsPanel regions")
        self.listen(ev.weights, self._on_model_weights, "RegionsPanel weights")
        self.listen(ev.weights_changing, self._on_model_weights, "RegionsPanel weights")
        self.listen(ev.shapes, self._on_model_shapes, "RegionsPanel shapes")
        self.listen(ev.handles, self._on_model_handles, "RegionsPanel handles")
        # closing (last in, first out): end the slider burst, then give the viewport back
        self.on_close(self.deactivate)
        self.on_close(self.grouper.flush)
        self._on_model_shapes()
        self._on_model_regions()
        self.activate()

    @property
    def active(self) -> bool:
        """True while the panel is shown (its overlay and pointer mode are on the viewport)."""
        return self._active

    # ------------------------------------------------------------ activation
    def activate(self) -> None:
        """Show the overlay (and drag or edit mode, if on) on the viewport."""
        if self._active:
            return
        self._active = True
        vp = self.viewport
        if vp is not None:
            self._saved_colors = vp.vertex_colors
            self._overlay_key = None
        self._update_overlay()
        if self.drag_mode.value:
            self._enter_drag_mode()
        else:
            self.edits.enter()

    def deactivate(self) -> None:
        """Leave drag and edit modes and give the viewport its previous colours back."""
        if not self._active:
            return
        self._leave_drag_mode()
        self.edits.leave()
        self._active = False
        vp = self.viewport
        if vp is not None and self._overlay_key is not None:
            vp.vertex_colors = self._saved_colors
        self._overlay_key = None

    # ------------------------------------------------------- UI -> model
    def segment(self, threshold: float | None = None) -> Any:
        """Run the segmentation at ``threshold`` (default: the slider's); returns the RegionState."""
        t = float(self.threshold.value if threshold is None else threshold)
        self.flush()
        row = self.progress_row
        row.start(f"<i>segmenting at t = {t:.2f} …</i>")
        t0 = time.perf_counter()
        try:
            state = self._model.regions.segment(t, progress=row)
        except Exception as exc:
            row.fail(f"segmentation at t = {t:.2f} failed: {exc}")
            raise
        self.segment_ms = (time.perf_counter() - t0) * 1e3
        counts = " / ".join(str(state.regions.n_regions(lv)) for lv in range(state.regions.n_levels))
        row.finish(f"t = {t:.2f}: {counts} regions (fine → coarse) in {self.segment_ms:.0f} ms")
        self.update_status()
        return state

    def _on_threshold(self, change: Any) -> None:
        if self._syncing:
            return  # the slider follows the model (undo/redo)
        st = self._model.regions.state
        if st is not None and abs(st.regions.threshold - float(change["new"])) < 1e-9:
            return
        self.segment(float(change["new"]))

    def _on_level(self, change: Any) -> None:
        st = self._model.regions.state
        if self._syncing or st is None or change["new"] is None or int(change["new"]) == st.level:
            return
        self.flush()
        self._model.regions.set_level(int(change["new"]))

    def set_region_weight(self, region: int | str, shape: str, value: float) -> None:
        """One weight of one region (what a weight slider does, grouped into one undo step per drag)."""
        self.sliders.set_region_weight(region, shape, value)

    # ------------------------------------------------------------ selection
    def _selected_index(self) -> int | None:
        sel = self.selected()
        return None if sel is None else sel[2]

    def selected(self) -> tuple[Any, int, int] | None:
        """(Regions, level, region index) of the dropdown's selection, or None."""
        st = self._model.regions.state
        if st is None or self.region.value is None:
            return None
        r = int(self.region.value)
        if not 0 <= r < st.regions.n_regions(st.level):
            return None
        return st.regions, st.level, r

    def select_index(self, r: int) -> None:
        """Select region ``r`` of the shown level (if the dropdown has it)."""
        if any(idx == r for _label, idx in self.region.options):
            self.region.value = r

    def _on_region_select(self, _change: Any = None) -> None:
        if self._syncing:
            return
        self.sliders.build()
        self.edits.refresh()

    # ------------------------------------------------------------ drag mode
    def _pin_vertices(self) -> np.ndarray:
        """(p,) int: the drag-mode markers — the default marker set, less the markers in the shown
        level's background (no region to solve: a drag there could only refuse), plus the model's
        handles (the user's own, always shown)."""
        from workbench.methods.handles.presets import default_face_handles

        if self._default_pins is None:
            try:
                self._default_pins = np.asarray(default_face_handles(self._model).vertices, np.int64)
            except Exception:  # a model without shapes / skin: only user handles
                self._default_pins = np.zeros(0, np.int64)
        pins = self._default_pins
        st = self._model.regions.state
        if st is not None and pins.size:
            inside = np.asarray((st.regions.weight_matrix(st.level)[pins] > 0).sum(axis=1)).ravel() > 0
            pins = pins[inside]
        extra = np.asarray(self._model.handles.vertices, np.int64)
        extra = extra[~np.isin(extra, pins)]
        return np.concatenate([pins, extra])

    @property
    def pins(self) -> np.ndarray:
        """(p,) int vertex ids of the drag-mode markers (marker ``k`` is ``pins[k]``)."""
        return self._pin_vertices()

    def _on_drag_options(self, _change: Any = None) -> None:
        self.drag_handler.damping = bool(self.damping.value)
        self.drag_handler.hold_others = bool(self.hold.value)

    def _on_drag_mode(self, change: Any) -> None:
        if change["new"]:  # one pointer mode at a time
            self.edits.split_mode.value = False
            self.edits.paint_mode.value = False
        if not self._active:
            return
        if change["new"]:
            self._enter_drag_mode()
        else:
            self._leave_drag_mode()

    def _enter_drag_mode(self) -> None:
        self._on_drag_options()
        self.marker_mode.install(self.drag_handler, self._pin_vertices(), before=self.flush)
        self.update_status()

    def _leave_drag_mode(self) -> None:
        self.drag_handler.end()
        if self.marker_mode.installed(self.drag_handler):
            self.marker_mode.release()
            self.update_status()

    def _on_model_handles(self) -> None:
        # Shift-click in drag mode adds a model handle: it becomes a pin too; in the edit
        # modes the viewport re-sent the model's handles: show the edit markers again.
        if self.marker_mode.installed(self.drag_handler):
            self.marker_mode.show(self._pin_vertices())
        elif self.edits.installed():
            self.marker_mode.show(self.edits.markers)

    def _on_drag_end(self, stats: dict[str, Any]) -> None:
        for label, idx in self.region.options:
            if label == stats["name"]:
                self.region.value = idx
                break
        self.update_status()

    # ------------------------------------------------------- model -> UI
    def _on_model_shapes(self) -> None:
        self._default_pins = None
        self.sliders.on_shapes()

    def _on_model_regions(self) -> None:
        st = self._model.regions.state
        for w in (self.level, self.region, self.drag_mode):
            w.disabled = st is None
        self.sliders.set_disabled(st is None)
        self.edits.set_disabled(st is None)
        if st is None:
            self._shown_regions = None
            self.region.options = []
            self.sliders.build()
            self.edits.refresh()
            self._update_overlay()
            self.update_status()
            return
        key = (id(st.regions), st.level)
        if self._shown_regions != key:
            self._shown_regions = key
            self._syncing = True
            try:
                self._show_regions(st.regions, st.level)
            finally:
                self._syncing = False
            self.sliders.build()
            self.edits.refresh()
            self._update_overlay()
            if self.marker_mode.installed(self.drag_handler):  # other regions: other draggable pins
                self.marker_mode.show(self._pin_vertices())
        else:
            self.sliders.refresh()
        self.update_status()

    def _show_regions(self, R: Any, lv: int) -> None:
        """Level slider, threshold slider and region dropdown for ``R`` shown on level ``lv``."""
        keep = self.region.label
        L = R.n_levels
        opts = []
        for i in range(L - 1, -1, -1):  # left = coarse, right = fine
            tag = " coarse" if i == L - 1 and L > 1 else " fine" if i == 0 else ""
            opts.append((f"L{i}{tag} ({R.n_regions(i)})", i))
        if list(self.level.options) != opts:
            self.level.options = opts
        if self.level.value != lv:
            self.level.value = lv
        if abs(self.threshold.value - R.threshold) > 1e-9:
            self.threshold.value = R.threshold
        ropts = [(nm, i) for i, nm in enumerate(R.names[lv])]
        self.region.options = ropts
        if keep in R.names[lv]:
            self.region.value = R.names[lv].index(keep)
        elif ropts:
            # default: the first skin region (rigid parts have nothing to sculpt)
            skin = [i for i, k in enumerate(R.kinds[lv]) if k == "skin"]
            self.region.value = skin[0] if skin else 0

    def _on_model_weights(self, _values: Any = None) -> None:
        st = self._model.regions.state
        if st is not None and st.weights is None:
            self.sliders.refresh()

    def _update_overlay(self) -> None:
        vp = self.viewport
        if vp is None or not self._active:
            return
        st = self._model.regions.state
        if st is None or not self.overlay.value:
            if self._overlay_key is not None:
                vp.vertex_colors = self._saved_colors
                self._overlay_key = None
            return
        key = (id(st.regions), st.level)
        if key != self._overlay_key:
            slots = self.color_slots(st.regions, st.level)
            vp.vertex_colors = region_colors(st.regions, st.level, slots=slots)
            self._overlay_key = key

    def update_status(self) -> None:
        """The status line: regions per level, segmentation and drag times, the pointer mode."""
        st = self._model.regions.state
        if st is None:
            self.status.value = "no regions yet: press <b>Find regions</b>"
            return
        R = st.regions
        per = ", ".join(f"L{lv}: {R.n_regions(lv)}" for lv in range(R.n_levels))
        parts = [f"regions per level ({per})", f"level <b>{st.level}</b>"]
        if self.segment_ms is not None:
            parts.append(f"segmentation {self.segment_ms:.0f} ms")
        d = self.drag_handler.last_drag
        if d:
            parts.append(
                f"last drag <i>{d['name']}</i>: solve {d['median_solve_ms']:.2f} ms "
                f"(update {d['median_ms']:.1f} ms), {d['moves']} updates"
            )
        if self.marker_mode.installed(self.drag_handler):
            parts.append(f"drag mode: {len(self._pin_vertices())} markers")
        elif self.edits.installed():
            parts.append(f"{self.edits.mode} mode: {len(self.edits.markers)} markers")
        self.status.value = " · ".join(parts)
