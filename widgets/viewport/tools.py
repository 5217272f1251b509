"""The viewport's tools: one registry, and the hooked drag and stroke panels install.

A tool is what the left button does in a viewport (``Viewport.tool``). ``"orbit"``
is the viewport's own (camera only). Every other tool belongs to a method family:
its registration names the module that registers the tool here
(``Family(viewport="my_package.my_tool")``, :mod:`workbench.core.families`), the
same way it names its Workbench tab. The viewport never names a family; it asks
its tools. A :class:`ToolSpec` gives:

* ``name``: the value of ``Viewport.tool``;
* ``kind``: how the page's pointer works with it. ``"drag"``: the tool's markers
  are dragged in the view plane, Shift-click on the surface *picks* a vertex,
  Alt-click on a marker *unpicks* it. ``"stroke"``: a press on the face starts a
  brush stroke whose dabs are the vertices under the brush;
* ``make(viewport) -> Tool``: the tool's state in one viewport, made with the
  viewport and kept for its lifetime.

A :class:`Tool` makes the :class:`~widgets.viewport.gestures.Gesture` a press
begins (:class:`DragGesture` or :class:`StrokeGesture`), answers picks, and may
draw markers (:meth:`Tool.markers`) and a per-vertex tint (:meth:`Tool.tint`)
whatever tool is current. When any of these changes it calls
``Viewport.refresh_tool()``.

Panels can borrow the pointer without a tool of their own. Marker drags go to
``viewport.drag_handler`` (:class:`HookedDrag`), with ``begin(index,
vertex)``, ``move(index, position) -> ms``, ``end()`` and optionally
``cancel()``; the handler owns its model interaction. Strokes go to the object
given to ``viewport.set_stroke_handler`` (:class:`HookedStroke`), with ``begin()``, ``dab(vertices)``, ``end()``, ``cancel()`` and
optionally ``overlay()``. Surface picks go to ``viewport.pick_handler``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import traitlets as t

from widgets.viewport.gestures import Gesture, vertex_ids

#: the pointer behaviours a tool can have (see the module docstring)
TOOL_KINDS = ("drag", "stroke")
#: the viewport's own tool: the left button orbits the camera
ORBIT = "orbit"


class DragGesture(Gesture):
    """A marker drag (message kind ``"drag"``): a message moves it with ``"position"`` (picked on the
    shown mesh) or, from Python (``Viewport.drag_to``), ``"model_position"``."""

    kind = "drag"

    def has_update(self, content: Mapping[str, Any]) -> bool:
        return content.get("position") is not None or "model_position" in content

    def model_point(self, content: Mapping[str, Any]) -> Any:
        """The message's point in model space (a picked one mapped back through the shown head pose)."""
        if "model_position" in content:
            return content["model_position"]
        return self.viewport.unposed(content["position"])


class StrokeGesture(Gesture):
    """A brush stroke (message kind ``"stroke"``): a message carries the dabbed ``"vertices"``."""

    kind = "stroke"

    def has_update(self, content: Mapping[str, Any]) -> bool:
        v = content.get("vertices")
        return v is not None and bool(np.size(v))


class Tool(t.HasTraits):
    """One tool's state in one viewport; subclasses override what their kind uses.

    Settings a panel links to are traits of the subclass.
    """

    kind: ClassVar[str] = ""

    def __init__(self, viewport: Any, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.viewport = viewport
        self.name = ""  # set by the registry

    @property
    def model(self) -> Any:
        return self.viewport.model

    def gesture(self, content: Mapping[str, Any]) -> Gesture:
        """The gesture a press begins (``content``: the "start" message)."""
        raise ValueError(f"Viewport: the {self.name!r} tool has no {self.kind or 'pointer'} gesture")

    def pick(self, vertex: int) -> None:
        """A click on the surface at ``vertex`` (drag tools: Shift-click)."""

    def unpick(self, index: int, vertex: int | None) -> None:
        """An Alt-click on marker ``index`` (at ``vertex``)."""

    def markers(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(vertex ids (h,), mirror index or -1 (h,))`` to draw as markers, or None."""
        return None

    def tint(self) -> np.ndarray | None:
        """(n,) weights in [0, 1] to tint the surface with, or None."""
        return None

    def target(self) -> str:
        """Stroke tools: what a stroke changes ("" = nothing; a press then orbits)."""
        return ""

    def close(self) -> None:
        """The viewport is closing: disconnect from the model."""


@dataclass(frozen=True)
class ToolSpec:
    """One registered viewport tool (see the module docstring)."""

    name: str
    kind: str
    make: Callable[[Any], Tool]
    order: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in TOOL_KINDS:
            raise ValueError(f"ToolSpec {self.name!r}: kind must be one of {TOOL_KINDS}, got {self.kind!r}")
        if self.name == ORBIT or not self.name:
            raise ValueError(f"ToolSpec: {self.name!r} cannot name a tool")


_TOOLS: dict[str, ToolSpec] = {}


def register_tool(spec: ToolSpec) -> ToolSpec:
    """Register (or replace, on reload) a viewport tool by name; returns it."""
    _TOOLS[spec.name] = spec
    return spec


def tool_specs() -> tuple[ToolSpec, ...]:
    """Every registered tool in order; the modules the method families name are imported first."""
    from workbench.core.families import families

    for f in families():
        if f.viewport:
            importlib.import_module(f.viewport)
    return tuple(sorted(_TOOLS.values(), key=lambda s: s.order))


def tool_names() -> tuple[str, ...]:
    """The values ``Viewport.tool`` accepts: ``"orbit"`` and every registered tool."""
    return (ORBIT, *(s.name for s in tool_specs()))


def make_tools(viewport: Any) -> dict[str, Tool]:
    """One :class:`Tool` per registered tool for ``viewport``."""
    tools = {}
    for spec in tool_specs():
        tool = spec.make(viewport)
        tool.name = spec.name
        tools[spec.name] = tool
    return tools


# ----------------------------------------------------------------- hooked gestures


class HookedStroke(StrokeGesture):
    """A stroke sent to a stroke handler (see ``Viewport.set_stroke_handler``)."""

    def __init__(self, viewport: Any, handler: Any, target: str = "") -> None:
        super().__init__(viewport)
        self.handler = handler
        self.label = target
        self._handler_open = False

    def start(self, content: Mapping[str, Any]) -> float:
        self.handler.begin()
        self._handler_open = True
        return self.update(content) if self.has_update(content) else 0.0

    def apply(self, content: Mapping[str, Any]) -> None:
        ids = vertex_ids(content.get("vertices"), self.model.n_vertices, "stroke")
        if ids.size:
            self.handler.dab(ids)
            self.viewport.sync.sync_tint()

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
            self.viewport.sync.sync_tint()

    def abort(self) -> None:
        # a failed dab drops the stroke (the handler applies nothing)
        self.cancelled = True
        self.close(keep=False)


class HookedDrag(DragGesture):
    """A marker drag sent to ``viewport.drag_handler``."""

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

    def update(self, content: Mapping[str, Any]) -> float:
        if not self.live or not self.has_update(content):
            return 0.0
        ms = float(self.handler.move(self.index, self.model_point(content)) or 0.0)
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
