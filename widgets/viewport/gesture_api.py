"""The viewport's gesture calls from Python: what the front end's messages do, callable from code.

:class:`GestureAPI` is mixed into :class:`widgets.viewport.widget.Viewport`
(kept apart so the widget's module stays readable). Each call is a thin
entry into :mod:`widgets.viewport.gestures` — begin / update / end / cancel of
a handle drag or a paint stroke, the same protocol the mouse drives — plus the
two lookups the gestures share (a picked point back in model space, a handle
found again by its vertex).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from widgets.viewport.gestures import Gesture, GestureDispatcher, vertex_ids
from widgets.viewport.tools import HandleDrag, HookedDrag, HookedStroke, PaintStroke


class GestureAPI:
    """Handle drags and paint strokes driven from Python (mixed into ``Viewport``)."""

    gestures: GestureDispatcher
    drag_handler: Any
    stroke_handler: Any
    stroke_target: str
    sync: Any
    errors: Any
    _model: Any

    if TYPE_CHECKING:  # the widget's (a definition here would shadow it)

        @property
        def _connected(self) -> bool: ...

    def begin_drag(self, index: int, vertex: int | None = None) -> None:
        """Start dragging model handle ``index`` (the front end's "start" message).

        Opens the interaction "Drag handle <name>"; an open gesture, and every
        interaction other widgets hold open (a slider burst), is ended first.
        """
        self.gestures.start(HandleDrag(self, index, vertex))

    def drag_to(self, position: Any) -> float:
        """Move the dragged handle's vertex to ``position`` (3,) in model space.

        The handle offset is ``position - model.blended()[vertex]`` (the edit sits
        on top of the blend); with :attr:`symmetric` the mirror handle follows.
        Returns the kernel time in ms (rank-1 update + evaluate + send); 0 without a drag.
        """
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(
                f"Viewport.drag_to: position must be 3 finite numbers, got {position!r}"
            )
        g = self.gestures.current(HandleDrag)
        return 0.0 if g is None else self.gestures.update(g, {"model_position": p})

    def end_drag(self) -> None:
        """End the open handle drag (one undo step); no-op without one."""
        self.gestures.finish(HandleDrag)

    def begin_stroke(self, expression: str | None = None) -> None:
        """Start a paint stroke of ``expression`` (default :attr:`paint_expression`).

        Opens the interaction "Paint <expression>"; an open gesture, and every
        interaction other widgets hold open, is ended first.
        """
        self.gestures.start(PaintStroke(self, expression))

    def paint_at(self, vertices: Any) -> float:
        """Brush dabs at vertex ids ``vertices`` (int or sequence) within the open stroke.

        One overlay + geometry update is sent after the last dab. Returns the
        kernel time in ms (dabs + updates); 0 without an open stroke.
        """
        ids = vertex_ids(vertices, self._model.n_vertices, "Viewport.paint_at")
        g = self.gestures.current(PaintStroke)
        return 0.0 if g is None else self.gestures.update(g, {"vertices": ids})

    def end_stroke(self) -> None:
        """End the open paint stroke (one undo step); no-op without one."""
        self.gestures.finish(PaintStroke)

    def cancel_gesture(self) -> None:
        """Cancel the open gesture: its edits are put back, no undo step."""
        self.gestures.cancel()

    def set_stroke_handler(self, handler: Any, target: str = "") -> None:
        """Send paint strokes to ``handler`` instead of the model's paint layers (None: back).

        ``handler`` has ``begin()``, ``dab(vertices)``, ``end()``, ``cancel()``
        and optionally ``overlay() -> (n,) float or None`` (drawn as the paint
        overlay while it is set). ``target`` describes what a stroke does (the
        front end paints on a press only when it, or :attr:`paint_expression`,
        is set). An open stroke of the previous handler is cancelled; an open
        paint stroke is ended.
        """
        if handler is not None and not str(target):
            raise ValueError("Viewport.set_stroke_handler: describe the stroke's target")
        g = self.gestures.active
        if isinstance(g, HookedStroke) and g.handler is not handler:
            self.gestures.cancel(HookedStroke)
        if handler is not None:
            self.gestures.finish(PaintStroke)
        self.stroke_handler = handler
        self.stroke_target = str(target) if handler is not None else ""
        overlay = getattr(handler, "overlay", None) if handler is not None else None
        self.sync.overlay_source = overlay if overlay is not None else (
            (lambda: None) if handler is not None else None
        )
        # the overlay's source changed: send the difference to what the front end has
        if self._connected:
            self.errors.guard("Viewport paint overlay")(self.sync.sync_paint)()

    def _handle_gesture(self, content: Mapping[str, Any]) -> Gesture:
        v = content.get("vertex")
        index, vertex = int(content["index"]), None if v is None else int(v)
        if self.drag_handler is not None:
            return HookedDrag(self, self.drag_handler, index, vertex)
        return HandleDrag(self, index, vertex)

    def _paint_gesture(self, content: Mapping[str, Any]) -> Gesture:
        if self.stroke_handler is not None:
            return HookedStroke(self, self.stroke_handler, self.stroke_target)
        return PaintStroke(self)

    def _unposed(self, position: Any) -> Any:
        """A point picked on the shown mesh, in model space.

        The view draws :meth:`FaceModel.evaluate`, which applies the keyed head pose
        last (or the unposed face under the pose :meth:`show_head_pose` set); handle
        offsets and region pins live before it, so a pointer position is mapped back
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

    def _resolve_handle(self, index: int, vertex: int | None) -> int | None:
        """The model handle ``index`` if it sits on ``vertex``, else the handle on ``vertex``."""
        verts = self._model.handles.vertices
        if 0 <= index < verts.size and (vertex is None or int(verts[index]) == vertex):
            return int(index)
        if vertex is not None:
            hits = np.flatnonzero(verts == vertex)
            if hits.size:
                return int(hits[0])
        return None
