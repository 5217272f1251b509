"""The Paint tab (paint family): the expression palette and the brush."""

from __future__ import annotations

from typing import Any

from widgets.panels import PaintPanel
from widgets.tabs import TabSpec, register_tab


def _build(wb: Any) -> tuple[Any, dict[str, Any]]:
    panel = PaintPanel(wb.model, wb.gallery, viewport=wb.viewport, errors=wb.errors,
                       before_edit=[wb.panel.grouper.flush])
    return panel, {"paint": panel}


TAB = register_tab(TabSpec("Paint", 40, _build, tool="paint", lazy="building the expression palette ...",
                           attrs=("paint",)))
