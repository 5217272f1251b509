"""The selected region's weight sliders (Joshi et al. 2003: per-region blend weights).

One slider per *driver* shape of the region (the shapes that move it most,
``Regions.drivers``; more can be added from a dropdown), editing that
region's weights only (``model.regions.set_region``). A slider drag is one
undo step (:class:`widgets._threading.InteractionGrouper`, as in the
expression panel); "Reset region" puts the region back on the global
weights, "Reset all" every region.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import ipywidgets as W

from widgets._threading import ErrorSink, InteractionGrouper
from widgets.slider_echoes import SliderEchoes

#: Step of the per-region weight sliders.
SLIDER_STEP = 0.01


def snap(value: float, lo: float) -> float:
    """``value`` on the slider grid ``lo + k * SLIDER_STEP`` (what the front end shows)."""
    return float(lo + round((value - lo) / SLIDER_STEP) * SLIDER_STEP)


def is_echo(slider_value: float, model_value: float, lo: float) -> bool:
    """True if a slider value is the model's value as the front end shows it.

    The browser snaps a slider to its step and sends the snapped value back;
    solved weights (0.0418) are not on the grid, so without this every region
    drag would be followed by one "slider" edit per driver shape.
    """
    return abs(slider_value - model_value) < 1e-6 or abs(slider_value - snap(model_value, lo)) < 1e-6


class RegionSliders:
    """Weight sliders of the selected region, plus "Reset region" / "Reset all".

    Parameters
    ----------
    model : workbench.FaceModel
    selected : callable returning int or None
        The selected region's index on the shown level.
    grouper : InteractionGrouper
        Groups a slider drag into one undo step.
    errors : ErrorSink
    flush : callable
        Ends open interactions before a discrete edit (the reset buttons).
    """

    def __init__(self, model: Any, selected: Callable[[], int | None], grouper: InteractionGrouper,
                 errors: ErrorSink, flush: Callable[[], Any]) -> None:
        self.model = model
        self.selected = selected
        self.grouper = grouper
        self.errors = errors
        self.flush = flush
        self.extra_shapes: list[str] = []
        self.weight_sliders: dict[str, W.FloatSlider] = {}
        #: the values sent to each (region, shape) slider: a late echo of one is no edit
        self._echoes = SliderEchoes()
        self.reset_region_button = W.Button(
            description="Reset region", icon="undo", layout=W.Layout(width="auto"),
            tooltip="This region follows the global sliders again",
        )  # fmt: skip
        self.reset_region_button.add_class("fwb-reset-region")
        self.reset_all_button = W.Button(
            description="Reset all", layout=W.Layout(width="auto"),
            tooltip="Every region follows the global sliders",
        )  # fmt: skip
        self.reset_all_button.add_class("fwb-reset-all-regions")
        self.add_shape = W.Dropdown(options=[("+ shape…", "")], value="", layout=W.Layout(width="200px"))
        self.add_shape.add_class("fwb-region-add-shape")
        self.box = W.VBox(layout=W.Layout(width="100%"))
        g = errors.guard
        self.reset_region_button.on_click(g("reset region")(self._on_reset_region))
        self.reset_all_button.on_click(g("reset all regions")(self._on_reset_all))
        self.add_shape.observe(g("add shape slider")(self._on_add_shape), "value")

    # ------------------------------------------------------- UI -> model
    def set_region_weight(self, region: int | str, shape: str, value: float) -> None:
        """One weight of one region (what a slider does, grouped into one undo step per drag)."""
        model = self.model
        with model.lock:
            if not model.regions.segmented:
                raise ValueError("RegionsPanel: no regions yet; press 'Find regions' first")
            rw = model.regions.effective_weights
            r = rw.region_index(region)
            if is_echo(float(value), rw.region(r)[shape], model.shape(shape).slider_min):
                return  # an echo of a model update
            label = f"Region {rw.region_names[r]}: {shape}"
            self.grouper.touch(label)
            model.regions.set_region(r, {shape: float(value)}, label)

    def on_slider(self, shape: str, value: float) -> None:
        """A slider of ``shape`` moved to ``value`` (the browser's message)."""
        r = self.selected()
        if r is None:
            return
        key = (r, shape)
        if self._echoes.is_echo(key, float(value), SLIDER_STEP):
            # the page's snapped echo of a value sent during a region drag: no edit
            self._echoes.resend_if_stale(key, float(value), SLIDER_STEP, lambda: self._current(r, shape),
                                         lambda: self.weight_sliders.get(shape), self._shown(shape))
            return
        self._echoes.forget(key)
        self.set_region_weight(r, shape, value)

    def _current(self, r: int, shape: str) -> float | None:
        st = self.model.regions.state
        if st is None or self.selected() != r:
            return None
        rw = self.model.regions.effective_weights
        return rw.region(r).get(shape) if r < len(rw.region_names) else None

    def _shown(self, shape: str) -> Callable[[float], float]:
        lo = self.model.shape(shape).slider_min
        return lambda v: snap(v, lo)

    def _on_reset_region(self, _b: Any = None) -> None:
        r = self.selected()
        if r is None or not self.model.regions.segmented:
            return
        self.flush()
        self.model.regions.reset_region(r)

    def _on_reset_all(self, _b: Any = None) -> None:
        st = self.model.regions.state
        if st is None or st.weights is None:
            return
        self.flush()
        self.model.regions.set_weights(None, "Reset all regions")

    def _on_add_shape(self, change: Any) -> None:
        nm = change["new"]
        if not nm:
            return
        if nm not in self.extra_shapes:
            self.extra_shapes.append(nm)
        self.add_shape.value = ""
        self.build()

    # ------------------------------------------------------- model -> UI
    def set_disabled(self, disabled: bool) -> None:
        self.reset_region_button.disabled = disabled
        self.reset_all_button.disabled = disabled

    def on_shapes(self) -> None:
        """The model's shapes changed: the "+ shape" choices, then the sliders."""
        names = list(self.model.shape_names)
        self.extra_shapes = [nm for nm in self.extra_shapes if nm in names]
        self.add_shape.options = [("+ shape…", ""), *((nm, nm) for nm in names)]
        self.add_shape.value = ""
        self.build()

    def shapes(self) -> list[str]:
        """The shapes with a slider: the selected region's drivers, then the added ones."""
        st = self.model.regions.state
        r = self.selected()
        if st is None or r is None:
            return []
        drivers = list(st.regions.drivers[st.level][r])
        return drivers + [nm for nm in self.extra_shapes if nm not in drivers]

    def build(self) -> None:
        """New sliders for the selected region."""
        # the old sliders close only once the box shows the new ones (never a closed child on the page)
        old, self.weight_sliders = list(self.weight_sliders.values()), {}
        shapes = self.shapes()
        r = self.selected()
        if r is None or not shapes:
            self.box.children = [W.HTML("<i>no region selected</i>")]
            for s in old:
                s.close()
            return
        model = self.model
        values = model.regions.effective_weights.region(r)
        self._echoes.forget()
        for nm in shapes:
            sh = model.shape(nm)
            self._echoes.sent((r, nm), values[nm])
            s = W.FloatSlider(
                value=snap(values[nm], sh.slider_min), min=sh.slider_min, max=sh.slider_max,
                step=SLIDER_STEP, description=nm, continuous_update=True, readout_format=".2f",
                style={"description_width": "140px"}, layout=W.Layout(width="98%"),
            )  # fmt: skip
            s.add_class("fwb-region-weight")
            s.add_class(f"fwb-region-weight-{nm}")
            s.observe(
                self.errors.guard(f"region weight {nm}")(lambda ch, nm=nm: self.on_slider(nm, ch["new"])),
                "value",
            )
            self.weight_sliders[nm] = s
        self.box.children = list(self.weight_sliders.values())
        for s in old:
            s.close()

    def refresh(self) -> None:
        """Slider values from the model (no new sliders)."""
        st = self.model.regions.state
        r = self.selected()
        if st is None or r is None or not self.weight_sliders:
            return
        rw = self.model.regions.effective_weights
        if r >= len(rw.region_names):
            return
        values = rw.region(r)
        for nm, s in self.weight_sliders.items():
            v = values.get(nm)
            if v is not None and not is_echo(s.value, v, s.min):
                self._echoes.sent((r, nm), v)
                s.value = snap(v, s.min)

    def close(self) -> None:
        for s in self.weight_sliders.values():
            s.close()
        self.weight_sliders = {}
