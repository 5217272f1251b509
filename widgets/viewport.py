"""``Viewport``: a client-side WebGL (three.js) view of a :class:`workbench.FaceModel`.

The viewport only *observes* the model: it subscribes to ``model.events.deformed``
and ``model.events.shapes`` and ships ``model.evaluate()`` to the browser. Two
viewports of one model therefore always agree, and an edit made from any cell
updates every view.

Transfer protocol (binary only, never JSON lists):

* ``_faces`` (uint32, m*3) and ``_labels`` (uint16, n) once per topology;
* ``_positions`` (float32, n*3): the full buffer, on load and whenever at least
  a third of the vertices changed;
* a custom message ``{"type": "patch", "version": v}`` with buffers
  ``[ids uint32 (k), values float32 (k*3)]`` when fewer than a third changed —
  a slider that moves the jaw touches a fraction of the head, so this is what a
  drag sends. ``_positions`` is then updated *without* a sync message so that a
  reloaded page still gets the current full state.

During an interaction (a slider drag, a handle drag: ``deformed(False)``) a
vertex is re-sent only when it moved more than :data:`DRAG_TOLERANCE` of the
mesh's size since the front end last got it: the shell basis of a handle moves
almost every vertex of the face by a tiny amount, and sending all of them
would turn every drag frame into a full buffer. The final event of the
interaction sends the exact positions.

Camera orbit/zoom/pan happen entirely in the browser (OrbitControls): they
never send a kernel message. Each view frames the camera on the *neutral*
mesh's bounds (``_neutral_bounds``, sent with every topology), not on the first
positions it receives, and at the canvas's current size: on its first geometry
and again whenever the canvas is resized, until the person orbits, zooms or
pans (from then on the camera is theirs). So a fresh app, a recovered session
and one opened on a posed face (jaw open, a sculpted handle) frame the face
identically, whatever width the notebook gave the view when it first drew.

Handle editing (``tool="sculpt"``, Bickel et al. 2008 §4): the front end picks
handle markers and sends small JSON messages

* ``{"type": "handle", "phase": "start" | "move" | "end", "index", "vertex",
  "position": [x, y, z], "seq"}`` — a drag in the view plane; Python wraps it
  in ``model.interaction("Drag handle <name>")`` (one undo step) and answers
  every message with ``{"type": "handle_ack", "seq", "version", "kernel_ms"}``.
  The front end keeps at most one move in flight (it sends the newest pointer
  position when the previous ack arrives), so a slow kernel is never flooded;
* ``{"type": "add_handle", "vertex"}`` (Shift-click on the surface) and
  ``{"type": "remove_handle", "index", "vertex"}`` (Alt-click on a marker).

The markers are the model's handles (``model.handles``), re-sent whenever the
handle *set* changes; ``Viewport.handles = ids`` draws other markers until the
model's handle set next changes.

Painterly blending (``tool="paint"``, Pighin et al. 1998 §4.2): a left press on
the face starts a stroke, every move raycasts the surface and the hit triangle's
nearest corner becomes a brush dab; release ends the stroke. Messages:

* ``{"type": "paint", "phase": "start" | "move" | "end", "vertices": [v, ...],
  "seq"}`` — Python wraps the stroke in ``model.interaction("Paint <expr>")``
  (one undo step) and calls ``model.paint_dab(paint_expression, v, brush)`` for
  every vertex (the front end queues the hit vertices spaced a quarter of the
  brush radius apart while a message is in flight, at most 8 per message, so a
  fast stroke has no gaps and a slow kernel still gets one message at a time).
  Every message is answered with ``{"type": "paint_ack", "seq", "version",
  "kernel_ms"}`` and its geometry patch carries the same ``seq``.
* Stroke hook: while an object is set with :meth:`Viewport.set_stroke_handler`
  (the Sculpt tab's wrinkle eraser, :class:`widgets.wrinkle_panel.WrinkleEraser`),
  the same strokes go to it instead of the model's paint layers:
  ``handler.begin()`` at "start", ``handler.dab(vertices)`` for the dabs of every
  message, ``handler.end()`` at "end" (``handler.cancel()`` after an error); the
  acks are the same. The front end lets a press paint when ``stroke_target`` (a
  description of what the stroke does) is set, even with no ``paint_expression``;
  the overlay then shows ``handler.overlay()`` (the stroke's mask so far).
* The weight-map overlay (the selected expression's painted weights, tinted
  magenta over the skin) is the binary trait ``_paint_weights`` (float32 n, or
  empty = nothing painted / overlay off) plus ``{"type": "paint_patch",
  "version"}`` messages with buffers ``[ids uint32, weights float32]`` for the
  vertices whose weight changed — the same full/patch scheme as the geometry,
  with its own version counter ``_paint_version``.

The brush (``brush_radius`` in model units along the surface, ``brush_opacity``,
``brush_falloff``, ``brush_mode``, ``brush_mirror``) lives on the viewport so the
front end can draw the brush cursor (a ring on the surface under the pointer, and
its mirror image with ``brush_mirror``); :class:`widgets.PaintPanel` links its
controls to these traits.

Feature-graph overlay (pose-space wrinkles, Bickel et al. 2008 §5.1): the edges
between handles on which a :class:`workbench.methods.wrinkles.layer.WrinkleLayer` measures
skin strain, drawn as line segments coloured by their relative stretch (blue =
compressed, grey = rest, red = stretched, full colour at ±:attr:`Viewport.strain_range`).
Two binary traits, each sent only when it changes: ``_feature_edges`` (uint32,
F*2 vertex ids: :meth:`Viewport.set_feature_graph`) and ``_feature_strain``
(float32, F: :meth:`Viewport.set_feature_strain`, called by
:class:`widgets.WrinklePanel` on every model change). The end points follow the
drawn geometry in the browser, so a drag sends only the F strain values
(~0.7 kB for ~175 edges). Hidden (``feature_graph = False``), no strain is sent.
The lines are depth-tested against the face, so the head hides them seen from
behind. An edge is a straight chord between two handles and dips under the
curved skin (up to about half its length where it crosses under the lips or
the side of the nose), so the front end moves its end points toward the
camera along their view rays (the same pixels, a smaller depth) by
``FEATURE_DEPTH_PULL`` (``viewport.js``) times the edge's length.

Why hand-written rather than pythreejs / pyvista: see ``widgets/js/src/viewport.js``.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections import deque
from pathlib import Path
from typing import Any

import anywidget
import ipywidgets
import numpy as np
import traitlets as t

from widgets._threading import (
    ErrorSink,
    close_interactions,
    register_interaction_closer,
    unregister_interaction_closer,
)

_STATIC = Path(__file__).resolve().parent / "static"
BUNDLE = _STATIC / "viewport.js"

#: Below this fraction of changed vertices an update is sent as (ids, values).
SPARSE_FRACTION = 1.0 / 3.0

#: During an interaction, vertices that moved less than this fraction of the mesh's
#: bounding-box diagonal are not re-sent (about 1/40 pixel at the default framing,
#: 1/4 pixel zoomed in 10x); the interaction's final update is exact.
DRAG_TOLERANCE = 5e-5

#: A handle drag or paint stroke with no message from the front end for this long is
#: ended (the page was closed mid-drag): the model must never be left inside an interaction.
DRAG_WATCHDOG_S = 30.0

TOOLS = ("orbit", "sculpt", "paint")
FALLOFFS = ("smooth", "linear", "constant", "sphere")
BRUSH_MODES = ("add", "subtract", "smooth")

#: Default brush radius as a fraction of the face height (the skin's extent along up).
BRUSH_RADIUS_FRACTION = 0.03

#: Most dabs one "paint" message may carry (the front end sends at most 8).
MAX_DABS_PER_MESSAGE = 32

#: Relative stretch drawn in full colour by the feature-graph overlay (±20 %).
STRAIN_RANGE = 0.2

#: A strain update is sent only when some edge changed by more than this (0.01 %).
STRAIN_TOLERANCE = 1e-4

_bundle_cache: dict[str, Any] = {}


def load_bundle(path: Path = BUNDLE) -> str:
    """The viewport's ESM bundle (three.js included), re-read when it changes on disk.

    Raises
    ------
    FileNotFoundError
        When the bundle was not built (``widgets/static/`` is not committed).
    """
    try:
        stat = path.stat()
    except FileNotFoundError:
        raise FileNotFoundError(
            f"the viewport's JavaScript bundle {path} is missing: it is built from "
            "widgets/js (three.js + esbuild). Run the README test/run command or "
            "`npm --prefix widgets/js ci && npm --prefix widgets/js run build`."
        ) from None
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    if _bundle_cache.get("key") != key:
        _bundle_cache["key"] = key
        _bundle_cache["text"] = path.read_text(encoding="utf-8")
    return str(_bundle_cache["text"])


def _f32_bytes(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype="<f4").tobytes()


def _u32_bytes(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype="<u4").tobytes()


def _as_ids(value: Any, n: int, what: str) -> np.ndarray:
    ids = np.asarray(value if value is not None else [], dtype=np.int64).reshape(-1)
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise ValueError(f"Viewport.{what}: vertex ids must be in 0..{n - 1}")
    return ids.astype(np.uint32)


def face_height(model: Any) -> float:
    """Extent of the skin (or of the whole mesh) along the model's up axis, model units."""
    V = np.asarray(model.vertices)
    if not V.size:
        return 1.0
    names = list(getattr(model, "component_names", []) or [])
    labels = np.asarray(getattr(model, "component_labels", np.zeros(0)))
    if "skin" in names and labels.size == V.shape[0]:
        skin = V[labels == names.index("skin")]
        V = skin if skin.size else V
    up = str(getattr(getattr(model, "metadata", None), "up_axis", "+y") or "+y")
    axis = {"x": 0, "y": 1, "z": 2}.get(up[-1:].lower(), 1)
    h = float(np.ptp(V[:, axis]))
    return h if h > 0 else float(np.linalg.norm(np.ptp(V, axis=0))) or 1.0


