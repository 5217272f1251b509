"""``WrinklePanel``: pose-space wrinkles while dragging handles (Bickel et al. 2008, §5–6).

The core (:mod:`workbench.methods.wrinkles.layer`) learns fine-scale detail from a few
*detailed example poses* as a function of the strain of a feature graph
between the handles, and adds it on top of the large-scale shell deformation
(§4) on every :meth:`~workbench.FaceModel.evaluate`. This panel is its view, in
the Sculpt tab under the handle controls:

* **Fit wrinkles from examples**: :func:`workbench.methods.wrinkles.layer.fit_sample_wrinkles`
  (default handles if the model has none, six procedural detailed expressions
  from :mod:`workbench.methods.wrinkles.examples`, WPSD fit, layer attached) with a
  progress bar; errors go to the panel's error line and the shared error Output.
* **Wrinkles** on/off and **strength** (0–2): undoable (one history command
  each, see :func:`set_wrinkle_strength`); the strength applies on release.
* **Feature graph**: the edges between handles drawn in the viewport, coloured
  by strain while dragging (blue compressed, grey rest, red stretched;
  :meth:`widgets.Viewport.set_feature_strain`).
* **Example poses**: one card per example (a small pyvista render of the
  example's detailed mesh, grooves tinted, and its name). Clicking the name
  *views* the example (sets its weights on the model, one undo step). **Scale
  wrinkles** multiplies the chosen example's details
  (:meth:`~workbench.methods.wrinkles.layer.WrinkleLayer.edit_example`; the change
  propagates to every pose near it). **Erase wrinkles** (a toggle on each
  card) paints the example's wrinkles out with the brush: while it is on, the
  viewport's paint tool sends its strokes to a :class:`WrinkleEraser` (the
  viewport's stroke hook, :meth:`widgets.Viewport.set_stroke_handler`) instead
  of the paint layers; the stroke's mask is tinted magenta while painting and
  on release becomes ``edit_example(example, mask=...)``: one undo step per
  stroke. **Add current pose** adds the current blend weights as a new example
  (the procedural sculptor's detailed mesh for those weights) and refits,
  keeping earlier scale and erase edits.

Like the other panels it keeps no model state of its own: it changes the
model and the layer only through their methods and follows
``model.events``. Scale and erase edits are undoable (:func:`edit_wrinkle_example`;
undo puts the layer's previous pose space back); fits are not (a refit makes
earlier example edits' undo steps no-ops). Edits made by calling
``layer.edit_example`` directly are not recorded.
"""

from __future__ import annotations

import hashlib
import math
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import ipywidgets as W
import numpy as np
import traitlets as t
from numpy.typing import NDArray

from widgets._threading import ErrorSink, close_interactions

__all__ = [
    "WrinkleEraser",
    "WrinklePanel",
    "edit_wrinkle_example",
    "example_detailed",
    "example_thumbnail",
    "set_wrinkle_strength",
    "set_wrinkles_enabled",
]

#: strength slider range
STRENGTH_MAX = 2.0
#: scale slider range for "Scale wrinkles"
SCALE_MAX = 3.0
#: thumbnail size in pixels
THUMB_SIZE = (96, 96)
#: groove depth (as a fraction of the face height) tinted in full colour in thumbnails
_TINT_DEPTH = 0.003
_GROOVE = np.array([0.32, 0.2, 0.66])  # violet: furrow
_CREST = np.array([1.0, 0.95, 0.88])  # pale: the skin bulging between furrows

_HELP = (
    "<div style='line-height:1.35'><b>Pose-space wrinkles</b> (Bickel et al. 2008, §5–6): "
    "fine detail learned from detailed example poses as a function of the skin strain "
    "between handles, added on top of the shell while you drag. Drag a brow marker up: "
    "the forehead furrows. Edges of the feature graph show the strain "
    "(<span style='color:#2a6bff'>blue</span> compressed, grey rest, "
    "<span style='color:#e52a1f'>red</span> stretched).</div>"
)


# --------------------------------------------------------------------------- undoable edits


def _record(
    model: Any,
    label: str,
    undo: Callable[[], None],
    redo: Callable[[], None],
    nbytes: int = 64,
) -> None:
    """Push an already-applied edit onto the model's undo history (one step)."""
    from workbench.core.history import Command

    model.history.push(Command(label, undo, redo, nbytes))
    model.events.history.emit()


def set_wrinkle_strength(model: Any, layer: Any, strength: float) -> bool:
    """Set the wrinkle layer's strength as one undoable step of ``model``.

    Parameters
    ----------
    model : workbench.FaceModel
        The model the layer is attached to (its history records the step).
    layer : workbench.methods.wrinkles.layer.WrinkleLayer
    strength : float
        ``>= 0``; 1 = as learned.

    Returns
    -------
    bool
        False when the strength was already ``strength`` (nothing recorded).
    """
    new = float(strength)
    if not (math.isfinite(new) and new >= 0.0):
        raise ValueError(f"wrinkle strength must be a finite number >= 0, got {strength!r}")
    with model.lock:
        old = float(layer.strength)
        if new == old:
            return False
        layer.set_strength(new)
        _record(
            model,
            f"Wrinkle strength {new:g}",
            lambda: layer.set_strength(old),
            lambda: layer.set_strength(new),
        )
        return True


def set_wrinkles_enabled(model: Any, layer: Any, enabled: bool) -> bool:
    """Switch the wrinkle layer on or off as one undoable step of ``model``.

    Returns False when it already was (nothing recorded).
    """
    new = bool(enabled)
    with model.lock:
        old = bool(layer.enabled)
        if new == old:
            return False
        layer.set_enabled(new)
        _record(
            model,
            f"Wrinkles {'on' if new else 'off'}",
            lambda: layer.set_enabled(old),
            lambda: layer.set_enabled(new),
        )
        return True


