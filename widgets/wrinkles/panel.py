"""``WrinklePanel``: pose-space wrinkles while dragging handles (Bickel et al. 2008, §5–6).

The core (``model.wrinkles``, :mod:`workbench.methods.wrinkles`) learns
fine-scale detail from a few *detailed example poses* as a function of the
strain of a feature graph between the handles, and adds it on top of the
large-scale shell deformation (§4) on every :meth:`~workbench.FaceModel.evaluate`.
This panel is its view, in the Sculpt tab under the handle controls:

* **Fit wrinkles from examples**:
  :func:`workbench.methods.wrinkles.family.fit_sample_wrinkles` (default
  handles if the model has none, the procedural detailed expressions of
  :mod:`workbench.methods.wrinkles.examples`, WPSD fit) with a progress bar;
  errors go to the panel's error line and the shared error Output.
* **Wrinkles** on/off and **strength** (0–2): ``model.wrinkles.set_enabled`` /
  ``set_strength``; the strength applies on release.
* **Feature graph**: the edges between handles drawn in the viewport, coloured
  by strain while dragging (blue compressed, grey rest, red stretched;
  :meth:`widgets.Viewport.set_feature_strain`).
* **Example poses**: one card per example (a small render of its detailed
  mesh, grooves tinted: :mod:`.thumbnails`). Clicking the name *views* the
  example (sets its weights, one undo step). **Scale wrinkles** is
  ``model.wrinkles.edit_example(name, scale=...)`` (the change propagates to
  every pose near it). **Erase** (a toggle on each card) paints the example's
  wrinkles out with the brush (:mod:`.eraser`): one
  ``edit_example(name, mask=...)`` per stroke. **Add current pose** is
  ``model.wrinkles.add_example`` with the procedural sculptor's detailed mesh
  for the current weights (earlier edits are kept).

Every edit — fit, strength, on/off, scale, erase, add — is one undo step of
the model, and undo puts the previous fit back exactly (no refit). The panel
keeps no model state: it edits through ``model.wrinkles`` and follows
``model.events`` (``wrinkles``, ``handles``, ``deformed``).
"""

from __future__ import annotations

import html
import math
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import ipywidgets as W
import numpy as np
from numpy.typing import NDArray

from widgets.panels.base import ModelPanel, button
from widgets.panels.names import next_free_name
from widgets.panels.progress import ProgressRow
from widgets.wrinkles.cards import ExampleCards
from widgets.wrinkles.eraser import EraseControls, WrinkleEraser

__all__ = ["SCALE_MAX", "STRENGTH_MAX", "WrinklePanel"]

#: strength slider range
STRENGTH_MAX = 2.0
#: scale slider range for "Scale wrinkles"
SCALE_MAX = 3.0

_HELP = (
    "<div style='line-height:1.35'><b>Pose-space wrinkles</b> (Bickel et al. 2008, §5–6): "
    "fine detail learned from detailed example poses as a function of the skin strain "
    "between handles, added on top of the shell while you drag. Drag a brow marker up: "
    "the forehead furrows. Edges of the feature graph show the strain "
    "(<span style='color:#2a6bff'>blue</span> compressed, grey rest, "
    "<span style='color:#e52a1f'>red</span> stretched).</div>"
)


def _sculptor_class() -> type:
    from workbench.methods.wrinkles.examples import WrinkleSculptor

    class ProgressSculptor(WrinkleSculptor):
        """A WrinkleSculptor that reports each detailed pose it makes (progress bar)."""

        on_detailed: Callable[[], None] | None = None

        def detailed(self, weights: Mapping[str, float]) -> NDArray[np.float32]:
            out = super().detailed(weights)
            if self.on_detailed is not None:
                self.on_detailed()
            return out

    return ProgressSculptor


