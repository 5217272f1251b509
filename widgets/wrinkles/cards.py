"""The example cards of the wrinkle panel: picture, *view* button, *Erase* toggle, detail factor.

One card per fitted example of ``model.wrinkles``: a thumbnail of its detailed
mesh (:mod:`.thumbnails`), a button with its name that views it (sets its
weights), the eraser's toggle (:mod:`.eraser`) and how strong its details are
now relative to when the feature graph was fitted ("detail ×0.50" after a
scale edit).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import ipywidgets as W
import numpy as np

from widgets.wrinkles.eraser import EraseControls
from widgets.wrinkles.thumbnails import THUMB_SIZE, ExampleThumbnails

__all__ = ["ExampleCards"]

_WIDTH = f"{THUMB_SIZE[0] + 8}px"


class ExampleCards:
    """The cards box (:attr:`box`) of a model's wrinkle examples, rebuilt by :meth:`update`.

    Parameters
    ----------
    model : workbench.FaceModel
    erase : EraseControls
        Makes each card's *Erase* toggle (and keeps them).
    view : callable (name) -> None
        What the name button does (guarded: errors go to ``guard``'s sink).
    guard : callable (where) -> decorator
        ``ErrorSink.guard`` of the panel.
    thumbnails : bool
        Render a picture per example.
    """

    def __init__(self, model: Any, erase: EraseControls, view: Callable[[str], None],
                 guard: Callable[[str], Callable[[Any], Any]], thumbnails: bool = True) -> None:
        self.model = model
        self.erase = erase
        self.view = view
        self.guard = guard
        self.thumbnails = bool(thumbnails)
        self.box = W.Box(layout=W.Layout(flex_flow="row wrap", width="100%", grid_gap="4px"))
        self.box.add_class("fwb-wrinkle-examples")
        self._pictures = ExampleThumbnails(model)
        self._first: tuple[Any, dict[str, float]] = (None, {})  # (graph, detail RMS at its fit)

    def factors(self) -> dict[str, float]:
        """Each example's detail RMS now over the one it had when its feature graph was fitted."""
        w = self.model.wrinkles
        values = w.pose_space.train_values
        now = {n: float(np.sqrt(np.mean(np.square(values[j], dtype=np.float64))))
               for j, n in enumerate(w.example_names)}
        if self._first[0] is not w.graph:
            self._first = (w.graph, {})
        first = self._first[1]
        for n, v in now.items():
            first.setdefault(n, v)
        return {n: v / first[n] if first[n] > 0 else 1.0 for n, v in now.items()}

    def update(self) -> None:
        """One card per example of ``model.wrinkles`` (none when not fitted)."""
        w = self.model.wrinkles
        if not w.fitted:
            self.box.children = []
            self.erase.toggles = {}
            return
        names = list(w.example_names)
        factors = self.factors()
        pngs = self._pictures.render(names) if self.thumbnails else {}
        toggles = {n: self.erase.toggle(n, f"Erase wrinkles with the brush: strokes on the face paint {n}'s "
                                           "wrinkles out (one undo step per stroke)", _WIDTH) for n in names}
        self.box.children = [self._card(n, factors[n], toggles[n], pngs.get(n)) for n in names]
        self.erase.toggles = toggles
        self.erase.sync()

    def _card(self, name: str, factor: float, erase: W.ToggleButton, png: bytes | None) -> W.VBox:
        b = W.Button(description=name, tooltip=f"View {name}: set its weights on the model (undoable)",
                     layout=W.Layout(width=_WIDTH))
        b.add_class("fwb-wrinkle-view")
        b.on_click(self.guard(f"view example {name}")(lambda _b: self.view(name)))
        label = W.HTML(f"<div style='font-size:11px;text-align:center;color:#555'>detail ×{factor:.2f}</div>",
                       layout=W.Layout(width=_WIDTH))
        parts: list[W.Widget] = [b, erase, label]
        if png is not None:
            parts.insert(0, W.Image(value=png, format="png", width=THUMB_SIZE[0], height=THUMB_SIZE[1]))
        card = W.VBox(parts, layout=W.Layout(align_items="center", border="1px solid #ddd", padding="2px"))
        card.add_class("fwb-wrinkle-card")
        return card
