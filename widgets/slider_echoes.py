"""Telling a page's echo of a slider value from a person moving the slider.

The browser snaps a value the kernel sends a slider to the slider's step and
sends the snapped value back, and ipywidgets 8 answers every value a page
sends with an ``echo_update`` of it, which the page applies. While the model
keeps moving (a playing timeline, a tracked take, a region drag solving
weights) such an echo arrives after newer values: compared with the model's
*current* value it looks like a person's edit (an undo step, and the model
pulled back to an old value), and the page would be left showing the old
value. :class:`SliderEchoes` remembers the last few values the kernel sent
each slider: a value within half a step of one of them is an echo, never an
edit; when it is not the model's current value, the slider is sent the
current value again, on the UI thread's next turn (after the update that
brought the echo), which the page's next echo then matches.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable
from typing import Any

from widgets._threading import ui_loop

__all__ = ["SliderEchoes"]


class SliderEchoes:
    """The values recently sent to each slider (by key), see the module docstring.

    Parameters
    ----------
    keep : int
        How many sent values per slider count (a burst of playback frames).
    """

    def __init__(self, keep: int = 8) -> None:
        self.keep = int(keep)
        self._sent: dict[Hashable, deque[float]] = {}

    def sent(self, key: Hashable, value: float) -> None:
        """The kernel sets slider ``key`` to ``value`` (call just before setting it)."""
        self._sent.setdefault(key, deque(maxlen=self.keep)).append(float(value))

    def forget(self, key: Hashable | None = None) -> None:
        """A person moves the slider now (older values are no echoes), or every slider (``None``)."""
        if key is None:
            self._sent.clear()
        else:
            self._sent.pop(key, None)

    def is_echo(self, key: Hashable, value: float, step: float) -> bool:
        """``value`` is one of the recently sent values, snapped to ``step`` by the page."""
        sent = self._sent.get(key)
        return bool(sent) and any(abs(v - value) <= 0.5 * step + 1e-9 for v in sent)  # type: ignore[union-attr]

    def resend_if_stale(self, key: Hashable, value: float, step: float, current: Callable[[], float | None],
                        slider: Callable[[], Any], shown: Callable[[float], float] = float) -> None:
        """After an echo ``value``: send the slider the model's ``current()`` value if the echo is not it.

        ``slider()`` gives the slider widget (None: gone); ``shown(v)`` is what the
        slider is set to for a model value ``v`` (e.g. snapped to its grid).
        """
        now = current()
        if now is None or abs(now - value) <= 0.5 * step + 1e-9:
            return  # the echo of the current value: in step

        def resend() -> None:
            v, s = current(), slider()
            if v is None or s is None or abs(float(s.value) - v) <= 0.5 * step + 1e-9:
                return
            self.sent(key, v)
            s.value = shown(v)  # the slider holds the page's stale value: a change, and sent

        loop = ui_loop()
        if loop is None:
            resend()
        else:
            loop.call_soon(resend)
