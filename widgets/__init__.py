"""Notebook UI of the Facial Editing Workbench (JupyterLab widgets).

Everything here *observes* a :class:`workbench.FaceModel` through its psygnal
events and edits it only through its methods; the headless core never imports
this package.

- :class:`Viewport`: client-side WebGL (three.js) view, binary partial updates.
- :class:`ExpressionPanel`: blendshape sliders grouped by face region.
- :class:`SculptPanel`: handle-based shell editing controls (the drag itself
  happens in the viewport's "sculpt" tool).
- :class:`PaintPanel`: painterly expression blending (palette of expression
  thumbnails, brush, global/regional blend, save as expression, bake); the
  strokes happen in the viewport's "paint" tool.
- :class:`ExpressionGallery`: the thumbnail grid (also the paint palette).
- :class:`Workbench` / :func:`show_workbench`: the viewport beside a tab of
  the panels ("Shapes", "Sculpt", "Paint"), plus an error log that callback
  errors go to.
"""

from __future__ import annotations

from typing import Any

import ipywidgets as W

from widgets.expression_panel import ExpressionPanel
from widgets.gallery import ExpressionGallery
from widgets.paint_panel import PaintPanel
from widgets.sculpt_panel import SculptPanel
from widgets.viewport import Viewport

__all__ = [
    "ExpressionGallery",
    "ExpressionPanel",
    "PaintPanel",
    "SculptPanel",
    "Viewport",
    "Workbench",
    "show_workbench",
]

#: tab index -> viewport tool
_TAB_TOOLS = ("orbit", "sculpt", "paint")
_PAINT_TAB = 2


class Workbench(W.VBox):
    """Viewport beside a tab of panels ("Shapes", "Sculpt", "Paint"), with a shared error Output.

    Selecting the "Sculpt" tab switches the viewport to its sculpt tool (drag
    handle markers), "Paint" to its paint tool (brush strokes on the face);
    "Shapes" switches back to plain orbiting. The Paint panel (and its palette
    of thumbnails, a few seconds of offscreen rendering) is built the first time
    its tab is opened or :attr:`paint` is read.

    Parameters
    ----------
    model : workbench.FaceModel
    height : int
        Viewport height in pixels.
    """

    def __init__(self, model: Any, *, height: int = 520) -> None:
        self.model = model
        self.errors = W.Output(layout=W.Layout(max_height="160px", overflow="auto"))
        self.errors.add_class("fwb-errors")
        self.viewport = Viewport(model, height=height, errors=self.errors)
        self.viewport.layout = W.Layout(flex="1 1 auto", min_width="320px")
        self.panel = ExpressionPanel(
            model, errors=self.errors, max_height=f"{max(height - 40, 200)}px"
        )
        self.sculpt = SculptPanel(
            model, self.viewport, errors=self.errors, before_edit=[self.panel.grouper.flush]
        )
        self._paint: PaintPanel | None = None
        self._paint_slot = W.VBox([W.HTML("<i>building the expression palette ...</i>")])
        self.tabs = W.Tab(
            children=[self.panel, self.sculpt, self._paint_slot],
            titles=("Shapes", "Sculpt", "Paint"),
            layout=W.Layout(flex="0 0 650px", width="650px"),
        )
        self.tabs.add_class("fwb-tabs")
        self.tabs.observe(self._on_tab, "selected_index")
        self.viewport.observe(self._on_tool, "tool")
        row = W.HBox([self.viewport, self.tabs], layout=W.Layout(width="100%"))
        super().__init__([row, self.errors], layout=W.Layout(width="100%"))
        self.add_class("fwb-workbench")

    @property
    def paint(self) -> PaintPanel:
        """The Paint tab's :class:`PaintPanel` (built on first use)."""
        if self._paint is None:
            self._paint = PaintPanel(
                self.model,
                viewport=self.viewport,
                errors=self.errors,
                before_edit=[self.panel.grouper.flush],
            )
            self._paint_slot.children = [self._paint]
        return self._paint

    def _on_tab(self, change: dict) -> None:
        i = change["new"]
        if i == _PAINT_TAB:
            try:
                self.paint  # noqa: B018 - builds the panel
            except Exception as exc:
                self.viewport.errors.report("building the Paint panel", exc)
        if i is not None and 0 <= i < len(_TAB_TOOLS):
            self.viewport.tool = _TAB_TOOLS[i]

    def _on_tool(self, change: dict) -> None:
        i = _TAB_TOOLS.index(change["new"])
        if self.tabs.selected_index != i:
            self.tabs.selected_index = i

    def close(self) -> None:
        if self._paint is not None:
            self._paint.close()
        self.sculpt.close()
        self.viewport.close()
        self.panel.close()
        self.errors.close()
        super().close()


def show_workbench(model: Any, **kwargs: Any) -> Workbench:
    """Display a :class:`Workbench` for ``model`` and return it.

    Assign the result (``wb = show_workbench(m)``): as the last bare expression
    of a cell it would be displayed a second time.
    """
    from IPython.display import display

    wb = Workbench(model, **kwargs)
    display(wb)
    return wb
