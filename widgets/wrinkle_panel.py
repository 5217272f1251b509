"""Moved to :mod:`widgets.wrinkles`; this name stays until ``widgets/__init__.py`` imports from there."""

from widgets.wrinkles import WrinkleEraser, WrinklePanel, example_thumbnail

__all__ = ["WrinkleEraser", "WrinklePanel", "example_thumbnail"]
