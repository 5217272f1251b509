"""The Enhance tab (enhance family); its *Enhanced preview* box is in the top bar too (one widget)."""

from __future__ import annotations

from typing import Any

from widgets.enhance import EnhancePanel
from widgets.tabs import TabSpec, register_tab


def _capture_result(wb: Any) -> Any:
    capture = wb.panels.get("capture")  # a Workbench without the Capture tab has none
    return None if capture is None else capture.result


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    panel = EnhancePanel(wb.model, errors=wb.errors, before_edit=[wb.panel.grouper.flush],
                         selected_keys=lambda: wb.timeline.selected_keys,
                         capture_result=lambda: _capture_result(wb))
    return panel, {"enhance": panel}


TAB = register_tab(TabSpec("Enhance", 70, _build, topbar=lambda wb: [wb.enhance.preview], attrs=("enhance",)))
