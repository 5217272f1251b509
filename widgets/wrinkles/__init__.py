"""The pose-space wrinkle panel of the Sculpt tab (``model.wrinkles``' view).

- :mod:`.panel`: :class:`WrinklePanel` (fit, on/off, strength, feature graph,
  example cards, scale, add the current pose).
- :mod:`.eraser`: :class:`WrinkleEraser`, the brush stroke handler that paints
  one example's wrinkles out, and the eraser's controls.
- :mod:`.thumbnails`: the example pictures.
"""

from widgets.wrinkles.eraser import WrinkleEraser
from widgets.wrinkles.panel import WrinklePanel
from widgets.wrinkles.thumbnails import example_thumbnail

__all__ = ["WrinkleEraser", "WrinklePanel", "example_thumbnail"]
