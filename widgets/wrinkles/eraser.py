"""Erasing one example's wrinkles with the brush: the stroke handler and its controls.

While an example card's *Erase* toggle is on, the viewport's paint tool sends
its strokes to a :class:`WrinkleEraser` (``Viewport.set_stroke_handler``)
instead of the paint layers: the dabs grow the stroke's mask
(:func:`workbench.methods.wrinkles.editing.brush_mask`), drawn as the paint
overlay while painting, and the release becomes one
``model.wrinkles.edit_example(example, mask=...)``: one undo step per stroke.
:class:`EraseControls` is the brush box (radius, strength, a note) and switches
the viewport's tool and stroke handler on and off.
"""

from __future__ import annotations

from typing import Any

import ipywidgets as W
import numpy as np
from numpy.typing import NDArray

__all__ = ["EraseControls", "WrinkleEraser"]


class WrinkleEraser:
    """Stroke handler that paints one example's wrinkles out (the viewport's stroke hook).

    Each dab adds the brush footprint (surface distance on the rest mesh, the
    brush's falloff, x-mirror) to the stroke's mask, keeping the largest
    strength any dab gave a vertex (as a paint stroke caps at its opacity);
    release applies the mask with ``panel.erase_wrinkles``: one undo step per
    stroke. Usable without a viewport (tests call :meth:`begin` / :meth:`dab` /
    :meth:`end`).

    Parameters
    ----------
    panel : WrinklePanel
        Gives the model, the brush (:meth:`WrinklePanel.eraser_brush`) and applies the stroke.
    example : str
        The example whose wrinkles the strokes erase.

    Attributes
    ----------
    last_mask : (n,) float32 or None
        The mask of the last applied stroke.
    """

    def __init__(self, panel: Any, example: str) -> None:
        self.panel = panel
        self.example = example
        self.last_mask: NDArray[np.float32] | None = None
        self._mask: NDArray[np.float32] | None = None
        self._brush: Any = None

    @property
    def stroking(self) -> bool:
        """True between :meth:`begin` and :meth:`end` / :meth:`cancel`."""
        return self._mask is not None

    def begin(self) -> None:
        """Start a stroke with the panel's eraser brush."""
        self._brush = self.panel.eraser_brush()
        self._mask = np.zeros(self.panel.model.n_vertices, np.float32)

    def dab(self, vertices: Any) -> None:
        """Brush dabs centred at vertex ids ``vertices`` (int or sequence)."""
        from workbench.methods.wrinkles.editing import brush_mask

        if self._mask is None:
            raise RuntimeError("WrinkleEraser.dab: no stroke open (begin first)")
        ids = np.asarray(vertices, np.int64).reshape(-1)
        n = self._mask.shape[0]
        if ids.size and (ids.min() < 0 or ids.max() >= n):
            raise ValueError(f"WrinkleEraser.dab: vertex ids must be in 0..{n - 1}")
        if ids.size:  # a new array each time: the viewport sends what changed
            self._mask = brush_mask(self._mask, self.panel.model.paint.surface, self._brush, ids)

    def overlay(self) -> NDArray[np.float32] | None:
        """The open stroke's mask so far (the viewport tints it), or None."""
        m = self._mask
        return None if m is None or not np.any(m) else m

    def end(self) -> bool:
        """Apply the stroke's mask (one undo step); False when it erased nothing."""
        mask, self._mask = self._mask, None
        if mask is None or not np.any(mask > 0):
            return False
        self.last_mask = mask
        return bool(self.panel.erase_wrinkles(self.example, mask))

    def cancel(self) -> None:
        """Drop the open stroke without changing anything."""
        self._mask = None


