"""The Sculpt tab (handles family): handle sculpting and, under it, the pose-space wrinkles."""

from __future__ import annotations

from typing import Any

import ipywidgets as W

from widgets.panels import SculptPanel
from widgets.tabs import TabSpec, register_tab
from widgets.wrinkles import WrinklePanel


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    flush = [wb.panel.grouper.flush]
    sculpt = SculptPanel(wb.model, wb.viewport, errors=wb.errors, before_edit=flush)
    wrinkles = WrinklePanel(wb.model, wb.viewport, errors=wb.errors, before_edit=flush)
    tab = W.VBox([sculpt, wrinkles], layout=W.Layout(width="100%"))
    tab.add_class("fwb-sculpt-tab")
    return tab, {"sculpt": sculpt, "wrinkles": wrinkles}


def _hide(wb: Any) -> None:
    wb.wrinkles.stop_erasing()  # the wrinkle eraser's strokes belong to the Sculpt tab


def _owns(wb: Any, tool: str) -> bool:
    return tool == "paint" and bool(wb.wrinkles.erasing)  # the eraser brushes with the paint tool


TAB = register_tab(TabSpec("Sculpt", 20, _build, tool="sculpt", on_hide=_hide, owns_tool=_owns,
                           attrs=("sculpt", "wrinkles")))
