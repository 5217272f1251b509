"""The handles family's viewport tool ``"sculpt"`` (Bickel et al. 2008 §4 handle editing).

Registered with :func:`widgets.viewport.tools.register_tool` (the handles family
names this module in its registration). In every viewport it:

* draws the model's handles as markers, with their mirror links, re-sent
  whenever the handle *set* changes (``model.events.handles``);
* turns a marker drag into a :class:`HandleDrag`: the handle moves in the view
  plane, ``model.begin_interaction("Drag handle <name>")``, one undo step;
* adds a handle on a Shift-click (:func:`add_handle`; with
  ``Viewport.symmetric`` a mirrored pair) and removes one on an Alt-click
  (:func:`remove_handle`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from widgets._threading import close_interactions
from widgets.viewport.gestures import GestureStopped
from widgets.viewport.tools import DragGesture, Tool, ToolSpec, register_tool


def resolve_handle(model: Any, index: int, vertex: int | None) -> int | None:
    """The model handle ``index`` if it sits on ``vertex``, else the handle on ``vertex`` (None: gone)."""
    verts = model.handles.vertices
    if 0 <= index < verts.size and (vertex is None or int(verts[index]) == vertex):
        return int(index)
    if vertex is not None:
        hits = np.flatnonzero(verts == vertex)
        if hits.size:
            return int(hits[0])
    return None


class HandleDrag(DragGesture):
    """Drag model handle ``index`` (found again by ``vertex`` if the handle set changes)."""

    def __init__(self, viewport: Any, index: int, vertex: int | None = None) -> None:
        super().__init__(viewport)
        self.index = int(index)
        self.vertex = vertex
        self.name = ""

    def start(self, content: Mapping[str, Any]) -> float:
        vp, model = self.viewport, self.model
        with model.lock:
            h = model.handles
            resolved = resolve_handle(model, self.index, self.vertex)
            if resolved is None:
                raise ValueError(
                    f"Viewport: no handle {self.index} at vertex {self.vertex} to drag "
                    f"(the model has {len(h)} handles)"
                )
            self.index, self.vertex = resolved, int(h.vertices[resolved])
            self.name = str(h.names[resolved])
            self.open_interaction(f"Drag handle {self.name}")
        vp.selected_marker = self.index
        return 0.0

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
        p = np.asarray(self.model_point(content), dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"Viewport.drag_to: position must be 3 finite numbers, got {p!r}")
        with model.lock:
            index = resolve_handle(model, self.index, self.vertex)
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


def add_handle(viewport: Any, vertex: int) -> int:
    """Add a model handle at ``vertex`` (Shift-click); with ``viewport.symmetric`` a mirrored pair.

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
            raise ValueError(f"add handle: vertex must be in 0..{model.n_vertices - 1}, got {v}")
        V = np.asarray(model.vertices)
        labels = np.asarray(model.component_labels)
        same = np.flatnonzero(labels == labels[v]) if labels.size else np.arange(model.n_vertices)
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
    """Remove a model handle (Alt-click); with ``viewport.symmetric`` its mirror too (one undo step)."""
    from workbench.model import HandleSet

    model = viewport.model
    close_interactions(model)
    with model.lock:
        i = resolve_handle(model, index, vertex)
        if i is None:
            return
        h = model.handles
        drop = {i}
        if viewport.symmetric and h.mirror[i] >= 0:
            drop.add(int(h.mirror[i]))
        if len(drop) == 1:
            model.handles.remove(i)
            return
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


class SculptTool(Tool):
    """Drag, add and remove the model's handles; draws them as markers (see the module docstring)."""

    kind = "drag"

    def __init__(self, viewport: Any) -> None:
        super().__init__(viewport)
        self._on_handles = viewport.errors.guard("Viewport handles update")(self._changed)
        ev = viewport.model.events
        ev.handles.connect(self._on_handles)
        ev.handles_changing.connect(self._on_handles)

    def _changed(self, *_args: Any) -> None:
        self.viewport.refresh_tool()

    def gesture(self, content: Mapping[str, Any]) -> HandleDrag:
        v = content.get("vertex")
        return HandleDrag(self.viewport, int(content["index"]), None if v is None else int(v))

    def pick(self, vertex: int) -> None:
        add_handle(self.viewport, vertex)

    def unpick(self, index: int, vertex: int | None) -> None:
        remove_handle(self.viewport, index, vertex)

    def markers(self) -> tuple[np.ndarray, np.ndarray]:
        h = self.model.handles
        return np.asarray(h.vertices), np.asarray(h.mirror)

    def close(self) -> None:
        ev = self.model.events
        ev.handles.disconnect(self._on_handles)
        ev.handles_changing.disconnect(self._on_handles)


TOOL = register_tool(ToolSpec("sculpt", "drag", SculptTool, order=10))
