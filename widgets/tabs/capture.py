"""The Capture tab (capture family): a take's points are shown while it is."""

from __future__ import annotations

from typing import Any

from widgets.capture import CapturePanel
from widgets.tabs import TabSpec, register_tab


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    panel = CapturePanel(wb.model, wb.viewport, errors=wb.errors, before_edit=[wb.panel.grouper.flush],
                         selected_keys=lambda: wb.timeline.selected_keys)
    return panel, {"capture": panel}


TAB = register_tab(TabSpec("Capture", 60, _build, on_show=lambda wb: wb.capture.show_frame(),
                           on_hide=lambda wb: wb.capture.hide_points(), attrs=("capture",)))
