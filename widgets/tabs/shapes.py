"""The Shapes tab (shape-tools family): the blendshape sliders and, under them, split / mirror / correctives."""

from __future__ import annotations

from typing import Any

import ipywidgets as W

from widgets.panels.shape_tools import ShapeToolsPanel
from widgets.tabs import TabSpec, register_tab


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    # the shape tools follow the last slider touched in the Workbench's sliders
    tools = ShapeToolsPanel(wb.model, wb.viewport, sliders=wb.panel, errors=wb.errors,
                            before_edit=[wb.panel.grouper.flush])
    tab = W.VBox([wb.panel, tools], layout=W.Layout(width="100%"))
    tab.add_class("fwb-shapes-tab")
    return tab, {"shape_tools": tools}


def _show(wb: Any) -> None:
    wb.panel.set_shown(True)


def _hide(wb: Any) -> None:
    wb.shape_tools.end_preview()  # the split preview's colours belong to the Shapes tab
    wb.panel.set_shown(False)  # a live stream's weights wait for the sliders' return


TAB = register_tab(TabSpec("Shapes", 10, _build, on_show=_show, on_hide=_hide, attrs=("shape_tools",)))