def _fit_key(layer: Any) -> tuple[Any, list[str]]:
    """What identifies one fit of the layer (a refit makes a new feature graph or examples)."""
    return layer.graph, list(layer.example_names)


def _restore_pose_space(model: Any, layer: Any, ps: Any, fit_key: tuple[Any, list[str]]) -> None:
    """Undo / redo of an example edit: put the pose space ``ps`` of the same fit back."""
    if layer.graph is not fit_key[0] or list(layer.example_names) != fit_key[1]:
        return  # refitted since: the edits of the earlier fit no longer apply
    if layer.pose_space is ps:
        return
    # WrinkleLayer has no public setter for its pose space (core: a `set_pose_space`
    # would do); _set_pose_space rebuilds the detail evaluator for it.
    layer._set_pose_space(ps, model)
    layer.set_enabled(layer.enabled)  # public: drops the cached evaluate, tells the views


def _nbytes(ps: Any) -> int:
    return int(sum(getattr(getattr(ps, k, None), "nbytes", 0) for k in ("weights", "train_values")))


def edit_wrinkle_example(
    model: Any,
    layer: Any,
    example: str,
    *,
    scale: float | NDArray[np.float64] = 1.0,
    mask: NDArray[np.float64] | None = None,
    label: str | None = None,
) -> None:
    """:meth:`WrinkleLayer.edit_example` as one undoable step of ``model``.

    Undo puts the layer's previous pose space back (bit-exact, no refit); undo
    and redo do nothing once the layer was refitted.
    """
    with model.lock:
        key, old = _fit_key(layer), layer.pose_space
        layer.edit_example(example, scale=scale, mask=mask)
        new = layer.pose_space
        _record(
            model,
            label or f"Edit wrinkles {example}",
            lambda: _restore_pose_space(model, layer, old, key),
            lambda: _restore_pose_space(model, layer, new, key),
            _nbytes(new),  # the pose space this step adds (the old one is the step before's)
        )


# --------------------------------------------------------------------------- examples


def _blend(model: Any, weights: Mapping[str, float]) -> NDArray[np.float64]:
    """``neutral + Σ w_k δ_k`` for the named weights (others 0), (n, 3) float64."""
    X = np.array(model.vertices, dtype=np.float64)
    for name, w in weights.items():
        shape = model.shape(name)
        if w and not shape.mute:
            X += float(w) * shape.effective_delta()
    return X


def example_detailed(
    model: Any, layer: Any, example: str | int, neighbours: NDArray[np.int32] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The large-scale and the detailed mesh of one fitted example, as the layer stores it now.

    The layer keeps each example's details in local frames of its blend
    (``R_vᵀ (detailed − blend)``, after any :meth:`edit_example`); this puts them
    back on the blend: ``detailed = blend + R_v d_v``.

    Parameters
    ----------
    model : workbench.FaceModel
    layer : workbench.methods.wrinkles.layer.WrinkleLayer
        Fitted.
    example : name or index
    neighbours : (n,) int, optional
        :func:`workbench.methods.wrinkles.pose_space.tangent_neighbours` of the mesh (computed if omitted).

    Returns
    -------
    blend, detailed : (n, 3) float64
    """
    from workbench.methods.wrinkles.pose_space import local_frames, tangent_neighbours, to_world

    if layer.pose_space is None:
        raise RuntimeError("example_detailed: the wrinkle layer is not fitted")
    j = layer.example_names.index(example) if isinstance(example, str) else int(example)
    nb = tangent_neighbours(model.faces, model.n_vertices) if neighbours is None else neighbours
    X = _blend(model, layer.example_weights[j])
    D = X + to_world(local_frames(X, model.faces, nb), layer.pose_space.train_values[j])
    return X, D


def example_thumbnail(
    model: Any,
    blend: NDArray[np.float64],
    detailed: NDArray[np.float64],
    size: tuple[int, int] = THUMB_SIZE,
    scene: Any = None,
) -> bytes:
    """PNG of a detailed example: shaded, grooves tinted violet (wrinkles are sub-pixel at 96 px).

    ``scene`` (a ``widgets.render._Scene`` built for ``model`` with RGB scalars)
    renders without building a plotter; default: :func:`widgets.render.render_png`.
    """
    from widgets.render import _model_axes, render_png, vertex_colors
    from widgets.viewport import face_height
    from workbench.methods.wrinkles.pose_space import vertex_normals

    _, front = _model_axes(model)
    base = vertex_colors(model, front).astype(np.float64) / 255.0
    h = np.sum((detailed - blend) * vertex_normals(blend, model.faces), axis=1)
    a = np.clip(np.abs(h) / (_TINT_DEPTH * face_height(model)), 0.0, 1.0)[:, None] * 0.85
    tint = np.where(h[:, None] < 0, _GROOVE, _CREST)
    rgb = np.clip((base * (1 - a) + a * tint) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if scene is None:
        return render_png(model, points=detailed, scalars=rgb, size=size, camera="face")
    scene.mesh.point_data["rgb"] = rgb
    scene.set_points(detailed)
    return bytes(scene.png())


def _warm_up(model: Any, layer: Any) -> None:
    """Build the shell basis and load the compiled detail kernels now, not on the first drag.

    The first evaluation of the layer in a fresh kernel loads numba's cached
    machine code (or compiles it: seconds); the first drag of a new handle set
    factorises the shell. Both used to swallow the first drag (one 2 s update).
    """
    model.prepare_handles()
    if not (layer.enabled and layer.strength and layer.fitted):
        return
    stretched = np.float32(1.01)  # 1 % stretch of every feature edge: non-zero strain
    X = np.asarray(layer.large_scale(model), np.float32) * stretched
    layer.details(model, X)
    layer.details(model)  # the real state again (its strain is what the views show)


# --------------------------------------------------------------------------- eraser


class WrinkleEraser:
    """Stroke handler that paints one example's wrinkles out (the viewport's stroke hook).

    :class:`WrinklePanel` installs it with :meth:`widgets.Viewport.set_stroke_handler`
    while an example's *Erase wrinkles* toggle is on: the viewport's paint tool
    (raycast, brush cursor, dab spacing) then sends its strokes here. Each dab
    adds the brush footprint (surface distance on the rest mesh, the brush's
    falloff, x-mirror) to the stroke's mask, keeping the largest strength any
    dab gave a vertex (as a paint stroke caps at its opacity); release applies
    the mask with :meth:`WrinklePanel.erase_wrinkles`: one undo step per
    stroke. Usable without a viewport (tests call :meth:`begin` / :meth:`dab` /
    :meth:`end`).

    Parameters
    ----------
    panel : WrinklePanel
    example : str
        The example whose wrinkles the strokes erase.

    Attributes
    ----------
    last_mask : (n,) float32 or None
        The mask of the last applied stroke.
    """

    def __init__(self, panel: WrinklePanel, example: str) -> None:
        self.panel = panel
        self.example = example
        self.last_mask: NDArray[np.float32] | None = None
        self._mask: NDArray[np.float32] | None = None
        self._overlay: NDArray[np.float32] | None = None
        self._brush: Any = None

    @property
    def stroking(self) -> bool:
        """True between :meth:`begin` and :meth:`end` / :meth:`cancel`."""
        return self._mask is not None

    def begin(self) -> None:
        """Start a stroke with the panel's eraser brush."""
        self._brush = self.panel.eraser_brush()
        self._mask = np.zeros(self.panel.model.n_vertices, np.float32)
        self._overlay = None

    def dab(self, vertices: Any) -> None:
        """Brush dabs centred at vertex ids ``vertices`` (int or sequence)."""
        from workbench.methods.paint.painting import falloff_curve

        mask, brush = self._mask, self._brush
        if mask is None:
            raise RuntimeError("WrinkleEraser.dab: no stroke open (begin first)")
        ids = np.asarray(vertices, np.int64).reshape(-1)
        if ids.size and (ids.min() < 0 or ids.max() >= mask.shape[0]):
            raise ValueError(f"WrinkleEraser.dab: vertex ids must be in 0..{mask.shape[0] - 1}")
        surface = self.panel.model.paint_surface
        for c in ids:
            centres = [int(c)]
            if brush.mirror and surface.mirror[c] != c:
                centres.append(int(surface.mirror[c]))
            for cc in centres:
                near, dist = surface.within(cc, brush.radius)
                st = (brush.opacity * falloff_curve(dist / brush.radius, brush.falloff)).astype(
                    np.float32
                )
                mask[near] = np.maximum(mask[near], st)
        if ids.size:
            self._overlay = mask.copy()  # a new array: the viewport sends what changed

    def overlay(self) -> NDArray[np.float32] | None:
        """The open stroke's mask so far (the viewport tints it), or None."""
        return self._overlay

    def end(self) -> bool:
        """Apply the stroke's mask (one undo step); False when it erased nothing."""
        mask = self._mask
        self._mask, self._overlay = None, None
        if mask is None or not np.any(mask > 0):
            return False
        self.last_mask = mask
        return self.panel.erase_wrinkles(self.example, mask)

    def cancel(self) -> None:
        """Drop the open stroke without changing anything."""
        self._mask, self._overlay = None, None


