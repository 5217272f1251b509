"""Its viewport tool ``"gain_brush"``: brush the mask the gain applies in (a ``"stroke"`` tool).

A press on the face with this tool paints the mask to 1 at the brushed
vertices (one undo step per stroke); the mask is drawn as the surface tint
while the tool is current. Registered for every viewport because the family
names this module (``Family(viewport="mouth_gain.tool")``); the viewport itself
is not edited.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from mouth_gain.layer import GainState

from widgets.viewport.tools import StrokeGesture, Tool, ToolSpec, register_tool


class GainStroke(StrokeGesture):
    def start(self, content: Mapping[str, Any]) -> float:
        self.open_interaction("Brush mouth gain mask")
        return self.update(content) if self.has_update(content) else 0.0

    def apply(self, content: Mapping[str, Any]) -> None:
        st: GainState = self.model.slot("mouth_gain")
        mask = np.zeros(self.model.n_vertices, np.float32) if st.mask is None else st.mask.copy()
        mask[np.asarray(content["vertices"], dtype=np.int64)] = 1.0
        self.model.mouth_gain.set(st.gain, mask)


class GainBrush(Tool):
    kind = "stroke"

    def __init__(self, viewport: Any) -> None:
        super().__init__(viewport)
        self._changed = viewport.errors.guard("gain brush")(lambda *_: viewport.refresh_tool())
        viewport.model.events.mouth_gain.connect(self._changed)

    def gesture(self, content: Mapping[str, Any]) -> GainStroke:
        return GainStroke(self.viewport)

    def tint(self) -> np.ndarray | None:
        mask = self.model.slot("mouth_gain").mask
        return mask if self.viewport.tool == self.name and mask is not None else None

    def target(self) -> str:
        return "mouth gain mask"

    def close(self) -> None:
        self.model.events.mouth_gain.disconnect(self._changed)


TOOL = register_tool(ToolSpec("gain_brush", "stroke", GainBrush, order=50))
