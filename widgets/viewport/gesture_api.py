"""The viewport's gesture calls from Python: what the front end's messages do, callable from code.

:class:`GestureAPI` is mixed into :class:`widgets.viewport.widget.Viewport`
(kept apart so the widget's module stays readable). Each call is a thin
entry into :mod:`widgets.viewport.gestures` — begin / update / end / cancel of
a marker drag or a brush stroke, the same protocol the mouse drives — routed
to a panel's hook or to the registered tool of that kind
(:mod:`widgets.viewport.tools`), plus the lookup gestures share (a picked
point back in model space).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from widgets.viewport.gestures import Gesture, GestureDispatcher, vertex_ids
from widgets.viewport.tools import DragGesture, HookedDrag, HookedStroke, StrokeGesture, Tool


class GestureAPI:
    """Marker drags and brush strokes driven from Python (mixed into ``Viewport``)."""

    gestures: GestureDispatcher
    drag_handler: Any
    stroke_handler: Any
    stroke_target: str
    tools: dict[str, Tool]
    tool: str
    sync: Any
    errors: Any
    _model: Any

    if TYPE_CHECKING:  # the widget's (a definition here would shadow it)

        @property
        def _connected(self) -> bool: ...

        def refresh_tool(self) -> None: ...

    def begin_drag(self, index: int, vertex: int | None = None) -> None:
        """Start dragging marker ``index`` (at ``vertex``): what the front end's "start" message does.

        The drag goes to ``drag_handler`` if a panel set one, else to the drag tool
        (the current tool if it drags markers, else the first registered one), which
        opens its model interaction. An open gesture, and every interaction other
        widgets hold open (a slider burst), is ended first.
        """
        self.gestures.start(self._drag_gesture({"index": int(index), "vertex": vertex}))

    def drag_to(self, position: Any) -> float:
        """Move the dragged marker's vertex to ``position`` (3,) in model space.

        Returns the kernel time in ms (the edit + evaluate + send); 0 without a drag.
        """
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(
                f"Viewport.drag_to: position must be 3 finite numbers, got {position!r}"
            )
        g = self.gestures.current(DragGesture)
        return 0.0 if g is None else self.gestures.update(g, {"model_position": p})

    def end_drag(self) -> None:
        """End the open marker drag (one undo step); no-op without one."""
        self.gestures.finish(DragGesture)

    def begin_stroke(self, target: str | None = None) -> None:
        """Start a brush stroke: what a press on the face does.

        The stroke goes to the stroke handler if a panel set one, else to the stroke
        tool (the current tool if it strokes, else the first registered one) with
        ``target`` (default: the tool's own :meth:`~widgets.viewport.tools.Tool.target`). An open
        gesture, and every interaction other widgets hold open, is ended first.
        """
        self.gestures.start(self._stroke_gesture({} if target is None else {"target": target}))

    def stroke_at(self, vertices: Any) -> float:
        """Brush dabs at vertex ids ``vertices`` (int or sequence) within the open stroke.

        One tint + geometry update is sent after the last dab. Returns the kernel
        time in ms (dabs + updates); 0 without an open stroke.
        """
        ids = vertex_ids(vertices, self._model.n_vertices, "Viewport.stroke_at")
        g = self.gestures.current(StrokeGesture)
        return 0.0 if g is None else self.gestures.update(g, {"vertices": ids})

    def end_stroke(self) -> None:
        """End the open brush stroke (one undo step); no-op without one."""
        self.gestures.finish(StrokeGesture)

    def cancel_gesture(self) -> None:
        """Cancel the open gesture: its edits are put back, no undo step."""
        self.gestures.cancel()

    def set_stroke_handler(self, handler: Any, target: str = "") -> None:
        """Send brush strokes to ``handler`` instead of the stroke tool (None: back).

        ``handler`` has ``begin()``, ``dab(vertices)``, ``end()``, ``cancel()``
        and optionally ``overlay() -> (n,) float or None`` (drawn as the surface
        tint while it is set). ``target`` describes what a stroke does (the front
        end strokes on a press only when it, or the stroke tool's target, is set).
        An open stroke of the previous handler is cancelled; an open stroke of the
        tool is ended.
        """
        if handler is not None and not str(target):
            raise ValueError("Viewport.set_stroke_handler: describe the stroke's target")
        g = self.gestures.active
        if isinstance(g, HookedStroke) and g.handler is not handler:
            self.gestures.cancel(HookedStroke)
        if handler is not None and not isinstance(self.gestures.active, HookedStroke):
            self.gestures.finish(StrokeGesture)
        self.stroke_handler = handler
        # while a handler is set, stroke_target is its target (refresh_tool leaves it)
        self.stroke_target = str(target) if handler is not None else ""
        overlay = getattr(handler, "overlay", None) if handler is not None else None
        self.sync.tint_source = overlay if overlay is not None else (
            (lambda: None) if handler is not None else None
        )
        # the tint's source changed: send the difference to what the front end has
        if self._connected:
            self.refresh_tool()

    def tool_of_kind(self, kind: str) -> Tool | None:
        """The tool a ``kind`` gesture goes to: the current tool if it is one, else the first registered."""
        current = self.tools.get(self.tool)
        if current is not None and current.kind == kind:
            return current
        return next((tl for tl in self.tools.values() if tl.kind == kind), None)

    def tools_current_first(self) -> list[Tool]:
        """The tools, the current one first (whose markers and tint are drawn first)."""
        current = self.tools.get(self.tool)
        return [current, *(tl for tl in self.tools.values() if tl is not current)] if current else list(self.tools.values())

    def _drag_gesture(self, content: Mapping[str, Any]) -> Gesture:
        v = content.get("vertex")
        index, vertex = int(content["index"]), None if v is None else int(v)
        if self.drag_handler is not None:
            return HookedDrag(self, self.drag_handler, index, vertex)
        tool = self.tool_of_kind("drag")
        if tool is None:
            raise ValueError("Viewport: no registered tool drags markers")
        return tool.gesture({**content, "index": index, "vertex": vertex})

    def _stroke_gesture(self, content: Mapping[str, Any]) -> Gesture:
        if self.stroke_handler is not None:
            return HookedStroke(self, self.stroke_handler, self.stroke_target)
        tool = self.tool_of_kind("stroke")
        if tool is None:
            raise ValueError("Viewport: no registered tool makes brush strokes")
        return tool.gesture(content)

    def unposed(self, position: Any) -> Any:
        """A point picked on the shown mesh, in model space.

        The view draws :meth:`FaceModel.evaluate`, which applies the keyed head pose
        last (or the unposed face under the pose :meth:`show_head_pose` set); the
        edits a pointer makes live before it, so a pointer position is mapped back
        with the inverse rigid transform (a no-op without a pose).
        """
        M = self.sync.shown_matrix()
        if np.array_equal(M, np.eye(4)):
            return position
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,):
            raise ValueError(f"Viewport: a position must be 3 numbers, got {position!r}")
        return np.linalg.solve(M, np.append(p, 1.0))[:3]

    def batch(self) -> Any:
        """A context: edits made inside update the view once, after the last (a panel's several edits of one frame)."""
        return self.sync.held()

    def show_head_pose(self, pose: Any) -> None:
        """Draw the face under ``pose`` instead of the timeline's head pose; None draws the model's again.

        A view-only preview (the Live tab shows the actor's head turning while nothing is
        keyed): the model does not change, picking maps through the shown pose, and the
        view updates once (inside :meth:`batch`, once with the edits made there).

        Parameters
        ----------
        pose : (4, 4) float or None
            A rigid transform ``p -> R p + t`` in model units.
        """
        if pose is None:
            M = None
        else:
            M = np.array(pose, dtype=np.float64)
            if M.shape != (4, 4) or not np.all(np.isfinite(M)):
                raise ValueError(f"show_head_pose: pose must be a finite (4, 4) matrix, got shape {M.shape}")
            R = M[:3, :3]
            if not (np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.allclose(M[3], [0, 0, 0, 1])):
                raise ValueError("show_head_pose: pose must be rigid (a rotation and a translation)")
        old = self.sync.view_pose
        if (M is None and old is None) or (M is not None and old is not None and np.array_equal(M, old)):
            return
        self.sync.view_pose = M
        if self._connected:
            self.sync.push_geometry_event(False)
