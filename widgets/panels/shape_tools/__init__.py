"""``ShapeToolsPanel``: split, mirror and corrective shapes, under the sliders of the Shapes tab.

The notebook front of ``model.shape_tools``
(:class:`workbench.methods.shapes.facet.ShapeToolsFacet`); every button is one
call of the facet, so one undo step:

* a **shape** dropdown: what Split, Mirror and Remove act on. It follows the
  last slider touched in the :class:`~widgets.panels.expressions.ExpressionPanel`
  given as ``sliders`` (its ``selected`` trait);
* **Split L/R** with the width of the smooth band across the mirror plane
  (model units; default :meth:`~ShapeToolsFacet.default_falloff`) and optional
  names of the halves, with a *Preview* of each half's share in the viewport
  (:mod:`~widgets.panels.shape_tools.preview`);
* **Mirror →** into a target (default: the mirrored name, e.g.
  ``mouthSmileLeft`` → ``mouthSmileRight``; an unsided shape flips in place);
* **Mirror expression** (a saved one, ``model.expressions``) and **Mirror
  paint** (a painted map, ``model.paint``), each with its target;
* **correctives**: two driver dropdowns, a name and the source (an empty shape
  to sculpt into, or the handle sculpt of the posed drivers), *Add
  corrective*; *Set drivers* makes the selected shape a corrective of the two
  drivers; *Remove corrective* (optionally keeping the shape). The sliders of
  correctives are read-only in the ExpressionPanel, with a "= A × B" badge.

Each action is one facet call that says what it did, or why it was refused,
in the status line (:mod:`~widgets.panels.shape_tools.actions`); the panel is
built and kept in step with the model in :mod:`~widgets.panels.shape_tools.panel`.
"""

from __future__ import annotations

from widgets.panels.shape_tools.panel import ShapeToolsPanel
from widgets.panels.shape_tools.preview import LEFT_COLOR, RIGHT_COLOR, split_preview_colors

__all__ = ["LEFT_COLOR", "RIGHT_COLOR", "ShapeToolsPanel", "split_preview_colors"]