def neutral_bounds(model: Any) -> dict[str, Any]:
    """``{"min": [x, y, z], "max": [x, y, z], "radius": r}`` of the neutral mesh (``model.vertices``).

    ``radius``: the largest distance of a vertex from the box centre (what
    three.js's ``computeBoundingSphere`` gives). The front end frames the camera
    on this box and sizes the handle markers by this radius, so neither depends
    on the expression shown when the view opened.
    """
    V = np.asarray(model.vertices, dtype=np.float64).reshape(-1, 3)
    if not V.size or not np.isfinite(V).all():
        return {}
    lo, hi = V.min(axis=0), V.max(axis=0)
    r = float(np.sqrt(((V - (lo + hi) / 2) ** 2).sum(axis=1).max()))
    return {"min": lo.tolist(), "max": hi.tolist(), "radius": r}


def default_brush_radius(model: Any) -> float:
    """:data:`BRUSH_RADIUS_FRACTION` of the face height (about a third of the mouth width)."""
    return BRUSH_RADIUS_FRACTION * face_height(model)


def brush_radius_slider(
    model: Any, viewport: Any, description: str, **kwargs: Any
) -> ipywidgets.FloatSlider:
    """The brush-radius slider shared by the paint and wrinkle-erase tools.

    Starts at the viewport's brush radius (or :func:`default_brush_radius`) and
    spans 0.5 %–30 % of the face height; ``kwargs`` go to the slider (style, layout).
    """
    H = face_height(model)
    r0 = float(getattr(viewport, "brush_radius", 0.0) or default_brush_radius(model))
    return ipywidgets.FloatSlider(
        value=r0,
        min=0.005 * H,
        max=0.3 * H,
        step=0.001 * H,
        readout_format=".3f",
        description=description,
        **kwargs,
    )


