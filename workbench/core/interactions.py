"""Interactions: a drag, a stroke or a slider scrub as one undo step.

A mixin of :class:`workbench.core.state.FaceState`. Inside an interaction
edits emit ``*_changing`` events and remember what they replaced; on release
the final values are installed once more (bumping their versions, so layers
that took shortcuts during the drag are recomputed exactly) and one undo step
is pushed. :class:`InteractionToken` holds an interaction open across separate
messages (the viewport's gestures): ``begin_interaction`` / ``end_interaction``
/ ``cancel_interaction``; ``close_interaction`` ends whatever is open before a
discrete edit and tells the owner.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from workbench.core.history import Command, payload_nbytes
from workbench.core.shapes import ModelError


@dataclass(frozen=True)
class InteractionToken:
    """Names one open interaction (a drag, a stroke) across separate messages.

    Returned by :meth:`FaceState.begin_interaction`; pass it back to
    :meth:`~FaceState.end_interaction` (one undo step) or
    :meth:`~FaceState.cancel_interaction` (everything put back, no undo step).
    A token of an interaction already closed is refused, so a late message of
    an old gesture can never close a newer one. ``kind`` says what holds it
    (``"gesture"``: a pointer drag or stroke; ``"burst"``: a run of slider
    updates ended by an idle timer), so views can close only one kind.
    """

    label: str
    serial: int
    kind: str = "gesture"


_serials = itertools.count(1)


@dataclass
class _Interaction:
    label: str
    token: InteractionToken | None = None
    on_close: Callable[[], None] | None = None
    weights_before: dict[str, float] = field(default_factory=dict)
    slots_before: dict[str, Any] = field(default_factory=dict)
    #: scratch space of the facets for this interaction (e.g. the paint stroke's running max)
    scratch: dict[str, Any] = field(default_factory=dict)



class Interactions:
    """Interaction bookkeeping of the state (see the module docstring)."""

    _lock: threading.RLock
    _interaction: _Interaction | None
    _weights: dict[str, float]
    _slots: dict[str, Any]
    events: Any

    def _bump(self, name: str) -> None:  # provided by FaceState
        raise NotImplementedError

    def push(self, cmd: Command) -> None:  # provided by FaceState
        raise NotImplementedError

    def begin_interaction(
        self, label: str, on_close: Callable[[], None] | None = None, *, kind: str = "gesture"
    ) -> InteractionToken:
        """Open an interaction spanning several messages (a drag); returns its token.

        ``on_close`` is called when somebody else closes it with :meth:`close_interaction`;
        ``kind`` is recorded on the token (``"gesture"`` or ``"burst"``).
        """
        with self._lock:
            if self._interaction is not None:
                raise ModelError(
                    f"begin_interaction({label!r}): interaction {self._interaction.label!r} is still "
                    "open; end, cancel or close it first"
                )
            token = InteractionToken(label, next(_serials), str(kind))
            self._interaction = _Interaction(label, token=token, on_close=on_close)
            return token

    def _take(self, token: InteractionToken, what: str) -> _Interaction:
        inter = self._interaction
        if inter is None or inter.token != token:
            open_ = "none is open" if inter is None else f"{inter.label!r} is"
            raise ModelError(f"{what}: interaction {token.label!r} is not the open one ({open_})")
        self._interaction = None
        return inter

    def end_interaction(self, token: InteractionToken) -> None:
        """Close the interaction of ``token``: one undo step with everything it changed."""
        with self._lock:
            self._finish(self._take(token, "end_interaction"))

    def cancel_interaction(self, token: InteractionToken) -> None:
        """Close the interaction of ``token`` and put back what it changed (no undo step)."""
        with self._lock:
            inter = self._take(token, "cancel_interaction")
            weights = {k: v for k, v in inter.weights_before.items() if k in self._weights}
            self._settle(weights, dict(inter.slots_before))

    def close_interaction(self, kind: str | None = None) -> bool:
        """End the open token interaction, keeping its edits; True if one was open.

        Discrete edits from views (Key, Import, undo) call this first so they never
        join a drag's undo step; the owner's ``on_close`` is told. With ``kind``
        only an interaction of that kind is closed (a new slider burst closes an
        older burst, never a pointer drag).
        """
        with self._lock:
            inter = self._interaction
            if inter is None or inter.token is None:
                return False
            if kind is not None and inter.token.kind != kind:
                return False
            self.end_interaction(inter.token)
        if inter.on_close is not None:
            inter.on_close()
        return True

    @property
    def interaction_token(self) -> InteractionToken | None:
        inter = self._interaction
        return None if inter is None else inter.token

    @property
    def interacting(self) -> bool:
        return self._interaction is not None

    def interaction_scratch(self) -> dict[str, Any] | None:
        """Per-interaction scratch space for facets (None outside an interaction)."""
        inter = self._interaction
        return None if inter is None else inter.scratch

    @contextmanager
    def interaction(self, label: str) -> Iterator[None]:
        """Group edits (a drag, a scrub) into one undo step; nested calls join the outer one."""
        with self._lock:
            outer = self._interaction is not None
            if not outer:
                self._interaction = _Interaction(label)
        if outer:
            yield
            return
        try:
            yield
        finally:
            with self._lock:
                inter = self._interaction
                self._interaction = None
                assert inter is not None
                self._finish(inter)

    def _settle(self, weights: dict[str, float], slots: dict[str, Any]) -> None:
        """Install final values (bumping versions even when unchanged: layers may have been approximate)."""
        with self._lock:
            if weights:
                self._weights.update(weights)
                self._bump("weights")
                self.events.weights.emit(dict(weights))
            for name, value in slots.items():
                self._slots[name] = value
                self._bump(name)
                getattr(self.events, name).emit()
            self.events.deformed.emit(True)

    def _finish(self, inter: _Interaction) -> None:
        w_before = {k: v for k, v in inter.weights_before.items() if k in self._weights}
        w_after = {k: self._weights[k] for k in w_before}
        w_before = {k: v for k, v in w_before.items() if w_after[k] != v}
        w_after = {k: w_after[k] for k in w_before}
        s_before = dict(inter.slots_before)
        s_after = {k: self._slots[k] for k in s_before}
        if not w_before and not any(s_before[k] is not s_after[k] for k in s_before):
            if inter.weights_before or inter.slots_before:
                self._settle({}, s_after)  # nothing net changed, but views saw "changing"
            return
        self._settle(w_after, s_after)
        self.push(
            Command(
                inter.label,
                lambda: self._settle(w_before, s_before),
                lambda: self._settle(w_after, s_after),
                payload_nbytes([w_before, w_after]) + payload_nbytes(list(s_after.values())),
            )
        )

