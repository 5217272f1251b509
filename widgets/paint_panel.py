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
import threading
from collections.abc import Callable, Iterable
from typing import Any

import ipywidgets as W
import numpy as np
import traitlets as t

from widgets._threading import ErrorSink, InteractionGrouper, close_interactions
from widgets.gallery import ExpressionGallery
from widgets.viewport import BRUSH_MODES, FALLOFFS, brush_radius_slider, face_height
from workbench.methods.paint.expressions import expression_names
from workbench.methods.paint.painting import (
    Brush,
    eyes_vertical_extent,
    feathered_presets,
    regional_mix,
)

_HELP = (
    "<div style='line-height:1.35'>Pick an expression in the palette, then <b>paint</b> on "
    "the face with the left button (one stroke = one undo step). Off the face, or with "
    "<b>Alt</b>, the left button orbits; the right button pans, the wheel zooms.</div>"
)

#: (label, key) of the blend presets; "auto" is added when the model has regions
PRESETS = [
    ("global (all vertices)", "global"),
    ("upper / lower", "upper_lower"),
    ("six regions (L/R)", "six"),
]


def _next_free(name: str, taken: Iterable[str]) -> str:
    """``painted_1`` -> the first of ``painted_1, painted_2, ...`` not in ``taken``."""
    used = set(taken)
    stem, _, num = name.rpartition("_")
    if not stem or not num.isdigit():
        stem, num = name, "0"
    k = max(int(num), 1)
    cand = name if name not in used else f"{stem}_{k}"
    while cand in used:
        k += 1
        cand = f"{stem}_{k}"
    return cand


def _auto_regions(model: Any) -> tuple[list[str], np.ndarray]:
    """(names, (r, n) memberships) of the model's automatic regions on the level shown.

    ``model.regions`` is a :class:`workbench.methods.regions.blend.RegionState` (the
    segmentation, the level the Regions tab shows and edits, and its weights);
    the memberships are the soft per-vertex region weights of that level (they
    sum to ``1 - background`` per vertex, so <= 1 as :func:`regional_mix` needs).
    """
    state = getattr(model, "regions", None)
    if state is None:
        raise ValueError("automatic regions: segment the model first (model.segment_regions())")
    regions, level = state.regions, int(state.level)
    R = np.asarray(regions.weight_matrix(level).toarray(), dtype=np.float64).T
    return list(regions.names[level]), R


