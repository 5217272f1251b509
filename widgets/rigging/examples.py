"""``ExamplesPanel``: the example poses of your face and their rough weights.

Li et al. 2010 refine the transferred shapes from a few example poses of the
actor, each with a rough guess of the template shapes it shows. Here each
example is a row: its name, a *Remove* button and one slider per shape in its
guess (released: one undo step on the session; 0 removes the shape), and a
shape picker to add one. *Add from file* reads a mesh in your face's topology
(OBJ, glTF, ...; other units are scaled); from code,
``session.add_example(vertices, {"jawOpen": 0.8})``.
"""

from __future__ import annotations

import html
from typing import Any

import ipywidgets as W

from widgets.panels.base import ModelPanel, button

__all__ = ["ExamplesPanel"]


class ExamplesPanel(ModelPanel):
    """One row per example with weight sliders (see the module docstring).

    Parameters
    ----------
    session : workbench.rigging.RigSession
    errors : ipywidgets.Output or ErrorSink, optional

    Attributes
    ----------
    path : ipywidgets.Text
    add_button : ipywidgets.Button
    rows : ipywidgets.VBox
    sliders : dict of (example, shape) to ipywidgets.FloatSlider
    """

    def __init__(self, session: Any, *, errors: Any = None) -> None:
        super().__init__(session, errors=errors, layout=W.Layout(width="100%"))
        self.session = session
        self.sliders: dict[tuple[str, str], W.FloatSlider] = {}
        self.path = W.Text(placeholder="path/to/pose.obj (your face's topology)", layout=W.Layout(width="60%"))
        self.path.add_class("fwb-rig-example-path")
        self.add_button = button("Add from file", "fwb-rig-add-example", "Read an example pose", "plus")
        self.add_button.on_click(self.guard("add example")(lambda _b: self.add_from_file()))
        self.rows = W.VBox()
        self.rows.add_class("fwb-rig-examples")
        self.children = [W.HBox([self.path, self.add_button]), self.rows]
        self.listen(session.events.examples, self.refresh, "examples")
        self.refresh()

    def add_from_file(self) -> str:
        path = self.path.value.strip()
        if not path:
            raise ValueError("Add from file: type the path of a pose mesh first")
        name = self.session.add_example(path)
        self.path.value = ""
        return name

    def _slider(self, example: str, shape: str, value: float) -> W.FloatSlider:
        s = self.session.template.shape(shape)
        sl = W.FloatSlider(value=value, min=float(s.slider_min), max=float(s.slider_max), step=0.01,
                           description=shape, continuous_update=False, readout_format=".2f",
                           style={"description_width": "130px"}, layout=W.Layout(width="95%"))
        sl.add_class("fwb-rig-weight")
        sl.observe(self.guard("example weight")(
            lambda ch: self.session.set_example_weights(example, {shape: float(ch["new"])})), "value")
        self.sliders[(example, shape)] = sl
        return sl

    def refresh(self) -> None:
        """Rebuild the rows from the session (sliders keep their place when only values change)."""
        self.sliders = {}
        rows: list[W.Widget] = []
        names = list(self.session.template.shape_names)
        for ex in self.session.examples:
            remove = button("Remove", "fwb-rig-remove-example", f"Remove {ex.name}", "minus")
            remove.on_click(self.guard("remove example")(lambda _b, n=ex.name: self.session.remove_example(n)))
            pick = W.Dropdown(options=[""] + [n for n in names if n not in ex.weights], description="add shape",
                              layout=W.Layout(width="300px"))
            pick.observe(self.guard("add weight")(
                lambda ch, n=ex.name: ch["new"] and self.session.set_example_weights(n, {ch["new"]: 0.5})), "value")
            head = W.HBox([W.HTML(f"<b>{html.escape(ex.name)}</b>", layout=W.Layout(width="160px")), remove, pick])
            sliders = [self._slider(ex.name, k, v) for k, v in sorted(ex.weights.items())]
            box = W.VBox([head, *sliders], layout=W.Layout(border="1px solid #ddd", padding="2px", margin="2px 0"))
            box.add_class("fwb-rig-example")
            rows.append(box)
        if not rows:
            rows = [W.HTML("<i>No examples yet: the transfer alone is a full rig; examples make it yours.</i>")]
        self.rows.children = rows
