"""``Viewport``: a client-side WebGL (three.js) view of a :class:`workbench.FaceModel`.

The viewport only *observes* the model: it subscribes to ``model.events.deformed``
and ``model.events.shapes`` and ships ``model.evaluate()`` to the browser. Two
viewports of one model therefore always agree, and an edit made from any cell
updates every view. What is sent and how (full buffers, patches, the surface
tint, markers, the feature graph) is :mod:`widgets.viewport.sync`; every
pointer interaction that edits the model is one
:class:`~widgets.viewport.gestures.Gesture` (:mod:`widgets.viewport.gestures`)
driven by one dispatcher, ``Viewport.gestures``.

Camera orbit/zoom/pan happen entirely in the browser (OrbitControls): they
never send a kernel message. Each view frames the camera on the *neutral*
mesh's bounds (``_neutral_bounds``, sent with every topology) at the canvas's
current size, until the person orbits, zooms or pans.

Tools (:mod:`widgets.viewport.tools`): ``tool`` is ``"orbit"`` or a tool a
method family registered; ``tools`` holds each one's state in this view
(``viewport.tools[name]``, settings a panel links to). The viewport knows only the two
kinds of pointer work a tool does:

* ``"drag"`` tools: a drag on a marker is a ``"drag"`` gesture (``{"type":
  "drag", "phase", "index", "vertex", "position": [x, y, z], "seq"}``);
  ``{"type": "pick", "vertex"}`` (Shift-click on the surface) and ``{"type":
  "unpick", "index", "vertex"}`` (Alt-click on a marker) are single clicks.
  The markers are the current tool's, else the first tool's that has some,
  re-sent when they change;
  ``Viewport.markers = ids`` draws other markers until then.
* ``"stroke"`` tools: a left press on the face is a ``"stroke"`` gesture
  (``{"type": "stroke", "phase", "vertices": [v, ...], "seq"}``): the front
  end queues hit vertices a quarter of the brush radius apart while a message
  is in flight (at most 8 per message). The brush (``brush_radius`` in model
  units along the surface, ``brush_opacity``, ``brush_falloff``,
  ``brush_mode``, ``brush_mirror``) lives on the viewport so the front end can
  draw the brush cursor; a press strokes only while ``stroke_target`` says
  what it changes.

Panels borrow the pointer with hooks (``drag_handler``,
``set_stroke_handler``, ``pick_handler``), which win over the tools.

Feature-graph overlay (Bickel et al. 2008 §5.1): edges between vertices on
which a layer measures skin strain, drawn as line segments coloured by their relative stretch
(blue = compressed, grey = rest, red = stretched, full colour at
±:attr:`Viewport.strain_range`): ``_feature_edges`` (uint32, F*2:
:meth:`Viewport.set_feature_graph`) and ``_feature_strain`` (float32, F:
:meth:`Viewport.set_feature_strain`), each sent only when it changes; the end
points follow the drawn geometry in the browser.

Why hand-written rather than pythreejs / pyvista: see ``widgets/js/src/viewport.js``.
"""

from __future__ import annotations

import uuid
from collections import deque
from collections.abc import Mapping
from typing import Any

import anywidget
import ipywidgets
import numpy as np
import traitlets as t

from widgets._threading import ErrorSink, slider_pointer
from widgets.viewport.common import (
    BRUSH_MODES,
    FALLOFFS,
    STRAIN_RANGE,
    as_ids,
    default_brush_radius,
    f32_bytes,
    load_bundle,
    scene_key,
    u32_bytes,
)
from widgets.viewport.gesture_api import GestureAPI
from widgets.viewport.gestures import GestureDispatcher
from widgets.viewport.overlays import OverlayAPI
from widgets.viewport.sync import SceneSync
from widgets.viewport.tools import DragGesture, StrokeGesture, make_tools, tool_names


