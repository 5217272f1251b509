"""The UI thread: error reporting, event-loop timers, slider bursts, and a guard.

ipywidgets keeps per-widget state with no lock (``hold_sync``,
``_states_to_send``, ``_property_lock``) and expects every trait change and
comm message on the kernel's main thread, the thread whose asyncio loop
handles the comm messages (:func:`route_widget_comms_to_main_thread` keeps
ipykernel from handling them on a subshell thread, whatever the page asks).
Everything here keeps the widgets on that one *UI thread*, as napari keeps Qt
on its main thread:

* :class:`UiTimer` / :func:`ui_loop`: timers on the kernel's event loop
  (``loop.call_later``), never ``threading.Timer``; :func:`call_on_ui_thread`
  hands a worker's result back with ``call_soon_threadsafe``.
* :func:`install_thread_guard`: a debug guard (``WORKBENCH_UI_THREAD_GUARD=1``,
  on in every test run) that raises, and records, when a widget trait is set
  or a comm message is sent off the UI thread.
* :class:`ErrorSink`: widget callbacks' exceptions go to an
  ``ipywidgets.Output`` (``append_stderr``) and the ``widgets`` logger.
* :class:`InteractionGrouper`: a slider drag is one
  :meth:`workbench.FaceModel.interaction` (one undo step). The page says when
  it ends: the viewport's front end reports a pointer press and release on a
  slider (:func:`slider_pointer`), sent only after the page has sent every
  value it set. An idle timer ends a burst only where no page reported a
  press (a keyboard nudge, a slider shown without a viewport), and a long one
  covers a page that vanished mid-drag.
* :func:`close_interactions`: ends every interaction widgets hold open on a
  model before a discrete edit (Key, Import, a drag's start, undo ...), so the
  edit is an undo step of its own.

Hand-written because neither ipywidgets nor psygnal offers a thread guard or
"an idle timeout around a context manager" on the kernel's loop.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import os
import threading
import traceback
import weakref
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import ipywidgets

log = logging.getLogger("widgets")

F = TypeVar("F", bound=Callable[..., Any])

#: the thread that owns the widgets (the kernel's main thread)
_ui_thread: threading.Thread = threading.main_thread()
#: the UI thread's running event loop, remembered when first seen running there
_ui_loop: asyncio.AbstractEventLoop | None = None


def on_ui_thread() -> bool:
    """True on the thread that owns the widgets (the kernel's main thread)."""
    return threading.current_thread() is _ui_thread


@contextmanager
def ui_thread_is(thread: threading.Thread) -> Iterator[None]:
    """Treat ``thread`` as the UI thread inside the block (a test running its own loop there)."""
    global _ui_thread, _ui_loop
    saved = _ui_thread, _ui_loop
    _ui_thread, _ui_loop = thread, None
    try:
        yield
    finally:
        _ui_thread, _ui_loop = saved


def ui_loop() -> asyncio.AbstractEventLoop | None:
    """The UI thread's running event loop (the kernel's), or None where none runs (a script).

    Remembered the first time it is seen running on the UI thread (any widget
    built in a notebook cell or comm handler), so a worker thread can hand
    work back to it.
    """
    global _ui_loop
    if on_ui_thread():
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            loop = None
        if loop is not None:
            _ui_loop = loop
            return loop
    known = _ui_loop
    if known is not None and known.is_running() and not known.is_closed():
        return known
    return None


def call_on_ui_thread(fn: Callable[[], Any]) -> None:
    """Run ``fn`` on the UI thread: now if this is it, else through the loop's ``call_soon_threadsafe``.

    With no loop known (a script without an event loop) ``fn`` runs here.
    """
    if on_ui_thread():
        fn()
        return
    loop = ui_loop()
    if loop is None:
        fn()
    else:
        loop.call_soon_threadsafe(fn)


class UiTimer:
    """A one-shot timer on the UI thread's event loop; :meth:`cancel` stops it.

    Created on the UI thread (widget callbacks are). Where no event loop runs
    (a script, a unit test) nothing is scheduled (:attr:`armed` is False): the
    owner's explicit ``flush``/``close`` ends what the timer would have.
    """

    def __init__(self, delay: float, callback: Callable[[], None]) -> None:
        loop = ui_loop()
        self._handle: asyncio.TimerHandle | None = (
            loop.call_later(max(float(delay), 0.0), callback) if loop is not None else None
        )

    @property
    def armed(self) -> bool:
        return self._handle is not None and not self._handle.cancelled()

    def cancel(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None


class UiScheduler:
    """A :class:`workbench.autosave.Scheduler` for notebooks: timers on the kernel's loop, results on the UI thread."""

    def call_later(self, delay: float, callback: Callable[[], Any], /) -> UiTimer:
        return UiTimer(delay, callback)

    def call_soon_threadsafe(self, callback: Callable[[], Any], /) -> None:
        call_on_ui_thread(callback)


# ------------------------------------------------------------------ the guard
#: what the guard caught (one line each); tests assert it stays empty
thread_violations: list[str] = []
_guard_installed = False


class UiThreadError(RuntimeError):
    """A widget was changed, or a comm message sent, off the UI thread."""


def _check_thread(what: str) -> None:
    if on_ui_thread():
        return
    text = f"{what} on thread {threading.current_thread().name!r}, not the UI thread"
    thread_violations.append(text)
    raise UiThreadError(text)


def install_thread_guard() -> None:
    """Raise :class:`UiThreadError` when a widget trait changes or a comm message goes out off the UI thread.

    A debug aid, on when ``WORKBENCH_UI_THREAD_GUARD=1`` (every test run sets
    it, the browser tests for their kernels too). Each violation is also kept
    in :data:`thread_violations`, since callbacks may swallow the exception.
    """
    global _guard_installed
    if _guard_installed:
        return
    _guard_installed = True
    widget = ipywidgets.Widget
    notify, send = widget.notify_change, widget._send

    @functools.wraps(notify)
    def notify_change(self: Any, change: Any) -> Any:
        _check_thread(f"{type(self).__name__}.{change.get('name', '?')} set")
        return notify(self, change)

    @functools.wraps(send)
    def _send(self: Any, msg: Any, buffers: Any = None) -> Any:
        _check_thread(f"{type(self).__name__} comm message {msg.get('method', '?')!r} sent")
        return send(self, msg, buffers)

    widget.notify_change = notify_change
    widget._send = _send


if os.environ.get("WORKBENCH_UI_THREAD_GUARD", "") not in ("", "0"):
    install_thread_guard()


#: the comm target of every ipywidgets widget
WIDGET_COMM_TARGET = "jupyter.widget"
#: ipywidgets' control comm: its ``request_states`` reads every widget's state (the page's restore)
WIDGET_CONTROL_TARGET = "jupyter.widget.control"
#: the comm targets whose messages must run on the main thread
MAIN_THREAD_TARGETS = frozenset({WIDGET_COMM_TARGET, WIDGET_CONTROL_TARGET})


def route_widget_comms_to_main_thread() -> bool:
    """Have ipykernel deliver every widget's comm messages on the kernel's main thread.

    ipykernel 7 can run a front end's comm messages on *subshell* threads; JupyterLab 4.4+
    asks for one per comm target unless *Kernel Comms over subshells* is *Disabled*, and
    Notebook 7.6 asks whatever that setting says (it does not load the plugin that applies
    it). ipykernel's shell-channel thread picks the subshell of an incoming
    ``comm_msg`` / ``comm_close`` by asking the comm (``_reply_subshell_for``, ipykernel
    7.4); this answers "the main shell" for widget comms and for ipywidgets' control comm,
    so the messages queue for the main thread as they did before subshells, whatever the
    page asked. The control comm matters as much: its ``request_states`` (the page restoring
    its widgets) walks every live widget and reads its state; on a subshell thread it ran
    while a cell on the main thread was still building widgets, and the page, given a
    half-built set, could look up a child model before it existed ("Error displaying
    widget: model not found", seen once in JupyterLab 4.6 from the wheel). Other comms
    keep ipykernel's routing. Returns False where ipykernel has no such hook (before 7.4;
    before 7.0 there are no subshells at all).
    """
    try:
        from ipykernel.comm.comm import BaseComm
    except ImportError:  # not in an ipykernel kernel
        return False
    routed = getattr(BaseComm, "_reply_subshell_for", None)
    if routed is None:
        return False
    if getattr(routed, "_fwb_main_thread", False):
        return True

    @functools.wraps(routed)
    def _reply_subshell_for(self: Any, data: Any, default: Any) -> Any:
        if getattr(self, "target_name", None) in MAIN_THREAD_TARGETS:
            return None  # the main shell: the kernel's main thread
        return routed(self, data, default)

    _reply_subshell_for._fwb_main_thread = True  # type: ignore[attr-defined]
    BaseComm._reply_subshell_for = _reply_subshell_for  # type: ignore[method-assign]
    return True


route_widget_comms_to_main_thread()


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
    still held. The open token interaction is closed with
    ``model.close_interaction()`` (its owner is told through ``on_close``).
    ``bursts_only``: only a slider burst (an :class:`InteractionGrouper`'s);
    pointer drags stay open.
    """
    close = getattr(model, "close_interaction", None)  # a rig session has no interactions
    if close is not None:
        close(kind="burst" if bursts_only else None)


class SliderPointer:
    """What the page said about the pointer on a slider: pressed, or released.

    The viewport's front end watches pointer presses on any ipywidgets slider
    of its page and sends ``slider_pointer`` messages (down / up); the up is
    sent only once the page has sent every widget state it had buffered, so
    the slider's last value reaches the kernel before it. ``up`` ends every
    open slider burst: a drag is one undo step because the page says when it
    ends.
    """

    def __init__(self) -> None:
        self.held = False
        #: presses and releases reported (tests, diagnostics)
        self.presses = 0
        self.releases = 0
        self._groupers: weakref.WeakSet[InteractionGrouper] = weakref.WeakSet()

    def down(self) -> None:
        self.held = True
        self.presses += 1
        for g in list(self._groupers):
            g._rearm()

    def up(self) -> None:
        self.held = False
        self.releases += 1
        for g in list(self._groupers):
            g.flush()


#: the one slider pointer of this kernel (a kernel's pages share the person's pointer)
slider_pointer = SliderPointer()


class InteractionGrouper:
    """Wraps one slider drag's stream of edits in one model interaction (a ``"burst"`` token).

    The first :meth:`touch` opens ``model.begin_interaction(label, kind="burst")``;
    the burst ends when the page reports the pointer's release on the slider
    (:data:`slider_pointer`), when another slider is touched, at :meth:`flush`
    (before undo/redo, reset, closing) or when another widget's edit closes it
    (:func:`close_interactions`, which calls back :meth:`_closed`). Timers, on
    the kernel's event loop, only cover what the page cannot say: ``idle_s``
    after the last touch when no press was reported (a keyboard nudge, a slider
    shown without a viewport), ``watchdog_s`` while the pointer is held (a page
    that vanished mid-drag). While a pointer drag is open a touch joins it (a
    slider update during a drag is the model's echo) and no burst is opened.

    Parameters
    ----------
    model : FaceModel
    idle_s : float
        Idle time that ends a burst no page reported a press for. 0.5 s keeps a
        keyboard-repeat run one step and ends it before a person reaches for
        Undo (whose button closes it at once anyway).
    errors : ErrorSink
    watchdog_s : float
        Idle time that ends a burst while the page says the pointer is held.
    """

    def __init__(
        self,
        model: Any,
        idle_s: float = 0.5,
        errors: ErrorSink | None = None,
        watchdog_s: float = 30.0,
    ) -> None:
        self.model = model
        self.idle_s = float(idle_s)
        self.watchdog_s = float(watchdog_s)
        self.errors = errors or ErrorSink()
        self._token: Any = None
        self._label = ""
        self._timer: UiTimer | None = None
        slider_pointer._groupers.add(self)

    @property
    def active(self) -> bool:
        return self._token is not None

    def touch(self, label: str) -> None:
        """Open the burst if needed and restart its timer.

        A different label (another slider) ends the current burst first, so
        each slider drag is its own undo step.
        """
        if self._token is not None and label != self._label:
            self._end()
        if self._token is None:
            model = self.model
            # another panel's burst ends first; a pointer drag stays open
            close_interactions(model, bursts_only=True)
            if model.interacting:
                return  # joins the open drag (no timer: nothing of ours to end)
            self._token = model.begin_interaction(label, on_close=self._closed, kind="burst")
            self._label = label
        self._rearm()

    def _rearm(self) -> None:
        if self._token is None:
            return
        if self._timer is not None:
            self._timer.cancel()
        delay = self.watchdog_s if slider_pointer.held else self.idle_s
        self._timer = UiTimer(delay, self._on_timer)

    def _on_timer(self) -> None:
        try:
            self.flush()
        except Exception as exc:
            self.errors.report("end of slider interaction", exc)

    def flush(self) -> None:
        """End the open burst now (no-op if none)."""
        self._end()

    def _closed(self) -> None:
        # the model closed our burst (close_interactions before another edit)
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._token = None

    def _end(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        token, self._token = self._token, None
        if token is not None and self.model.interaction_token == token:
            self.model.end_interaction(token)
