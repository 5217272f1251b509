"""Building the shape tools panel, and keeping its choices in step with the model."""

from __future__ import annotations

import html
from collections.abc import Callable, Iterable
from typing import Any

import ipywidgets as W

from widgets.panels.base import button
from widgets.panels.shape_tools.actions import _ShapeActions

_SOURCES = (("empty (sculpt it afterwards)", "empty"), ("from current sculpt (handles)", "handles"))


def _row(*children: W.Widget) -> W.HBox:
    return W.HBox(
        list(children), layout=W.Layout(width="100%", align_items="center", grid_gap="4px")
    )


def _text(cls: str, placeholder: str = "", width: str = "150px") -> W.Text:
    t = W.Text(placeholder=placeholder, continuous_update=False, layout=W.Layout(width=width))
    t.add_class(cls)
    return t


def _dropdown(cls: str, width: str = "170px", description: str = "") -> W.Dropdown:
    d = W.Dropdown(
        options=[],
        description=description,
        style={"description_width": "initial"},
        layout=W.Layout(width=width),
    )
    d.add_class(cls)
    return d


class ShapeToolsPanel(_ShapeActions):
    """Split / mirror / corrective controls for a FaceModel (see :mod:`widgets.panels.shape_tools`).

    Parameters
    ----------
    model : workbench.FaceModel
    viewport : widgets.Viewport, optional
        Where the split preview is drawn (``viewport.vertex_colors``).
    sliders : widgets.panels.ExpressionPanel, optional
        Its ``selected`` trait (the last slider touched) becomes the selected shape.
    errors : ipywidgets.Output, optional
        Where errors are shown (``Workbench`` passes a shared one).
    before_edit : iterable of callables
        Called before each action (e.g. the slider panel's ``grouper.flush``).

    Attributes
    ----------
    status : ipywidgets.HTML
        What the last action did, or why it was refused (red).
    last_error : str
        The last refusal's message ("" after a success).
    """

    def __init__(
        self,
        model: Any,
        viewport: Any = None,
        *,
        sliders: Any = None,
        errors: W.Output | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
    ) -> None:
        super().__init__(
            model,
            errors=errors,
            before_edit=before_edit,
            layout=W.Layout(width="100%", border_top="1px solid #ddd", padding="4px 0 0 0"),
        )
        self.viewport = viewport
        self.last_error = ""
        self._saved_colors: Any = None
        self._previewing = False
        self._shown: str | None = None  # the selection the name fields were filled for
        tools = model.shape_tools
        units = html.escape(model.metadata.units)
        default = float(tools.default_falloff())

        header = W.HTML(
            "<b>Shape tools</b> <span style='color:#666'>split · mirror · correctives</span>"
        )
        self.shape = _dropdown("fwb-shape-tools-shape", "260px", "Shape")
        self.badge = W.HTML("")
        self.badge.add_class("fwb-shape-tools-badge")

        # split
        self.split_button = button(
            "Split L/R",
            "fwb-split",
            "Split the shape into left and right halves "
            "that sum to it (they take its place, weight and keys)",
            width="90px",
        )
        self.falloff = W.FloatSlider(
            value=default,
            min=0.0,
            max=max(5.0 * default, 1e-6),
            step=max(default / 100.0, 1e-9),
            description="band",
            readout_format=".3g",
            continuous_update=True,
            style={"description_width": "34px"},
            layout=W.Layout(width="250px"),
            tooltip=f"width of the smooth blend across the mirror plane ({units})",
        )
        self.falloff.add_class("fwb-split-falloff")
        self.preview = W.ToggleButton(
            value=False,
            description="Preview",
            icon="eye",
            tooltip="Colour the face by the share of each half "
            "(orange: subject's left, blue: right)",
            layout=W.Layout(width="90px"),
        )
        self.preview.add_class("fwb-split-preview")
        self.left_name = _text("fwb-split-left", width="140px")
        self.right_name = _text("fwb-split-right", width="140px")
        self.keep = W.Checkbox(
            value=False, description="keep original", indent=False, layout=W.Layout(width="auto")
        )
        self.keep.add_class("fwb-split-keep")

        # mirror
        self.mirror_button = button(
            "Mirror →",
            "fwb-mirror",
            "Mirror the shape to the other side (replaces the target's delta, or adds it)",
            width="90px",
        )
        self.mirror_target = _text("fwb-mirror-target", "target shape", "180px")
        self.expression = _dropdown("fwb-mirror-expression-source", "160px")
        self.expression_target = _text("fwb-mirror-expression-target", "target", "150px")
        self.mirror_expression_button = button(
            "Mirror expression",
            "fwb-mirror-expression",
            "Mirror the saved expression (model.expressions)",
            width="140px",
        )
        self.painted = _dropdown("fwb-mirror-paint-source", "160px")
        self.paint_target = _text("fwb-mirror-paint-target", "target", "150px")
        self.mirror_paint_button = button(
            "Mirror paint",
            "fwb-mirror-paint",
            "Paint the mirror image of this painted map on the other side",
            width="140px",
        )

        # correctives
        self.driver_a = _dropdown("fwb-corrective-driver-a", "160px")
        self.driver_b = _dropdown("fwb-corrective-driver-b", "160px")
        self.corrective_name = _text("fwb-corrective-name", "name (A_B)", "160px")
        self.corrective_source = W.Dropdown(
            options=_SOURCES, value="empty", layout=W.Layout(width="230px")
        )
        self.corrective_source.add_class("fwb-corrective-source")
        self.add_corrective_button = button(
            "Add corrective",
            "fwb-add-corrective",
            "A new shape whose weight is the product of the drivers' weights",
            width="120px",
        )
        self.set_drivers_button = button(
            "Set drivers",
            "fwb-set-drivers",
            "Make the selected shape a corrective of the two drivers",
            width="100px",
        )
        self.remove_corrective_button = button(
            "Remove corrective",
            "fwb-remove-corrective",
            "Remove the selected corrective (its shape too, unless kept)",
            width="160px",
        )
        self.keep_shape = W.Checkbox(
            value=False, description="keep shape", indent=False, layout=W.Layout(width="auto")
        )
        self.keep_shape.add_class("fwb-corrective-keep-shape")
        self.symmetry_label = W.HTML("")
        self.symmetry_label.add_class("fwb-shape-tools-symmetry")
        self.status = W.HTML("")
        self.status.add_class("fwb-shape-tools-status")

        def label(text: str) -> W.HTML:
            return W.HTML(
                f"<span style='color:#555;font-size:12px'>{text}</span>",
                layout=W.Layout(width="90px", min_width="90px"),
            )

        self.children = [
            header,
            _row(self.shape, self.badge),
            _row(self.split_button, self.falloff, W.HTML(units), self.preview),
            _row(label("halves"), self.left_name, self.right_name, self.keep),
            _row(self.mirror_button, self.mirror_target, self.symmetry_label),
            _row(
                label("expression"),
                self.expression,
                W.HTML("→"),
                self.expression_target,
                self.mirror_expression_button,
            ),
            _row(
                label("paint"),
                self.painted,
                W.HTML("→"),
                self.paint_target,
                self.mirror_paint_button,
            ),
            _row(
                label("corrective"), self.driver_a, W.HTML("×"), self.driver_b, self.corrective_name
            ),
            _row(
                label("from"),
                self.corrective_source,
                self.add_corrective_button,
                self.set_drivers_button,
            ),
            _row(self.remove_corrective_button, self.keep_shape),
            self.status,
        ]
        self.add_class("fwb-shape-tools")

        g = self.errors.guard
        self.split_button.on_click(g("Split L/R")(lambda _b: self.do_split()))
        self.mirror_button.on_click(g("Mirror")(lambda _b: self.do_mirror()))
        self.mirror_expression_button.on_click(
            g("Mirror expression")(lambda _b: self.do_mirror_expression())
        )
        self.mirror_paint_button.on_click(g("Mirror paint")(lambda _b: self.do_mirror_paint()))
        self.add_corrective_button.on_click(
            g("Add corrective")(lambda _b: self.do_add_corrective())
        )
        self.set_drivers_button.on_click(g("Set drivers")(lambda _b: self.do_set_drivers()))
        self.remove_corrective_button.on_click(
            g("Remove corrective")(lambda _b: self.do_remove_corrective())
        )
        self.shape.observe(g("shape tools: shape")(self._on_shape), "value")
        self.expression.observe(g("shape tools: expression")(self._on_expression), "value")
        self.painted.observe(g("shape tools: paint")(self._on_painted), "value")
        self.driver_a.observe(g("shape tools: drivers")(self._on_drivers), "value")
        self.driver_b.observe(g("shape tools: drivers")(self._on_drivers), "value")
        self.preview.observe(g("split preview")(self._on_preview), "value")
        self.falloff.observe(g("split preview")(self._on_falloff), "value")
        ev = model.events
        self.listen(ev.shapes, self._refresh_shapes, "ShapeToolsPanel shapes")
        self.listen(ev.correctives, self._refresh_shapes, "ShapeToolsPanel correctives")
        self.listen(ev.expressions, self._refresh_expressions, "ShapeToolsPanel expressions")
        self.listen(ev.paint_layers, self._refresh_paint, "ShapeToolsPanel paint")
        if sliders is not None:
            self.observe_trait(sliders, self._on_slider_selected, "selected", "shape tools: follow the sliders")
        self.on_close(self.end_preview)  # first on close: the viewport gets its colours back
        self._refresh_shapes()
        self._refresh_expressions()
        self._refresh_paint()
        self._update_symmetry()

    # ------------------------------------------------------------ model -> UI
    def _refresh_shapes(self) -> None:
        m = self._model
        with m.lock:
            names = list(m.shape_names)
            tools = m.shape_tools
            plain = [n for n in names if not tools.is_corrective(n)]
        current = self.selected
        if tuple(self.shape.options) != tuple(names):
            self.shape.options = names
            self.shape.value = current if current in names else (names[0] if names else None)
        for dd, k in ((self.driver_a, 0), (self.driver_b, 1)):
            cur = dd.value
            if tuple(dd.options) != tuple(plain):
                dd.options = plain
                fallback = plain[k] if len(plain) > k else (plain[0] if plain else None)
                dd.value = cur if cur in plain else fallback
        self._on_shape()

    def _refresh_expressions(self) -> None:
        names = list(self._model.expressions)
        if tuple(self.expression.options) != tuple(names):
            cur = self.expression.value
            self.expression.options = names
            self.expression.value = cur if cur in names else (names[0] if names else None)
        self.mirror_expression_button.disabled = self.expression.disabled = not names
        self._on_expression()

    def _refresh_paint(self) -> None:
        names = list(self._model.paint)
        if tuple(self.painted.options) != tuple(names):
            cur = self.painted.value
            self.painted.options = names
            self.painted.value = cur if cur in names else (names[0] if names else None)
        self.mirror_paint_button.disabled = self.painted.disabled = not names
        self._on_painted()

    def _update_symmetry(self) -> None:
        sym = self._model.shape_tools.symmetry()
        colour = "#b00" if sym.unmatched_fraction > 0.02 else "#666"
        self.symmetry_label.value = (
            f"<span style='color:{colour};font-size:11px' title='{html.escape(sym.summary())}'>"
            f"mirror plane {'xyz'[sym.axis]} = {sym.mid:.3g}, "
            f"{100 * sym.unmatched_fraction:.1f} % unmatched</span>"
        )

    # ------------------------------------------------------------ UI reactions
    def _on_slider_selected(self, change: dict) -> None:
        self.select(change["new"])

    def _on_shape(self, _change: Any = None) -> None:
        from workbench.arkit import mirror_name
        from workbench.methods.shapes.split import split_names

        name = self.selected
        tools = self._model.shape_tools
        corrective = name is not None and tools.is_corrective(name)
        self.badge.value = (
            f"<span style='color:#06c'>corrective = {html.escape(' × '.join(tools.drivers(name)))}</span>"
            if name is not None and corrective
            else ""
        )
        if (
            name != self._shown
        ):  # a new selection: its default names (what was typed stays otherwise)
            self._shown = name
            left, right = split_names(name) if name is not None else ("", "")
            self.left_name.placeholder, self.right_name.placeholder = left, right
            self.mirror_target.value = "" if name is None else (mirror_name(name) or name)
        for b in (self.split_button, self.mirror_button, self.set_drivers_button):
            b.disabled = name is None
        self.remove_corrective_button.disabled = not corrective
        if self._previewing:
            self._draw_preview()

    def _on_expression(self, _change: Any = None) -> None:
        from workbench.arkit import mirror_name

        name = self.expression.value
        self.expression_target.value = "" if not name else (mirror_name(name) or f"{name}_mirrored")

    def _on_painted(self, _change: Any = None) -> None:
        from workbench.arkit import mirror_name

        name = self.painted.value
        if not name:
            self.paint_target.value = ""
            return
        m = self._model
        known = set(m.expressions) | set(m.shape_names)
        mn = mirror_name(name)
        self.paint_target.value = mn if mn is not None and mn in known else name

    def _on_drivers(self, _change: Any = None) -> None:
        a, b = self.driver_a.value, self.driver_b.value
        self.corrective_name.placeholder = f"{a}_{b}" if a and b else "name"
