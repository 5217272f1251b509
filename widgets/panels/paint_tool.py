"""The paint family's viewport tool ``"paint"`` (Pighin et al. 1998 §4.2 painterly blending).

Registered with :func:`widgets.viewport.tools.register_tool` (the paint family
names this module in its registration). In every viewport it:

* turns a press on the face into a :class:`PaintStroke`: brush dabs on the paint
  layer of :attr:`PaintTool.expression` with the viewport's brush
  (``brush_radius`` along the surface, ``brush_opacity``, ``brush_falloff``,
  ``brush_mode``, ``brush_mirror``), ``model.begin_interaction("Paint
  <expression>")``, one undo step per stroke;
* tints the surface by the painted weight of :attr:`PaintTool.expression` (white
  skin -> magenta at weight 1) while :attr:`PaintTool.overlay` is on, re-sent as
  the paint layers change.

``viewport.tools["paint"]`` is this tool: :class:`widgets.PaintPanel` links its
palette and overlay check box to :attr:`~PaintTool.expression` and
:attr:`~PaintTool.overlay`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import traitlets as t

from widgets.viewport.gestures import vertex_ids
from widgets.viewport.tools import StrokeGesture, Tool, ToolSpec, register_tool
from workbench.methods.paint.expressions import expression_names
from workbench.methods.paint.painting import Brush


def viewport_brush(viewport: Any) -> Brush:
    """The :class:`~workbench.methods.paint.painting.Brush` of a viewport's brush settings."""
    return Brush(
        radius=viewport.brush_radius,
        opacity=viewport.brush_opacity,
        falloff=viewport.brush_falloff,
        mode=viewport.brush_mode,
        mirror=viewport.brush_mirror,
    )


class PaintStroke(StrokeGesture):
    """Paint ``expression`` with the brush of the press."""

    def __init__(self, viewport: Any, expression: str) -> None:
        super().__init__(viewport)
        self.expression = expression
        self.dabs = 0
        self.dab_ms: list[float] = []
        self.brush: Brush | None = None

    def start(self, content: Mapping[str, Any]) -> float:
        model, expr = self.model, self.expression
        if not expr:
            raise ValueError(
                "Viewport: pick an expression to paint with first "
                "(click a thumbnail in the Paint tab's palette, or set viewport.tools['paint'].expression)"
            )
        with model.lock:
            if expr not in expression_names(model):
                raise KeyError(
                    f"Viewport: cannot paint {expr!r}: no such expression; "
                    f"have {expression_names(model)[:8]}..."
                )
            self.open_interaction(f"Paint {expr}")
        # The brush of the press is used for the whole stroke: slider changes made
        # mid-stroke (another view) apply to the next one.
        self.brush = viewport_brush(self.viewport)
        return self.update(content) if self.has_update(content) else 0.0

    def update(self, content: Mapping[str, Any]) -> float:
        ids = vertex_ids(content.get("vertices"), self.model.n_vertices, "Viewport.stroke_at")
        if not ids.size or not self.live:
            return 0.0
        ms = super().update({"vertices": ids})
        self.dabs += int(ids.size)
        self.viewport.stroke_ms.append(ms)
        return ms

    def apply(self, content: Mapping[str, Any]) -> None:
        vp, model = self.viewport, self.model
        # one overlay + geometry update after the last dab of the message
        with vp.batch(), model.lock:
            for v in content["vertices"]:
                t0 = time.perf_counter()
                model.paint.dab(self.expression, int(v), self.brush)
                ms = (time.perf_counter() - t0) * 1e3
                self.dab_ms.append(ms)
                vp.dab_ms.append(ms)

    def finished(self) -> None:
        vp, st = self.viewport, self.stats()
        dab = self.dab_ms
        vp.last_stroke = {
            "expression": self.expression,
            "dabs": self.dabs,
            "messages": self.updates,
            "seconds": st["seconds"],
            "median_dab_ms": float(np.median(dab)) if dab else float("nan"),
            "median_ms": st["median_ms"],
            "updates_per_s": st["updates_per_s"],
        }
        if self.label and not self.cancelled:
            for fn in list(vp.stroke_listeners):
                vp.errors.guard("stroke listener")(fn)(dict(vp.last_stroke))


class PaintTool(Tool):
    """Paint the model's expressions with the viewport's brush (see the module docstring)."""

    kind = "stroke"

    #: the expression the brush paints (a blendshape or saved expression; "" = none: the
    #: left button then orbits)
    expression = t.Unicode("")
    #: tint the surface by the painted weight of :attr:`expression`
    overlay = t.Bool(True)

    def __init__(self, viewport: Any) -> None:
        super().__init__(viewport)
        self._on_paint = viewport.errors.guard("Viewport paint overlay")(self._changed)
        ev = viewport.model.events
        ev.paint_layers.connect(self._on_paint)
        ev.paint_layers_changing.connect(self._on_paint)

    @t.observe("expression", "overlay")
    def _changed(self, *_args: Any) -> None:
        self.viewport.refresh_tool()

    @property
    def brush(self) -> Brush:
        """The brush a stroke starting now uses."""
        return viewport_brush(self.viewport)

    def gesture(self, content: Mapping[str, Any]) -> PaintStroke:
        target = content.get("target")
        return PaintStroke(self.viewport, str(target) if target else self.expression)

    def tint(self) -> np.ndarray | None:
        expr = self.expression if self.overlay else ""
        return self.model.paint.get(expr) if expr else None

    def target(self) -> str:
        return self.expression

    def close(self) -> None:
        ev = self.model.events
        ev.paint_layers.disconnect(self._on_paint)
        ev.paint_layers_changing.disconnect(self._on_paint)


TOOL = register_tool(ToolSpec("paint", "stroke", PaintTool, order=20))
