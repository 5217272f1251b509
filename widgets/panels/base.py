"""``ModelPanel``: what every tool panel over a :class:`workbench.FaceModel` shares.

A panel observes the model through ``model.events`` and edits it only through
its public methods and facets. The base holds the plumbing each panel used to
repeat:

* the model, the :class:`widgets._threading.ErrorSink` callback errors go to,
  and the ``before_edit`` callables (another panel's slider burst, the
  viewport's open drag or stroke) that end before a whole-model edit;
* :meth:`listen`: connect a model event to a slot guarded by the error sink,
  :meth:`link` and :meth:`observe_trait` for another widget's traits (the
  viewport's brush, tool), and :meth:`on_close` for any other teardown (listener
  lists, progress callbacks); :meth:`close` undoes all of it exactly once, last in
  first out, then closes the widget;
* :meth:`flush` (end every open interaction, then the ``before_edit``
  callables), :meth:`undo` / :meth:`redo` after it, and
  :meth:`undo_redo_buttons` (:class:`widgets.panels.undo_redo.UndoRedoButtons`
  wired to them, disconnected on close);
* :func:`button`, the small helper that makes a classed button.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

import ipywidgets as W
import traitlets

from widgets._threading import ErrorSink, close_interactions
from widgets.panels.undo_redo import UndoRedoButtons

__all__ = ["ModelPanel", "button"]

F = TypeVar("F", bound=Callable[..., Any])


def button(desc: str, cls: str, tip: str = "", icon: str = "", width: str = "auto") -> W.Button:
    """A button with description, CSS class, tooltip, icon and width."""
    b = W.Button(description=desc, tooltip=tip, icon=icon, layout=W.Layout(width=width))
    b.add_class(cls)
    return b


def _remove(listeners: list[Any], item: Any) -> None:
    if item in listeners:
        listeners.remove(item)


class ModelPanel(W.VBox):
    """Base of the panels: a VBox over one model, with guarded, recorded connections.

    Subclasses call ``super().__init__(model, errors=..., before_edit=..., layout=...)``
    first, then build their widgets, set ``self.children`` and connect with
    :meth:`listen`.

    Parameters
    ----------
    model : workbench.FaceModel
    errors : ipywidgets.Output or ErrorSink, optional
        Where callback errors are shown (``Workbench`` passes a shared Output).
    before_edit : iterable of callables
        Called by :meth:`flush` (before undo/redo and whole-model edits), e.g.
        to close another panel's slider interaction.
    on_error : callable, optional
        Also told a one-line summary of each error (when ``errors`` is not
        already an ErrorSink).
    **box : Any
        Passed to :class:`ipywidgets.VBox` (``layout`` ...).

    Attributes
    ----------
    errors : ErrorSink
    """

    def __init__(
        self,
        model: Any,
        *,
        errors: W.Output | ErrorSink | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
        on_error: Callable[[str], None] | None = None,
        **box: Any,
    ) -> None:
        self._model = model
        self.errors = errors if isinstance(errors, ErrorSink) else ErrorSink(errors, on_error)
        self._before_edit: list[Callable[[], Any]] = list(before_edit)
        self._teardown = contextlib.ExitStack()
        self._connected = True
        super().__init__(**box)

    @property
    def model(self) -> Any:
        return self._model

    @property
    def connected(self) -> bool:
        """True until :meth:`close` (or :meth:`disconnect`) ran."""
        return self._connected

    # ------------------------------------------------------------ connections
    def guard(self, what: str) -> Callable[[F], F]:
        """Decorator reporting a callback's exceptions to :attr:`errors` under ``what``."""
        return self.errors.guard(what)

    def listen(self, signal: Any, slot: Callable[..., Any], what: str) -> Callable[..., Any]:
        """Connect ``slot`` (guarded under ``what``) to a psygnal ``signal`` until :meth:`close`.

        Returns the guarded slot that was connected.
        """
        guarded = self.errors.guard(what)(slot)
        signal.connect(guarded)
        self.on_close(signal.disconnect, guarded)
        return guarded

    def add_listener(
        self, listeners: list[Any], slot: Callable[..., Any], what: str
    ) -> Callable[..., Any]:
        """Append ``slot`` (guarded under ``what``) to a plain listener list until :meth:`close`.

        For the viewport's ``drag_listeners`` / ``stroke_listeners``; returns the guarded slot.
        """
        guarded = self.errors.guard(what)(slot)
        listeners.append(guarded)
        self.on_close(_remove, listeners, guarded)
        return guarded

    def link(self, source: tuple[Any, str], target: tuple[Any, str]) -> None:
        """Keep two traits equal (``traitlets.link``) until :meth:`close`."""
        self.on_close(traitlets.link(source, target).unlink)

    def observe_trait(self, obj: Any, slot: Callable[..., Any], name: str, what: str) -> Callable[..., Any]:
        """Observe trait ``name`` of ``obj`` with ``slot`` (guarded under ``what``) until :meth:`close`.

        Returns the guarded slot that was connected.
        """
        guarded = self.errors.guard(what)(slot)
        obj.observe(guarded, name)
        self.on_close(obj.unobserve, guarded, name)
        return guarded

    def on_close(self, fn: Callable[..., Any], *args: Any) -> None:
        """Have :meth:`close` call ``fn(*args)`` (once; the last registered runs first)."""
        self._teardown.callback(fn, *args)

    def disconnect(self) -> None:
        """Undo every :meth:`listen` and run every :meth:`on_close` callable, once.

        Every one runs even if another raises (the exception is raised after).
        """
        if not getattr(self, "_connected", False):  # closed, or __init__ never got that far
            return
        if not self._connected:
            return
        self._connected = False
        stack, self._teardown = self._teardown, contextlib.ExitStack()
        stack.close()

    def close(self) -> None:
        """Disconnect from the model (and whatever :meth:`on_close` registered), close the widget."""
        try:
            self.disconnect()
        finally:
            super().close()

    # ------------------------------------------------------------ edits
    def flush(self) -> None:
        """End every interaction open on the model, then call the ``before_edit`` callables."""
        close_interactions(self._model)
        for fn in self._before_edit:
            fn()

    def undo(self) -> str | None:
        """Undo the model's last step (after :meth:`flush`); its label, or None."""
        self.flush()
        return self._model.undo()

    def redo(self) -> str | None:
        """Redo the model's last undone step (after :meth:`flush`); its label, or None."""
        self.flush()
        return self._model.redo()

    def undo_redo_buttons(
        self, undo_class: str, redo_class: str, *, width: str = "80px"
    ) -> UndoRedoButtons:
        """Undo / Redo buttons calling :meth:`undo` / :meth:`redo`, following the history until close."""
        buttons = UndoRedoButtons(
            self._model,
            on_undo=self.undo,
            on_redo=self.redo,
            classes=(undo_class, redo_class),
            width=width,
            errors=self.errors,
            where=type(self).__name__,
        )
        self.on_close(buttons.close)
        return buttons