class Viewport(GestureAPI, OverlayAPI, anywidget.AnyWidget):
    """Interactive three.js view of a FaceModel (smooth shading, orbit/zoom/pan).

    Parameters
    ----------
    model : workbench.FaceModel
        The model to draw; the viewport subscribes to its events.
    height : int
        Height in CSS pixels (the width follows the container).
    errors : ipywidgets.Output, optional
        Where callback errors are shown (``Workbench`` passes a shared one).

    Attributes (Python side)
    ------------------------
    wireframe : bool
        Draw the triangle edges over the shaded surface.
    vertex_colors : (n, 3) float or None
        Per-vertex sRGB colour overlay in [0, 1]; None shows component colours.
    markers : (h,) int
        Vertex ids drawn as markers (display only, until the tools' markers change).
    component_visible : dict[str, bool]
        Component name -> visible (missing names are visible).
    probe_ids : (p,) int
        Test hook: the front end writes the screen positions of these vertices
        to the ``data-probe`` attribute of its root element after each render.
    tool : str
        ``"orbit"`` (camera only) or a registered tool (:func:`widgets.viewport.tools.tool_names`).
        With a ``"drag"`` tool, left-drag a marker to move it in the view plane,
        Shift-click the surface to pick a vertex, Alt-click a marker to unpick it;
        orbit/zoom/pan still work off the markers. With a ``"stroke"`` tool a
        left-drag on the face is a brush stroke (one undo step); off the face,
        with Alt held, or while ``stroke_target`` is empty, the left button orbits.
    tools : dict[str, widgets.viewport.tools.Tool]
        Each registered tool's state in this view.
    symmetric : bool
        Marker drags also move the mirror marker's edit (x reflected); Shift-click
        picks a mirrored pair; the mirror marker is highlighted.
    add_on_click : bool
        With a drag tool, a plain click (no modifier) on the surface picks too.
    selected_marker : int
        Index of the last dragged marker (highlighted), or -1. Cleared when the
        tool changes and when the pointer leaves the view.
    brush_radius, brush_opacity, brush_falloff, brush_mode, brush_mirror
        The brush of stroke tools; the radius is a surface distance in model
        units (default :func:`default_brush_radius`).
    stroke_target : str
        What a stroke changes: the stroke handler's target while one is set, else
        the stroke tool's (:meth:`~widgets.viewport.tools.Tool.target`); "" = the
        left button orbits.
    feature_graph : bool
        Draw the feature-graph edges given to :meth:`set_feature_graph`, coloured
        by the strain given to :meth:`set_feature_strain` (blue compressed, grey
        rest, red stretched), with a colour-scale legend.
    strain_range : float
        Relative stretch drawn in full colour (default ``0.2``: ±20 %).
    overlay_points : (p, 3) float
        Free points drawn over the face, always on top (:meth:`set_overlay_points`;
        the Capture tab's input markers, landmarks or cloud at the current frame).
    overlay_point_px : float
        Their size in CSS pixels.
    gpu : bool
        Evaluate the rig in the browser (default), once a view says it can: the
        kernel uploads the neutral, the shapes' deltas and the shell basis once
        and then sends only weights, the linear layer's controls, the head pose and the rows
        of layers the GPU does not evaluate (:mod:`widgets.viewport.gpu`).
        ``False`` (or a browser without WebGL2 float textures) streams evaluated
        vertex rows, with a note in the view.
    fast_interaction : {"auto", "on", "off"}
        While the rig's parameters change (a slider moves, a marker is dragged,
        a clip plays), draw a simplified copy of the face evaluated on the GPU at
        its own vertices, and the full mesh once the changes pause (~0.14 s), as
        Maya's Fast Interaction does. ``"auto"`` (default): only in a view whose
        full frame measured slower than 30 ms (software WebGL at tens of
        thousands of vertices); ``"on"``: always; ``"off"``: never. GPU path only.
    camera_group : str
        Viewports with the same non-empty group orbit and zoom together in the
        browser (the same side of the face at the same relative size, whatever
        their units or up axes; no kernel messages), e.g. the Rig tab's template
        and target views.

    The front end writes the markers' screen positions to ``data-markers``
    (JSON ``[[x, y, in_front], ...]`` in page pixels) after every render.
    """

    _esm = t.Unicode("").tag(sync=True)
    _uid = t.Unicode("").tag(sync=True)
    _scene = t.Unicode("").tag(sync=True)
    _faces = t.Bytes(b"").tag(sync=True)
    _labels = t.Bytes(b"").tag(sync=True)
    _positions = t.Bytes(b"").tag(sync=True)
    _version = t.Int(0).tag(sync=True)
    _topology = t.Int(0).tag(sync=True)
    _component_names = t.List(t.Unicode()).tag(sync=True)
    # per component, the look of its part role (workbench.geometry.parts.part_material): the colours
    _component_materials = t.List(t.Unicode()).tag(sync=True)
    _up_axis = t.Unicode("+y").tag(sync=True)
    _neutral_bounds = t.Dict().tag(sync=True)
    _vertex_colors = t.Bytes(None, allow_none=True).tag(sync=True)
    _markers = t.Bytes(b"").tag(sync=True)
    _probe_ids = t.Bytes(b"").tag(sync=True)
    _error = t.Unicode("").tag(sync=True)
    _marker_mirror = t.Bytes(b"").tag(sync=True)
    _tint = t.Bytes(b"").tag(sync=True)
    _tint_version = t.Int(0).tag(sync=True)
    #: tool name -> its kind ("drag" | "stroke"): how the page's pointer works with it
    _tool_kinds = t.Dict(value_trait=t.Unicode()).tag(sync=True)

    tool = t.Unicode("orbit").tag(sync=True)
    symmetric = t.Bool(False).tag(sync=True)
    add_on_click = t.Bool(False).tag(sync=True)
    selected_marker = t.Int(-1).tag(sync=True)
    brush_radius = t.Float(0.1).tag(sync=True)
    brush_opacity = t.Float(0.5).tag(sync=True)
    brush_falloff = t.Unicode("smooth").tag(sync=True)
    brush_mode = t.Unicode("add").tag(sync=True)
    brush_mirror = t.Bool(False).tag(sync=True)
    stroke_target = t.Unicode("").tag(sync=True)
    wireframe = t.Bool(False).tag(sync=True)
    component_visible = t.Dict(value_trait=t.Bool()).tag(sync=True)
    height = t.Int(480).tag(sync=True)
    # feature-graph overlay (see "feature graph overlay" below)
    _feature_edges = t.Bytes(b"").tag(sync=True)
    _feature_strain = t.Bytes(b"").tag(sync=True)
    feature_graph = t.Bool(True).tag(sync=True)
    strain_range = t.Float(STRAIN_RANGE).tag(sync=True)
    camera_group = t.Unicode("").tag(sync=True)
    _overlay_points = t.Bytes(b"").tag(sync=True)
    _overlay_colors = t.Bytes(b"").tag(sync=True)
    overlay_point_px = t.Float(6.0).tag(sync=True)
    # GPU evaluation (widgets.viewport.gpu): the rig once, then parameters per update
    gpu = t.Bool(True).tag(sync=True)
    fast_interaction = t.Enum(["auto", "on", "off"], "auto").tag(sync=True)
    #: shape name -> slider model id (plain ids, not widget references: the page looks
    #: the sliders up when it needs them, so the viewport never waits for their models)
    _weight_slider_ids = t.Dict(value_trait=t.Unicode()).tag(sync=True)
    _gpu_mode = t.Unicode("stream").tag(sync=True)
    _gpu_meta = t.Dict().tag(sync=True)
    _gpu_neutral = t.Bytes(b"").tag(sync=True)
    _gpu_morph_index = t.Bytes(b"").tag(sync=True)
    _gpu_morph_entries = t.Bytes(b"").tag(sync=True)
    _gpu_basis = t.Bytes(b"").tag(sync=True)
    _gpu_gain = t.Bytes(b"").tag(sync=True)
    _gpu_residual = t.Bytes(b"").tag(sync=True)
    _gpu_params = t.Bytes(b"").tag(sync=True)
    _gpu_clip = t.Bytes(b"").tag(sync=True)
    _gpu_clip_meta = t.Dict().tag(sync=True)

    def __init__(
        self,
        model: Any,
        *,
        height: int = 480,
        errors: ipywidgets.Output | None = None,
        **kwargs: Any,
    ) -> None:
        esm = load_bundle()  # clear error before any widget state exists
        kwargs.setdefault("brush_radius", default_brush_radius(model))
        super().__init__(
            _esm=esm, _uid=uuid.uuid4().hex, _scene=scene_key(model), height=height, **kwargs
        )
        self._model = model
        self.errors = ErrorSink(errors, on_error=self._show_error)
        #: what the front end has, and how updates are sent (widgets.viewport.sync)
        self.sync = SceneSync(self, model)
        #: comm messages received from the front end (tests assert orbit sends none)
        self.frontend_msg_count = 0
        #: full updates the page asked for, with its reason ("gap": a version it never got,
        #: "rig": GPU parameters without the rig); the browser tests require none
        self.resyncs: list[str] = []
        #: kernel-side ms per marker move (the tool's edit + evaluate + send)
        self.drag_ms: deque[float] = deque(maxlen=512)
        #: the geometry-send part of the last drag_ms entries
        self.drag_push_ms: deque[float] = deque(maxlen=512)
        #: called after each tool drag ends with a dict of stats (a panel's status line)
        self.drag_listeners: list[Any] = []
        self.last_drag: dict[str, Any] = {}
        #: core ms per brush dab of a stroke tool, for the status line and benchmarks
        self.dab_ms: deque[float] = deque(maxlen=2048)
        #: kernel ms per stroke message (its dabs + tint + geometry send)
        self.stroke_ms: deque[float] = deque(maxlen=512)
        #: called after each tool stroke ends with a dict of stats (a panel's status line)
        self.stroke_listeners: list[Any] = []
        self.last_stroke: dict[str, Any] = {}
        #: receives brush strokes instead of the stroke tool (set_stroke_handler)
        self.stroke_handler: Any = None
        #: receives marker drags instead of the drag tool (a plain attribute: a panel
        #: sets its own drag here)
        self.drag_handler: Any = None
        #: the shape sliders the page plays itself (follow_sliders)
        self.weight_sliders: dict[str, Any] = {}
        #: receives surface clicks and marker Alt-clicks instead of the drag tool: an
        #: object with ``pick(vertex)`` and optionally ``remove(index, vertex)`` (the Rig
        #: tab's landmark picker); ``None`` = the drag tool's pick / unpick
        self.pick_handler: Any = None
        #: every pointer gesture (widgets.viewport.gestures): one open at a time
        self.gestures = GestureDispatcher(
            self,
            {"drag": self._drag_gesture, "stroke": self._stroke_gesture},
            ack_extra={"stroke": lambda: {"tint_version": self._tint_version}},
        )
        #: each registered tool's state in this view (widgets.viewport.tools)
        self.tools = make_tools(self)
        self._tool_kinds = {name: tool.kind for name, tool in self.tools.items()}
        self._on_deformed = self.errors.guard("Viewport update")(self.sync.push_geometry_event)
        self._on_shapes = self.errors.guard("Viewport shapes update")(self.sync.push_geometry_event)
        self.on_msg(self._on_frontend_msg)
        ev = model.events
        ev.deformed.connect(self._on_deformed)
        ev.shapes.connect(self._on_shapes)
        self.sync.connected = True
        self.sync.push_geometry(force_full=True)
        self.refresh_tool()

    # ------------------------------------------------------------------ public
    @property
    def _connected(self) -> bool:
        # (observers run inside super().__init__, before the sync exists)
        sync = self.__dict__.get("sync")
        return sync is not None and sync.connected

    @property
    def model(self) -> Any:
        """The observed FaceModel."""
        return self._model

    @property
    def vertex_colors(self) -> np.ndarray | None:
        """(n, 3) float32 sRGB overlay, or None."""
        if self._vertex_colors is None:
            return None
        return np.frombuffer(self._vertex_colors, dtype="<f4").reshape(-1, 3)

    @vertex_colors.setter
    def vertex_colors(self, value: Any) -> None:
        if value is None:
            self._vertex_colors = None  # type: ignore[assignment]  # allow_none trait
            return
        c = np.asarray(value, dtype=np.float32)
        n = self._model.n_vertices
        if c.shape != (n, 3):
            raise ValueError(f"Viewport.vertex_colors must be (n, 3) = ({n}, 3), got {c.shape}")
        if not np.isfinite(c).all():
            raise ValueError("Viewport.vertex_colors contains NaN/inf")
        self._vertex_colors = f32_bytes(c)

    @property
    def markers(self) -> np.ndarray:
        """(h,) uint32 vertex ids drawn as markers."""
        return np.frombuffer(self._markers, dtype="<u4").copy()

    @markers.setter
    def markers(self, value: Any) -> None:
        # Display-only markers: no mirror links; the tools' markers come back when
        # they next change (or on show_tool_markers).
        with self.hold_sync():
            self._markers = u32_bytes(as_ids(value, self._model.n_vertices, "markers"))
            self._marker_mirror = b""

    def show_tool_markers(self) -> None:
        """Draw the tools' markers again (after display-only ones set through :attr:`markers`)."""
        self.sync.sync_markers(force=True)

    def refresh_tool(self) -> None:
        """A tool's markers, tint or stroke target may have changed: send what differs.

        Tools call this from their model-event callbacks and when their settings change.
        """
        if not self._connected:
            return
        self.sync.sync_markers()
        self.sync.sync_tint()
        if self.stroke_handler is None:
            tool = self.tool_of_kind("stroke")
            self.stroke_target = tool.target() if tool is not None else ""

    @property
    def probe_ids(self) -> np.ndarray:
        """(p,) uint32: vertices whose screen positions go to ``data-probe``."""
        return np.frombuffer(self._probe_ids, dtype="<u4").copy()

    @probe_ids.setter
    def probe_ids(self, value: Any) -> None:
        self._probe_ids = u32_bytes(as_ids(value, self._model.n_vertices, "probe_ids"))

    def set_component_visible(self, name: str, visible: bool) -> None:
        """Show or hide one component (e.g. ``"eyelashes_left"``)."""
        if name not in self._model.component_names:
            raise ValueError(
                f"Viewport.set_component_visible: unknown component {name!r}; "
                f"have {self._model.component_names}"
            )
        self.component_visible = {**self.component_visible, name: bool(visible)}

    @t.validate("tool")
    def _valid_tool(self, proposal: Any) -> str:
        value = str(proposal["value"])
        names = tool_names()
        if value not in names:
            raise t.TraitError(f"Viewport.tool must be one of {names}, got {value!r}")
        return value

    @t.observe("tool")
    def _on_tool_changed(self, _change: Any) -> None:
        # the last dragged marker is no longer highlighted once another tool is picked
        self.selected_marker = -1
        if self._connected:
            self.refresh_tool()

    @t.validate("brush_falloff")
    def _valid_falloff(self, proposal: Any) -> str:
        value = str(proposal["value"])
        if value not in FALLOFFS:
            raise t.TraitError(f"Viewport.brush_falloff must be one of {FALLOFFS}, got {value!r}")
        return value

    @t.validate("brush_mode")
    def _valid_mode(self, proposal: Any) -> str:
        value = str(proposal["value"])
        if value not in BRUSH_MODES:
            raise t.TraitError(f"Viewport.brush_mode must be one of {BRUSH_MODES}, got {value!r}")
        return value

    @t.validate("brush_radius")
    def _valid_radius(self, proposal: Any) -> float:
        value = float(proposal["value"])
        if not (np.isfinite(value) and value > 0):
            raise t.TraitError(f"Viewport.brush_radius must be > 0 (model units), got {value!r}")
        return value

    @t.validate("brush_opacity")
    def _valid_opacity(self, proposal: Any) -> float:
        value = float(proposal["value"])
        if not 0.0 <= value <= 1.0:
            raise t.TraitError(f"Viewport.brush_opacity must be in [0, 1], got {value!r}")
        return value

    @property
    def dragging(self) -> bool:
        """True while a marker drag (a tool's or a drag handler's) is open."""
        return self.gestures.current(DragGesture) is not None

    @property
    def stroking(self) -> bool:
        """True while a brush stroke (a tool's or a stroke handler's) is open."""
        return self.gestures.current(StrokeGesture) is not None

    def close(self) -> None:
        """End an open gesture, disconnect from the model, then close the widget."""
        if self._connected:
            try:
                self.gestures.finish()
                self.set_stroke_handler(None)
            finally:
                ev = self._model.events
                ev.deformed.disconnect(self._on_deformed)
                ev.shapes.disconnect(self._on_shapes)
                for tool in self.tools.values():
                    tool.close()
                self.sync.connected = False
        super().close()

    @property
    def gpu_active(self) -> bool:
        """True while updates go to the browser as rig parameters (:mod:`widgets.viewport.gpu`)."""
        return self._gpu_mode == "gpu"

    @property
    def gpu_unavailable(self) -> str:
        """Why the front end cannot evaluate on the GPU ("" when it can or has not said)."""
        return self.sync.gpu.unavailable

    @property
    def gpu_payload(self) -> Any:
        """Bytes of each parameter message sent (JSON + buffers), newest last."""
        return self.sync.gpu.payload

    def follow_sliders(self, sliders: Mapping[str, Any]) -> None:
        """Let the page play these shape sliders itself (GPU path), before the kernel answers.

        ``sliders`` maps shape names to slider widgets whose ``value`` is the shape's
        weight (the Shapes tab's). A slider moved in the page then changes the weight
        the browser evaluates at once; the kernel's answer (the exact parameters and
        the rows of non-linear layers) follows and wins. Call again when the sliders are rebuilt.
        """
        self.weight_sliders = dict(sliders)
        self._weight_slider_ids = {str(k): str(w.model_id) for k, w in self.weight_sliders.items()}

    @t.observe("gpu")
    def _on_gpu(self, change: Any) -> None:
        if self._connected:
            if change["new"]:
                self.sync.gpu.unavailable = ""  # try again
            self.errors.guard("Viewport resync")(self.sync.push_geometry)(force_full=True)

    # ------------------------------------------------------------------ clicks
    def pick_at(self, vertex: int) -> None:
        """What a Shift-click on the surface at ``vertex`` does: ``pick_handler``'s pick, else the drag tool's."""
        vertex = int(vertex)
        if not 0 <= vertex < self._model.n_vertices:
            raise ValueError(f"Viewport.pick_at: vertex must be in 0..{self._model.n_vertices - 1}, got {vertex}")
        if self.pick_handler is not None:
            self.pick_handler.pick(vertex)
            return
        tool = self.tool_of_kind("drag")
        if tool is not None:
            tool.pick(vertex)

    def unpick_at(self, index: int, vertex: int | None = None) -> None:
        """What an Alt-click on marker ``index`` (at ``vertex``) does: ``pick_handler``'s remove, else the drag tool's unpick."""
        if self.pick_handler is not None:
            remove = getattr(self.pick_handler, "remove", None)
            if remove is not None:
                remove(int(index), vertex)
            return
        tool = self.tool_of_kind("drag")
        if tool is not None:
            tool.unpick(int(index), vertex)

    # --------------------------------------------------------------- messages
    def _show_error(self, text: str) -> None:
        self._error = text

    def _handle_msg(self, msg: dict[str, Any]) -> None:
        # Every comm message from the front end passes here (state updates too).
        self.frontend_msg_count += 1
        super()._handle_msg(msg)

    def _on_frontend_msg(self, _widget: Any, content: Any, _buffers: Any) -> None:
        if not isinstance(content, dict):
            return
        kind = content.get("type")
        if kind in ("drag", "stroke"):
            self.gestures.on_message(kind, content)
        elif kind == "gpu_ready":
            # a view can evaluate the rig: upload it, then send parameters only
            if not self.sync.gpu.ready:
                self.sync.gpu.ready = True
                self.errors.guard("Viewport resync")(self.sync.push_geometry)(force_full=True)
        elif kind == "gpu_unavailable":
            # a view cannot evaluate the rig: stream vertex rows to every view of this widget
            was = self.sync.gpu.active
            self.sync.gpu.unavailable = str(content.get("reason") or "unavailable")
            if was:
                self.errors.guard("Viewport resync")(self.sync.push_geometry)(force_full=True)
        elif kind == "slider_pointer":
            # the page's pointer pressed / released a slider (sent after its last value)
            if content.get("phase") == "down":
                slider_pointer.down()
            else:
                self.errors.guard("end of slider drag")(slider_pointer.up)()
        elif kind == "request_full":
            # a protocol step, not a repair: the page saw a version gap that lasted, or GPU
            # parameters without their rig (content['why']); counted, the browser tests require none
            self.resyncs.append(str(content.get("why") or "gap"))
            self.errors.guard("Viewport resync")(self.sync.resync)(rig=bool(content.get("rig")))
        elif kind == "request_tint":
            self.errors.guard("Viewport tint resync")(self.sync.resend_tint)()
        elif kind == "pick":
            self.errors.guard("pick")(self.pick_at)(int(content["vertex"]))
        elif kind == "unpick":
            v = content.get("vertex")
            self.errors.guard("unpick")(self.unpick_at)(int(content["index"]), None if v is None else int(v))

    # ----------------------------------------------- what the front end was sent
    # (read by tests and benchmarks; widgets.viewport.sync owns it)
    @property
    def updates_sent(self) -> dict[str, int]:
        return self.sync.updates_sent

    @property
    def tint_updates_sent(self) -> dict[str, int]:
        return self.sync.tint_updates_sent

    @property
    def push_ms(self) -> deque[float]:
        return self.sync.push_ms

    @property
    def _last(self) -> np.ndarray | None:
        return self.sync.last

    @property
    def _tolerance(self) -> float:
        return self.sync.tolerance

    def _push_geometry(self, force_full: bool, tolerance: float = 0.0) -> None:
        self.sync.push_geometry(force_full, tolerance)

    @t.observe("feature_graph")
    def _on_feature_graph_shown(self, change: Any) -> None:
        pending = self.sync.strain_pending
        if change["new"] and pending is not None and pending.size == len(self._feature_edges) // 8:
            self.errors.guard("Viewport feature graph")(self.set_feature_strain)(pending)
