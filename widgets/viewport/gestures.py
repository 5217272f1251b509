"""One gesture protocol for every pointer interaction of the viewport.

A gesture is a press, moves and a release in the browser that changes the
model across several comm messages: a tool's marker drag or brush stroke
(:mod:`widgets.viewport.tools`), and the hooked ones panels install through
``Viewport.drag_handler`` and ``Viewport.set_stroke_handler``. All of them speak the same protocol:

* the front end sends ``{"type": kind, "phase": "start" | "move" | "end" |
  "cancel", "seq", ...}`` (``kind`` is ``"drag"`` or ``"stroke"``; an optional
  ``"gesture"`` id names the press the message belongs to);
* it keeps ONE message in flight: the next one (the newest pointer position,
  or the dabs queued since) goes when the kernel answers
  ``{"type": kind + "_ack", "seq", "phase", "version", "kernel_ms"[,
  "tint_version"]}`` - or when the geometry patch carrying that ``seq``
  arrives;
* ``{"type": kind + "_cancel"}`` tells the front end the gesture is over on the
  kernel side (an error, the dragged marker gone, another widget's edit
  closed it): it stops sending;
* ``"end"`` keeps the edits: one undo step. ``"cancel"`` puts everything back
  (no undo step). An error ends the gesture keeping what was done before it.

On the model side a gesture holds an interaction *token*
(``model.begin_interaction(label, on_close=...)``): ``end_interaction`` on
release, ``cancel_interaction`` on cancel. When another widget closes it
(``model.close_interaction()`` before a discrete edit), ``on_close`` tells the
gesture, which stops and tells the front end; any later message of that
gesture is refused (acked with ``"stale": true``). A message naming a gesture
id other than the open one's is refused the same way.

:class:`Gesture` is the base class (begin / update / end / cancel),
:class:`GestureDispatcher` the one per viewport that routes messages, acks them,
keeps at most one gesture open and ends an abandoned one (watchdog).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np

from widgets._threading import UiTimer, close_interactions
from widgets.viewport.common import MAX_DABS_PER_MESSAGE

#: A gesture with no message from the front end for this long is ended (the page was
#: closed mid-drag): the model must never be left inside an interaction.
DRAG_WATCHDOG_S = 30.0


class GestureStopped(Exception):
    """Raised by a gesture that cannot go on (not an error: e.g. its marker was removed)."""


class Gesture:
    """One pointer interaction: :meth:`begin`, :meth:`update` \\*, then :meth:`end` or :meth:`cancel`.

    Subclasses set :attr:`kind` (the message type) and override :meth:`start`,
    :meth:`apply` and, when they hold more than a model interaction token,
    :meth:`close`. :meth:`open_interaction` opens the token; the base class
    ends or cancels it. Use through :class:`GestureDispatcher`, which calls
    :meth:`finished` exactly once.
    """

    kind: ClassVar[str] = ""

    def __init__(self, viewport: Any) -> None:
        self.viewport = viewport
        self.model = viewport.model
        self.token: Any = None
        self.gid: Any = None  # the front end's id of the press (None: any)
        self.label = ""
        self.open = False
        self.cancelled = False
        self.t0 = time.perf_counter()
        self.updates = 0
        self.ms: list[float] = []
        #: set by the dispatcher: called when the model closes the interaction under us
        self.on_closed_elsewhere: Callable[[Gesture], None] | None = None

    # ---------------------------------------------------------------- the protocol
    def begin(self, content: Mapping[str, Any]) -> float:
        """Start (what the "start" message does); returns kernel ms. Raises to refuse."""
        self.open = True
        try:
            return self.start(content)
        except BaseException:
            self.abort()
            raise

    def update(self, content: Mapping[str, Any]) -> float:
        """Apply one "move" message; returns kernel ms (0 once closed)."""
        if not self.live:
            return 0.0
        t0 = time.perf_counter()
        self.apply(content)
        ms = (time.perf_counter() - t0) * 1e3
        self.updates += 1
        self.ms.append(ms)
        return ms

    def end(self, content: Mapping[str, Any] | None = None) -> float:
        """Apply the "end" message's last update, then close keeping the edits (one undo step)."""
        ms = 0.0
        try:
            if content is not None and self.live and self.has_update(content):
                ms = self.update(content)
        finally:
            self.close(keep=True)
        return ms

    def cancel(self) -> None:
        """Close putting back everything the gesture changed (no undo step)."""
        self.cancelled = True
        self.close(keep=False)

    def abort(self) -> None:
        """Close after an error: by default keep what was done before it."""
        self.close(keep=True)

    @property
    def live(self) -> bool:
        """Open, and (with a token) still the model's open interaction."""
        if not self.open:
            return False
        return self.token is None or self.model.interaction_token == self.token

    # --------------------------------------------------------- for subclasses
    def start(self, content: Mapping[str, Any]) -> float:
        return 0.0

    def apply(self, content: Mapping[str, Any]) -> None:
        """One update's edit."""

    def has_update(self, content: Mapping[str, Any]) -> bool:
        return False

    def open_interaction(self, label: str) -> None:
        """Open the model interaction this gesture's edits go into (one undo step)."""
        self.label = label
        self.token = self.model.begin_interaction(label, on_close=self._closed_by_model)

    def close(self, keep: bool) -> None:
        """End (``keep``) or cancel the model interaction; idempotent."""
        self.open = False
        token, self.token = self.token, None
        if token is None:
            return
        model = self.model
        # Model lock first: the same order as edits (model lock, then events).
        with model.lock:
            if model.interaction_token != token:
                return  # closed elsewhere meanwhile (on_close has run or will run)
            if keep:
                model.end_interaction(token)
            else:
                model.cancel_interaction(token)

    def _closed_by_model(self) -> None:
        # model.close_interaction() ended our interaction (another widget's edit)
        self.token = None
        if self.open:
            self.open = False
            if self.on_closed_elsewhere is not None:
                self.on_closed_elsewhere(self)

    def stats(self) -> dict[str, Any]:
        dur = time.perf_counter() - self.t0
        ms = self.ms
        return {
            "name": self.label,
            "moves": self.updates,
            "seconds": dur,
            "median_ms": float(np.median(ms)) if ms else float("nan"),
            "last_ms": ms[-1] if ms else float("nan"),
            "updates_per_s": self.updates / dur if dur > 0 else float("nan"),
            "cancelled": self.cancelled,
        }

    def finished(self) -> None:
        """Called once after the gesture closed by any path (stats, listeners)."""


