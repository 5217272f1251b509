"""The Capture and Live tabs (capture family): a take's points are shown while Capture is; Live holds the webcam."""

from __future__ import annotations

from typing import Any

from widgets.capture import CapturePanel
from widgets.live import LivePanel
from widgets.tabs import TabSpec, register_tab


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    panel = CapturePanel(wb.model, wb.viewport, errors=wb.errors, before_edit=[wb.panel.grouper.flush],
                         selected_keys=lambda: wb.timeline.selected_keys)
    return panel, {"capture": panel}


TAB = register_tab(TabSpec("Capture", 60, _build, on_show=lambda wb: wb.capture.show_frame(),
                           on_hide=lambda wb: wb.capture.hide_points(), attrs=("capture",)))


def _build_live(wb: Any) -> tuple[Any, dict[str, Any]]:
    panel = LivePanel(wb.model, wb.viewport, errors=wb.errors, before_edit=[wb.panel.grouper.flush])
    return panel, {"live": panel}


# leaving the tab stops the camera (nobody is filmed by a tab they cannot see)
LIVE = register_tab(TabSpec("Live", 62, _build_live, on_hide=lambda wb: wb.live.stop_camera(), attrs=("live",)))
