"""The Regions tab (regions family): its overlay and pin drag mode are on while it is shown."""

from __future__ import annotations

from typing import Any

from widgets.regions import RegionsPanel
from widgets.tabs import TabSpec, register_tab


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    panel = RegionsPanel(wb.model, wb.viewport, errors=wb.errors, before_edit=[wb.panel.grouper.flush])
    return panel, {"regions": panel}


def _show(wb: Any) -> None:
    wb.regions.activate()


def _hide(wb: Any) -> None:
    wb.regions.deactivate()  # first: leaving drag mode gives the viewport its previous tool back


TAB = register_tab(TabSpec(
    "Regions", 30, _build, lazy="finding the blend regions ...", on_show=_show, on_hide=_hide,
    owns_tool=lambda wb, tool: True,  # its drag mode switches to the sculpt tool without leaving the tab
    close=_hide, attrs=("regions",),
))