class GestureDispatcher:
    """Routes a viewport's gesture messages; at most one gesture is open.

    Parameters
    ----------
    viewport : Viewport
    factories : mapping kind -> callable(content) -> Gesture
        Makes the gesture a "start" message of that kind begins (it may look at
        the viewport's hooks: a drag handler, a stroke handler).
    ack_extra : mapping kind -> callable() -> dict
        Extra fields of that kind's acks.
    """

    def __init__(
        self,
        viewport: Any,
        factories: Mapping[str, Callable[[Mapping[str, Any]], Gesture]],
        ack_extra: Mapping[str, Callable[[], dict[str, Any]]] | None = None,
    ) -> None:
        self.viewport = viewport
        self.factories = dict(factories)
        self.ack_extra = dict(ack_extra or {})
        self.active: Gesture | None = None
        self.watchdog_s = DRAG_WATCHDOG_S
        self._watchdog: UiTimer | None = None
        self._last_msg = 0.0
        #: messages refused as stale (a closed gesture's, or another press's)
        self.refused = 0

    # ------------------------------------------------------------------ Python API
    def start(self, gesture: Gesture, content: Mapping[str, Any] | None = None) -> float:
        """Close any open gesture and every other interaction, then begin ``gesture``."""
        close_interactions(self.viewport.model)
        self.finish()
        gesture.on_closed_elsewhere = self._closed_elsewhere
        self.active = gesture
        try:
            ms = gesture.begin(content or {})
        except BaseException:
            self._retire(gesture)
            raise
        self._arm_watchdog()
        return ms

    def current(self, cls: type[Gesture] | tuple[type[Gesture], ...] = Gesture) -> Any:
        """The open gesture if it is a ``cls``, else None."""
        g = self.active
        return g if isinstance(g, cls) and g.open else None

    def update(self, gesture: Gesture, content: Mapping[str, Any]) -> float:
        if gesture is not self.active:
            return 0.0
        try:
            ms = gesture.update(content)
        except GestureStopped:
            self.abort()
            self._send_cancel(gesture.kind, gesture.gid)
            return 0.0
        self._arm_watchdog()
        return ms

    def finish(self, cls: type[Gesture] | tuple[type[Gesture], ...] = Gesture) -> None:
        """End the open gesture if it is a ``cls`` (one undo step); no-op otherwise."""
        g = self.active
        if g is None or not isinstance(g, cls):
            return
        try:
            g.end(None)
        finally:
            self._retire(g)

    def cancel(self, cls: type[Gesture] | tuple[type[Gesture], ...] = Gesture) -> None:
        """Cancel the open gesture if it is a ``cls`` (its edits put back)."""
        g = self.active
        if g is None or not isinstance(g, cls):
            return
        try:
            g.cancel()
        finally:
            self._retire(g)

    def abort(self) -> None:
        g = self.active
        if g is None:
            return
        try:
            g.abort()
        finally:
            self._retire(g)

    # ------------------------------------------------------------------ messages
    def on_message(self, kind: str, content: Mapping[str, Any]) -> None:
        """One gesture message from the front end: apply it and acknowledge it."""
        phase = content.get("phase")
        ms, stale = 0.0, False
        vp = self.viewport
        try:
            g = self.active
            if phase == "start":
                new = self.factories[kind](content)
                new.gid = content.get("gesture")
                with vp.sync.patching(content.get("seq")):
                    ms = self.start(new, content)
            elif g is None or g.kind != kind or not self._same_press(g, content):
                stale = phase in ("move", "end", "cancel")
                if stale:
                    self.refused += 1
            elif not g.live:
                stale = True
                self.refused += 1
                self._retire(g)
            elif phase == "move":
                with vp.sync.patching(content.get("seq")):
                    ms = self.update(g, content)
            elif phase == "end":
                try:
                    ms = g.end(content)
                finally:
                    self._retire(g)
            elif phase == "cancel":
                self.cancel()
        except GestureStopped:
            self.abort()
            self._send_cancel(kind, content.get("gesture"))
        except Exception as exc:
            # Never leave the model inside an interaction after a failed message.
            try:
                self.abort()
            finally:
                vp.errors.report(f"{_WHAT.get(kind, kind)} ({phase})", exc)
                self._send_cancel(kind, content.get("gesture"))
        finally:
            ack: dict[str, Any] = {
                "type": f"{kind}_ack",
                "seq": content.get("seq"),
                "phase": phase,
                "version": vp._version,
                "kernel_ms": round(ms, 3),
            }
            extra = self.ack_extra.get(kind)
            if extra is not None:
                ack.update(extra())
            if stale:
                ack["stale"] = True
            vp.send(ack)

    @staticmethod
    def _same_press(g: Gesture, content: Mapping[str, Any]) -> bool:
        gid = content.get("gesture")
        return gid is None or g.gid is None or gid == g.gid

    # ------------------------------------------------------------------ internals
    def _retire(self, g: Gesture) -> None:
        """``g`` is closed: forget it, stop the watchdog, report its stats (once)."""
        if g is not self.active:
            return
        self.active = None
        self._cancel_watchdog()
        g.finished()

    def _closed_elsewhere(self, g: Gesture) -> None:
        # another widget closed the model interaction: tell the front end to stop
        try:
            self._retire(g)
        finally:
            self._send_cancel(g.kind, g.gid)

    def _send_cancel(self, kind: str, gid: Any) -> None:
        """Tell the front end the gesture (press ``gid``, if it named one) is over."""
        msg: dict[str, Any] = {"type": f"{kind}_cancel"}
        if gid is not None:
            msg["gesture"] = gid
        self.viewport.send(msg)

    def _arm_watchdog(self) -> None:
        # One timer per gesture, not per message (an event-loop timer on the UI thread):
        # it re-arms itself for the time left.
        self._last_msg = time.monotonic()
        if self._watchdog is None:
            self._start_watchdog(self.watchdog_s)

    def _cancel_watchdog(self) -> None:
        if self._watchdog is not None:
            self._watchdog.cancel()
            self._watchdog = None

    def _start_watchdog(self, delay: float) -> None:
        self._watchdog = UiTimer(delay, self._on_watchdog)

    def _on_watchdog(self) -> None:
        try:
            if self.active is None:
                self._watchdog = None
                return
            idle = time.monotonic() - self._last_msg
            if idle < self.watchdog_s:
                self._start_watchdog(self.watchdog_s - idle)
                return
            self._watchdog = None
            self.finish()
        except Exception as exc:
            self.viewport.errors.report("ending an abandoned drag or stroke", exc)


_WHAT = {"drag": "marker drag", "stroke": "brush stroke"}


def vertex_ids(vertices: Any, n: int, what: str) -> np.ndarray:
    """The newest :data:`MAX_DABS_PER_MESSAGE` vertex ids of a message, checked against ``n``."""
    ids = np.asarray(vertices if vertices is not None else [], dtype=np.int64).reshape(-1)
    ids = ids[-MAX_DABS_PER_MESSAGE:]
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise ValueError(f"{what}: vertex ids must be in 0..{n - 1}, got {ids}")
    return ids
