"""The Export tab (timeline family): write the animation to the formats of other tools."""

from __future__ import annotations

from typing import Any

from widgets.panels import ExportPanel
from widgets.tabs import TabSpec, register_tab


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    panel = ExportPanel(wb.model, errors=wb.errors)
    return panel, {"export": panel}


TAB = register_tab(TabSpec("Export", 50, _build, attrs=("export",)))
