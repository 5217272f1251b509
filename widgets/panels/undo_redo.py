"""``UndoRedoButtons``: an Undo and a Redo button that follow ``model.history``.

Each button is disabled when there is nothing to undo / redo, and its tooltip
names the step it would undo or redo ("Undo Drag jawOpen"). A click calls the
owner's ``undo`` / ``redo`` (which first ends the open interactions: the model
refuses to undo inside one); an exception from it goes to the error sink under
``[undo]`` / ``[redo]``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import ipywidgets as W

from widgets._threading import ErrorSink

__all__ = ["UndoRedoButtons"]


class UndoRedoButtons:
    """Undo / Redo buttons bound to a model's history.

    Parameters
    ----------
    model : workbench.FaceModel
    on_undo, on_redo : callables
        What a click does (e.g. :meth:`widgets.panels.base.ModelPanel.undo`).
    classes : (str, str)
        CSS classes of the two buttons (tests and browser tests select by them:
        ``fwb-undo``, ``fwb-sculpt-undo``, ``fwb-paint-undo``, ``fwb-wb-undo`` ...).
    width : str
        CSS width of each button.
    errors : ErrorSink, optional
        Where exceptions of a click or of the history callback go.
    where : str
        Prefix of the history callback's error label (``"<where> history"``).

    Attributes
    ----------
    undo_button, redo_button : ipywidgets.Button
    """

    def __init__(
        self,
        model: Any,
        *,
        on_undo: Callable[[], Any],
        on_redo: Callable[[], Any],
        classes: tuple[str, str] = ("fwb-undo", "fwb-redo"),
        width: str = "80px",
        errors: ErrorSink | None = None,
        where: str = "undo/redo",
    ) -> None:
        self.model = model
        self.errors = errors if errors is not None else ErrorSink()
        self.undo_button = W.Button(description="Undo", icon="undo", layout=W.Layout(width=width))
        self.redo_button = W.Button(description="Redo", icon="repeat", layout=W.Layout(width=width))
        self.undo_button.add_class(classes[0])
        self.redo_button.add_class(classes[1])
        g = self.errors.guard
        self.undo_button.on_click(g("undo")(lambda _b: on_undo()))
        self.redo_button.on_click(g("redo")(lambda _b: on_redo()))
        self._on_history = g(f"{where} history")(self.refresh)
        model.events.history.connect(self._on_history)
        self._connected = True
        self.refresh()

    @property
    def buttons(self) -> tuple[W.Button, W.Button]:
        return self.undo_button, self.redo_button

    def refresh(self) -> None:
        """Enable / disable the buttons and name the steps in their tooltips."""
        m = self.model
        u, r = m.history.undo_labels, m.history.redo_labels
        self.undo_button.disabled = not m.can_undo
        self.redo_button.disabled = not m.can_redo
        self.undo_button.tooltip = f"Undo {u[-1]}" if u else "Nothing to undo"
        self.redo_button.tooltip = f"Redo {r[-1]}" if r else "Nothing to redo"

    def close(self) -> None:
        """Stop following the history (idempotent); the buttons stay as they are."""
        connected, self._connected = self._connected, False
        if connected:
            self.model.events.history.disconnect(self._on_history)
