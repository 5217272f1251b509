"""``model.mouth_gain``: the family's undoable edits."""

from __future__ import annotations

from typing import Any

import numpy as np
from mouth_gain.layer import TRACK, GainState
from numpy.typing import ArrayLike


class MouthGainFacet:
    def __init__(self, model: Any) -> None:
        self._model = model

    @property
    def value(self) -> GainState:
        st: GainState = self._model.slot("mouth_gain")
        return st

    def set(self, gain: float, mask: ArrayLike | None = None) -> None:
        """Set the gain (and its mask, (n,) in [0, 1]); one undo step."""
        m = self.value.mask if mask is None else np.asarray(mask, np.float32).reshape(self._model.n_vertices)
        self._model.set_slot("mouth_gain", GainState(float(gain), m), f"Mouth gain {gain:g}")

    def key(self, time: float, gain: float) -> None:
        """Key the gain at ``time`` (seconds) on the model's timeline; one undo step."""
        self._model.timeline.add_key(TRACK, time, [float(gain)])
