"""The layer: ``below + d = neutral + (1 + (g − 1) m) ⊙ (below − neutral)``, m a soft mask."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.core.linear import LinearTerms

TRACK = "mouth_gain"  # the timeline track that keys the gain


@dataclass(frozen=True)
class GainState:
    """The slot's value: the gain and the mask it applies in (None: the whole face)."""

    gain: float = 1.0
    mask: NDArray[np.float32] | None = None


def mask_of(st: GainState, view: Any) -> NDArray[np.float64]:
    """(n,) the mask the gain applies in (ones without one)."""
    return np.ones(view.n_vertices) if st.mask is None else np.asarray(st.mask, np.float64)


class MouthGainLayer:
    """Linear in the keyed weights while the gain itself is not keyed (then it is baked)."""

    name = "mouth_gain"
    reads = ("mouth_gain",)
    linear = True

    def gain(self, view: Any) -> NDArray[np.float64] | None:
        st: GainState = view.slot("mouth_gain")
        return None if st.gain == 1.0 else 1.0 + (st.gain - 1.0) * mask_of(st, view)

    def controls(self, view: Any, timeline: Any) -> None:
        return None

    def linear_terms(self, view: Any, timeline: Any) -> LinearTerms:
        if timeline is not None and TRACK in timeline.tracks:
            return LinearTerms(baked="the gain is keyed: a product of two keyed quantities")
        g = self.gain(view)
        return LinearTerms(gain=g, detail="" if g is None else f"gain {view.slot('mouth_gain').gain:g}")

    def displacement(self, view: Any, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        g = self.gain(view)
        if g is None:
            return None
        return ((g.astype(np.float32) - np.float32(1.0))[:, None] * (below - view.vertices32)).astype(np.float32)