class WrinklePanel(ModelPanel):
    """Controls of the pose-space wrinkles of a FaceModel (``model.wrinkles``; Sculpt tab).

    Parameters
    ----------
    model : workbench.FaceModel
    viewport : widgets.Viewport, optional
        Draws the feature graph coloured by strain; its ``feature_graph`` trait
        follows the panel's checkbox; its paint tool brushes the eraser.
    errors : ipywidgets.Output, optional
        Where callback errors are shown (``Workbench`` passes a shared one); the
        panel's error line repeats the last one.
    before_edit : iterable of callables
        Called before model edits (e.g. to close another panel's slider interaction).
    thumbnails : bool
        Render a small picture per example (~0.1 s each with one plotter).

    Attributes
    ----------
    last_fit_s : float
        Seconds the last fit took (thumbnails excluded).
    eraser : WrinkleEraser or None
        The stroke handler while an example's *Erase* toggle is on.
    erase_toggles : dict of str -> ipywidgets.ToggleButton
        The *Erase* toggle of each example card.
    """

    def __init__(
        self,
        model: Any,
        viewport: Any = None,
        *,
        errors: W.Output | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
        thumbnails: bool = True,
    ) -> None:
        super().__init__(
            model,
            errors=errors,
            before_edit=before_edit,
            on_error=self._show_error,
            layout=W.Layout(width="100%", min_width="380px"),
        )
        self.viewport = viewport
        if viewport is not None:
            self._before_edit.append(viewport.end_drag)
        self._sculptor: Any = None
        self._sculptor_shapes: Any = None
        self._seen: Any = None  # the pose space the cards show
        self._graph_sent: tuple[Any, bytes] | None = None
        self._last_status_t = 0.0
        self.last_fit_s = math.nan

        self.fit_button = button(
            "Fit wrinkles from examples", "fwb-wrinkle-fit",
            "Default handles if none, six procedural detailed expressions, WPSD fit (a few seconds)",
            icon="magic",
        )
        #: the fit's progress (also a ``progress(fraction, message)`` callback)
        self.progress_row = ProgressRow("fwb-wrinkle-progress", "fwb-wrinkle-progress-label")
        self.progress, self.progress_label = self.progress_row.bar, self.progress_row.label
        self.enabled = W.Checkbox(value=True, description="Wrinkles", indent=False,
                                  layout=W.Layout(width="110px"))
        self.enabled.add_class("fwb-wrinkles-on")
        self.strength = W.FloatSlider(
            value=1.0, min=0.0, max=STRENGTH_MAX, step=0.05, description="strength",
            continuous_update=False,  # one undo step per release
            readout_format=".2f", style={"description_width": "60px"}, layout=W.Layout(width="320px"),
        )
        self.strength.add_class("fwb-wrinkle-strength")
        self.show_graph = W.Checkbox(value=bool(getattr(viewport, "feature_graph", True)),
                                     description="feature graph (strain colours)", indent=False,
                                     layout=W.Layout(width="240px"))
        self.show_graph.add_class("fwb-feature-graph")
        self.example = W.Dropdown(options=[], description="example", layout=W.Layout(width="230px"))
        self.example.add_class("fwb-wrinkle-example")
        self.scale = W.FloatSlider(value=1.0, min=0.0, max=SCALE_MAX, step=0.05, description="× ",
                                   readout_format=".2f", style={"description_width": "20px"},
                                   layout=W.Layout(width="220px"))
        self.scale.add_class("fwb-wrinkle-scale")
        self.scale_button = button("Scale wrinkles", "fwb-wrinkle-scale-apply",
                                    "Multiply this example's details and refit", icon="arrows-v")
        self.rest_button = button("Rest pose", "fwb-wrinkle-rest", "Set every weight to 0 (undoable)")
        self._erase = EraseControls(self, viewport)
        self._cards = ExampleCards(model, self._erase, self.view_example, self.errors.guard, thumbnails)
        self.cards = self._cards.box
        self.erase_radius, self.erase_strength = self._erase.radius, self._erase.strength
        self.erase_note, self.erase_box = self._erase.note, self._erase.box
        self.new_name = W.Text(value="pose_1", placeholder="example name", layout=W.Layout(width="140px"))
        self.new_name.add_class("fwb-wrinkle-new-name")
        self.add_button = button(
            "Add current pose as example", "fwb-wrinkle-add",
            "The current blend weights + their procedurally sculpted wrinkles become an example; refit",
            icon="plus",
        )
        self.status = W.HTML("")
        self.status.add_class("fwb-wrinkle-status")
        self.error_line = W.HTML("")
        self.error_line.add_class("fwb-wrinkle-error")
        def row() -> W.Layout:
            return W.Layout(flex_flow="row wrap")

        self.controls = W.VBox([
            W.HBox([self.enabled, self.strength], layout=W.Layout(align_items="center")),
            self.show_graph,
            W.HTML("<b>Example poses</b> (click a name to view it; <i>Erase</i> "
                   "paints that example's wrinkles out with the brush)"),
            self.cards,
            self.erase_box,
            W.HBox([self.example, self.scale, self.scale_button], layout=row()),
            W.HBox([self.new_name, self.add_button, self.rest_button], layout=row()),
        ])
        rows = [W.HTML(_HELP), self.fit_button, self.progress_row, self.controls,
                self.status, self.error_line]
        self.children = rows
        self.add_class("fwb-wrinkle-panel")

        g = self.errors.guard
        self.fit_button.on_click(g("fit wrinkles")(lambda _b: self.fit()))
        self.scale_button.on_click(
            g("scale wrinkles")(lambda _b: self.scale_example(self.example.value, self.scale.value))
        )
        self.add_button.on_click(g("add example pose")(lambda _b: self.add_current_pose(self.new_name.value)))
        self.rest_button.on_click(g("rest pose")(self._on_rest))
        self.enabled.observe(g("wrinkles on/off")(self._on_enabled), "value")
        self.strength.observe(g("wrinkle strength")(self._on_strength), "value")
        if viewport is not None:
            self.link((self.show_graph, "value"), (viewport, "feature_graph"))
            self.link((self.erase_radius, "value"), (viewport, "brush_radius"))
            self.observe_trait(viewport, self._erase.on_tool, "tool", "WrinklePanel tool")
            self.add_listener(viewport.drag_listeners, self._on_drag_end, "WrinklePanel drag stats")
        ev = model.events
        self.listen(ev.wrinkles, self._on_wrinkles, "WrinklePanel wrinkles")
        self.listen(ev.deformed, self._on_deformed, "WrinklePanel update")
        self.listen(ev.handles, self._sync_graph, "WrinklePanel handles")
        self.on_close(self.stop_erasing)  # registered last: runs first on close
        self._refresh()

    @property
    def fresh(self) -> bool:
        """True when the wrinkles are fitted for the model's current handle set."""
        return bool(self._model.wrinkles.fresh)

    def current_strain(self) -> NDArray[np.float64] | None:
        """(F,) strain of the feature graph now (None if not fitted or stale)."""
        return self._model.wrinkles.strain()

    def sculptor(self) -> Any:
        """The procedural sculptor of the model (rebuilt when the shapes changed)."""
        shapes = self._model.shapes
        if self._sculptor is None or self._sculptor_shapes is not shapes:
            self._sculptor = _sculptor_class()(self._model)
            self._sculptor_shapes = shapes
        return self._sculptor

    # ------------------------------------------------------- actions (UI -> model)
    def _require_fit(self, what: str) -> Any:
        w = self._model.wrinkles
        if not w.fitted:
            raise RuntimeError(f"{what}: press 'Fit wrinkles from examples' first")
        return w

    def fit(self) -> Any:
        """Fit the wrinkles to the procedural example poses (refit if fitted); returns ``model.wrinkles``.

        :func:`workbench.methods.wrinkles.family.fit_sample_wrinkles` (default
        handles first if the model has none: an undo step of its own; the fit
        is another) with a progress bar, then the example thumbnails.
        """
        from workbench.methods.wrinkles.examples import example_poses_for
        from workbench.methods.wrinkles.family import fit_sample_wrinkles

        self.flush()
        self.error_line.value = ""
        model = self._model
        poses, skipped = example_poses_for(model.shape_names)
        total, done = max(len(poses), 1), [0]
        t0 = time.perf_counter()
        self.fit_button.disabled = True
        try:
            self.progress_row(0.02, "preparing the procedural sculptor (operators of the mesh) ...")
            sculptor = self.sculptor()

            def on_detailed() -> None:
                done[0] += 1
                if done[0] < total:
                    self.progress_row(0.1 + 0.6 * done[0] / total,
                                   f"sculpting example pose {done[0] + 1} of {total} ...")
                else:
                    self.progress_row(0.72, "fitting WPSD (details in local frames, per-vertex RBF weights) ...")

            sculptor.on_detailed = on_detailed
            try:
                self.progress_row(0.1, f"sculpting example pose 1 of {total} ...")
                wrinkles = fit_sample_wrinkles(model, sculptor=sculptor)
            finally:
                sculptor.on_detailed = None
            self.last_fit_s = time.perf_counter() - t0
            self.progress_row(0.8, "preparing the first drag (shell basis, detail kernels) ...")
            wrinkles.prepare()
            self.progress_row(0.85, "rendering the example thumbnails ...")
            self._refresh()
            self.progress_row(1.0, "")
        except BaseException:
            self.progress_row.fail("fit failed (see the error below)")
            raise
        finally:
            self.fit_button.disabled = False
        note = f"fitted in {self.last_fit_s:.1f} s"
        if skipped:
            note += " (" + "; ".join(f"{k}: {html.escape(v)}" for k, v in skipped.items()) + ")"
        self._update_status(note)
        return wrinkles

    def view_example(self, name: str) -> None:
        """Set the weights of example ``name`` on the model (others 0), one undo step."""
        w = self._require_fit("view example")
        if name not in w.example_names:
            raise KeyError(f"view example: no example {name!r}; have {w.example_names}")
        self.flush()
        weights = dict.fromkeys(self._model.shape_names, 0.0)
        weights.update(w.example_weights[w.example_names.index(name)])
        self._model.set_weights(weights, label=f"View example {name}")
        self.example.value = name
        note = f"viewing <b>{name}</b>"
        if np.any(self._model.handles.offsets):
            note += " (on top of the current handle offsets: <i>Reset offsets</i> shows it exactly)"
        self._update_status(note)

    def scale_example(self, name: str, scale: float) -> None:
        """Multiply example ``name``'s wrinkles by ``scale`` and refit (propagates to nearby poses)."""
        w = self._require_fit("scale wrinkles")
        if not name:
            raise ValueError("scale wrinkles: choose an example first")
        s = float(scale)
        if not (math.isfinite(s) and s >= 0):
            raise ValueError(f"scale wrinkles: the factor must be a finite number >= 0, got {scale!r}")
        self.flush()
        w.edit_example(name, scale=s)
        self._update_status(f"<b>{name}</b> wrinkles ×{s:g}")

    def add_current_pose(self, name: str) -> None:
        """Add the current blend weights as example ``name`` and refit (``model.wrinkles.add_example``).

        The detailed mesh is the procedural sculptor's wrinkles for those
        weights (the sample head has no scans); the earlier examples keep their
        current (possibly scaled or erased) details. Handle offsets are not part
        of an example (examples are blend-weight poses): bake them to a shape first.
        """
        w = self._require_fit("add example pose")
        model = self._model
        name = (name or "").strip()
        if not name:
            raise ValueError("add example pose: type a name for the new example")
        if np.any(model.handles.offsets):
            raise ValueError(
                "add example pose: the handles have offsets; examples are blend-weight poses, so "
                "bake the handle edit to a shape first (Sculpt: Bake to shape), then add the pose"
            )
        weights = {k: float(v) for k, v in model.weights.items() if v != 0.0}
        if not weights:
            raise ValueError("add example pose: all weights are 0 (the rest pose); set an expression first")
        self.flush()
        t0 = time.perf_counter()
        self.progress_row(0.1, f"sculpting {name} ...")
        try:
            detailed = self.sculptor().detailed(weights)
            self.progress_row(0.5, f"refitting with {len(w.example_names) + 1} examples ...")
            w.add_example(name, weights, detailed)
        finally:
            self.progress_row(1.0, "")
        self.new_name.value = next_free_name(name, w.example_names)
        self._update_status(f"added <b>{name}</b>, refitted in {time.perf_counter() - t0:.1f} s")

    # ---- erasing wrinkles with the brush (the controls: .eraser.EraseControls)
    @property
    def eraser(self) -> WrinkleEraser | None:
        """The stroke handler while an example's *Erase* toggle is on."""
        return self._erase.eraser

    @property
    def erasing(self) -> str | None:
        """The example whose wrinkles brush strokes erase, or None."""
        return self._erase.erasing

    @property
    def erase_toggles(self) -> dict[str, W.ToggleButton]:
        return self._erase.toggles

    def eraser_brush(self) -> Any:
        """The eraser's :class:`~workbench.methods.paint.painting.Brush`: the panel's radius and
        strength, the viewport's falloff and x-mirror."""
        from workbench.methods.paint.painting import Brush

        vp = self.viewport
        return Brush(
            radius=float(self.erase_radius.value),
            opacity=float(self.erase_strength.value),
            falloff=getattr(vp, "brush_falloff", "smooth"),
            mirror=bool(getattr(vp, "brush_mirror", False)),
        )

    def start_erasing(self, name: str) -> WrinkleEraser:
        """Make brush strokes in the viewport erase example ``name``'s wrinkles.

        Switches the viewport to its paint tool with a :class:`WrinkleEraser` as
        stroke handler (the previous tool comes back with :meth:`stop_erasing`).
        Each stroke is one undo step. The face keeps its pose: view the example
        (click its name) to see the wrinkles you erase.
        """
        w = self._require_fit("erase wrinkles")
        if name not in w.example_names:
            raise KeyError(f"erase wrinkles: no example {name!r}; have {w.example_names}")
        if self.erasing != name:
            self.flush()
        return self._erase.start(name)

    def stop_erasing(self) -> None:
        """Back to the previous viewport tool; brush strokes paint expressions again."""
        self._erase.stop()

    def erase_wrinkles(self, name: str, mask: Any) -> bool:
        """Paint example ``name``'s wrinkles out where ``mask`` (n,) is 1 (0 keeps them).

        ``model.wrinkles.edit_example(name, mask=mask)``: one undo step (what an
        eraser stroke does on release); the change propagates to every pose
        near the example. False when ``mask`` is all 0 (no step).
        """
        w = self._require_fit("erase wrinkles")
        n = self._model.n_vertices
        m = np.clip(np.asarray(mask, np.float64).reshape(n), 0.0, 1.0)
        if not np.any(m > 0):
            return False
        self.flush()
        before = w.pose_space
        if w.edit_example(name, mask=m) is before:
            return False
        self._update_status(f"erased <b>{name}</b> wrinkles on {np.count_nonzero(m) / n:.1%} of the vertices")
        return True

    def _on_rest(self, _b: Any = None) -> None:
        self.flush()
        self._model.reset_weights()

    def _on_enabled(self, change: dict) -> None:
        w = self._model.wrinkles
        if not w.fitted or bool(change["new"]) == w.enabled:
            return  # the model's own value coming back (or nothing to switch yet)
        self.flush()
        w.set_enabled(change["new"])

    def _on_strength(self, change: dict) -> None:
        w = self._model.wrinkles
        if not w.fitted or float(change["new"]) == w.strength:
            return
        self.flush()
        w.set_strength(change["new"])

    def _show_error(self, text: str) -> None:
        self.error_line.value = f"<span style='color:#b00'>⚠ {html.escape(text)}</span>"

    # ------------------------------------------------------- model -> UI
    def _on_wrinkles(self) -> None:
        if self._model.wrinkles.pose_space is not self._seen:
            self._refresh()  # fitted, edited, an example added, undone, ...
        else:
            self._sync_controls()

    def _on_deformed(self, final: bool = True) -> None:
        if self._model.wrinkles.pose_space is not self._seen:
            self._refresh()
            return
        self._sync_graph()
        self._sync_controls()
        # At most 4 status updates a second while dragging (each is a comm message); the
        # detail magnitude only after drags and panel actions.
        if final or time.monotonic() - self._last_status_t > 0.25:
            self._update_status(detail=False)

    def _on_drag_end(self, stats: dict[str, Any]) -> None:
        self._update_status()

    def _sync_controls(self) -> None:
        w = self._model.wrinkles
        fitted = w.fitted
        self.controls.layout.display = "" if fitted else "none"
        self.fit_button.description = "Refit from examples" if fitted else "Fit wrinkles from examples"
        self.fit_button.tooltip = (
            "Fit again from the procedural examples (an undo step: Undo brings the current fit back)"
            if fitted
            else "Default handles if none, six procedural detailed expressions, WPSD fit (a few seconds)"
        )
        # Handlers ignore values equal to the model's: no feedback loop, no flag.
        if self.enabled.value != w.enabled:
            self.enabled.value = w.enabled
        s = float(w.strength)
        if abs(self.strength.value - s) > 1e-12 and 0.0 <= s <= STRENGTH_MAX:
            self.strength.value = s

    def _sync_graph(self) -> None:
        """Feature-graph edges (when the fit or the handle set changed) and strain to the viewport."""
        vp = self.viewport
        if vp is None:
            return
        w = self._model.wrinkles
        if not w.fresh:
            if self._graph_sent is not None:
                vp.set_feature_graph(None)
                self._graph_sent = None
            return
        pairs = w.feature_edges
        graph = w.graph
        if self._graph_sent is None or self._graph_sent[0] is not graph or self._graph_sent[1] != pairs.tobytes():
            vp.set_feature_graph(pairs)
            self._graph_sent = (graph, pairs.tobytes())
        strain = w.strain()
        if strain is not None:
            vp.set_feature_strain(strain)

    def _refresh(self) -> None:
        """Rebuild the example cards and the dropdown from ``model.wrinkles``."""
        w = self._model.wrinkles
        self._sync_controls()
        if self.eraser is not None and self.eraser.example not in w.example_names:
            self.stop_erasing()
        self._seen = w.pose_space
        self._cards.update()
        names = list(w.example_names)
        current = self.example.value
        self.example.options = names
        self.example.value = current if current in names else names[0] if names else None
        if names and (self.new_name.value.strip() in names or not self.new_name.value.strip()):
            self.new_name.value = next_free_name("pose_1", names)
        self._sync_graph()
        self._update_status(detail=False)

    def _update_status(self, note: str = "", *, detail: bool = True) -> None:
        self._last_status_t = time.monotonic()
        model = self._model
        w = model.wrinkles
        if not w.fitted:
            parts = ["not fitted: press <i>Fit wrinkles from examples</i>"]
            if not len(model.handles):
                parts.append("(default handles are set first)")
        elif not w.fresh:
            parts = ["<b style='color:#b60'>the handles changed since the fit</b>: press <i>Refit</i>"]
        else:
            parts = [f"<b>{len(w.example_names)}</b> examples, <b>{len(w.graph)}</b> feature edges",
                     f"strength {w.strength:.2f}" if w.enabled else "wrinkles off"]
            f = w.strain()
            if f is not None and len(f) and np.abs(f).max() >= 0.005:
                lo, hi = round(100 * float(np.min(f))), round(100 * float(np.max(f)))
                parts.append(f"strain {lo:+d}% … {hi:+d}%")
            elif f is not None:
                parts.append("at rest (no strain)")
            if detail and w.enabled and w.strength:
                d = w.details()
                mm = 0.0 if d is None else float(np.abs(d).max()) * 1e3 * model.metadata.metres_per_unit
                parts.append(f"max detail {mm:.2f} mm")
        if note:
            parts.append(note)
        self.status.value = " · ".join(parts)