def _changed_rows(new: np.ndarray, old: np.ndarray, tolerance: float) -> np.ndarray:
    """Rows (vertices) of (n, 3) ``new`` that differ from ``old`` by more than ``tolerance``.

    Column-wise ORs instead of ``.any(axis=1)``: numpy's axis reduction over a
    short last axis was half of the kernel's time per drag frame at 100k vertices.
    """
    if tolerance > 0:
        d = np.abs(new - old)
        mask = d[:, 0] > tolerance
        mask |= d[:, 1] > tolerance
        mask |= d[:, 2] > tolerance
    else:
        mask = new[:, 0] != old[:, 0]
        mask |= new[:, 1] != old[:, 1]
        mask |= new[:, 2] != old[:, 2]
    return np.flatnonzero(mask)


class Viewport(anywidget.AnyWidget):
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

    The front end writes the markers' screen positions to ``data-handles``
    (JSON ``[[x, y, in_front], ...]`` in page pixels) after every render.
    """

    _esm = t.Unicode("").tag(sync=True)
    _uid = t.Unicode("").tag(sync=True)
    _faces = t.Bytes(b"").tag(sync=True)
    _labels = t.Bytes(b"").tag(sync=True)
    _positions = t.Bytes(b"").tag(sync=True)
    _version = t.Int(0).tag(sync=True)
    _topology = t.Int(0).tag(sync=True)
    _component_names = t.List(t.Unicode()).tag(sync=True)
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
    # feature-graph overlay (see "Feature graph overlay" below)
    _feature_edges = t.Bytes(b"").tag(sync=True)
    _feature_strain = t.Bytes(b"").tag(sync=True)
    feature_graph = t.Bool(True).tag(sync=True)
    strain_range = t.Float(STRAIN_RANGE).tag(sync=True)

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
        super().__init__(_esm=esm, _uid=uuid.uuid4().hex, height=height, **kwargs)
        self._model = model
        self._send_lock = threading.RLock()
        self._last: np.ndarray | None = None  # what the front end has, (n, 3) float32
        self._last_faces: np.ndarray | None = None
        self._faces_ref: np.ndarray | None = None
        self._positions_stale = False
        self.errors = ErrorSink(errors, on_error=self._show_error)
        #: comm messages received from the front end (tests assert orbit sends none)
        self.frontend_msg_count = 0
        self.updates_sent = {"full": 0, "patch": 0}
        #: kernel-side ms per geometry update (diff + serialise + send), for benchmarks
        self.push_ms: deque[float] = deque(maxlen=256)
        #: kernel-side ms per handle move (move_handle: rank-1 update + evaluate + send)
        self.drag_ms: deque[float] = deque(maxlen=512)
        #: the geometry-send part of the last drag_ms entries
        self.drag_push_ms: deque[float] = deque(maxlen=512)
        #: called after each handle drag ends with a dict of stats (SculptPanel status line)
        self.drag_listeners: list[Any] = []
        self.last_drag: dict[str, Any] = {}
        self._drag_lock = threading.RLock()
        self._drag: dict[str, Any] | None = None
        self._drag_cm: Any = None
        self._watchdog: threading.Timer | None = None
        self._last_drag_msg = 0.0
        self._drag_seq: Any = None  # seq of the move being applied (sent with its patch)
        self._last_push_ms = 0.0
        # paint strokes (tool="paint")
        self._stroke: dict[str, Any] | None = None
        self._stroke_cm: Any = None
        #: core ms per brush dab (model.paint_dab), for the status line and benchmarks
        self.dab_ms: deque[float] = deque(maxlen=2048)
        #: kernel ms per paint message (its dabs + overlay + geometry send)
        self.paint_ms: deque[float] = deque(maxlen=512)
        #: called after each stroke ends with a dict of stats (PaintPanel status line)
        self.stroke_listeners: list[Any] = []
        self.last_stroke: dict[str, Any] = {}
        #: receives paint strokes instead of the model's paint layers (set_stroke_handler)
        self.stroke_handler: Any = None
        self._hook_stroke = False  # a hooked stroke is open
        # While a message's dabs run, model events only mark the view stale; one
        # overlay + geometry update is sent after the last dab of the message.
        self._hold_pushes = 0
        self._push_pending = False
        self._paint_last: np.ndarray | None = None  # weights the front end has (None = empty)
        self._paint_last_ref: Any = None  # the model's array they came from
        self.paint_updates_sent = {"full": 0, "patch": 0}
        size = np.ptp(np.asarray(model.vertices), axis=0) if model.n_vertices else np.zeros(3)
        self._tolerance = float(DRAG_TOLERANCE * np.linalg.norm(size))
        self._on_deformed = self.errors.guard("Viewport update")(self._push_geometry_event)
        self._on_shapes = self.errors.guard("Viewport shapes update")(self._push_geometry_event)
        self._on_handles = self.errors.guard("Viewport handles update")(self._sync_handles)
        self._on_paint = self.errors.guard("Viewport paint overlay")(self._sync_paint)
        self.on_msg(self._on_frontend_msg)
        model.events.deformed.connect(self._on_deformed)
        model.events.shapes.connect(self._on_shapes)
        model.events.handles.connect(self._on_handles)
        model.events.handles_changing.connect(self._on_handles)
        model.events.paint_layers.connect(self._on_paint)
        model.events.paint_layers_changing.connect(self._on_paint)
        # other widgets' edits end an open drag or stroke first (one undo step each)
        register_interaction_closer(model, self.end_drag)
        register_interaction_closer(model, self.end_stroke)
        self._connected = True
        self._push_geometry(force_full=True)
        self._sync_handles()
        self._sync_paint()

    # ------------------------------------------------------------------ public
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
            self._vertex_colors = None
            return
        c = np.asarray(value, dtype=np.float32)
        n = self._model.n_vertices
        if c.shape != (n, 3):
            raise ValueError(f"Viewport.vertex_colors must be (n, 3) = ({n}, 3), got {c.shape}")
        if not np.isfinite(c).all():
            raise ValueError("Viewport.vertex_colors contains NaN/inf")
        self._vertex_colors = _f32_bytes(c)

    @property
    def handles(self) -> np.ndarray:
        """(h,) uint32 vertex ids drawn as handle markers."""
        return np.frombuffer(self._handles, dtype="<u4").copy()

    @handles.setter
    def handles(self, value: Any) -> None:
        # Display-only markers: no mirror links; the model's handles come back when
        # its handle set next changes.
        with self.hold_sync():
            self._handles = _u32_bytes(_as_ids(value, self._model.n_vertices, "handles"))
            self._handle_mirror = b""

    @property
    def probe_ids(self) -> np.ndarray:
        """(p,) uint32: vertices whose screen positions go to ``data-probe``."""
        return np.frombuffer(self._probe_ids, dtype="<u4").copy()

    @probe_ids.setter
    def probe_ids(self, value: Any) -> None:
        self._probe_ids = _u32_bytes(_as_ids(value, self._model.n_vertices, "probe_ids"))

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
        """True while a handle drag from the front end is open."""
        return self._drag is not None

    @property
    def painting(self) -> bool:
        """True while a paint stroke from the front end is open."""
        return self._stroke is not None

    def close(self) -> None:
        """End an open handle drag or stroke, disconnect from the model, then close the widget."""
        if getattr(self, "_connected", False):
            try:
                self.end_drag()
                self.end_stroke()
                self.set_stroke_handler(None)
            finally:
                ev = self._model.events
                ev.deformed.disconnect(self._on_deformed)
                ev.shapes.disconnect(self._on_shapes)
                ev.handles.disconnect(self._on_handles)
                ev.handles_changing.disconnect(self._on_handles)
                ev.paint_layers.disconnect(self._on_paint)
                ev.paint_layers_changing.disconnect(self._on_paint)
                unregister_interaction_closer(self._model, self.end_drag)
                unregister_interaction_closer(self._model, self.end_stroke)
                self._connected = False
        super().close()

    # ------------------------------------------------------------ paint strokes
    def set_stroke_handler(self, handler: Any, target: str = "") -> None:
        """Send paint strokes to ``handler`` instead of the model's paint layers (None: back).

        ``handler`` has ``begin()``, ``dab(vertices)``, ``end()``, ``cancel()``
        and optionally ``overlay() -> (n,) float or None`` (drawn as the paint
        overlay while it is set). ``target`` describes what a stroke does (the
        front end paints on a press only when it, or :attr:`paint_expression`,
        is set). An open stroke of the previous handler is cancelled.
        """
        if handler is not None and not str(target):
            raise ValueError("Viewport.set_stroke_handler: describe the stroke's target")
        with self._drag_lock:
            old = self.stroke_handler
            if old is not None and old is not handler and self._hook_stroke:
                self._hook_stroke = False
                old.cancel()
            if handler is not None:
                self.end_stroke()
            self.stroke_handler = handler
            self._hook_stroke = self._hook_stroke and handler is old
            self.stroke_target = str(target) if handler is not None else ""
        # the overlay's source changed: send the difference to what the front end has
        if getattr(self, "_connected", False):
            self.errors.guard("Viewport paint overlay")(self._sync_paint)()

    def _on_hooked_paint_msg(self, content: dict[str, Any]) -> None:
        """A paint message while a stroke handler is set (see :meth:`set_stroke_handler`)."""
        handler, phase, ms = self.stroke_handler, content.get("phase"), 0.0
        verts = content.get("vertices") or []
        try:
            with self._drag_lock:
                if phase == "start":
                    close_interactions(self._model)
                    self.end_drag()
                    self.end_stroke()
                    handler.begin()
                    self._hook_stroke = True
                if verts and self._hook_stroke:
                    ids = np.asarray([int(v) for v in verts], np.int64)[-MAX_DABS_PER_MESSAGE:]
                    if ids.min() < 0 or ids.max() >= self._model.n_vertices:
                        raise ValueError(f"paint stroke: vertex ids out of range: {ids}")
                    t0 = time.perf_counter()
                    handler.dab(ids)
                    self._sync_paint()
                    ms = (time.perf_counter() - t0) * 1e3
                if phase == "end" and self._hook_stroke:
                    self._hook_stroke = False
                    handler.end()
                    self._sync_paint()
        except Exception as exc:
            try:
                if self._hook_stroke:
                    self._hook_stroke = False
                    handler.cancel()
                    self._sync_paint()
            finally:
                self.errors.report(f"paint stroke ({phase})", exc)
                self.send({"type": "paint_cancel"})
        finally:
            self._send_paint_ack(content.get("seq"), phase, ms)

    def begin_stroke(self, expression: str | None = None) -> None:
        """Start a paint stroke (what the front end's "start" message does).

        Enters ``model.interaction("Paint <expression>")``; an open drag or stroke,
        and every interaction other widgets hold open (a slider drag waiting for
        its idle timer), is ended first. ``expression`` defaults to
        :attr:`paint_expression`.
        """
        from workbench.methods.paint.expressions import expression_names

        model = self._model
        expr = expression if expression is not None else self.paint_expression
        close_interactions(model)
        with self._drag_lock:
            self.end_drag()
            self.end_stroke()
            if not expr:
                raise ValueError(
                    "Viewport: pick an expression to paint with first "
                    "(click a thumbnail in the Paint tab's palette, or set paint_expression)"
                )
            with model.lock:
                if expr not in model.expressions and expr not in model.shape_names:
                    raise KeyError(
                        f"Viewport: cannot paint {expr!r}: no such expression; "
                        f"have {expression_names(model)[:8]}..."
                    )
                cm = model.interaction(f"Paint {expr}")
                cm.__enter__()
            self._stroke_cm = cm
            self._stroke = {
                "expression": expr,
                "brush": self.brush,
                "t0": time.perf_counter(),
                "dabs": 0,
                "messages": 0,
                "dab_ms": [],
                "ms": [],
            }
            self._arm_watchdog()

    def paint_at(self, vertices: Any) -> float:
        """Brush dabs at vertex ids ``vertices`` (int or sequence) within the open stroke.

        One overlay + geometry update is sent after the last dab. Returns the
        kernel time in ms (dabs + updates); 0 without an open stroke.
        """
        ids = np.asarray(vertices, dtype=np.int64).reshape(-1)
        model = self._model
        if ids.size > MAX_DABS_PER_MESSAGE:
            ids = ids[-MAX_DABS_PER_MESSAGE:]
        if ids.size and (ids.min() < 0 or ids.max() >= model.n_vertices):
            raise ValueError(
                f"Viewport.paint_at: vertex ids must be in 0..{model.n_vertices - 1}, got {ids}"
            )
        with self._drag_lock:
            stroke = self._stroke
            if stroke is None or not ids.size:
                return 0.0
            t0 = time.perf_counter()
            # The brush of the press is used for the whole stroke: slider changes made
            # mid-stroke (another view) apply to the next one.
            brush = stroke["brush"]
            self._hold_pushes += 1
            try:
                with model.lock:
                    for v in ids:
                        td = time.perf_counter()
                        model.paint_dab(stroke["expression"], int(v), brush)
                        ms = (time.perf_counter() - td) * 1e3
                        stroke["dab_ms"].append(ms)
                        self.dab_ms.append(ms)
            finally:
                self._hold_pushes -= 1
            if self._push_pending and not self._hold_pushes:
                self._push_pending = False
                self._sync_paint()
                self._push_geometry_event(False)
            ms = (time.perf_counter() - t0) * 1e3
            stroke["dabs"] += int(ids.size)
            stroke["messages"] += 1
            stroke["ms"].append(ms)
            self.paint_ms.append(ms)
            self._arm_watchdog()
            return ms

    def end_stroke(self) -> None:
        """End the open paint stroke (one undo step); no-op without one."""
        with self._drag_lock:
            if self._drag is None:
                self._cancel_watchdog()
            cm, stroke = self._stroke_cm, self._stroke
            self._stroke_cm, self._stroke = None, None
            if cm is None or stroke is None:
                return
            # Model lock first: the same order as edits (model lock, then events).
            with self._model.lock:
                cm.__exit__(None, None, None)
            dur = time.perf_counter() - stroke["t0"]
            dab, ms = stroke["dab_ms"], stroke["ms"]
            self.last_stroke = {
                "expression": stroke["expression"],
                "dabs": stroke["dabs"],
                "messages": stroke["messages"],
                "seconds": dur,
                "median_dab_ms": float(np.median(dab)) if dab else float("nan"),
                "median_ms": float(np.median(ms)) if ms else float("nan"),
                "updates_per_s": stroke["messages"] / dur if dur > 0 else float("nan"),
            }
        for fn in list(self.stroke_listeners):
            self.errors.guard("stroke listener")(fn)(dict(self.last_stroke))

    def _sync_paint(self, *_args: Any) -> None:
        """Send the selected expression's painted weights: full buffer or changed vertices."""
        if self._hold_pushes:
            self._push_pending = True
            return
        model = self._model
        with model.lock, self._send_lock:
            if not getattr(self, "_connected", False):
                return
            handler = self.stroke_handler
            if handler is not None:
                overlay = getattr(handler, "overlay", None)
                w = overlay() if overlay is not None else None
                w = None if w is None else np.asarray(w, dtype=np.float32)
            else:
                expr = self.paint_expression if self.paint_overlay else ""
                w = model.paint_layers.get(expr) if expr else None
            last = self._paint_last
            if w is None:
                if last is not None:
                    self._send_paint_full(None)
                return
            if last is None or last.shape != w.shape:
                self._send_paint_full(w)
                return
            if w is self._paint_last_ref:
                return
            changed = np.flatnonzero(w != last)
            self._paint_last_ref = w
            if changed.size == 0:
                return
            if changed.size >= SPARSE_FRACTION * w.shape[0]:
                self._send_paint_full(w)
                return
            last[changed] = w[changed]
            version = self._paint_version + 1
            # Silent: a reloaded page gets the current weights without a full sync here.
            self._trait_values["_paint_version"] = version
            self._trait_values["_paint_weights"] = _f32_bytes(last)
            self.send(
                {"type": "paint_patch", "version": version, "count": int(changed.size)},
                buffers=[_u32_bytes(changed), _f32_bytes(w[changed])],
            )
            self.paint_updates_sent["patch"] += 1

    def _send_paint_full(self, w: np.ndarray | None) -> None:
        self._paint_last = None if w is None else np.array(w, dtype=np.float32)
        self._paint_last_ref = w
        with self.hold_sync():
            self._paint_weights = b"" if w is None else _f32_bytes(w)
            self._paint_version = self._paint_version + 1
        self.paint_updates_sent["full"] += 1

    @t.observe("paint_expression", "paint_overlay")
    def _on_paint_settings(self, _change: Any) -> None:
        if getattr(self, "_connected", False):
            self.errors.guard("Viewport paint overlay")(self._sync_paint)()

    # ------------------------------------------------------------ handle drags
    def begin_drag(self, index: int, vertex: int | None = None) -> None:
        """Start dragging handle ``index`` (what the front end's "start" message does).

        Enters ``model.interaction("Drag handle <name>")``; an open drag or stroke,
        and every interaction other widgets hold open (a slider drag waiting for
        its idle timer), is ended first.
        """
        model = self._model
        close_interactions(model)
        with self._drag_lock:
            self.end_drag()
            self.end_stroke()
            with model.lock:
                h = model.handles
                resolved = self._resolve_handle(index, vertex)
                if resolved is None:
                    raise ValueError(
                        f"Viewport: no handle {index} at vertex {vertex} to drag "
                        f"(the model has {len(h)} handles)"
                    )
                index = resolved
                name = h.names[index]
                cm = model.interaction(f"Drag handle {name}")
                cm.__enter__()
            self._drag_cm = cm
            self._drag = {
                "index": index,
                "vertex": int(h.vertices[index]),
                "name": name,
                "t0": time.perf_counter(),
                "moves": 0,
                "ms": [],
            }
            self.selected_handle = index
            self._arm_watchdog()

    def _unposed(self, position: Any) -> Any:
        """A point picked on the shown mesh, in model space.

        The view draws :meth:`FaceModel.evaluate`, which applies the keyed head pose
        last; handle offsets and region pins live before it, so a pointer position
        is mapped back with the inverse rigid transform (a no-op without a pose).
        """
        M = self._model.head_matrix()
        if np.array_equal(M, np.eye(4)):
            return position
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,):
            raise ValueError(f"Viewport: a position must be 3 numbers, got {position!r}")
        return np.linalg.solve(M, np.append(p, 1.0))[:3]

    def drag_to(self, position: Any) -> float:
        """Move the dragged handle's vertex to ``position`` (3,) in model space.

        The handle offset is ``position - model.blended()[vertex]`` (the edit sits
        on top of the blend); with :attr:`symmetric` the mirror handle follows.
        Returns the kernel time in ms (rank-1 update + evaluate + send).
        """
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(
                f"Viewport.drag_to: position must be 3 finite numbers, got {position!r}"
            )
        model = self._model
        with self._drag_lock:
            drag = self._drag
            if drag is None:
                return 0.0
            t0 = time.perf_counter()
            self._last_push_ms = 0.0
            with model.lock:
                index = self._resolve_handle(drag["index"], drag["vertex"])
                if index is None:  # the handle was removed while dragging
                    self.end_drag()
                    self.send({"type": "handle_cancel"})
                    return 0.0
                drag["index"] = index
                offset = p - model.blended()[drag["vertex"]]
                model.move_handle(index, offset, symmetric=self.symmetric)
            ms = (time.perf_counter() - t0) * 1e3
            drag["moves"] += 1
            drag["ms"].append(ms)
            self.drag_ms.append(ms)
            self.drag_push_ms.append(self._last_push_ms)
            self._arm_watchdog()
            return ms

    def end_drag(self) -> None:
        """End the open handle drag (one undo step); no-op without one."""
        with self._drag_lock:
            if self._stroke is None:
                self._cancel_watchdog()
            cm, drag = self._drag_cm, self._drag
            self._drag_cm, self._drag = None, None
            if cm is None or drag is None:
                return
            # Model lock first: the same order as edits (model lock, then events).
            with self._model.lock:
                cm.__exit__(None, None, None)
            dur = time.perf_counter() - drag["t0"]
            ms = drag["ms"]
            self.last_drag = {
                "name": drag["name"],
                "moves": drag["moves"],
                "seconds": dur,
                "median_ms": float(np.median(ms)) if ms else float("nan"),
                "last_ms": ms[-1] if ms else float("nan"),
                "updates_per_s": drag["moves"] / dur if dur > 0 else float("nan"),
            }
        for fn in list(self.drag_listeners):
            self.errors.guard("drag listener")(fn)(dict(self.last_drag))

    def _arm_watchdog(self) -> None:
        # One timer per drag, not per move: starting a thread per move cost up to
        # 100 ms on 2 cores busy with software WebGL. The timer re-arms itself
        # for the time left since the last message.
        self._last_drag_msg = time.monotonic()
        if self._watchdog is None:
            self._start_watchdog(DRAG_WATCHDOG_S)

    def _cancel_watchdog(self) -> None:
        if self._watchdog is not None:
            self._watchdog.cancel()
            self._watchdog = None

    def _start_watchdog(self, delay: float) -> None:
        self._watchdog = threading.Timer(delay, self._on_watchdog)
        self._watchdog.daemon = True
        self._watchdog.start()

    def _on_watchdog(self) -> None:
        try:
            with self._drag_lock:
                if self._drag is None and self._stroke is None:
                    self._watchdog = None
                    return
                idle = time.monotonic() - self._last_drag_msg
                if idle < DRAG_WATCHDOG_S:
                    self._start_watchdog(DRAG_WATCHDOG_S - idle)
                    return
                self._watchdog = None
            self.end_drag()
            self.end_stroke()
        except Exception as exc:
            self.errors.report("ending an abandoned handle drag or paint stroke", exc)

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

    def add_handle_at(self, vertex: int) -> int:
        """Add a model handle at ``vertex`` (Shift-click); with :attr:`symmetric` a mirrored pair.

        A pair is one undo step. Returns the new handle's index.
        """
        from workbench.methods.handles.presets import mirror_vertices
        from workbench.model import HandleSet

        model = self._model
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
            if not self.symmetric or abs(V[v, 0]) <= mid_tol:
                return int(model.add_handle(v, name=name))
            m = int(mirror_vertices(V, np.array([v]), same)[0])
            side, other = ("L", "R") if V[v, 0] > 0 else ("R", "L")
            model.set_handles(
                HandleSet(
                    np.append(h.vertices, [v, m]),
                    np.vstack([h.offsets, np.zeros((2, 3), np.float32)]),
                    (*h.names, f"user_{side}_{idx}", f"user_{other}_{idx}"),
                    np.append(h.mirror, [idx + 1, idx]),
                ),
                label=f"Add handle pair user_{idx}",
            )
            return idx

    def remove_handle_at(self, index: int, vertex: int | None = None) -> None:
        """Remove a model handle (Alt-click); with :attr:`symmetric` its mirror too (one undo step)."""
        from workbench.model import HandleSet

        model = self._model
        close_interactions(model)
        with model.lock:
            i = self._resolve_handle(index, vertex)
            if i is None:
                return
            h = model.handles
            drop = {i}
            if self.symmetric and h.mirror[i] >= 0:
                drop.add(int(h.mirror[i]))
            if len(drop) == 1:
                model.remove_handle(i)
            else:
                keep = np.array([k not in drop for k in range(len(h))])
                remap = np.cumsum(keep) - 1
                mir = h.mirror[keep]
                gone = np.isin(mir, list(drop)) | (mir < 0)
                mir = np.where(gone, -1, remap[np.maximum(mir, 0)])
                model.set_handles(
                    HandleSet(
                        h.vertices[keep],
                        h.offsets[keep],
                        tuple(nm for k, nm in enumerate(h.names) if k not in drop),
                        mir,
                    ),
                    label=f"Remove handle pair {h.names[i]}",
                )
            if self.selected_handle >= len(model.handles):
                self.selected_handle = -1

    def _sync_handles(self, *_args: Any) -> None:
        """Send the model's handle vertices / mirror links when the handle *set* changed."""
        with self._model.lock:
            h = self._model.handles
            verts = _u32_bytes(h.vertices)
            mirror = np.ascontiguousarray(h.mirror, dtype="<i4").tobytes()
        if (verts, mirror) != self._model_handles_sent:
            self._model_handles_sent = (verts, mirror)
            with self.hold_sync():
                self._handles = verts
                self._handle_mirror = mirror
                if self.selected_handle >= len(h):
                    self.selected_handle = -1

    _model_handles_sent: tuple[bytes, bytes] | None = None

    # --------------------------------------------------------------- internals
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
        if kind == "request_full":
            self.errors.guard("Viewport resync")(self._push_geometry)(force_full=True)
        # --- drag_handler hook (RegionsPanel drag mode, widgets/regions_panel.py) ---
        # While an object is set as ``viewport.drag_handler`` (plain attribute, default
        # unset/None), marker drags call its begin(index, vertex) / move(index, position)
        # -> kernel ms / end() instead of moving model handles; acks are the same.
        elif kind == "handle" and getattr(self, "drag_handler", None) is not None:
            handler, phase, ms = self.drag_handler, content.get("phase"), 0.0
            try:
                if phase == "start":
                    v = content.get("vertex")
                    close_interactions(self._model)
                    handler.begin(int(content["index"]), None if v is None else int(v))
                elif phase in ("move", "end") and content.get("position") is not None:
                    pos = self._unposed(content["position"])
                    ms = float(handler.move(int(content["index"]), pos) or 0.0)
                if phase == "end":
                    handler.end()
            except Exception as exc:
                try:
                    handler.end()  # never leave the model inside an interaction
                finally:
                    self.errors.report(f"drag handler ({phase})", exc)
                    self.send({"type": "handle_cancel"})
            finally:
                ack = {"type": "handle_ack", "seq": content.get("seq"), "phase": phase}
                self.send({**ack, "version": self._version, "kernel_ms": round(ms, 3)})
        # --- end drag_handler hook ---
        elif kind == "handle":
            self._on_handle_msg(content)
        elif kind == "paint" and self.stroke_handler is not None:
            self._on_hooked_paint_msg(content)
        elif kind == "paint":
            self._on_paint_msg(content)
        elif kind == "request_paint":
            with self._model.lock, self._send_lock:
                self._paint_last = None
            self.errors.guard("Viewport paint resync")(self._sync_paint)()
        elif kind == "add_handle":
            self.errors.guard("add handle")(self.add_handle_at)(int(content["vertex"]))
        elif kind == "remove_handle":
            v = content.get("vertex")
            self.errors.guard("remove handle")(self.remove_handle_at)(
                int(content["index"]), None if v is None else int(v)
            )

    def _on_handle_msg(self, content: dict[str, Any]) -> None:
        phase = content.get("phase")
        ms = 0.0
        try:
            if phase == "start":
                v = content.get("vertex")
                self.begin_drag(int(content["index"]), None if v is None else int(v))
            elif phase == "move":
                # The geometry patch of this move carries its seq: the front end may
                # send the next move as soon as the patch arrives (acks were seen to
                # arrive 100+ ms after the patch sent just before them in headless
                # Chromium while it handles pointer input).
                self._drag_seq = content.get("seq")
                try:
                    ms = self.drag_to(self._unposed(content["position"]))
                finally:
                    self._drag_seq = None
            elif phase == "end":
                try:
                    if content.get("position") is not None and self._drag is not None:
                        ms = self.drag_to(self._unposed(content["position"]))
                finally:
                    self.end_drag()
        except Exception as exc:
            # Never leave the model inside an interaction after a failed move.
            try:
                self.end_drag()
            finally:
                self.errors.report(f"handle drag ({phase})", exc)
                self.send({"type": "handle_cancel"})
        finally:
            self.send(
                {
                    "type": "handle_ack",
                    "seq": content.get("seq"),
                    "phase": phase,
                    "version": self._version,
                    "kernel_ms": round(ms, 3),
                }
            )

    def _on_paint_msg(self, content: dict[str, Any]) -> None:
        phase = content.get("phase")
        ms = 0.0
        verts = content.get("vertices") or []
        try:
            if phase == "start":
                self.begin_stroke()
            # The geometry patch of these dabs carries the seq (see _on_handle_msg).
            self._drag_seq = content.get("seq")
            try:
                if verts:
                    ms = self.paint_at([int(v) for v in verts])
            finally:
                self._drag_seq = None
            if phase == "end":
                self.end_stroke()
        except Exception as exc:
            # Never leave the model inside an interaction after a failed dab.
            try:
                self.end_stroke()
            finally:
                self.errors.report(f"paint stroke ({phase})", exc)
                self.send({"type": "paint_cancel"})
        finally:
            self._send_paint_ack(content.get("seq"), phase, ms)

    def _send_paint_ack(self, seq: Any, phase: str, ms: float) -> None:
        """Acknowledge one stroke message (the front end keeps one dab in flight)."""
        self.send(
            {
                "type": "paint_ack",
                "seq": seq,
                "phase": phase,
                "version": self._version,
                "paint_version": self._paint_version,
                "kernel_ms": round(ms, 3),
            }
        )

    def _push_geometry_event(self, final: bool = True, *_args: Any) -> None:
        if self._hold_pushes:
            self._push_pending = True
            return
        t0 = time.perf_counter()
        self._push_geometry(force_full=False, tolerance=0.0 if final else self._tolerance)
        ms = (time.perf_counter() - t0) * 1e3
        self._last_push_ms = ms
        self.push_ms.append(ms)

    def _push_geometry(self, force_full: bool, tolerance: float = 0.0) -> None:
        model = self._model
        # Model lock: read a consistent evaluate(); send lock: one update at a time
        # even when edits arrive from several threads (timer, subshell, main).
        with model.lock, self._send_lock:
            if not self._connected:
                return
            pos = np.asarray(model.evaluate(), dtype=np.float32)
            faces = model.faces
            topo_changed = (
                self._last is None
                or self._last.shape != pos.shape
                or self._last_faces is None
                or self._last_faces.shape != faces.shape
                # the model keeps one read-only faces array: identity is the cheap test
                or (faces is not self._faces_ref and not np.array_equal(self._last_faces, faces))
            )
            self._faces_ref = faces
            if topo_changed or force_full:
                self._send_full(pos, faces if topo_changed else None)
                return
            assert self._last is not None
            changed = _changed_rows(pos, self._last, tolerance)
            if changed.size == 0:
                if tolerance == 0 and self._positions_stale:
                    self._store_positions_silently()
                return
            if changed.size >= SPARSE_FRACTION * pos.shape[0]:
                self._send_full(pos, None)
                return
            self._last[changed] = pos[changed]
            version = self._version + 1
            self._trait_values["_version"] = version
            if tolerance == 0:
                self._store_positions_silently()
            else:
                # Mid-interaction: skip re-serialising the whole buffer on every drag
                # frame (1 MB at 100k); the exact final update of the interaction does it.
                self._positions_stale = True
            content = {"type": "patch", "version": version, "count": int(changed.size)}
            if self._drag_seq is not None:
                content["seq"] = self._drag_seq
            self.send(content, buffers=[_u32_bytes(changed), _f32_bytes(pos[changed])])
            self.updates_sent["patch"] += 1

    def _store_positions_silently(self) -> None:
        # Silent update: a page reload must get the current full buffer, but
        # syncing it would send the full buffer that patches avoid.
        assert self._last is not None
        self._trait_values["_positions"] = _f32_bytes(self._last)
        self._positions_stale = False

    def _send_full(self, pos: np.ndarray, faces: np.ndarray | None) -> None:
        model = self._model
        self._positions_stale = False
        self._last = pos.copy()
        with self.hold_sync():
            if faces is not None:
                self._last_faces = faces.copy()
                labels = np.asarray(model.component_labels)
                if labels.size and labels.max() >= 65535:
                    raise ValueError("Viewport: more than 65535 components are not supported")
                self._labels = labels.astype("<u2").tobytes()
                self._component_names = list(model.component_names)
                self._up_axis = str(getattr(model.metadata, "up_axis", "+y"))
                self._neutral_bounds = neutral_bounds(model)
                self._faces = _u32_bytes(faces.reshape(-1))
                self._topology = self._topology + 1
            self._positions = _f32_bytes(pos)
            self._version = self._version + 1
        self.updates_sent["full"] += 1

    # ------------------------------------------------------- feature graph overlay
    # Pose-space wrinkles (Bickel et al. 2008 §5.1): the edges between handles on
    # which strain is measured, coloured by strain. Self-contained: the viewport does
    # not know about wrinkle layers; widgets.WrinklePanel feeds it.

    #: (F,) float32 strain the front end has (None: nothing sent yet)
    _strain_sent: np.ndarray | None = None
    #: newest strain given while the overlay was hidden (sent when it is shown)
    _strain_pending: np.ndarray | None = None
    #: strain updates sent (tests, benchmarks)
    feature_updates_sent: int = 0

    @property
    def feature_edges(self) -> np.ndarray:
        """(F, 2) uint32 vertex ids of the drawn feature-graph edges (empty: none)."""
        return np.frombuffer(self._feature_edges, dtype="<u4").reshape(-1, 2).copy()

    @property
    def feature_strain(self) -> np.ndarray:
        """(F,) float32 strain of each edge as last sent to the front end."""
        return np.frombuffer(self._feature_strain, dtype="<f4").copy()

    def set_feature_graph(self, vertex_pairs: Any) -> None:
        """Draw line segments between vertex pairs (F, 2) (None or empty: no graph).

        Resets the strain to zero (every edge grey) until :meth:`set_feature_strain`.
        """
        n = self._model.n_vertices
        pairs = np.zeros((0, 2), np.int64) if vertex_pairs is None else np.asarray(vertex_pairs)
        pairs = pairs.astype(np.int64).reshape(-1, 2)
        if pairs.size and (pairs.min() < 0 or pairs.max() >= n):
            raise ValueError(f"Viewport.set_feature_graph: vertex ids must be in 0..{n - 1}")
        edges = _u32_bytes(pairs.reshape(-1))
        zero = np.zeros(pairs.shape[0], np.float32)
        with self._send_lock:
            self._strain_pending = None
            self._strain_sent = zero
            with self.hold_sync():
                if edges != self._feature_edges:
                    self._feature_edges = edges
                self._feature_strain = _f32_bytes(zero)

    def set_feature_strain(self, strain: Any) -> bool:
        """Colour the edges by ``strain`` (F,): relative stretch ``(l - l0) / l0``.

        Sent only when some edge changed by more than :data:`STRAIN_TOLERANCE`
        (or returned to exactly zero) and the overlay is shown; returns True when
        an update was sent.
        """
        f = np.asarray(strain, dtype=np.float32).reshape(-1)
        count = len(self._feature_edges) // 8
        if f.size != count:
            raise ValueError(
                f"Viewport.set_feature_strain: expected {count} values (one per edge), got {f.size}"
            )
        if not np.isfinite(f).all():
            raise ValueError("Viewport.set_feature_strain: strain contains NaN/inf")
        with self._send_lock:
            if not self.feature_graph:
                self._strain_pending = f.copy()
                return False
            self._strain_pending = None
            last = self._strain_sent
            if last is not None and last.shape == f.shape:
                moved = bool(f.size) and float(np.abs(f - last).max()) > STRAIN_TOLERANCE
                settled = not f.any() and bool(last.any())
                if not (moved or settled):
                    return False
            self._strain_sent = f.copy()
            self._feature_strain = _f32_bytes(f)
            self.feature_updates_sent += 1
            return True

    @t.observe("feature_graph")
    def _on_feature_graph_shown(self, change: Any) -> None:
        pending = self._strain_pending
        if change["new"] and pending is not None and pending.size == len(self._feature_edges) // 8:
            self.errors.guard("Viewport feature graph")(self.set_feature_strain)(pending)
