"""``PaintPanel``: painterly expression blending (Pighin et al. 1998, §4.2 of the SIGGRAPH 2006 course).

A new expression is a locally varying convex combination of existing ones
(:mod:`workbench.methods.paint.painting`). The panel offers the paper's three ways of specifying
the blend functions:

* **painterly**: a palette whose "colours" are expressions
  (:class:`widgets.gallery.ExpressionGallery` with the saved expressions first;
  click a thumbnail's name to pick it) and a 3D brush — radius (surface distance,
  model units), opacity, falloff curve, mode add / subtract / smooth, X-mirror —
  that paints in the :class:`widgets.Viewport` (``tool="paint"``: press, move,
  release = one undo step), plus *Flood* (the whole face at the brush opacity),
  *Normalize* (no base left where anything is painted) and *Clear*;
* **global blend**: one weight per expression for every vertex (preset
  "global");
* **regional blend**: softly feathered regions (upper/lower face, six regions
  split left/right, or the automatic regions of ``model.regions`` when
  segmented), one slider per region for the selected expression. Each region
  keeps its own mix of expressions; moving a slider rebuilds the whole paint
  layer with :func:`workbench.methods.paint.painting.regional_mix` (it *replaces* brush strokes —
  paint on top afterwards). One slider drag is one undo step.

Also: the weight-map overlay toggle (the selected expression's weights tinted
magenta in the viewport), "Save as expression" (the current face becomes a
named expression and appears in the palette), "Bake to new shape" (the paint
layer becomes a blendshape at weight 1), undo / redo and a status line (dabs
and kernel time per dab of the last stroke).

Like the other panels it keeps no model state of its own: it edits the model
through its public methods and follows ``model.events``. Hand-written because
no widget library offers expression painting.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import ipywidgets as W
import numpy as np

from widgets._threading import InteractionGrouper
from widgets.gallery import ExpressionGallery
from widgets.panels.base import ModelPanel, button
from widgets.panels.names import next_free_name
from widgets.panels.paint_blend import PRESETS, RegionalBlend
from widgets.viewport import BRUSH_MODES, FALLOFFS, brush_radius_slider, face_height
from workbench.methods.paint.expressions import expression_names
from workbench.methods.paint.painting import Brush

__all__ = ["PRESETS", "PaintPanel"]

_HELP = (
    "<div style='line-height:1.35'>Pick an expression in the palette, then <b>paint</b> on "
    "the face with the left button (one stroke = one undo step). Off the face, or with "
    "<b>Alt</b>, the left button orbits; the right button pans, the wheel zooms.</div>"
)


class PaintPanel(ModelPanel):
    """Palette, brush, blend tools and save/bake for painterly blending.

    Parameters
    ----------
    model : workbench.FaceModel
    gallery : widgets.ExpressionGallery, optional
        The palette; by default a new gallery of all expressions (saved ones
        first) with small thumbnails.
    viewport : widgets.Viewport, optional
        The viewport that paints: the brush controls are linked to its ``brush_*``
        traits, the overlay toggle and the picked expression to its paint tool's
        ``overlay`` and ``expression`` (:class:`widgets.panels.paint_tool.PaintTool`);
        the status line shows its stroke timings.
    errors : ipywidgets.Output, optional
        Where callback errors are shown (``Workbench`` passes a shared one).
    before_edit : iterable of callables
        Called before undo/redo and whole-layer edits (e.g. to close another
        panel's slider interaction).
    thumb_size : (int, int)
        Palette thumbnail size in pixels.
    columns : int
        Palette thumbnails per row.

    Attributes
    ----------
    expression : str or None
        The picked expression (the palette's selection).
    brush : workbench.methods.paint.painting.Brush
        The brush the controls describe.
    """

    def __init__(
        self,
        model: Any,
        gallery: ExpressionGallery | None = None,
        *,
        viewport: Any = None,
        errors: W.Output | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
        thumb_size: tuple[int, int] = (72, 72),
        columns: int = 7,
    ) -> None:
        super().__init__(
            model,
            errors=errors,
            before_edit=before_edit,
            layout=W.Layout(width="100%", min_width="380px"),
        )
        self.viewport = viewport
        if viewport is not None:
            self._before_edit += [viewport.end_stroke, viewport.end_drag]
        self.grouper = InteractionGrouper(model, errors=self.errors)
        self._before_edit.append(self.grouper.flush)
        self._own_gallery = gallery is None
        units = str(getattr(model.metadata, "units", "") or "units")
        H = face_height(model)
        self._height = H

        # ---- palette
        self.gallery = gallery or ExpressionGallery(
            model, size=thumb_size, columns=columns, expressions=True, label_size="10px"
        )
        # A scrolling box around the gallery: constraining the gallery's own height
        # would make its flex children shrink (squashed thumbnails) instead of scroll.
        self.gallery.layout.flex = "0 0 auto"
        self.palette = W.Box(
            [self.gallery],
            layout=W.Layout(max_height="320px", overflow="auto", flex="0 0 auto", display="block"),
        )
        self.palette.add_class("fwb-paint-palette")
        self.picked = W.HTML("")
        self.picked.add_class("fwb-paint-picked")

        # ---- brush
        wide = {"description_width": "90px"}
        self.radius = brush_radius_slider(
            model, viewport, f"radius ({units})", style=wide, layout=W.Layout(width="98%")
        )
        self.opacity = W.FloatSlider(
            value=float(getattr(viewport, "brush_opacity", 0.5)),
            min=0.0,
            max=1.0,
            step=0.01,
            description="opacity",
            style=wide,
            layout=W.Layout(width="98%"),
        )
        self.falloff = W.Dropdown(
            options=list(FALLOFFS),
            value=getattr(viewport, "brush_falloff", "smooth"),
            description="falloff",
            style=wide,
            layout=W.Layout(width="220px"),
        )
        self.mode = W.ToggleButtons(
            options=list(BRUSH_MODES),
            value=getattr(viewport, "brush_mode", "add"),
            style={"button_width": "84px"},
        )
        self.mirror = W.ToggleButton(
            value=bool(getattr(viewport, "brush_mirror", False)),
            description="X-mirror",
            icon="arrows-h",
            tooltip="Also paint at the x-mirrored spot",
            layout=W.Layout(width="110px"),
        )
        self.overlay = W.ToggleButton(
            value=bool(viewport.tools["paint"].overlay) if viewport is not None else True,
            description="overlay",
            icon="eye",
            tooltip="Show the picked expression's painted weights (magenta)",
            layout=W.Layout(width="100px"),
        )
        for w, cls in (
            (self.radius, "fwb-brush-radius"),
            (self.opacity, "fwb-brush-opacity"),
            (self.falloff, "fwb-brush-falloff"),
            (self.mode, "fwb-brush-mode"),
            (self.mirror, "fwb-brush-mirror"),
            (self.overlay, "fwb-paint-overlay"),
        ):
            w.add_class(cls)

        self.flood_button = button(
            "Flood",
            "fwb-paint-flood",
            "Paint the picked expression everywhere at the brush opacity",
        )
        self.normalize_button = button(
            "Normalize",
            "fwb-paint-normalize",
            "Scale the painted weights to sum to 1 wherever anything is painted",
        )
        self.clear_button = button("Clear", "fwb-paint-clear", "Remove all paint (undoable)")
        self.history_buttons = self.undo_redo_buttons("fwb-paint-undo", "fwb-paint-redo")
        self.undo_button, self.redo_button = self.history_buttons.buttons

        # ---- global / regional blend
        self.blend = RegionalBlend(
            model,
            expression=lambda: self.expression,
            grouper=self.grouper,
            errors=self.errors,
            flush=self.flush,
            end_stroke=None if viewport is None else viewport.end_stroke,
            units=units,
            height=H,
        )
        self.preset, self.feather, self.region_box = (
            self.blend.preset,
            self.blend.feather,
            self.blend.box,
        )

        # ---- save / bake
        self.save_name = W.Text(
            value=next_free_name("painted_1", expression_names(model)),
            placeholder="expression name",
            layout=W.Layout(width="180px"),
        )
        self.save_name.add_class("fwb-save-name")
        self.save_button = button(
            "Save as expression",
            "fwb-save-expression",
            "Save the current face as a named expression (it appears in the palette)",
        )
        self.bake_name = W.Text(
            value=next_free_name("paint_1", model.shape_names),
            placeholder="new shape name",
            layout=W.Layout(width="180px"),
        )
        self.bake_name.add_class("fwb-paint-bake-name")
        self.bake_button = button(
            "Bake to new shape",
            "fwb-paint-bake",
            "Turn the paint layer into a blendshape at weight 1 and clear the paint",
        )
        self.status = W.HTML("")
        self.status.add_class("fwb-paint-status")

        rows = [
            W.HTML(_HELP),
            self.palette,
            self.picked,
            W.HTML("<b>Brush</b>"),
            self.radius,
            self.opacity,
            W.HBox([self.falloff, self.mirror, self.overlay]),
            self.mode,
            W.HBox([self.flood_button, self.normalize_button, self.clear_button]),
            W.HTML(
                "<b>Global / regional blend</b> of the picked expression (replaces the paint layer)"
            ),
            self.preset,
            self.feather,
            self.region_box,
            W.HBox([self.save_name, self.save_button]),
            W.HBox([self.bake_name, self.bake_button]),
            W.HBox([self.undo_button, self.redo_button]),
            self.status,
        ]
        self.children = rows
        self.add_class("fwb-paint-panel")

        g = self.errors.guard
        self.flood_button.on_click(g("flood")(self._on_flood))
        self.normalize_button.on_click(g("normalize")(self._on_normalize))
        self.clear_button.on_click(g("clear paint")(self._on_clear))
        self.save_button.on_click(g("save expression")(self._on_save))
        self.bake_button.on_click(g("bake paint")(self._on_bake))
        cb_select = g("palette")(self._on_select)
        self.gallery.on_select(cb_select)
        self.on_close(self.gallery.on_select, cb_select, True)  # remove=True
        if viewport is not None:
            for control, brush_trait in ((self.radius, "brush_radius"), (self.opacity, "brush_opacity"),
                                         (self.falloff, "brush_falloff"), (self.mode, "brush_mode"),
                                         (self.mirror, "brush_mirror")):
                self.link((control, "value"), (viewport, brush_trait))
            self.link((self.overlay, "value"), (viewport.tools["paint"], "overlay"))
            self.add_listener(
                viewport.stroke_listeners, self._on_stroke_end, "PaintPanel stroke stats"
            )
        if self._own_gallery:
            self.on_close(self.gallery.close)
        ev = model.events
        self.listen(ev.paint_layers, self._on_model_paint, "PaintPanel paint")
        self.listen(ev.expressions, self._on_model_expressions, "PaintPanel expressions")
        self.listen(ev.shapes, self._on_model_shapes, "PaintPanel shapes")
        self.listen(ev.regions, self.blend.on_model_regions, "PaintPanel regions")
        self.on_close(self.grouper.flush)  # first: an open slider drag becomes its undo step
        self._on_select(self.gallery.selected)
        self._update_status()

    # ------------------------------------------------------------------ public
    @property
    def expression(self) -> str | None:
        """The picked expression, or None."""
        return self.gallery.selected

    def pick(self, name: str | None) -> None:
        """Pick ``name`` in the palette (as a click on its thumbnail does)."""
        self.gallery.select(name)

    @property
    def brush(self) -> Brush:
        """The brush described by the controls."""
        return Brush(
            radius=float(self.radius.value),
            opacity=float(self.opacity.value),
            falloff=self.falloff.value,
            mode=self.mode.value,
            mirror=bool(self.mirror.value),
        )

    @property
    def region_sliders(self) -> dict[str, W.FloatSlider]:
        """One slider per region of the chosen blend preset."""
        return self.blend.sliders

    def region_weights(
        self, preset: str | None = None, feather: float | None = None
    ) -> tuple[list[str], np.ndarray]:
        """(names, (r, n) memberships) of a blend preset (default: the chosen one)."""
        return self.blend.region_weights(preset, feather)

    def set_region_weight(self, region: str, value: float, expression: str | None = None) -> None:
        """Set ``expression``'s weight in one region of the chosen preset and apply the blend.

        The region's other expressions are scaled down if the total would exceed 1.
        """
        self.blend.set_region_weight(region, value, expression)

    # ------------------------------------------------------- UI -> model
    def _require_expression(self, what: str) -> str:
        expr = self.expression
        if not expr:
            raise ValueError(f"{what}: pick an expression in the palette first")
        return expr

    def _on_select(self, name: str | None) -> None:
        if self.viewport is not None:
            self.viewport.tools["paint"].expression = name or ""
        self.picked.value = (
            f"painting with <b>{name}</b>" if name else "<i>pick an expression to paint with</i>"
        )
        self.blend.sync_sliders()

    def _on_flood(self, _b: Any = None) -> None:
        expr = self._require_expression("Flood")
        self.flush()
        self._model.paint.flood(expr, float(self.opacity.value))

    def _on_normalize(self, _b: Any = None) -> None:
        self.flush()
        self._model.paint.normalize()

    def _on_clear(self, _b: Any = None) -> None:
        self.flush()
        if len(self._model.paint):
            self._model.paint.clear()
        self.blend.forget()

    def _on_save(self, _b: Any = None) -> None:
        name = self.save_name.value.strip()
        if not name:
            raise ValueError("Save as expression: type a name first")
        self.flush()
        self._model.expressions.save(name)
        self._update_status(f"saved expression <b>{name}</b>")

    def _on_bake(self, _b: Any = None) -> None:
        name = self.bake_name.value.strip()
        if not name:
            raise ValueError("Bake to new shape: type a name for the new shape first")
        if not len(self._model.paint):
            raise ValueError("Bake to new shape: nothing is painted")
        self.flush()
        self._model.paint.bake_to_shape(name)
        self.bake_name.value = next_free_name(name, self._model.shape_names)
        self._update_status(f"baked <b>{name}</b>")

    # ------------------------------------------------------- model -> UI
    def _on_model_paint(self) -> None:
        # Final events only (a stroke sends one, at release): cheap enough to follow all.
        self._update_status()

    def _on_model_expressions(self) -> None:
        if self.save_name.value.strip() in self._model.expressions:
            self.save_name.value = next_free_name(
                self.save_name.value.strip(), expression_names(self._model)
            )

    def _on_model_shapes(self) -> None:
        if self.bake_name.value.strip() in self._model.shape_names:
            self.bake_name.value = next_free_name(
                self.bake_name.value.strip(), self._model.shape_names
            )

    def _on_stroke_end(self, stats: dict[str, Any]) -> None:
        self._update_status()

    def _update_status(self, note: str = "") -> None:
        model = self._model
        mix = model.paint
        parts = []
        if len(mix):
            n = max(model.n_vertices, 1)
            cover = ", ".join(
                f"{name} ({np.count_nonzero(w) / n:.0%})" for name, w in mix.items()
            )
            parts.append(f"painted: {cover}")
        else:
            parts.append("nothing painted")
        st = getattr(self.viewport, "last_stroke", None) or {}
        if st:
            ups = st["updates_per_s"]
            rate = f", {ups:.0f} updates/s" if math.isfinite(ups) else ""
            parts.append(
                f"last stroke <i>{st['expression']}</i>: {st['dabs']} dabs, "
                f"{st['median_dab_ms']:.1f} ms per dab, {st['median_ms']:.1f} ms per update"
                f"{rate}"
            )
        if note:
            parts.append(note)
        self.status.value = " · ".join(parts)
