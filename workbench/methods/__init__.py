"""The method families, one folder each (see :mod:`workbench.core.families`).

Importing this package registers them all: handles (thin-shell handle editing),
wrinkles (pose-space deformation), regions (blend regions, marker fitting),
paint (expressions, painterly blending) and shape tools (split, mirror,
corrective shapes). The timeline registers from
:mod:`workbench.animation.family`.
"""

from workbench.methods.handles import family as _handles
from workbench.methods.paint import family as _paint
from workbench.methods.regions import family as _regions
from workbench.methods.shapes import family as _shapes
from workbench.methods.wrinkles import family as _wrinkles

__all__ = ["_handles", "_paint", "_regions", "_shapes", "_wrinkles"]
