"""``SculptPanel``: the controls of handle-based shell editing (Bickel et al. 2008, §4).

Dragging happens in the :class:`widgets.Viewport` (``tool="sculpt"``); this panel
holds everything else a person needs around it:

* handle sets: the default mocap-like set (:func:`workbench.methods.handles.presets.default_face_handles`),
  clear, reset offsets (the face goes back to the blend);
* symmetric drag (the mirror handle follows with x reflected) and "click adds
  handles" (plain clicks add, without holding Shift);
* the thin-shell stiffness ``k_s`` (stretching) and ``k_b`` (bending) on log
  sliders: both change the basis, so they apply on release, not while dragging;
* "Bake to shape": the handle layer becomes a named blendshape at weight 1;
* undo / redo, a progress bar for basis precomputes (100k+ vertices take a
  second or more) and a status line (handle count, kernel time per drag update,
  updates per second of the last drag).

Like the other widgets it keeps no state of its own: it edits the model through
its public methods and follows ``model.events``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from typing import Any

import ipywidgets as W

from widgets.panels.base import ModelPanel, button
from widgets.panels.names import next_free_name
from widgets.panels.progress import ProgressRow

_HELP = (
    "<div style='line-height:1.35'>"
    "<b>Drag</b> a marker to pull the skin (it moves in the view plane). "
    "<b>Shift-click</b> the face to add a handle, <b>Alt-click</b> a marker to remove it. "
    "Off the markers the mouse orbits (right button pans, wheel zooms).</div>"
)

#: log10 range of the stiffness sliders
_LOG_RANGE = (-3.0, 3.0)


class SculptPanel(ModelPanel):
    """Handle-editing controls for a FaceModel (drag happens in the viewport).

    Parameters
    ----------
    model : workbench.FaceModel
    viewport : widgets.Viewport, optional
        The viewport whose ``symmetric`` / ``add_on_click`` the toggles drive and
        whose drag statistics the status line shows.
    errors : ipywidgets.Output, optional
        Where callback errors are shown (``Workbench`` passes a shared one).
    before_edit : iterable of callables, optional
        Called before undo/redo and other whole-model edits, e.g. to close a
        slider interaction of another panel (``model.undo`` refuses to run
        inside an interaction).
    """

    def __init__(
        self,
        model: Any,
        viewport: Any = None,
        *,
        errors: W.Output | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
    ) -> None:
        super().__init__(
            model,
            errors=errors,
            before_edit=before_edit,
            layout=W.Layout(width="100%", min_width="380px"),
        )
        self.viewport = viewport
        if viewport is not None:
            self._before_edit.append(viewport.end_drag)
        self._syncing = False  # True while model -> UI updates set the stiffness sliders
        self._last_status_t = 0.0

        self.default_button = button(
            "Default handles",
            "fwb-default-handles",
            "Mocap-like handle set on brows, lids, cheeks, nose, lips, jaw",
        )
        self.clear_button = button("Clear handles", "fwb-clear-handles", "Remove every handle")
        self.reset_button = button(
            "Reset offsets", "fwb-reset-offsets", "Put every handle back on the blend (undoable)"
        )
        self.history_buttons = self.undo_redo_buttons("fwb-sculpt-undo", "fwb-sculpt-redo")
        self.undo_button, self.redo_button = self.history_buttons.buttons
        self.symmetric = W.ToggleButton(
            value=bool(getattr(viewport, "symmetric", False)),
            description="Symmetric",
            icon="arrows-h",
            tooltip="Drag the mirror handle too (x reflected); Shift-click adds a mirrored pair",
            layout=W.Layout(width="120px"),
        )
        self.symmetric.add_class("fwb-symmetric")
        self.add_on_click = W.Checkbox(
            value=bool(getattr(viewport, "add_on_click", False)),
            description="click adds handles",
            indent=False,
            layout=W.Layout(width="170px"),
        )
        self.add_on_click.add_class("fwb-add-on-click")
        k_s, k_b = model.handles.stiffness
        slider_kw = dict(
            base=10,
            min=_LOG_RANGE[0],
            max=_LOG_RANGE[1],
            step=0.05,
            continuous_update=False,  # every value rebuilds the basis
            readout_format=".3g",
            style={"description_width": "150px"},
            layout=W.Layout(width="98%"),
        )
        self.k_s = W.FloatLogSlider(
            value=max(k_s, 10 ** _LOG_RANGE[0]), description="k_s stretching", **slider_kw
        )
        self.k_b = W.FloatLogSlider(
            value=max(k_b, 10 ** _LOG_RANGE[0]), description="k_b bending", **slider_kw
        )
        self.k_s.add_class("fwb-ks")
        self.k_b.add_class("fwb-kb")
        self.bake_name = W.Text(
            value=next_free_name("sculpt_1", model.shape_names),
            placeholder="new shape name",
            layout=W.Layout(width="180px"),
        )
        self.bake_name.add_class("fwb-bake-name")
        self.bake_button = button(
            "Bake to shape", "fwb-bake", "Turn the handle edit into a blendshape at weight 1"
        )
        #: the shell basis precompute's progress (``model.handles.set_progress``)
        self.progress_row = ProgressRow("fwb-progress", template="<i>shell basis: {message}</i>")
        self.progress, self.progress_label = self.progress_row.bar, self.progress_row.label
        self.status = W.HTML("")
        self.status.add_class("fwb-sculpt-status")

        rows = [
            W.HTML(_HELP),
            W.HBox([self.default_button, self.clear_button, self.reset_button]),
            W.HBox([self.symmetric, self.add_on_click]),
            W.HTML("<b>Shell stiffness</b> (applies on release; rebuilds the basis)"),
            self.k_s,
            self.k_b,
            W.HBox([self.bake_name, self.bake_button]),
            W.HBox([self.undo_button, self.redo_button]),
            self.progress_row,
            self.status,
        ]
        self.children = rows
        self.add_class("fwb-sculpt-panel")

        g = self.errors.guard
        self.default_button.on_click(g("default handles")(self._on_default))
        self.clear_button.on_click(g("clear handles")(self._on_clear))
        self.reset_button.on_click(g("reset offsets")(self._on_reset))
        self.bake_button.on_click(g("bake to shape")(self._on_bake))
        self.k_s.observe(g("k_s")(self._on_stiffness), "value")
        self.k_b.observe(g("k_b")(self._on_stiffness), "value")
        if viewport is not None:
            self.link((self.symmetric, "value"), (viewport, "symmetric"))
            self.link((self.add_on_click, "value"), (viewport, "add_on_click"))
            self.add_listener(viewport.drag_listeners, self._on_drag_end, "SculptPanel drag stats")
        ev = model.events
        self.listen(ev.handles, self._on_model_handles, "SculptPanel handles")
        self.listen(ev.shell_stiffness, self._on_model_stiffness, "SculptPanel stiffness")
        self.listen(ev.handles_changing, self._on_handles_changing, "SculptPanel handles")
        self.listen(ev.shapes, self._on_model_shapes, "SculptPanel shapes")
        model.handles.set_progress(self.progress_row)
        self.on_close(model.handles.set_progress, None)
        self._update_status()

    # ------------------------------------------------------- UI -> model
    def _on_default(self, _b: Any = None) -> None:
        from workbench.methods.handles.presets import default_face_handles

        self.flush()
        self._model.handles.set(default_face_handles(self._model), label="Default handles")
        self._model.handles.prepare()  # build the basis now, not on the first drag

    def _on_clear(self, _b: Any = None) -> None:
        from workbench.model import HandleSet

        self.flush()
        if len(self._model.handles):
            self._model.handles.set(HandleSet(), label="Clear handles")

    def _on_reset(self, _b: Any = None) -> None:
        self.flush()
        if len(self._model.handles):
            self._model.handles.reset_offsets()

    def _on_bake(self, _b: Any = None) -> None:
        name = self.bake_name.value.strip()
        if not name:
            raise ValueError("Bake to shape: type a name for the new shape first")
        self.flush()
        self._model.handles.bake_to_shape(name)
        self.bake_name.value = next_free_name(name, self._model.shape_names)
        self._update_status(f"baked <b>{name}</b>")

    def _on_stiffness(self, _change: Any = None) -> None:
        if self._syncing:
            return  # the sliders follow the model (undo/redo): not an edit
        k_s, k_b = float(self.k_s.value), float(self.k_b.value)
        if (k_s, k_b) == tuple(self._model.handles.stiffness):
            return
        self.flush()
        self._model.handles.set_stiffness(k_s, k_b)

    # ------------------------------------------------------- model -> UI
    def _on_model_handles(self) -> None:
        self._update_status()

    def _on_model_stiffness(self) -> None:
        """Show the model's ``(k_s, k_b)`` (after an undo/redo or an edit from code)."""
        k_s, k_b = self._model.handles.stiffness
        lo = 10 ** _LOG_RANGE[0]
        self._syncing = True
        try:
            with self.k_s.hold_sync(), self.k_b.hold_sync():
                self.k_s.value = max(k_s, lo)
                self.k_b.value = max(k_b, lo)
        finally:
            self._syncing = False

    def _on_handles_changing(self) -> None:
        # During a drag: at most 4 status updates a second (each one is a comm message).
        now = time.monotonic()
        if now - self._last_status_t > 0.25:
            self._update_status()

    def _on_drag_end(self, stats: dict[str, Any]) -> None:
        self._update_status()

    def _on_model_shapes(self) -> None:
        if self.bake_name.value.strip() in self._model.shape_names:
            self.bake_name.value = next_free_name(
                self.bake_name.value.strip(), self._model.shape_names
            )

    def _update_status(self, note: str = "") -> None:
        self._last_status_t = time.monotonic()
        h = self._model.handles
        parts = [f"<b>{len(h)}</b> handles"]
        vp = self.viewport
        drag = getattr(vp, "last_drag", None) or {}
        if vp is not None and vp.dragging and vp.drag_ms:
            parts.append(f"dragging: {vp.drag_ms[-1]:.1f} ms per update")
        elif drag:
            ups = drag["updates_per_s"]
            fps = f"{ups:.0f} updates/s" if math.isfinite(ups) else ""
            parts.append(
                f"last drag <i>{drag['name']}</i>: {drag['last_ms']:.1f} ms per update "
                f"(median {drag['median_ms']:.1f}), {drag['moves']} updates, {fps}"
            )
        elif not len(h):
            parts.append("press <i>Default handles</i> or Shift-click the face")
        if note:
            parts.append(note)
        self.status.value = " · ".join(parts)
