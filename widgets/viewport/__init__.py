"""The three.js viewport widget: :class:`Viewport` and the helpers other panels use.

Layout:

* :mod:`widgets.viewport.widget` - the ``Viewport`` anywidget: traits, public API,
  message routing;
* :mod:`widgets.viewport.sync` - what is shipped to the browser (geometry patches,
  surface tint, markers, feature graph);
* :mod:`widgets.viewport.gestures` - the one gesture protocol (begin / update /
  end / cancel, one message in flight, acks, interaction tokens) and its dispatcher;
* :mod:`widgets.viewport.tools` - the tool registry (the method families' tools:
  marker drags, brush strokes) and the hooked drag / stroke panels install;
* :mod:`widgets.viewport.common` - constants, the bundle loader, brush defaults.

The front end is ``widgets/js/src/viewport.js`` and ``widgets/js/src/viewport/``.
"""

from widgets.viewport.common import (
    BRUSH_MODES,
    BRUSH_RADIUS_FRACTION,
    BUNDLE,
    DRAG_TOLERANCE,
    FALLOFFS,
    MAX_DABS_PER_MESSAGE,
    SPARSE_FRACTION,
    STRAIN_RANGE,
    STRAIN_TOLERANCE,
    brush_radius_slider,
    default_brush_radius,
    face_height,
    load_bundle,
    neutral_bounds,
    scene_key,
)
from widgets.viewport.gestures import DRAG_WATCHDOG_S, Gesture, GestureDispatcher
from widgets.viewport.tools import (
    DragGesture,
    StrokeGesture,
    Tool,
    ToolSpec,
    register_tool,
    tool_names,
    tool_specs,
)
from widgets.viewport.widget import Viewport

__all__ = [
    "BRUSH_MODES",
    "BRUSH_RADIUS_FRACTION",
    "BUNDLE",
    "DRAG_TOLERANCE",
    "DRAG_WATCHDOG_S",
    "FALLOFFS",
    "MAX_DABS_PER_MESSAGE",
    "SPARSE_FRACTION",
    "STRAIN_RANGE",
    "STRAIN_TOLERANCE",
    "DragGesture",
    "Gesture",
    "GestureDispatcher",
    "StrokeGesture",
    "Tool",
    "ToolSpec",
    "Viewport",
    "brush_radius_slider",
    "default_brush_radius",
    "face_height",
    "load_bundle",
    "neutral_bounds",
    "register_tool",
    "scene_key",
    "tool_names",
    "tool_specs",
]
