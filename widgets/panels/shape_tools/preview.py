"""The split preview: colours by each half's share, shown in the viewport and given back after.

While *Preview* is on (moving the band slider turns it on) the viewport colours
each vertex by the share each half would get (orange = subject's left, blue =
right, brighter where the shape moves), through the public
``viewport.vertex_colors``; the previous colours come back when the preview
ends (a split, the toggle, leaving the tab, closing).
"""

from __future__ import annotations

from typing import Any

import ipywidgets as W
import numpy as np

from widgets.panels.base import ModelPanel

#: preview colours (sRGB) of the subject's left and right halves, and of vertices that do not move
LEFT_COLOR = (0.98, 0.55, 0.18)
RIGHT_COLOR = (0.22, 0.50, 0.98)
_STILL = (0.80, 0.80, 0.80)
#: how much of the side colour vertices the shape does not move still get
_STILL_TINT = 0.35


def split_preview_colors(left_share: Any, delta: Any = None) -> np.ndarray:
    """(n, 3) float32 sRGB: :data:`LEFT_COLOR` / :data:`RIGHT_COLOR` mixed by ``left_share``.

    Where ``delta`` ((n, 3), the shape being split) moves a vertex the colour is
    full; elsewhere it is faded toward grey, so the band shows where it matters.
    """
    f = np.clip(np.asarray(left_share, np.float64).reshape(-1, 1), 0.0, 1.0)
    side = f * np.asarray(LEFT_COLOR) + (1.0 - f) * np.asarray(RIGHT_COLOR)
    strength = np.full((len(f), 1), 1.0)
    if delta is not None:
        mag = np.linalg.norm(np.asarray(delta, np.float64), axis=1)
        top = float(mag.max()) if mag.size else 0.0
        if top > 0.0:
            strength = (
                _STILL_TINT + (1.0 - _STILL_TINT) * np.clip(mag / (0.25 * top), 0.0, 1.0)[:, None]
            )
        else:
            strength[:] = _STILL_TINT
    out = strength * side + (1.0 - strength) * np.asarray(_STILL)
    return out.astype(np.float32)


class _SplitPreview(ModelPanel):
    """The shape selection and the split preview of :class:`ShapeToolsPanel` (built there)."""

    viewport: Any
    shape: W.Dropdown
    preview: W.ToggleButton
    falloff: W.FloatSlider
    _saved_colors: Any
    _previewing: bool

    # ------------------------------------------------------------ reading
    @property
    def selected(self) -> str | None:
        """The shape the split / mirror / remove buttons act on."""
        value = self.shape.value
        return value if isinstance(value, str) else None

    def select(self, name: str) -> None:
        """Select shape ``name`` (ignored when the model has no such shape)."""
        if name in self._model.shape_names:
            self.shape.value = name

    @property
    def previewing(self) -> bool:
        return self._previewing

    # ------------------------------------------------------------ split preview
    def _on_preview(self, change: dict) -> None:
        if change["new"]:
            self.show_preview()
        else:
            self.end_preview()

    def _on_falloff(self, _change: Any = None) -> None:
        if self._previewing:
            self._draw_preview()
        else:
            self.show_preview()  # adjusting the band shows it

    def show_preview(self) -> None:
        """Colour the viewport by the split's left share (keeps the current colours to give back)."""
        vp = self.viewport
        if vp is None:
            return
        if not self._previewing:
            self._saved_colors = vp.vertex_colors
            self._previewing = True
        if not self.preview.value:
            self.preview.value = True  # its observer comes back here and draws
            return
        self._draw_preview()

    def _draw_preview(self) -> None:
        vp = self.viewport
        if vp is None or not self._previewing:
            return
        m = self._model
        share = m.shape_tools.split_weights(float(self.falloff.value))
        name = self.selected
        delta = m.shape(name).delta if name is not None and name in m.shape_names else None
        vp.vertex_colors = split_preview_colors(share, delta)

    def end_preview(self) -> None:
        """Stop the split preview: the viewport gets its previous colours back."""
        if self._previewing:
            self._previewing = False
            if self.viewport is not None:
                self.viewport.vertex_colors = self._saved_colors
            self._saved_colors = None
        if self.preview.value:
            self.preview.value = False
