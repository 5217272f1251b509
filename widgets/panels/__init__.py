"""The tool panels of the workbench, and the base they share.

* :mod:`widgets.panels.base` — :class:`ModelPanel` (model, error sink,
  ``before_edit``, guarded :meth:`~ModelPanel.listen` connections undone once
  on close, :meth:`~ModelPanel.flush`, undo / redo) and :func:`button`;
* :mod:`widgets.panels.undo_redo` — :class:`UndoRedoButtons` that follow
  ``model.history`` (also the app's top bar);
* :mod:`widgets.panels.progress` — :class:`ProgressRow`, a bar and a label
  that is itself the ``progress(fraction, message)`` callback;
* :mod:`widgets.panels.names` — :func:`next_free_name` for baked shapes and
  saved expressions;
* the panels: :mod:`.expressions` (:class:`ExpressionPanel`, the Shapes tab),
  :mod:`.sculpt` (:class:`SculptPanel`), :mod:`.paint` (:class:`PaintPanel`,
  its regional blend in :mod:`.paint_blend`), :mod:`.export`
  (:class:`ExportPanel`).

The Regions and wrinkle panels live in their own packages
(:mod:`widgets.regions`, :mod:`widgets.wrinkles`).
"""

from __future__ import annotations

from widgets.panels.base import ModelPanel, button
from widgets.panels.export import ExportPanel
from widgets.panels.expressions import ExpressionPanel
from widgets.panels.names import next_free_name
from widgets.panels.paint import PaintPanel
from widgets.panels.progress import ProgressRow
from widgets.panels.sculpt import SculptPanel
from widgets.panels.undo_redo import UndoRedoButtons

__all__ = [
    "ExportPanel",
    "ExpressionPanel",
    "ModelPanel",
    "PaintPanel",
    "ProgressRow",
    "SculptPanel",
    "UndoRedoButtons",
    "button",
    "next_free_name",
]