# --------------------------------------------------------------------------- the panel


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


class WrinklePanel(W.VBox):
    """Controls of the pose-space wrinkle layer of a FaceModel (Sculpt tab).

    Parameters
    ----------
    model : workbench.FaceModel
    viewport : widgets.Viewport, optional
        Draws the feature graph coloured by strain; its ``feature_graph`` trait
        follows the panel's checkbox.
    layer : workbench.methods.wrinkles.layer.WrinkleLayer, optional
        An already fitted (and attached) layer; default none until **Fit**.
    errors : ipywidgets.Output, optional
        Where callback errors are shown (``Workbench`` passes a shared one); the
        panel's error line repeats the last one.
    before_edit : iterable of callables
        Called before model edits (e.g. to close another panel's slider interaction).
    thumbnails : bool
        Render a small picture per example (~0.1 s each with one plotter).

    Attributes
    ----------
    layer : WrinkleLayer or None
    last_fit_s : float
        Seconds the last fit took (thumbnails excluded).
    eraser : WrinkleEraser or None
        The stroke handler while an example's *Erase wrinkles* toggle is on.
    erase_toggles : dict of str -> ipywidgets.ToggleButton
        The *Erase wrinkles* toggle of each example card.
    """

    def __init__(
        self,
        model: Any,
        viewport: Any = None,
        *,
        layer: Any = None,
        errors: W.Output | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
        thumbnails: bool = True,
    ) -> None:
        self._model = model
        self.viewport = viewport
        self.layer: Any = None
        self.thumbnails = bool(thumbnails)
        self.errors = ErrorSink(errors, on_error=self._show_error)
        self._before_edit = list(before_edit)
        if viewport is not None:
            self._before_edit.append(viewport.end_drag)
        self._lock = threading.RLock()
        self._sculptor: Any = None
        self._sculptor_shapes: Any = None
        self._neighbours: NDArray[np.int32] | None = None
        self._seen_pose_space: Any = None
        self._graph_sent: tuple[Any, bytes] | None = None
        self._fitted_norms: dict[str, float] = {}
        self._thumb_cache: dict[str, tuple[str, bytes]] = {}
        self._last_status_t = 0.0
        self.last_fit_s = math.nan
        self._links: list[Any] = []
        self.eraser: WrinkleEraser | None = None
        self.erase_toggles: dict[str, W.ToggleButton] = {}
        self._tool_before_erase: str | None = None

        def button(desc: str, cls: str, tip: str, icon: str = "", width: str = "auto") -> W.Button:
            b = W.Button(description=desc, tooltip=tip, icon=icon, layout=W.Layout(width=width))
            b.add_class(cls)
            return b

        self.fit_button = button(
            "Fit wrinkles from examples",
            "fwb-wrinkle-fit",
            "Default handles if none, six procedural detailed expressions, WPSD fit (a few seconds)",
            icon="magic",
        )
        self.progress = W.FloatProgress(
            value=0.0,
            min=0.0,
            max=1.0,
            bar_style="info",
            layout=W.Layout(width="98%", visibility="hidden"),
        )
        self.progress.add_class("fwb-wrinkle-progress")
        self.progress_label = W.HTML("")
        self.progress_label.add_class("fwb-wrinkle-progress-label")
        self.enabled = W.Checkbox(
            value=True, description="Wrinkles", indent=False, layout=W.Layout(width="110px")
        )
        self.enabled.add_class("fwb-wrinkles-on")
        self.strength = W.FloatSlider(
            value=1.0,
            min=0.0,
            max=STRENGTH_MAX,
            step=0.05,
            description="strength",
            continuous_update=False,  # one undo step per release
            readout_format=".2f",
            style={"description_width": "60px"},
            layout=W.Layout(width="320px"),
        )
        self.strength.add_class("fwb-wrinkle-strength")
        self.show_graph = W.Checkbox(
            value=bool(getattr(viewport, "feature_graph", True)),
            description="feature graph (strain colours)",
            indent=False,
            layout=W.Layout(width="240px"),
        )
        self.show_graph.add_class("fwb-feature-graph")
        self.cards = W.Box(layout=W.Layout(flex_flow="row wrap", width="100%", grid_gap="4px"))
        self.cards.add_class("fwb-wrinkle-examples")
        self.example = W.Dropdown(options=[], description="example", layout=W.Layout(width="230px"))
        self.example.add_class("fwb-wrinkle-example")
        self.scale = W.FloatSlider(
            value=1.0,
            min=0.0,
            max=SCALE_MAX,
            step=0.05,
            description="× ",
            readout_format=".2f",
            style={"description_width": "20px"},
            layout=W.Layout(width="220px"),
        )
        self.scale.add_class("fwb-wrinkle-scale")
        self.scale_button = button(
            "Scale wrinkles",
            "fwb-wrinkle-scale-apply",
            "Multiply this example's details and refit",
            icon="arrows-v",
        )
        self.rest_button = button(
            "Rest pose", "fwb-wrinkle-rest", "Set every weight to 0 (undoable)"
        )
        # ---- eraser brush (shown while an example's "Erase wrinkles" toggle is on)
        from widgets.viewport import brush_radius_slider

        self.erase_radius = brush_radius_slider(
            model,
            viewport,
            "radius",
            style={"description_width": "60px"},
            layout=W.Layout(width="260px"),
        )
        self.erase_radius.add_class("fwb-wrinkle-erase-radius")
        self.erase_strength = W.FloatSlider(
            value=1.0,
            min=0.0,
            max=1.0,
            step=0.05,
            description="strength",
            readout_format=".2f",
            style={"description_width": "60px"},
            layout=W.Layout(width="220px"),
        )
        self.erase_strength.add_class("fwb-wrinkle-erase-strength")
        self.erase_note = W.HTML("")
        self.erase_note.add_class("fwb-wrinkle-erase-note")
        self.erase_box = W.VBox(
            [
                self.erase_note,
                W.HBox(
                    [self.erase_radius, self.erase_strength],
                    layout=W.Layout(flex_flow="row wrap"),
                ),
            ],
            layout=W.Layout(display="none", border="1px solid #c6c", padding="2px"),
        )
        self.erase_box.add_class("fwb-wrinkle-erase-box")
        self.new_name = W.Text(
            value="pose_1", placeholder="example name", layout=W.Layout(width="140px")
        )
        self.new_name.add_class("fwb-wrinkle-new-name")
        self.add_button = button(
            "Add current pose as example",
            "fwb-wrinkle-add",
            "The current blend weights + their procedurally sculpted wrinkles become an example; refit",
            icon="plus",
        )
        self.status = W.HTML("")
        self.status.add_class("fwb-wrinkle-status")
        self.error_line = W.HTML("")
        self.error_line.add_class("fwb-wrinkle-error")
        self.controls = W.VBox(
            [
                W.HBox([self.enabled, self.strength], layout=W.Layout(align_items="center")),
                self.show_graph,
                W.HTML(
                    "<b>Example poses</b> (click a name to view it; <i>Erase wrinkles</i> "
                    "paints that example's wrinkles out with the brush)"
                ),
                self.cards,
                self.erase_box,
                W.HBox(
                    [self.example, self.scale, self.scale_button],
                    layout=W.Layout(flex_flow="row wrap"),
                ),
                W.HBox(
                    [self.new_name, self.add_button, self.rest_button],
                    layout=W.Layout(flex_flow="row wrap"),
                ),
            ]
        )
        rows = [
            W.HTML(_HELP),
            self.fit_button,
            self.progress,
            self.progress_label,
            self.controls,
            self.status,
            self.error_line,
        ]
        super().__init__(rows, layout=W.Layout(width="100%", min_width="380px"))
        self.add_class("fwb-wrinkle-panel")

        g = self.errors.guard
        self.fit_button.on_click(g("fit wrinkles")(lambda _b: self.fit()))
        self.scale_button.on_click(
            g("scale wrinkles")(lambda _b: self.scale_example(self.example.value, self.scale.value))
        )
        self.add_button.on_click(
            g("add example pose")(lambda _b: self.add_current_pose(self.new_name.value))
        )
        self.rest_button.on_click(g("rest pose")(self._on_rest))
        self.enabled.observe(g("wrinkles on/off")(self._on_enabled), "value")
        self.strength.observe(g("wrinkle strength")(self._on_strength), "value")
        if viewport is not None:
            self._links = [
                t.link((self.show_graph, "value"), (viewport, "feature_graph")),
                t.link((self.erase_radius, "value"), (viewport, "brush_radius")),
            ]
            self._cb_tool = g("WrinklePanel tool")(self._on_tool)
            viewport.observe(self._cb_tool, "tool")
        self._cb_deformed = g("WrinklePanel update")(self._on_deformed)
        self._cb_handles = g("WrinklePanel handles")(self._on_handles)
        self._cb_drag = g("WrinklePanel drag stats")(self._on_drag_end)
        if viewport is not None:
            viewport.drag_listeners.append(self._cb_drag)
        model.events.deformed.connect(self._cb_deformed)
        model.events.handles.connect(self._cb_handles)
        self._connected = True
        if layer is not None:
            self.adopt(layer)
        else:
            self._refresh()

    @property
    def model(self) -> Any:
        return self._model

    # ------------------------------------------------------- actions (UI -> model)
    def _flush(self) -> None:
        close_interactions(self._model)
        for fn in self._before_edit:
            fn()

    def _require_layer(self, what: str) -> Any:
        if self.layer is None or not self.layer.fitted:
            raise RuntimeError(f"{what}: press 'Fit wrinkles from examples' first")
        return self.layer

    def fit(self) -> Any:
        """Fit the wrinkle layer to the procedural example poses (refit if fitted).

        Calls :func:`workbench.methods.wrinkles.layer.fit_sample_wrinkles` (which sets the
        default handles first if the model has none) with a progress bar, then
        renders the example thumbnails. Returns the fitted layer.
        """
        from workbench.methods.wrinkles.examples import EXAMPLE_POSES
        from workbench.methods.wrinkles.layer import fit_sample_wrinkles

        self._flush()
        self.error_line.value = ""
        model = self._model
        total = len(EXAMPLE_POSES)
        done = [0]
        t0 = time.perf_counter()
        self.fit_button.disabled = True
        try:
            self._progress(0.02, "preparing the procedural sculptor (operators of the mesh) ...")
            sculptor = self.sculptor()

            def on_detailed() -> None:
                done[0] += 1
                if done[0] < total:
                    self._progress(
                        0.1 + 0.6 * done[0] / total,
                        f"sculpting example pose {done[0] + 1} of {total} ...",
                    )
                else:
                    self._progress(
                        0.72, "fitting WPSD (details in local frames, per-vertex RBF weights) ..."
                    )

            sculptor.on_detailed = on_detailed
            try:
                self._progress(0.1, f"sculpting example pose 1 of {total} ...")
                layer = fit_sample_wrinkles(model, layer=self.layer, sculptor=sculptor)
            finally:
                sculptor.on_detailed = None
            self.last_fit_s = time.perf_counter() - t0
            self._progress(0.8, "preparing the first drag (shell basis, detail kernels) ...")
            _warm_up(model, layer)
            # attach() does not notify views: re-announce the layer (a posed face gets wrinkles now)
            layer.set_enabled(layer.enabled)
            self._fitted_norms = {}
            self._progress(0.85, "rendering the example thumbnails ...")
            self.adopt(layer)
            self._progress(1.0, "")
        except BaseException:
            self.progress.bar_style = "danger"
            self.progress_label.value = (
                "<span style='color:#b00'>fit failed (see the error below)</span>"
            )
            raise
        finally:
            self.fit_button.disabled = False
        self._update_status(f"fitted in {self.last_fit_s:.1f} s")
        return layer

    def adopt(self, layer: Any) -> None:
        """Show (and drive) ``layer``: a fitted WrinkleLayer attached to the model."""
        with self._lock:
            self.layer = layer
            self._seen_pose_space = None
        self._refresh()

    def view_example(self, name: str) -> None:
        """Set the weights of example ``name`` on the model (others 0), one undo step."""
        layer = self._require_layer("view example")
        j = layer.example_names.index(name)
        self._flush()
        w = {k: 0.0 for k in self._model.shape_names}
        w.update(layer.example_weights[j])
        self._model.set_weights(w, label=f"View example {name}")
        self.example.value = name
        note = f"viewing <b>{name}</b>"
        if np.any(self._model.handles.offsets):
            note += " (on top of the current handle offsets: <i>Reset offsets</i> shows it exactly)"
        self._update_status(note)

    def scale_example(self, name: str, scale: float) -> None:
        """Multiply example ``name``'s wrinkles by ``scale`` and refit (propagates to nearby poses)."""
        layer = self._require_layer("scale wrinkles")
        if not name:
            raise ValueError("scale wrinkles: choose an example first")
        s = float(scale)
        if not (math.isfinite(s) and s >= 0):
            raise ValueError(
                f"scale wrinkles: the factor must be a finite number >= 0, got {scale!r}"
            )
        self._flush()
        edit_wrinkle_example(
            self._model, layer, name, scale=s, label=f"Scale wrinkles {name} ×{s:g}"
        )
        self._refresh()
        self._update_status(f"<b>{name}</b> wrinkles ×{s:g}")

    # ---- erasing wrinkles with the brush
    @property
    def erasing(self) -> str | None:
        """The example whose wrinkles brush strokes erase, or None."""
        return None if self.eraser is None else self.eraser.example

    def eraser_brush(self) -> Any:
        """The eraser's :class:`workbench.methods.paint.painting.Brush`: the panel's radius and strength,
        the viewport's falloff and x-mirror."""
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
        layer = self._require_layer("erase wrinkles")
        if name not in layer.example_names:
            raise KeyError(f"erase wrinkles: no example {name!r}; have {layer.example_names}")
        if self.eraser is not None:
            if self.eraser.example == name:
                return self.eraser
            self.stop_erasing()
        self._flush()
        eraser = WrinkleEraser(self, name)
        self.eraser = eraser  # first: the Workbench keeps the Sculpt tab for this tool change
        vp = self.viewport
        if vp is not None:
            vp.set_stroke_handler(eraser, f"erase {name} wrinkles")
            if vp.tool != "paint":
                self._tool_before_erase = vp.tool
                vp.tool = "paint"
        self._sync_erase_controls()
        return eraser

    def stop_erasing(self) -> None:
        """Back to the previous viewport tool; brush strokes paint expressions again."""
        eraser = self.eraser
        if eraser is None:
            return
        self.eraser = None
        eraser.cancel()
        vp = self.viewport
        if vp is not None:
            if vp.stroke_handler is eraser:
                vp.set_stroke_handler(None)
            before, self._tool_before_erase = self._tool_before_erase, None
            if before is not None and vp.tool == "paint":
                vp.tool = before
        self._sync_erase_controls()

    def erase_wrinkles(self, name: str, mask: Any) -> bool:
        """Paint example ``name``'s wrinkles out where ``mask`` (n,) is 1 (0 keeps them).

        One undo step (what an eraser stroke does on release); the change
        propagates to every pose near the example. False when ``mask`` is all 0.
        """
        layer = self._require_layer("erase wrinkles")
        if name not in layer.example_names:
            raise KeyError(f"erase wrinkles: no example {name!r}; have {layer.example_names}")
        n = self._model.n_vertices
        m = np.clip(np.asarray(mask, np.float64).reshape(n), 0.0, 1.0)
        if not np.any(m > 0):
            return False
        self._flush()
        edit_wrinkle_example(self._model, layer, name, mask=m, label=f"Erase wrinkles {name}")
        self._refresh()
        self._update_status(
            f"erased <b>{name}</b> wrinkles on {np.count_nonzero(m) / n:.1%} of the vertices"
        )
        return True

    def _on_erase_toggle(self, name: str, change: dict) -> None:
        if self._syncing_toggles:
            return
        if change["new"]:
            self.start_erasing(name)
        elif self.erasing == name:
            self.stop_erasing()

    def _on_tool(self, change: dict) -> None:
        # another tool picked (a tab, a cell): the eraser no longer gets strokes
        if self.eraser is not None and change["new"] != "paint":
            self._tool_before_erase = None
            self.stop_erasing()

    _syncing_toggles = False

    def _sync_erase_controls(self) -> None:
        name = self.erasing
        self._syncing_toggles = True
        try:
            for n, tb in self.erase_toggles.items():
                if tb.value != (n == name):
                    tb.value = n == name
        finally:
            self._syncing_toggles = False
        self.erase_box.layout.display = "" if name else "none"
        self.erase_note.value = (
            f"<b>Erasing {name}</b>'s wrinkles: paint on the face (one undo step per stroke). "
            f"Click <i>{name}</i> to view its pose; untoggle to stop."
            if name
            else ""
        )

    def add_current_pose(self, name: str) -> None:
        """Add the current blend weights as example ``name`` and refit.

        The detailed mesh is the procedural sculptor's wrinkles for those
        weights (the sample head has no scans); the earlier examples keep their
        current (possibly scaled) details. Handle offsets are not part of an
        example (examples are blend-weight poses): bake them to a shape first.
        """
        layer = self._require_layer("add example pose")
        model = self._model
        name = (name or "").strip()
        if not name:
            raise ValueError("add example pose: type a name for the new example")
        if name in layer.example_names:
            raise ValueError(f"add example pose: an example named {name!r} exists already")
        if np.any(model.handles.offsets):
            raise ValueError(
                "add example pose: the handles have offsets; examples are blend-weight poses, so "
                "bake the handle edit to a shape first (Sculpt: Bake to shape), then add the pose"
            )
        weights = {k: float(v) for k, v in model.weights.items() if v != 0.0}
        if not weights:
            raise ValueError(
                "add example pose: all weights are 0 (the rest pose); set an expression first"
            )
        for ex, w in zip(layer.example_names, layer.example_weights, strict=True):
            keys = set(w) | set(weights)
            if all(abs(w.get(k, 0.0) - weights.get(k, 0.0)) < 1e-6 for k in keys):
                raise ValueError(
                    f"add example pose: the current weights are those of example {ex!r} already"
                )
        self._flush()
        t0 = time.perf_counter()
        self._progress(0.1, f"sculpting {name} ...")
        try:
            nb = self._tangent_neighbours()
            examples: dict[str, tuple[dict[str, float], Any]] = {}
            for j, ex in enumerate(layer.example_names):
                examples[ex] = (
                    dict(layer.example_weights[j]),
                    example_detailed(model, layer, j, nb)[1],
                )
            examples[name] = (weights, self.sculptor().detailed(weights))
            self._progress(0.5, f"refitting with {len(examples)} examples ...")
            layer.fit(model, examples, graph=layer.graph)
            self._progress(0.85, "rendering the thumbnail ...")
            self._refresh()
        finally:
            self._progress(1.0, "")
        self.new_name.value = _next_name(name, layer.example_names)
        self._update_status(f"added <b>{name}</b>, refitted in {time.perf_counter() - t0:.1f} s")

    def _on_rest(self, _b: Any = None) -> None:
        self._flush()
        self._model.reset_weights()

    def _on_enabled(self, change: dict) -> None:
        layer = self.layer
        if layer is None or bool(change["new"]) == bool(layer.enabled):
            return  # the model's own value coming back (or nothing to switch yet)
        self._flush()
        set_wrinkles_enabled(self._model, layer, change["new"])

    def _on_strength(self, change: dict) -> None:
        layer = self.layer
        if layer is None or float(change["new"]) == float(layer.strength):
            return
        self._flush()
        set_wrinkle_strength(self._model, layer, change["new"])

    # ------------------------------------------------------- helpers
    def sculptor(self) -> Any:
        """The procedural sculptor of the model (rebuilt when the shapes changed)."""
        with self._lock:
            shapes = self._model.shapes
            if self._sculptor is None or self._sculptor_shapes is not shapes:
                self._sculptor = _sculptor_class()(self._model)
                self._sculptor_shapes = shapes
            return self._sculptor

    def _tangent_neighbours(self) -> NDArray[np.int32]:
        from workbench.methods.wrinkles.pose_space import tangent_neighbours

        if self._neighbours is None:
            self._neighbours = tangent_neighbours(self._model.faces, self._model.n_vertices)
        return self._neighbours

    def _progress(self, fraction: float, message: str) -> None:
        done = fraction >= 1.0
        self.progress.bar_style = "info"
        self.progress.value = min(max(float(fraction), 0.0), 1.0)
        self.progress.layout.visibility = "hidden" if done else "visible"
        self.progress_label.value = "" if done else f"<i>{message}</i>"

    def _show_error(self, text: str) -> None:
        import html

        self.error_line.value = f"<span style='color:#b00'>⚠ {html.escape(text)}</span>"

    @property
    def fresh(self) -> bool:
        """True when the layer is fitted for the model's current handle set."""
        layer = self.layer
        if layer is None or not layer.fitted:
            return False
        fitted = getattr(layer, "_handles", None)  # the layer has no public accessor for it
        h = self._model.handles.vertices
        return fitted is not None and fitted.shape == h.shape and bool(np.all(fitted == h))

    def current_strain(self) -> NDArray[np.float64] | None:
        """(F,) strain of the feature graph in the model's current state (None if not fitted/stale)."""
        layer = self.layer
        if not self.fresh:
            return None
        model = self._model
        with model.lock:
            if layer.enabled and layer.strength != 0.0:
                model.evaluate()  # cached; runs the layer, which measures the strain
                if layer.last_strain is not None:
                    return np.asarray(layer.last_strain)
            X = np.asarray(layer.large_scale(model), np.float64)
            return np.asarray(layer.graph.strain(X[model.handles.vertices]))

    # ------------------------------------------------------- model -> UI
    def _on_handles(self) -> None:
        self._sync_graph()

    def _on_deformed(self, final: bool = True) -> None:
        layer = self.layer
        if layer is None:
            return
        if layer.pose_space is not self._seen_pose_space:
            self._refresh()  # refitted or edited from a cell
            return
        self._sync_graph()
        self._sync_controls()
        # At most 4 status updates a second while dragging (each is a comm message); the
        # detail magnitude costs a layer evaluation: only after drags and panel actions.
        if final or time.monotonic() - self._last_status_t > 0.25:
            self._update_status(detail=False)

    def _on_drag_end(self, stats: dict[str, Any]) -> None:
        self._update_status()

    def _sync_controls(self) -> None:
        layer = self.layer
        fitted = layer is not None and layer.fitted
        self.controls.layout.display = "" if fitted else "none"
        self.fit_button.description = (
            "Refit from examples" if fitted else "Fit wrinkles from examples"
        )
        self.fit_button.tooltip = (
            "Fit again from the six procedural examples (discards scale edits and added poses)"
            if fitted
            else "Default handles if none, six procedural detailed expressions, WPSD fit (a few seconds)"
        )
        if layer is None:
            return
        # Handlers ignore values equal to the layer's: no feedback loop, no flag.
        if self.enabled.value != bool(layer.enabled):
            self.enabled.value = bool(layer.enabled)
        s = min(max(float(layer.strength), 0.0), STRENGTH_MAX)
        if abs(self.strength.value - s) > 1e-12 and float(layer.strength) <= STRENGTH_MAX:
            self.strength.value = s

    def _sync_graph(self) -> None:
        """Feature-graph edges (when the fit or the handle set changed) and strain to the viewport."""
        vp = self.viewport
        if vp is None:
            return
        layer = self.layer
        if not self.fresh:
            if self._graph_sent is not None:
                vp.set_feature_graph(None)
                self._graph_sent = None
            return
        pairs = np.asarray(self._model.handles.vertices)[np.asarray(layer.graph.edges)]
        key = (layer.graph, pairs.tobytes())
        if (
            self._graph_sent is None
            or self._graph_sent[0] is not key[0]
            or self._graph_sent[1] != key[1]
        ):
            vp.set_feature_graph(pairs)
            self._graph_sent = key
        strain = self.current_strain()
        if strain is not None:
            vp.set_feature_strain(strain)

    def _refresh(self) -> None:
        """Rebuild the example list (names, thumbnails, dropdown) from the layer."""
        layer = self.layer
        self._sync_controls()
        if self.eraser is not None and (
            layer is None or not layer.fitted or self.eraser.example not in layer.example_names
        ):
            self.stop_erasing()
        if layer is None or not layer.fitted:
            self.cards.children = []
            self.erase_toggles = {}
            self.example.options = []
            self._sync_graph()
            self._update_status(detail=False)
            return
        with self._lock:
            self._seen_pose_space = layer.pose_space
            names = list(layer.example_names)
            values = layer.pose_space.train_values
            norms = {
                n: float(np.sqrt(np.mean(np.square(values[j], dtype=np.float64))))
                for j, n in enumerate(names)
            }
            for n, v in norms.items():
                self._fitted_norms.setdefault(n, v)
            pngs = self._thumbnails(names) if self.thumbnails else {}
        cards = []
        toggles: dict[str, W.ToggleButton] = {}
        for n in names:
            ref = self._fitted_norms.get(n, 0.0)
            factor = norms[n] / ref if ref > 0 else 1.0
            b = W.Button(
                description=n,
                tooltip=f"View {n}: set its weights on the model (undoable)",
                layout=W.Layout(width=f"{THUMB_SIZE[0] + 8}px"),
            )
            b.add_class("fwb-wrinkle-view")
            b.on_click(self.errors.guard(f"view example {n}")(lambda _b, n=n: self.view_example(n)))
            label = W.HTML(
                f"<div style='font-size:11px;text-align:center;color:#555'>detail ×{factor:.2f}</div>",
                layout=W.Layout(width=f"{THUMB_SIZE[0] + 8}px"),
            )
            erase = W.ToggleButton(
                value=self.erasing == n,
                description="Erase",
                icon="eraser",
                tooltip=f"Erase wrinkles with the brush: strokes on the face paint {n}'s "
                "wrinkles out (one undo step per stroke)",
                layout=W.Layout(width=f"{THUMB_SIZE[0] + 8}px"),
            )
            erase.add_class("fwb-wrinkle-erase")
            erase.observe(
                self.errors.guard(f"erase wrinkles {n}")(
                    lambda change, n=n: self._on_erase_toggle(n, change)
                ),
                "value",
            )
            toggles[n] = erase
            parts: list[W.Widget] = [b, erase, label]
            if n in pngs:
                parts.insert(
                    0,
                    W.Image(value=pngs[n], format="png", width=THUMB_SIZE[0], height=THUMB_SIZE[1]),
                )
            card = W.VBox(
                parts, layout=W.Layout(align_items="center", border="1px solid #ddd", padding="2px")
            )
            card.add_class("fwb-wrinkle-card")
            cards.append(card)
        self.cards.children = cards
        self.erase_toggles = toggles
        self._sync_erase_controls()
        current = self.example.value
        self.example.options = names
        self.example.value = current if current in names else names[0] if names else None
        if self.new_name.value.strip() in names or not self.new_name.value.strip():
            self.new_name.value = _next_name("pose_1", names)
        self._sync_graph()
        self._update_status(detail=False)

    def _thumbnails(self, names: list[str]) -> dict[str, bytes]:
        """PNG per example, re-rendered only for examples whose details changed."""
        layer = self.layer
        values = layer.pose_space.train_values
        out: dict[str, bytes] = {}
        todo = []
        for j, n in enumerate(names):
            h = hashlib.blake2b(np.ascontiguousarray(values[j]).tobytes(), digest_size=12)
            h.update(repr(sorted(layer.example_weights[j].items())).encode())
            key = h.hexdigest()
            hit = self._thumb_cache.get(n)
            if hit is not None and hit[0] == key:
                out[n] = hit[1]
            elif threading.current_thread() is not threading.main_thread():
                # VTK must render on the main thread (an edit from a timer or a subshell
                # thread): keep the old picture until the next refresh on the main thread.
                if hit is not None:
                    out[n] = hit[1]
            else:
                todo.append((j, n, key))
        if todo:
            from widgets.render import _Scene

            nb = self._tangent_neighbours()
            model = self._model
            blank = np.zeros((model.n_vertices, 3), np.uint8)
            scene = _Scene(
                model,
                np.asarray(model.vertices),
                size=THUMB_SIZE,
                camera="face",
                scalars=blank,
                cmap=None,
                clim=None,
                background="white",
            )
            try:
                for j, n, key in todo:
                    X, D = example_detailed(model, layer, j, nb)
                    png = example_thumbnail(model, X, D, scene=scene)
                    self._thumb_cache[n] = (key, png)
                    out[n] = png
            finally:
                scene.close()
        return out

    def _update_status(self, note: str = "", *, detail: bool = True) -> None:
        self._last_status_t = time.monotonic()
        layer = self.layer
        model = self._model
        if layer is None or not layer.fitted:
            parts = ["not fitted: press <i>Fit wrinkles from examples</i>"]
            if not len(model.handles):
                parts.append("(default handles are set first)")
        elif not self.fresh:
            parts = [
                "<b style='color:#b60'>the handles changed since the fit</b>: press <i>Refit</i>"
            ]
        else:
            parts = [
                f"<b>{len(layer.example_names)}</b> examples, <b>{len(layer.graph)}</b> feature edges"
            ]
            if not layer.enabled:
                parts.append("wrinkles off")
            else:
                parts.append(f"strength {layer.strength:.2f}")
            f = self.current_strain()
            if f is not None and len(f) and np.abs(f).max() >= 0.005:
                lo, hi = round(100 * float(np.min(f))), round(100 * float(np.max(f)))
                parts.append(f"strain {lo:+d}% … {hi:+d}%")
            elif f is not None:
                parts.append("at rest (no strain)")
            if detail and layer.enabled and layer.strength:
                d = layer.details(model)
                mm = (
                    0.0
                    if d is None
                    else float(np.abs(d).max()) * 1e3 * model.metadata.metres_per_unit
                )
                parts.append(f"max detail {mm:.2f} mm")
        if note:
            parts.append(note)
        self.status.value = " · ".join(parts)

    # ------------------------------------------------------------ closing
    def close(self) -> None:
        """Disconnect from the model and the viewport, then close the child widgets."""
        if getattr(self, "_connected", False):
            self.stop_erasing()
            if self.viewport is not None:
                self.viewport.unobserve(self._cb_tool, "tool")
            ev = self._model.events
            ev.deformed.disconnect(self._cb_deformed)
            ev.handles.disconnect(self._cb_handles)
            for link in self._links:
                link.unlink()
            if self.viewport is not None and self._cb_drag in self.viewport.drag_listeners:
                self.viewport.drag_listeners.remove(self._cb_drag)
            self._connected = False
        super().close()


def _next_name(name: str, taken: Iterable[str]) -> str:
    """``pose_1`` -> the first of ``pose_1, pose_2, ...`` not in ``taken``."""
    used = set(taken)
    stem, _, num = name.rpartition("_")
    if not stem or not num.isdigit():
        stem, num = name, "1"
    k = max(int(num), 1)
    cand = f"{stem}_{k}"
    while cand in used:
        k += 1
        cand = f"{stem}_{k}"
    return cand