class EraseControls:
    """The eraser's brush box and the switch of the viewport's stroke handler.

    Parameters
    ----------
    panel : WrinklePanel
    viewport : widgets.Viewport or None

    Attributes
    ----------
    radius, strength : ipywidgets.FloatSlider
        The brush (the radius is linked to the viewport's ``brush_radius``: its cursor ring).
    note : ipywidgets.HTML
    box : ipywidgets.VBox
        Shown while erasing.
    eraser : WrinkleEraser or None
    toggles : dict of str -> ipywidgets.ToggleButton
        The *Erase* toggle of each example card (set by the panel).
    """

    def __init__(self, panel: Any, viewport: Any) -> None:
        from widgets.viewport import brush_radius_slider

        self.panel = panel
        self.viewport = viewport
        self.eraser: WrinkleEraser | None = None
        self.toggles: dict[str, W.ToggleButton] = {}
        self._tool_before: str | None = None
        self._syncing = False
        style = {"description_width": "60px"}
        self.radius = brush_radius_slider(panel.model, viewport, "radius", style=style,
                                          layout=W.Layout(width="260px"))
        self.radius.add_class("fwb-wrinkle-erase-radius")
        self.strength = W.FloatSlider(value=1.0, min=0.0, max=1.0, step=0.05, description="strength",
                                      readout_format=".2f", style=style, layout=W.Layout(width="220px"))
        self.strength.add_class("fwb-wrinkle-erase-strength")
        self.note = W.HTML("")
        self.note.add_class("fwb-wrinkle-erase-note")
        self.box = W.VBox(
            [self.note, W.HBox([self.radius, self.strength], layout=W.Layout(flex_flow="row wrap"))],
            layout=W.Layout(display="none", border="1px solid #c6c", padding="2px"),
        )
        self.box.add_class("fwb-wrinkle-erase-box")

    @property
    def erasing(self) -> str | None:
        return None if self.eraser is None else self.eraser.example

    def toggle(self, name: str, tooltip: str, width: str) -> W.ToggleButton:
        """A card's *Erase* toggle for example ``name`` (kept in :attr:`toggles` by the panel)."""
        tb = W.ToggleButton(value=self.erasing == name, description="Erase", icon="eraser",
                            tooltip=tooltip, layout=W.Layout(width=width))
        tb.add_class("fwb-wrinkle-erase")
        guard = self.panel.errors.guard(f"erase wrinkles {name}")
        tb.observe(guard(lambda change: self._on_toggle(name, change)), "value")
        return tb

    def start(self, name: str) -> WrinkleEraser:
        """Strokes now erase ``name``'s wrinkles (the viewport's paint tool, previous tool kept)."""
        if self.eraser is not None:
            if self.eraser.example == name:
                return self.eraser
            self.stop()
        eraser = WrinkleEraser(self.panel, name)
        self.eraser = eraser  # first: the Workbench keeps the Sculpt tab for this tool change
        vp = self.viewport
        if vp is not None:
            vp.set_stroke_handler(eraser, f"erase {name} wrinkles")
            if vp.tool != "paint":
                self._tool_before = vp.tool
                vp.tool = "paint"
        self.sync()
        return eraser

    def stop(self) -> None:
        """The previous viewport tool again; strokes paint expressions."""
        eraser = self.eraser
        if eraser is None:
            return
        self.eraser = None
        eraser.cancel()
        vp = self.viewport
        if vp is not None:
            if vp.stroke_handler is eraser:
                vp.set_stroke_handler(None)
            before, self._tool_before = self._tool_before, None
            if before is not None and vp.tool == "paint":
                vp.tool = before
        self.sync()

    def on_tool(self, change: dict) -> None:
        """Another tool picked (a tab, a cell): the eraser no longer gets strokes."""
        if self.eraser is not None and change["new"] != "paint":
            self._tool_before = None
            self.stop()

    def _on_toggle(self, name: str, change: dict) -> None:
        if self._syncing:
            return
        if change["new"]:
            self.panel.start_erasing(name)
        elif self.erasing == name:
            self.stop()

    def sync(self) -> None:
        """Toggles, box and note follow :attr:`erasing`."""
        name = self.erasing
        self._syncing = True
        try:
            for n, tb in self.toggles.items():
                if tb.value != (n == name):
                    tb.value = n == name
        finally:
            self._syncing = False
        self.box.layout.display = "" if name else "none"
        self.note.value = (
            f"<b>Erasing {name}</b>'s wrinkles: paint on the face (one undo step per stroke). "
            f"Click <i>{name}</i> to view its pose; untoggle to stop."
            if name else ""
        )
