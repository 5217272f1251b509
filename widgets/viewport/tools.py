"""The viewport's gestures: handle drag, paint stroke, and the hooked drag / stroke.

Each is a :class:`~widgets.viewport.gestures.Gesture` run by the viewport's
:class:`~widgets.viewport.gestures.GestureDispatcher`:

* :class:`HandleDrag` (``tool="sculpt"``, Bickel et al. 2008 §4): moves a model
  handle in the view plane; ``model.begin_interaction("Drag handle <name>")``.
* :class:`PaintStroke` (``tool="paint"``, Pighin et al. 1998 §4.2): brush dabs
  on the selected expression's paint layer; ``"Paint <expression>"``.
* :class:`HookedDrag`: marker drags go to ``viewport.drag_handler`` (region pin
  drag, region brush, split-seed pick in :mod:`widgets.regions.tools`) with
  ``begin(index, vertex)``, ``move(index, position) -> ms``, ``end()`` and
  optionally ``cancel()``; the handler owns its model interaction.
* :func:`add_handle` / :func:`remove_handle`: Shift-click / Alt-click (single
  messages, not gestures).
* :class:`HookedStroke`: paint strokes go to the object given to
  ``viewport.set_stroke_handler`` (the wrinkle eraser) with ``begin()``,
  ``dab(vertices)``, ``end()``, ``cancel()`` and optionally ``overlay()``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from widgets._threading import close_interactions
from widgets.viewport.gestures import Gesture, GestureStopped, vertex_ids


class HandleDrag(Gesture):
    """Drag model handle ``index`` (found again by ``vertex`` if the handle set changes)."""

    kind = "handle"

    def __init__(self, viewport: Any, index: int, vertex: int | None = None) -> None:
        super().__init__(viewport)
        self.index = int(index)
        self.vertex = vertex
        self.name = ""

    def start(self, content: Mapping[str, Any]) -> float:
        vp, model = self.viewport, self.model
        with model.lock:
            h = model.handles
            resolved = vp._resolve_handle(self.index, self.vertex)
            if resolved is None:
                raise ValueError(
                    f"Viewport: no handle {self.index} at vertex {self.vertex} to drag "
                    f"(the model has {len(h)} handles)"
                )
            self.index, self.vertex = resolved, int(h.vertices[resolved])
            self.name = str(h.names[resolved])
            self.open_interaction(f"Drag handle {self.name}")
        vp.selected_handle = self.index
        return 0.0

    def has_update(self, content: Mapping[str, Any]) -> bool:
        return content.get("position") is not None or "model_position" in content

    def update(self, content: Mapping[str, Any]) -> float:
        vp = self.viewport
        vp.sync.last_push_ms = 0.0
        ms = super().update(content)
        if ms:
            vp.drag_ms.append(ms)
            vp.drag_push_ms.append(vp.sync.last_push_ms)
        return ms

    def apply(self, content: Mapping[str, Any]) -> None:
        vp, model = self.viewport, self.model
        if "model_position" in content:
            p = np.asarray(content["model_position"], dtype=np.float64).reshape(-1)
        else:
            p = np.asarray(vp._unposed(content["position"]), dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"Viewport.drag_to: position must be 3 finite numbers, got {p!r}")
        with model.lock:
            index = vp._resolve_handle(self.index, self.vertex)
            if index is None:
                raise GestureStopped("the dragged handle was removed")
            self.index = index
            offset = p - model.blended()[self.vertex]
            model.handles.move(index, offset, symmetric=vp.symmetric)

    def finished(self) -> None:
        vp = self.viewport
        st = self.stats()
        vp.last_drag = {**{k: v for k, v in st.items() if k != "cancelled"}, "name": self.name}
        if self.label and not self.cancelled:
            for fn in list(vp.drag_listeners):
                vp.errors.guard("drag listener")(fn)(dict(vp.last_drag))


class PaintStroke(Gesture):
    """Paint ``expression`` (default the viewport's ``paint_expression``) with the press's brush."""

    kind = "paint"

    def __init__(self, viewport: Any, expression: str | None = None) -> None:
        super().__init__(viewport)
        self.expression = expression if expression is not None else viewport.paint_expression
        self.dabs = 0
        self.dab_ms: list[float] = []
        self.brush: Any = None

    def start(self, content: Mapping[str, Any]) -> float:
        from workbench.methods.paint.expressions import expression_names

        model, expr = self.model, self.expression
        if not expr:
            raise ValueError(
                "Viewport: pick an expression to paint with first "
                "(click a thumbnail in the Paint tab's palette, or set paint_expression)"
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
        self.brush = self.viewport.brush
        return self.update(content) if self.has_update(content) else 0.0

    def has_update(self, content: Mapping[str, Any]) -> bool:
        v = content.get("vertices")
        return v is not None and bool(np.size(v))

    def update(self, content: Mapping[str, Any]) -> float:
        ids = vertex_ids(content.get("vertices"), self.model.n_vertices, "Viewport.paint_at")
        if not ids.size or not self.live:
            return 0.0
        ms = super().update({"vertices": ids})
        self.dabs += int(ids.size)
        self.viewport.paint_ms.append(ms)
        return ms

    def apply(self, content: Mapping[str, Any]) -> None:
        vp, model = self.viewport, self.model
        # one overlay + geometry update after the last dab of the message
        with vp.sync.held(), model.lock:
            for v in content["vertices"]:
                td = time_ms()
                model.paint.dab(self.expression, int(v), self.brush)
                ms = time_ms() - td
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


class HookedStroke(Gesture):
    """A paint stroke sent to a stroke handler (see ``Viewport.set_stroke_handler``)."""

    kind = "paint"

    def __init__(self, viewport: Any, handler: Any, target: str = "") -> None:
        super().__init__(viewport)
        self.handler = handler
        self.label = target
        self._handler_open = False

    def start(self, content: Mapping[str, Any]) -> float:
        self.handler.begin()
        self._handler_open = True
        return self.update(content) if self.has_update(content) else 0.0

    def has_update(self, content: Mapping[str, Any]) -> bool:
        v = content.get("vertices")
        return v is not None and bool(np.size(v))

    def apply(self, content: Mapping[str, Any]) -> None:
        ids = vertex_ids(content.get("vertices"), self.model.n_vertices, "paint stroke")
        if ids.size:
            self.handler.dab(ids)
            self.viewport.sync.sync_paint()

    def close(self, keep: bool) -> None:
        self.open = False
        if not self._handler_open:
            return
        self._handler_open = False
        try:
            if keep:
                self.handler.end()
            else:
                self.handler.cancel()
        finally:
            self.viewport.sync.sync_paint()

    def abort(self) -> None:
        # a failed dab drops the stroke (the handler applies nothing)
        self.cancelled = True
        self.close(keep=False)


class HookedDrag(Gesture):
    """A marker drag sent to ``viewport.drag_handler`` (region pin drag, region brush, seed pick)."""

    kind = "handle"

    def __init__(self, viewport: Any, handler: Any, index: int, vertex: int | None) -> None:
        super().__init__(viewport)
        self.handler = handler
        self.index = int(index)
        self.vertex = vertex
        self._handler_open = False

    def start(self, content: Mapping[str, Any]) -> float:
        self._handler_open = True
        self.handler.begin(self.index, self.vertex)
        return 0.0

    def has_update(self, content: Mapping[str, Any]) -> bool:
        return content.get("position") is not None

    def update(self, content: Mapping[str, Any]) -> float:
        if not self.live or content.get("position") is None:
            return 0.0
        pos = self.viewport._unposed(content["position"])
        ms = float(self.handler.move(self.index, pos) or 0.0)
        self.updates += 1
        self.ms.append(ms)
        return ms

    def close(self, keep: bool) -> None:
        self.open = False
        if not self._handler_open:
            return
        self._handler_open = False
        cancel = getattr(self.handler, "cancel", None)
        if not keep and cancel is not None:
            cancel()
        else:
            self.handler.end()


# ----------------------------------------------------------------- handle clicks


def add_handle(viewport: Any, vertex: int) -> int:
    """Add a model handle at ``vertex`` (Shift-click); with :attr:`symmetric` a mirrored pair.

    A pair is one undo step. Returns the new handle's index.
    """
    from workbench.methods.handles.presets import mirror_vertices
    from workbench.model import HandleSet

    model = viewport.model
    close_interactions(model)
    with model.lock:
        h = model.handles
        v = int(vertex)
        if not 0 <= v < model.n_vertices:
            raise ValueError(
                f"Viewport.add_handle_at: vertex must be in 0..{model.n_vertices - 1}"
            )
        V = np.asarray(model.vertices)
        labels = np.asarray(model.component_labels)
        same = (
            np.flatnonzero(labels == labels[v]) if labels.size else np.arange(model.n_vertices)
        )
        mid_tol = 0.01 * float(np.linalg.norm(np.ptp(V[same], axis=0)))
        idx = len(h)
        name = f"user_{idx}"
        if not viewport.symmetric or abs(V[v, 0]) <= mid_tol:
            return int(model.handles.add(v, name=name))
        m = int(mirror_vertices(V, np.array([v]), same)[0])
        side, other = ("L", "R") if V[v, 0] > 0 else ("R", "L")
        model.handles.set(
            HandleSet(
                np.append(h.vertices, [v, m]),
                np.vstack([h.offsets, np.zeros((2, 3), np.float32)]),
                (*h.names, f"user_{side}_{idx}", f"user_{other}_{idx}"),
                np.append(h.mirror, [idx + 1, idx]),
            ),
            label=f"Add handle pair user_{idx}",
        )
        return idx

def remove_handle(viewport: Any, index: int, vertex: int | None = None) -> None:
    """Remove a model handle (Alt-click); with :attr:`symmetric` its mirror too (one undo step)."""
    from workbench.model import HandleSet

    model = viewport.model
    close_interactions(model)
    with model.lock:
        i = viewport._resolve_handle(index, vertex)
        if i is None:
            return
        h = model.handles
        drop = {i}
        if viewport.symmetric and h.mirror[i] >= 0:
            drop.add(int(h.mirror[i]))
        if len(drop) == 1:
            model.handles.remove(i)
        else:
            keep = np.array([k not in drop for k in range(len(h))])
            remap = np.cumsum(keep) - 1
            mir = h.mirror[keep]
            gone = np.isin(mir, list(drop)) | (mir < 0)
            mir = np.where(gone, -1, remap[np.maximum(mir, 0)])
            model.handles.set(
                HandleSet(
                    h.vertices[keep],
                    h.offsets[keep],
                    tuple(nm for k, nm in enumerate(h.names) if k not in drop),
                    mir,
                ),
                label=f"Remove handle pair {h.names[i]}",
            )
        if viewport.selected_handle >= len(model.handles):
            viewport.selected_handle = -1


def time_ms() -> float:
    return time.perf_counter() * 1e3
