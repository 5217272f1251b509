"""The Regions tab: blend regions and region sculpting (Joshi et al. 2003).

* :mod:`widgets.regions.panel` — :class:`RegionsPanel`, the tab itself;
* :mod:`widgets.regions.sliders` — the selected region's weight sliders;
* :mod:`widgets.regions.edits` — rename / merge / split / paint controls;
* :mod:`widgets.regions.tools` — the viewport marker-drag handlers (pin drag,
  region brush, split-seed pick) and :class:`MarkerMode`;
* :mod:`widgets.regions.colors` — the region colour overlay.

The numerics are the core's (``model.regions``, :mod:`workbench.methods.regions`).
"""

from __future__ import annotations

from widgets.regions.colors import BACKGROUND_GREY, ColorSlots, region_colors, region_palette
from widgets.regions.edits import RegionEdits
from widgets.regions.panel import RegionsPanel
from widgets.regions.sliders import RegionSliders
from widgets.regions.tools import (
    MarkerMode,
    RegionBrushHandler,
    RegionDragHandler,
    RegionSeedPicker,
)

__all__ = [
    "BACKGROUND_GREY",
    "ColorSlots",
    "MarkerMode",
    "RegionBrushHandler",
    "RegionDragHandler",
    "RegionEdits",
    "RegionSeedPicker",
    "RegionSliders",
    "RegionsPanel",
    "region_colors",
    "region_palette",
]
