"""Error reporting and thread helpers shared by the notebook widgets.

Widget callbacks run in places where an exception is easy to lose: psygnal
callbacks fired by a model edit made on another thread, ipywidgets ``observe``
handlers called while the kernel processes a comm message (possibly on a
kernel *subshell* thread, see ``widgets/jupyter_settings/overrides.json``),
and ``threading.Timer`` callbacks. :class:`ErrorSink` catches them and appends
the traceback to an ``ipywidgets.Output`` (via ``append_stderr``, which works
from any thread, unlike ``with output:`` that depends on the current cell) and
to the ``widgets`` logger.

:class:`InteractionGrouper` turns a stream of slider updates into one
:meth:`workbench.FaceModel.interaction` (one undo step): ipywidgets does not
tell Python when a slider drag ends, so the interaction ends after a short
idle time. Hand-written because neither ipywidgets nor psygnal offers an
"idle timeout around a context manager".

:func:`close_interactions` ends every interaction that widgets hold open on a
model before a discrete edit (Key, Import, a drag's start, undo ...). Pointer
gestures (``widgets.viewport.gestures``) and slider bursts hold an interaction
*token* (``model.begin_interaction(label, on_close=...)``), so this is
``model.close_interaction()``: the model ends the open one (one undo step) and
tells its owner through ``on_close``. Without it such an edit made within the
idle time of a slider drag would join the drag's interaction and share its undo
step ("Drag jawOpen" swallowing "Key 1 weights"), and ``set_time`` / ``undo``,
which refuse to run inside an interaction, would fail.
"""

from __future__ import annotations

import functools
import logging
import threading
import traceback
import weakref
from collections.abc import Callable
from typing import Any, TypeVar

import ipywidgets

log = logging.getLogger("widgets")

F = TypeVar("F", bound=Callable[..., Any])


class ErrorSink:
    """Collects exceptions from widget callbacks into a visible Output widget.

    Parameters
    ----------
    output : ipywidgets.Output, optional
        Where tracebacks are appended; a new one is created if omitted.
    on_error : callable, optional
        Called with a one-line summary (e.g. to show a banner in the viewport).
    """

    def __init__(
        self,
        output: ipywidgets.Output | None = None,
        on_error: Callable[[str], None] | None = None,
    ) -> None:
        self.output = output if output is not None else ipywidgets.Output()
        self.on_error = on_error
        self.count = 0

    def report(self, where: str, exc: BaseException) -> None:
        """Show ``exc`` (raised in ``where``) in the Output and the log."""
        self.count += 1
        text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        log.error("error in %s:\n%s", where, text)
        try:
            self.output.append_stderr(f"[{where}] {text}")
            if self.on_error is not None:
                self.on_error(f"{where}: {type(exc).__name__}: {exc}")
        except Exception:  # the sink itself must never raise into psygnal/ipywidgets
            log.exception("could not display an error from %s", where)

    def guard(self, where: str) -> Callable[[F], F]:
        """Decorator: run the function, report (do not propagate) any exception."""

        def deco(fn: F) -> F:
            @functools.wraps(fn)
            def wrapper(*args: Any, **kwargs: Any) -> Any:
                try:
                    return fn(*args, **kwargs)
                except Exception as exc:
                    self.report(where, exc)
                    return None

            return wrapper  # type: ignore[return-value]

        return deco


def close_interactions(model: Any, *, bursts_only: bool = False) -> None:
    """End every interaction the widgets hold open on ``model`` (each becomes its undo step).

    Call before a discrete edit (a key, an import, undo, the start of a drag),
    so the edit is an undo step of its own instead of joining a slider drag
    whose idle timer has not fired yet. The open token interaction is closed
    with ``model.close_interaction()`` (its owner is told through ``on_close``).
    ``bursts_only``: only a slider burst (an :class:`InteractionGrouper`'s);
    pointer drags stay open.
    """
    token = getattr(model, "interaction_token", None)
    if token is not None and (not bursts_only or token in _burst_tokens):
        model.close_interaction()


#: tokens of the open slider bursts (``close_interactions(bursts_only=True)`` closes only these)
_burst_tokens: weakref.WeakSet[Any] = weakref.WeakSet()


class InteractionGrouper:
    """Wraps bursts of edits in one model interaction (an interaction token).

    The first :meth:`touch` opens ``model.begin_interaction(label)``; every
    further touch within ``idle_s`` seconds extends it; ``idle_s`` after the last
    touch a timer thread ends it, which records ONE undo step and emits the
    final events. :meth:`flush` ends it at once (before undo/redo, reset,
    closing); :func:`close_interactions` (any other widget's edit of the model)
    closes it through the model, which calls back :meth:`_closed`. A new burst
    first closes another panel's burst. While a pointer drag is open the
    touch joins it (a slider update during a drag is the model's echo, not
    the user's edit) and no burst is opened.

    Parameters
    ----------
    model : FaceModel
    idle_s : float
        Idle time that ends the burst. Slider updates of one drag arrive every
        16-100 ms in a normal browser, but gaps of up to 0.23 s were measured in
        headless Chromium with software WebGL on 2 busy cores; 0.5 s keeps such a
        drag one step while still closing it before a person reaches for Undo
        (and the panel's Undo button closes it at once anyway). Holding the mouse
        still for longer than this mid-drag starts a new step.
    errors : ErrorSink
    """

    def __init__(self, model: Any, idle_s: float = 0.5, errors: ErrorSink | None = None) -> None:
        self.model = model
        self.idle_s = float(idle_s)
        self.errors = errors or ErrorSink()
        self._lock = threading.RLock()
        self._token: Any = None
        self._label = ""
        self._timer: threading.Timer | None = None

    @property
    def active(self) -> bool:
        return self._token is not None

    def touch(self, label: str) -> None:
        """Open the burst if needed and restart the idle timer.

        A different label (another slider) ends the current burst first, so
        each slider drag is its own undo step.
        """
        with self._lock:
            if self._token is not None and label != self._label:
                self._end_locked()
            if self._token is None:
                model = self.model
                # another panel's burst ends first; a pointer drag stays open
                close_interactions(model, bursts_only=True)
                with model.lock:
                    if model.interacting:
                        return  # joins the open drag (no timer: nothing of ours to end)
                    token = model.begin_interaction(label, on_close=self._closed)
                    _burst_tokens.add(token)
                self._token, self._label = token, label
            if self._timer is not None:
                self._timer.cancel()
            self._timer = threading.Timer(self.idle_s, self._on_idle)
            self._timer.daemon = True
            self._timer.start()

    def _on_idle(self) -> None:
        try:
            self.flush()
        except Exception as exc:
            self.errors.report("end of slider interaction", exc)

    def flush(self) -> None:
        """End the open burst now (no-op if none)."""
        with self._lock:
            self._end_locked()

    def _closed(self) -> None:
        # the model closed our burst (close_interactions before another edit)
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            self._token = None

    def _end_locked(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        token, self._token = self._token, None
        if token is not None:
            # Model lock first: the same order as edits (model lock, then events).
            with self.model.lock:
                if self.model.interaction_token == token:
                    self.model.end_interaction(token)
