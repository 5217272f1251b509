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
"""

from __future__ import annotations

import functools
import logging
import threading
import traceback
from collections.abc import Callable
from contextlib import AbstractContextManager
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


class InteractionGrouper:
    """Wraps bursts of edits in one ``model.interaction(label)``.

    The first :meth:`touch` enters the interaction; every further touch within
    ``idle_s`` seconds extends it; ``idle_s`` after the last touch a timer
    thread exits it, which records ONE undo step and emits the final events.
    :meth:`flush` ends it at once (before undo/redo, reset, closing).

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
        self._cm: AbstractContextManager[None] | None = None
        self._label = ""
        self._timer: threading.Timer | None = None

    @property
    def active(self) -> bool:
        return self._cm is not None

    def touch(self, label: str) -> None:
        """Enter the interaction if needed and restart the idle timer.

        A different label (another slider) ends the current burst first, so
        each slider drag is its own undo step.
        """
        with self._lock:
            if self._cm is not None and label != self._label:
                self._end_locked()
            if self._cm is None:
                cm = self.model.interaction(label)
                cm.__enter__()
                self._cm, self._label = cm, label
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
        """End the open interaction now (no-op if none)."""
        with self._lock:
            self._end_locked()

    def _end_locked(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        cm, self._cm = self._cm, None
        if cm is not None:
            # Model lock first: the same order as edits (model lock, then events).
            with self.model.lock:
                cm.__exit__(None, None, None)
