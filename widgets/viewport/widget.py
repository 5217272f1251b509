"""``Viewport``: a client-side WebGL (three.js) view of a :class:`workbench.FaceModel`.

The viewport only *observes* the model: it subscribes to ``model.events.deformed``
and ``model.events.shapes`` and ships ``model.evaluate()`` to the browser. Two
viewports of one model therefore always agree, and an edit made from any cell
updates every view. What is sent and how (full buffers, patches, the paint
overlay, handle markers, the feature graph) is :mod:`widgets.viewport.sync`;
every pointer interaction that edits the model (handle drag, paint stroke, and
the hooked region pin drag, region brush and wrinkle eraser) is one
:class:`~widgets.viewport.gestures.Gesture` (:mod:`widgets.viewport.gestures`,
:mod:`widgets.viewport.tools`) driven by one dispatcher, ``Viewport.gestures``.

Camera orbit/zoom/pan happen entirely in the browser (OrbitControls): they
never send a kernel message. Each view frames the camera on the *neutral*
mesh's bounds (``_neutral_bounds``, sent with every topology) at the canvas's
current size, until the person orbits, zooms or pans.

Handle editing (``tool="sculpt"``, Bickel et al. 2008 §4): a drag on a marker
is a ``"handle"`` gesture (``{"type": "handle", "phase", "index", "vertex",
"position": [x, y, z], "seq"}``); ``{"type": "add_handle", "vertex"}``
(Shift-click on the surface) and ``{"type": "remove_handle", "index",
"vertex"}`` (Alt-click on a marker) are single clicks. The markers are the
model's handles, re-sent whenever the handle *set* changes;
``Viewport.handles = ids`` draws other markers until it next changes.

Painterly blending (``tool="paint"``, Pighin et al. 1998 §4.2): a left press on
the face is a ``"paint"`` gesture (``{"type": "paint", "phase", "vertices":
[v, ...], "seq"}``): the front end queues hit vertices a quarter of the brush
radius apart while a message is in flight (at most 8 per message); Python calls
``model.paint.dab(paint_expression, v, brush)`` for each. The brush
(``brush_radius`` in model units along the surface, ``brush_opacity``,
``brush_falloff``, ``brush_mode``, ``brush_mirror``) lives on the viewport so
the front end can draw the brush cursor; :class:`widgets.PaintPanel` links its
controls to these traits.

Feature-graph overlay (pose-space wrinkles, Bickel et al. 2008 §5.1): the edges
between handles on which a :class:`workbench.methods.wrinkles.layer.WrinkleLayer`
measures skin strain, drawn as line segments coloured by their relative stretch
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
    TOOLS,
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
from widgets.viewport.tools import (
    HandleDrag,
    PaintStroke,
    add_handle,
    remove_handle,
)


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
    handles : (h,) int
        Vertex ids drawn as handle markers.
    component_visible : dict[str, bool]
        Component name -> visible (missing names are visible).
    probe_ids : (p,) int
        Test hook: the front end writes the screen positions of these vertices
        to the ``data-probe`` attribute of its root element after each render.
    tool : {"orbit", "sculpt", "paint"}
        ``"sculpt"``: left-drag a handle marker to move it in the view plane,
        Shift-click the surface to add a handle, Alt-click a marker to remove it;
        orbit/zoom/pan still work off the markers. ``"paint"``: left-drag on the
        face paints :attr:`paint_expression` with the brush (one undo step per
        stroke); off the face, or with Alt held, the left button orbits.
        ``"orbit"``: camera only.
    symmetric : bool
        Handle drags also move the mirror handle (x reflected); Shift-click adds
        a mirrored pair; the mirror marker is highlighted.
    add_on_click : bool
        In sculpt mode, a plain click (no modifier) on the surface adds a handle.
    selected_handle : int
        Index of the last dragged handle (highlighted), or -1. Cleared when the
        tool changes and when the pointer leaves the view.
    paint_expression : str
        The expression the brush paints (a blendshape or saved expression name;
        "" = none: the left button then orbits in paint mode).
    brush_radius, brush_opacity, brush_falloff, brush_mode, brush_mirror
        The brush (:class:`workbench.methods.paint.painting.Brush`); the radius is a surface
        distance in model units (default :func:`default_brush_radius`).
    paint_overlay : bool
        Tint the surface by the painted weight of :attr:`paint_expression`
        (white skin -> magenta at weight 1).
    stroke_target : str
        Set by :meth:`set_stroke_handler`: what paint strokes do while a stroke
        handler receives them ("" = the model's paint layers).
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
        and then sends only weights, handle offsets, the head pose and the rows
        of layers the GPU does not evaluate (:mod:`widgets.viewport.gpu`).
        ``False`` (or a browser without WebGL2 float textures) streams evaluated
        vertex rows, with a note in the view.
    fast_interaction : {"auto", "on", "off"}
        While the rig's parameters change (a slider moves, a handle is dragged,
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

    The front end writes the markers' screen positions to ``data-handles``
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
    _handles = t.Bytes(b"").tag(sync=True)
    _probe_ids = t.Bytes(b"").tag(sync=True)
    _error = t.Unicode("").tag(sync=True)
    _handle_mirror = t.Bytes(b"").tag(sync=True)
    _paint_weights = t.Bytes(b"").tag(sync=True)
    _paint_version = t.Int(0).tag(sync=True)

    tool = t.Unicode("orbit").tag(sync=True)
    symmetric = t.Bool(False).tag(sync=True)
    add_on_click = t.Bool(False).tag(sync=True)
    selected_handle = t.Int(-1).tag(sync=True)
    paint_expression = t.Unicode("").tag(sync=True)
    brush_radius = t.Float(0.1).tag(sync=True)
    brush_opacity = t.Float(0.5).tag(sync=True)
    brush_falloff = t.Unicode("smooth").tag(sync=True)
    brush_mode = t.Unicode("add").tag(sync=True)
    brush_mirror = t.Bool(False).tag(sync=True)
    paint_overlay = t.Bool(True).tag(sync=True)
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
        #: kernel-side ms per handle move (move_handle: rank-1 update + evaluate + send)
        self.drag_ms: deque[float] = deque(maxlen=512)
        #: the geometry-send part of the last drag_ms entries
        self.drag_push_ms: deque[float] = deque(maxlen=512)
        #: called after each handle drag ends with a dict of stats (SculptPanel status line)
        self.drag_listeners: list[Any] = []
        self.last_drag: dict[str, Any] = {}
        #: core ms per brush dab (model.paint.dab), for the status line and benchmarks
        self.dab_ms: deque[float] = deque(maxlen=2048)
        #: kernel ms per paint message (its dabs + overlay + geometry send)
        self.paint_ms: deque[float] = deque(maxlen=512)
        #: called after each stroke ends with a dict of stats (PaintPanel status line)
        self.stroke_listeners: list[Any] = []
        self.last_stroke: dict[str, Any] = {}
        #: receives paint strokes instead of the model's paint layers (set_stroke_handler)
        self.stroke_handler: Any = None
        #: receives marker drags instead of the model's handles (a plain attribute:
        #: RegionsPanel sets its pin drag, region brush or seed picker here)
        self.drag_handler: Any = None
        #: the shape sliders the page plays itself (follow_sliders)
        self.weight_sliders: dict[str, Any] = {}
        #: receives surface clicks and marker Alt-clicks instead of the model's handles: an
        #: object with ``pick(vertex)`` and optionally ``remove(index, vertex)`` (the Rig
        #: tab's landmark picker); ``None`` = add / remove model handles
        self.pick_handler: Any = None
        #: every pointer gesture (widgets.viewport.gestures): one open at a time
        self.gestures = GestureDispatcher(
            self,
            {"handle": self._handle_gesture, "paint": self._paint_gesture},
            ack_extra={"paint": lambda: {"paint_version": self._paint_version}},
        )
        self._on_deformed = self.errors.guard("Viewport update")(self.sync.push_geometry_event)
        self._on_shapes = self.errors.guard("Viewport shapes update")(self.sync.push_geometry_event)
        self._on_handles = self.errors.guard("Viewport handles update")(self.sync.sync_handles)
        self._on_paint = self.errors.guard("Viewport paint overlay")(self.sync.sync_paint)
        self.on_msg(self._on_frontend_msg)
        ev = model.events
        ev.deformed.connect(self._on_deformed)
        ev.shapes.connect(self._on_shapes)
        ev.handles.connect(self._on_handles)
        ev.handles_changing.connect(self._on_handles)
        ev.paint_layers.connect(self._on_paint)
        ev.paint_layers_changing.connect(self._on_paint)
        self.sync.connected = True
        self.sync.push_geometry(force_full=True)
        self.sync.sync_handles()
        self.sync.sync_paint()

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
    def handles(self) -> np.ndarray:
        """(h,) uint32 vertex ids drawn as handle markers."""
        return np.frombuffer(self._handles, dtype="<u4").copy()

    @handles.setter
    def handles(self, value: Any) -> None:
        # Display-only markers: no mirror links; the model's handles come back when
        # its handle set next changes.
        with self.hold_sync():
            self._handles = u32_bytes(as_ids(value, self._model.n_vertices, "handles"))
            self._handle_mirror = b""

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
        if value not in TOOLS:
            raise t.TraitError(f"Viewport.tool must be one of {TOOLS}, got {value!r}")
        return value

    @t.observe("tool")
    def _on_tool_changed(self, _change: Any) -> None:
        # the last dragged marker is no longer highlighted once another tool is picked
        self.selected_handle = -1

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
    def brush(self) -> Any:
        """The current :class:`workbench.methods.paint.painting.Brush` (built from the brush traits)."""
        from workbench.methods.paint.painting import Brush

        return Brush(
            radius=self.brush_radius,
            opacity=self.brush_opacity,
            falloff=self.brush_falloff,  # type: ignore[arg-type]
            mode=self.brush_mode,  # type: ignore[arg-type]
            mirror=self.brush_mirror,
        )

    @property
    def dragging(self) -> bool:
        """True while a handle drag is open."""
        return self.gestures.current(HandleDrag) is not None

    @property
    def painting(self) -> bool:
        """True while a paint stroke (on the model's paint layers) is open."""
        return self.gestures.current(PaintStroke) is not None

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
                ev.handles.disconnect(self._on_handles)
                ev.handles_changing.disconnect(self._on_handles)
                ev.paint_layers.disconnect(self._on_paint)
                ev.paint_layers_changing.disconnect(self._on_paint)
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
        any wrinkle rows) follows and wins. Call again when the sliders are rebuilt.
        """
        self.weight_sliders = dict(sliders)
        self._weight_slider_ids = {str(k): str(w.model_id) for k, w in self.weight_sliders.items()}

    @t.observe("gpu")
    def _on_gpu(self, change: Any) -> None:
        if self._connected:
            if change["new"]:
                self.sync.gpu.unavailable = ""  # try again
            self.errors.guard("Viewport resync")(self.sync.push_geometry)(force_full=True)

    @t.observe("paint_expression", "paint_overlay")
    def _on_paint_settings(self, _change: Any) -> None:
        if self._connected:
            self.errors.guard("Viewport paint overlay")(self.sync.sync_paint)()

    # ------------------------------------------------------------ handle clicks
    def add_handle_at(self, vertex: int) -> int:
        """Add a model handle at ``vertex`` (Shift-click); with :attr:`symmetric` a mirrored pair.

        A pair is one undo step. Returns the new handle's index.
        """
        return add_handle(self, vertex)

    def remove_handle_at(self, index: int, vertex: int | None = None) -> None:
        """Remove a model handle (Alt-click); with :attr:`symmetric` its mirror too (one undo step)."""
        remove_handle(self, index, vertex)

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
        if kind in ("handle", "paint"):
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
        elif kind == "request_paint":
            self.errors.guard("Viewport paint resync")(self.sync.resend_paint)()
        elif kind == "add_handle":
            if self.pick_handler is not None:
                self.errors.guard("pick")(self.pick_handler.pick)(int(content["vertex"]))
            else:
                self.errors.guard("add handle")(self.add_handle_at)(int(content["vertex"]))
        elif kind == "remove_handle":
            v = content.get("vertex")
            vertex = None if v is None else int(v)
            if self.pick_handler is not None:
                remove = getattr(self.pick_handler, "remove", None)
                if remove is not None:
                    self.errors.guard("pick remove")(remove)(int(content["index"]), vertex)
            else:
                self.errors.guard("remove handle")(self.remove_handle_at)(int(content["index"]), vertex)

    # ----------------------------------------------- what the front end was sent
    # (read by tests and benchmarks; widgets.viewport.sync owns it)
    @property
    def updates_sent(self) -> dict[str, int]:
        return self.sync.updates_sent

    @property
    def paint_updates_sent(self) -> dict[str, int]:
        return self.sync.paint_updates_sent

    @property
    def push_ms(self) -> deque[float]:
        return self.sync.push_ms

    @property
    def _last(self) -> np.ndarray | None:
        return self.sync.last

    @property
    def _tolerance(self) -> float:
        return self.sync.tolerance

    @property
    def _model_handles_sent(self) -> tuple[bytes, bytes] | None:
        return self.sync.handles_sent

    @_model_handles_sent.setter
    def _model_handles_sent(self, value: tuple[bytes, bytes] | None) -> None:
        self.sync.handles_sent = value

    def _push_geometry(self, force_full: bool, tolerance: float = 0.0) -> None:
        self.sync.push_geometry(force_full, tolerance)

    def _sync_handles(self, *_args: Any) -> None:
        self.sync.sync_handles()

    def _sync_paint(self, *_args: Any) -> None:
        self.sync.sync_paint()

    @t.observe("feature_graph")
    def _on_feature_graph_shown(self, change: Any) -> None:
        pending = self.sync.strain_pending
        if change["new"] and pending is not None and pending.size == len(self._feature_edges) // 8:
            self.errors.guard("Viewport feature graph")(self.set_feature_strain)(pending)
