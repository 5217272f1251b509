"""Moved to the :mod:`widgets.regions` package (kept until ``widgets/__init__.py`` imports from there)."""

from __future__ import annotations

from widgets.regions import (
    BACKGROUND_GREY,
    RegionBrushHandler,
    RegionDragHandler,
    RegionSeedPicker,
    RegionsPanel,
    region_colors,
    region_palette,
)

__all__ = [
    "BACKGROUND_GREY",
    "RegionBrushHandler",
    "RegionDragHandler",
    "RegionSeedPicker",
    "RegionsPanel",
    "region_colors",
    "region_palette",
]
