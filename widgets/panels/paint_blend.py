"""The Paint tab's global / regional blend (Pighin et al. 1998: blend functions by region).

:class:`RegionalBlend` holds the blend preset (one region for every vertex,
upper / lower face, six regions split left / right, or the automatic regions of
``model.regions``), the feather width of the geometric presets and one slider
per region for the picked expression. Each region keeps its own mix of
expressions per preset; moving a slider rebuilds the whole paint layer with
:func:`workbench.methods.paint.painting.regional_mix` (it *replaces* brush
strokes). One slider drag is one undo step (the panel's
:class:`widgets._threading.InteractionGrouper`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import ipywidgets as W
import numpy as np

from widgets._threading import ErrorSink, InteractionGrouper
from workbench.methods.paint.painting import eyes_vertical_extent, feathered_presets, regional_mix

__all__ = ["PRESETS", "RegionalBlend", "auto_regions"]

#: (label, key) of the blend presets; "auto" is added when the model has regions
PRESETS = [
    ("global (all vertices)", "global"),
    ("upper / lower", "upper_lower"),
    ("six regions (L/R)", "six"),
]
#: presets whose regions depend on the feather width
_FEATHERED = ("upper_lower", "six")


def auto_regions(model: Any) -> tuple[list[str], np.ndarray]:
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


class RegionalBlend:
    """Preset dropdown, feather slider and region sliders of the picked expression.

    Parameters
    ----------
    model : workbench.FaceModel
    expression : callable
        Returns the picked expression (or None).
    grouper : InteractionGrouper
        Groups one slider drag into one undo step.
    errors : ErrorSink
    flush : callable
        Ends the open interactions before a whole-layer edit (a new feather width).
    end_stroke : callable, optional
        Ends the viewport's open paint stroke before the layer is replaced.
    units : str
        Model units (the feather slider's label).
    height : float
        Face height in model units (the feather slider's range).

    Attributes
    ----------
    preset : ipywidgets.Dropdown
    feather : ipywidgets.FloatSlider
    box : ipywidgets.VBox
        The region sliders' container.
    sliders : dict of str to ipywidgets.FloatSlider
        One slider per region of the chosen preset.
    """

    def __init__(
        self,
        model: Any,
        *,
        expression: Callable[[], str | None],
        grouper: InteractionGrouper,
        errors: ErrorSink,
        flush: Callable[[], None],
        end_stroke: Callable[[], Any] | None = None,
        units: str = "units",
        height: float = 1.0,
    ) -> None:
        self._model = model
        self._expression = expression
        self.grouper = grouper
        self.errors = errors
        self._flush = flush
        self._end_stroke = end_stroke
        self._updating = False
        wide = {"description_width": "90px"}
        H = height
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
        self.box = W.VBox([], layout=W.Layout(width="100%"))
        self.box.add_class("fwb-blend-regions")
        self.sliders: dict[str, W.FloatSlider] = {}
        #: preset -> one {expression: weight} per region (each sums to <= 1)
        self.mixes: dict[str, list[dict[str, float]]] = {}
        self._region_cache: dict[tuple[str, float], tuple[list[str], np.ndarray]] = {}
        g = errors.guard
        self.preset.observe(g("blend preset")(lambda _c: self.build_sliders()), "value")
        self.feather.observe(g("feather")(self._on_feather), "value")
        self.build_sliders()

    @property
    def widgets(self) -> list[W.Widget]:
        return [self.preset, self.feather, self.box]

    # ------------------------------------------------------------ regions
    def region_weights(
        self, preset: str | None = None, feather: float | None = None
    ) -> tuple[list[str], np.ndarray]:
        """(names, (r, n) memberships) of a blend preset (default: the chosen one)."""
        preset = self.preset.value if preset is None else preset
        feather = float(self.feather.value if feather is None else feather)
        key = (preset, feather if preset in _FEATHERED else 0.0)
        if key not in self._region_cache:
            m = self._model
            if preset == "global":
                out = (["all"], np.ones((1, m.n_vertices)))
            elif preset == "auto":
                out = auto_regions(m)
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
        expr = expression or self._expression()
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
        self._apply()

    def forget(self, preset: str | None = None) -> None:
        """Drop a preset's mixes (the paint was cleared) and show zeros."""
        self.mixes.pop(self.preset.value if preset is None else preset, None)
        self.sync_sliders()

    # ------------------------------------------------------------ sliders
    def _preset_options(self) -> list[tuple[str, str]]:
        opts = list(PRESETS)
        if getattr(self._model, "regions", None) is not None:
            opts.append(("automatic regions", "auto"))
        return opts

    def _mixes_for(self, preset: str, r: int) -> list[dict[str, float]]:
        mixes = self.mixes.get(preset)
        if mixes is None or len(mixes) != r:
            mixes = [{} for _ in range(r)]
            self.mixes[preset] = mixes
        return mixes

    def build_sliders(self) -> None:
        """One slider per region of the chosen preset."""
        names, _ = self.region_weights()
        self.sliders = {}
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
            s.observe(self.errors.guard(f"region {name}")(self._on_slider), "value")
            self.sliders[name] = s
            rows.append(s)
        self.box.children = rows
        self.feather.layout.display = "" if self.preset.value in _FEATHERED else "none"
        self.sync_sliders()

    def sync_sliders(self) -> None:
        """Show the picked expression's weight in every region (no model edit)."""
        names = list(self.sliders)
        mixes = self.mixes.get(self.preset.value) or [{} for _ in names]
        expr = self._expression()
        self._updating = True
        try:
            for i, name in enumerate(names):
                s = self.sliders[name]
                s.value = float(mixes[i].get(expr, 0.0)) if expr and i < len(mixes) else 0.0
                s.disabled = not expr
        finally:
            self._updating = False

    def _on_slider(self, change: dict[str, Any]) -> None:
        if self._updating:
            return
        region = change["owner"].description
        expr = self._expression()
        if not expr:
            raise ValueError("regional blend: pick an expression in the palette first")
        # One slider drag = one undo step (the grouper closes it when the drag idles).
        self.grouper.touch(f"Blend {expr} ({self.preset.value})")
        self.set_region_weight(region, float(change["new"]), expr)
        self.sync_sliders()

    def _apply(self) -> None:
        names, R = self.region_weights()
        mixes = self._mixes_for(self.preset.value, len(names))
        mix = regional_mix(R, mixes, self._model.n_vertices)
        label = "Global blend" if self.preset.value == "global" else "Regional blend"
        if self._end_stroke is not None:
            self._end_stroke()
        self._model.paint.set(mix, label)

    def _on_feather(self, _change: Any = None) -> None:
        # a new feather width reshapes the regions: re-apply the preset's mix if it has one
        mixes = self.mixes.get(self.preset.value)
        if mixes and any(mx for mx in mixes):
            self._flush()
            self._apply()

    # ------------------------------------------------------------ model -> UI
    def on_model_regions(self) -> None:
        """The model's regions changed: offer / drop "auto" and rebuild its sliders."""
        value = self.preset.value
        opts = self._preset_options()
        old = [v[0] for k, v in self._region_cache.items() if k[0] == "auto"]
        self._region_cache = {k: v for k, v in self._region_cache.items() if k[0] != "auto"}
        if "auto" in self.mixes:
            # each region keeps its mix only while the regions are the same ones
            # (another level, a merge, split or re-segmentation starts afresh)
            new = auto_regions(self._model)[0] if self._model.regions.state is not None else None
            if not old or new != old[0]:
                self.mixes.pop("auto", None)
        self.preset.options = opts
        self.preset.value = value if value in [k for _, k in opts] else "global"
        self.build_sliders()