class PaintPanel(W.VBox):
    """Palette, brush, blend tools and save/bake for painterly blending.

    Parameters
    ----------
    model : workbench.FaceModel
    gallery : widgets.ExpressionGallery, optional
        The palette; by default a new gallery of all expressions (saved ones
        first) with small thumbnails.
    viewport : widgets.Viewport, optional
        The viewport that paints: the brush controls, the overlay toggle and the
        picked expression are linked to its ``brush_*``, ``paint_overlay`` and
        ``paint_expression`` traits; the status line shows its stroke timings.
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
        self._model = model
        self.viewport = viewport
        self.errors = ErrorSink(errors)
        self._before_edit = list(before_edit)
        if viewport is not None:
            self._before_edit += [viewport.end_stroke, viewport.end_drag]
        self.grouper = InteractionGrouper(model, errors=self.errors)
        self._before_edit.append(self.grouper.flush)
        self._links: list[Any] = []
        self._status_lock = threading.Lock()
        self._updating = False
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
            style={"button_width": "70px"},
        )
        self.mirror = W.ToggleButton(
            value=bool(getattr(viewport, "brush_mirror", False)),
            description="X-mirror",
            icon="arrows-h",
            tooltip="Also paint at the x-mirrored spot",
            layout=W.Layout(width="110px"),
        )
        self.overlay = W.ToggleButton(
            value=bool(getattr(viewport, "paint_overlay", True)),
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

        def button(desc: str, cls: str, tip: str, icon: str = "", width: str = "auto") -> W.Button:
            b = W.Button(description=desc, tooltip=tip, icon=icon, layout=W.Layout(width=width))
            b.add_class(cls)
            return b

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
        self.undo_button = button("Undo", "fwb-paint-undo", "", icon="undo", width="80px")
        self.redo_button = button("Redo", "fwb-paint-redo", "", icon="repeat", width="80px")

        # ---- global / regional blend
        self.preset = W.Dropdown(
            options=self._preset_options(),
            value="global",
            description="blend",
            style=wide,
            layout=W.Layout(width="300px"),
        )
        self.preset.add_class("fwb-blend-preset")
        self.feather = W.FloatSlider(
            value=0.05 * H,
            min=0.0,
            max=0.3 * H,
            step=0.002 * H,
            readout_format=".3f",
            description=f"feather ({units})",
            continuous_update=False,
            style=wide,
            layout=W.Layout(width="98%"),
        )
        self.feather.add_class("fwb-blend-feather")
        self.region_box = W.VBox([], layout=W.Layout(width="100%"))
        self.region_box.add_class("fwb-blend-regions")
        self.region_sliders: dict[str, W.FloatSlider] = {}
        #: preset -> one {expression: weight} per region (each sums to <= 1)
        self._mixes: dict[str, list[dict[str, float]]] = {}
        self._region_cache: dict[tuple[str, float], tuple[list[str], np.ndarray]] = {}

        # ---- save / bake
        self.save_name = W.Text(
            value=_next_free("painted_1", expression_names(model)),
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
            value=_next_free("paint_1", model.shape_names),
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
        super().__init__(rows, layout=W.Layout(width="100%", min_width="380px"))
        self.add_class("fwb-paint-panel")

        g = self.errors.guard
        self.flood_button.on_click(g("flood")(self._on_flood))
        self.normalize_button.on_click(g("normalize")(self._on_normalize))
        self.clear_button.on_click(g("clear paint")(self._on_clear))
        self.undo_button.on_click(g("undo")(self._on_undo))
        self.redo_button.on_click(g("redo")(self._on_redo))
        self.save_button.on_click(g("save expression")(self._on_save))
        self.bake_button.on_click(g("bake paint")(self._on_bake))
        self.preset.observe(g("blend preset")(self._on_preset), "value")
        self.feather.observe(g("feather")(self._on_feather), "value")
        self._cb_select = g("palette")(self._on_select)
        self.gallery.on_select(self._cb_select)
        if viewport is not None:
            self._links = [
                t.link((self.radius, "value"), (viewport, "brush_radius")),
                t.link((self.opacity, "value"), (viewport, "brush_opacity")),
                t.link((self.falloff, "value"), (viewport, "brush_falloff")),
                t.link((self.mode, "value"), (viewport, "brush_mode")),
                t.link((self.mirror, "value"), (viewport, "brush_mirror")),
                t.link((self.overlay, "value"), (viewport, "paint_overlay")),
            ]
            self._cb_stroke = g("PaintPanel stroke stats")(self._on_stroke_end)
            viewport.stroke_listeners.append(self._cb_stroke)
        self._cb_history = g("PaintPanel history")(self._on_model_history)
        self._cb_paint = g("PaintPanel paint")(self._on_model_paint)
        self._cb_expressions = g("PaintPanel expressions")(self._on_model_expressions)
        self._cb_shapes = g("PaintPanel shapes")(self._on_model_shapes)
        self._cb_regions = g("PaintPanel regions")(self._on_model_regions)
        ev = model.events
        ev.history.connect(self._cb_history)
        ev.paint_layers.connect(self._cb_paint)
        ev.expressions.connect(self._cb_expressions)
        ev.shapes.connect(self._cb_shapes)
        ev.regions.connect(self._cb_regions)
        self._connected = True
        self._build_region_sliders()
        self._on_select(self.gallery.selected)
        self._on_model_history()
        self._update_status()

    # ------------------------------------------------------------------ public
    @property
    def model(self) -> Any:
        return self._model

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

    def region_weights(
        self, preset: str | None = None, feather: float | None = None
    ) -> tuple[list[str], np.ndarray]:
        """(names, (r, n) memberships) of a blend preset (default: the chosen one)."""
        preset = self.preset.value if preset is None else preset
        feather = float(self.feather.value if feather is None else feather)
        key = (preset, feather if preset in ("upper_lower", "six") else 0.0)
        if key not in self._region_cache:
            m = self._model
            if preset == "global":
                out = (["all"], np.ones((1, m.n_vertices)))
            elif preset == "auto":
                out = _auto_regions(m)
            else:
                eyes = eyes_vertical_extent(m.vertices, m.component_labels, m.component_names)
                names, R = feathered_presets(np.asarray(m.vertices), preset, feather, eyes_y=eyes)
                out = (list(names), np.asarray(R))
            self._region_cache = {k: v for k, v in self._region_cache.items() if k[0] != preset}
            self._region_cache[key] = out
        return self._region_cache[key]

    def set_region_weight(self, region: str, value: float, expression: str | None = None) -> None:
        """Set ``expression``'s weight in one region of the chosen preset and apply the blend.

        The region's other expressions are scaled down if the total would exceed 1.
        """
        expr = expression or self.expression
        if not expr:
            raise ValueError("regional blend: pick an expression in the palette first")
        names, _ = self.region_weights()
        if region not in names:
            raise KeyError(f"regional blend: no region {region!r}; regions are {names}")
        v = float(min(max(value, 0.0), 1.0))
        mixes = self._mixes_for(self.preset.value, len(names))
        mx = mixes[names.index(region)]
        others = sum(w for k, w in mx.items() if k != expr)
        if others + v > 1.0 and others > 0:
            scale = (1.0 - v) / others
            for k in list(mx):
                if k != expr:
                    mx[k] *= scale
        mx[expr] = v
        self._apply_blend()

    # ------------------------------------------------------- UI -> model
    def _flush(self) -> None:
        close_interactions(self._model)
        for fn in self._before_edit:
            fn()

    def _require_expression(self, what: str) -> str:
        expr = self.expression
        if not expr:
            raise ValueError(f"{what}: pick an expression in the palette first")
        return expr

    def _on_select(self, name: str | None) -> None:
        if self.viewport is not None:
            self.viewport.paint_expression = name or ""
        self.picked.value = (
            f"painting with <b>{name}</b>" if name else "<i>pick an expression to paint with</i>"
        )
        self._sync_region_sliders()

    def _on_flood(self, _b: Any = None) -> None:
        expr = self._require_expression("Flood")
        self._flush()
        self._model.paint.flood(expr, float(self.opacity.value))

    def _on_normalize(self, _b: Any = None) -> None:
        self._flush()
        self._model.paint.normalize()

    def _on_clear(self, _b: Any = None) -> None:
        self._flush()
        if len(self._model.paint):
            self._model.paint.clear()
        self._mixes.pop(self.preset.value, None)
        self._sync_region_sliders()

    def _on_undo(self, _b: Any = None) -> None:
        self._flush()
        self._model.undo()

    def _on_redo(self, _b: Any = None) -> None:
        self._flush()
        self._model.redo()

    def _on_save(self, _b: Any = None) -> None:
        name = self.save_name.value.strip()
        if not name:
            raise ValueError("Save as expression: type a name first")
        self._flush()
        self._model.expressions.save(name)
        self._update_status(f"saved expression <b>{name}</b>")

    def _on_bake(self, _b: Any = None) -> None:
        name = self.bake_name.value.strip()
        if not name:
            raise ValueError("Bake to new shape: type a name for the new shape first")
        if not len(self._model.paint):
            raise ValueError("Bake to new shape: nothing is painted")
        self._flush()
        self._model.paint.bake_to_shape(name)
        self.bake_name.value = _next_free(name, self._model.shape_names)
        self._update_status(f"baked <b>{name}</b>")

    # ---- regional blend
    def _preset_options(self) -> list[tuple[str, str]]:
        opts = list(PRESETS)
        if getattr(self._model, "regions", None) is not None:
            opts.append(("automatic regions", "auto"))
        return opts

    def _mixes_for(self, preset: str, r: int) -> list[dict[str, float]]:
        mixes = self._mixes.get(preset)
        if mixes is None or len(mixes) != r:
            mixes = [{} for _ in range(r)]
            self._mixes[preset] = mixes
        return mixes

    def _build_region_sliders(self) -> None:
        names, _ = self.region_weights()
        self.region_sliders = {}
        rows = []
        for name in names:
            s = W.FloatSlider(
                value=0.0,
                min=0.0,
                max=1.0,
                step=0.01,
                description=name,
                style={"description_width": "90px"},
                layout=W.Layout(width="98%"),
            )
            s.add_class("fwb-region-slider")
            s.observe(self.errors.guard(f"region {name}")(self._on_region_slider), "value")
            self.region_sliders[name] = s
            rows.append(s)
        self.region_box.children = rows
        self.feather.layout.display = "" if self.preset.value in ("upper_lower", "six") else "none"
        self._sync_region_sliders()

    def _sync_region_sliders(self) -> None:
        """Show the picked expression's weight in every region (no model edit)."""
        names = list(self.region_sliders)
        mixes = self._mixes.get(self.preset.value) or [{} for _ in names]
        expr = self.expression
        self._updating = True
        try:
            for i, name in enumerate(names):
                s = self.region_sliders[name]
                s.value = float(mixes[i].get(expr, 0.0)) if expr and i < len(mixes) else 0.0
                s.disabled = not expr
        finally:
            self._updating = False

    def _on_region_slider(self, change: dict[str, Any]) -> None:
        if self._updating:
            return
        region = change["owner"].description
        expr = self._require_expression("regional blend")
        # One slider drag = one undo step (the grouper closes it when the drag idles).
        self.grouper.touch(f"Blend {expr} ({self.preset.value})")
        self.set_region_weight(region, float(change["new"]), expr)
        self._sync_region_sliders()

    def _apply_blend(self) -> None:
        names, R = self.region_weights()
        mixes = self._mixes_for(self.preset.value, len(names))
        mix = regional_mix(R, mixes, self._model.n_vertices)
        label = "Global blend" if self.preset.value == "global" else "Regional blend"
        if self.viewport is not None:
            self.viewport.end_stroke()
        self._model.paint.set(mix, label)

    def _on_preset(self, _change: Any = None) -> None:
        self._build_region_sliders()

    def _on_feather(self, _change: Any = None) -> None:
        # a new feather width reshapes the regions: re-apply the preset's mix if it has one
        mixes = self._mixes.get(self.preset.value)
        if mixes and any(mx for mx in mixes):
            self._flush()
            self._apply_blend()

    # ------------------------------------------------------- model -> UI
    def _on_model_history(self) -> None:
        model = self._model
        self.undo_button.disabled = not model.can_undo
        self.redo_button.disabled = not model.can_redo
        u, r = model.history.undo_labels, model.history.redo_labels
        self.undo_button.tooltip = f"Undo {u[-1]}" if u else "Nothing to undo"
        self.redo_button.tooltip = f"Redo {r[-1]}" if r else "Nothing to redo"

    def _on_model_paint(self) -> None:
        # Final events only (a stroke sends one, at release): cheap enough to follow all.
        self._update_status()

    def _on_model_expressions(self) -> None:
        if self.save_name.value.strip() in self._model.expressions:
            self.save_name.value = _next_free(
                self.save_name.value.strip(), expression_names(self._model)
            )

    def _on_model_shapes(self) -> None:
        if self.bake_name.value.strip() in self._model.shape_names:
            self.bake_name.value = _next_free(self.bake_name.value.strip(), self._model.shape_names)

    def _on_model_regions(self) -> None:
        value = self.preset.value
        opts = self._preset_options()
        old = [v[0] for k, v in self._region_cache.items() if k[0] == "auto"]
        self._region_cache = {k: v for k, v in self._region_cache.items() if k[0] != "auto"}
        if "auto" in self._mixes:
            # each region keeps its mix only while the regions are the same ones
            # (another level, a merge, split or re-segmentation starts afresh)
            new = _auto_regions(self._model)[0] if self._model.regions.state is not None else None
            if not old or new != old[0]:
                self._mixes.pop("auto", None)
        self.preset.options = opts
        self.preset.value = value if value in [k for _, k in opts] else "global"
        self._build_region_sliders()

    def _on_stroke_end(self, stats: dict[str, Any]) -> None:
        self._update_status()

    def _update_status(self, note: str = "") -> None:
        with self._status_lock:
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

    # ------------------------------------------------------------ closing
    def close(self) -> None:
        """Disconnect from the model and the viewport, then close the child widgets."""
        if getattr(self, "_connected", False):
            self.grouper.flush()
            ev = self._model.events
            ev.history.disconnect(self._cb_history)
            ev.paint_layers.disconnect(self._cb_paint)
            ev.expressions.disconnect(self._cb_expressions)
            ev.shapes.disconnect(self._cb_shapes)
            ev.regions.disconnect(self._cb_regions)
            self.gallery.on_select(self._cb_select, remove=True)
            if self.viewport is not None:
                for link in self._links:
                    link.unlink()
                if self._cb_stroke in self.viewport.stroke_listeners:
                    self.viewport.stroke_listeners.remove(self._cb_stroke)
            if self._own_gallery:
                self.gallery.close()
            self._connected = False
        super().close()
