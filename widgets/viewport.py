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
never send a kernel message.

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

from widgets._threading import ErrorSink

_STATIC = Path(__file__).resolve().parent / "static"
BUNDLE = _STATIC / "viewport.js"

#: Below this fraction of changed vertices an update is sent as (ids, values).
SPARSE_FRACTION = 1.0 / 3.0

#: During an interaction, vertices that moved less than this fraction of the mesh's
#: bounding-box diagonal are not re-sent (about 1/40 pixel at the default framing,
#: 1/4 pixel zoomed in 10x); the interaction's final update is exact.
DRAG_TOLERANCE = 5e-5

#: A handle drag with no message from the front end for this long is ended (the
#: page was closed mid-drag): the model must never be left inside an interaction.
DRAG_WATCHDOG_S = 30.0

TOOLS = ("orbit", "sculpt")

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
    tool : {"orbit", "sculpt"}
        ``"sculpt"``: left-drag a handle marker to move it in the view plane,
        Shift-click the surface to add a handle, Alt-click a marker to remove it;
        orbit/zoom/pan still work off the markers. ``"orbit"``: camera only.
    symmetric : bool
        Handle drags also move the mirror handle (x reflected); Shift-click adds
        a mirrored pair; the mirror marker is highlighted.
    add_on_click : bool
        In sculpt mode, a plain click (no modifier) on the surface adds a handle.
    selected_handle : int
        Index of the last dragged handle (highlighted), or -1.

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
    _vertex_colors = t.Bytes(None, allow_none=True).tag(sync=True)
    _handles = t.Bytes(b"").tag(sync=True)
    _probe_ids = t.Bytes(b"").tag(sync=True)
    _error = t.Unicode("").tag(sync=True)
    _handle_mirror = t.Bytes(b"").tag(sync=True)

    tool = t.Unicode("orbit").tag(sync=True)
    symmetric = t.Bool(False).tag(sync=True)
    add_on_click = t.Bool(False).tag(sync=True)
    selected_handle = t.Int(-1).tag(sync=True)
    wireframe = t.Bool(False).tag(sync=True)
    component_visible = t.Dict(value_trait=t.Bool()).tag(sync=True)
    height = t.Int(480).tag(sync=True)

    def __init__(
        self,
        model: Any,
        *,
        height: int = 480,
        errors: ipywidgets.Output | None = None,
        **kwargs: Any,
    ) -> None:
        esm = load_bundle()  # clear error before any widget state exists
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
        size = np.ptp(np.asarray(model.vertices), axis=0) if model.n_vertices else np.zeros(3)
        self._tolerance = float(DRAG_TOLERANCE * np.linalg.norm(size))
        self._on_deformed = self.errors.guard("Viewport update")(self._push_geometry_event)
        self._on_shapes = self.errors.guard("Viewport shapes update")(self._push_geometry_event)
        self._on_handles = self.errors.guard("Viewport handles update")(self._sync_handles)
        self.on_msg(self._on_frontend_msg)
        model.events.deformed.connect(self._on_deformed)
        model.events.shapes.connect(self._on_shapes)
        model.events.handles.connect(self._on_handles)
        model.events.handles_changing.connect(self._on_handles)
        self._connected = True
        self._push_geometry(force_full=True)
        self._sync_handles()

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

    @property
    def dragging(self) -> bool:
        """True while a handle drag from the front end is open."""
        return self._drag is not None

    def close(self) -> None:
        """End an open handle drag, disconnect from the model, then close the widget."""
        if getattr(self, "_connected", False):
            try:
                self.end_drag()
            finally:
                ev = self._model.events
                ev.deformed.disconnect(self._on_deformed)
                ev.shapes.disconnect(self._on_shapes)
                ev.handles.disconnect(self._on_handles)
                ev.handles_changing.disconnect(self._on_handles)
                self._connected = False
        super().close()

    # ------------------------------------------------------------ handle drags
    def begin_drag(self, index: int, vertex: int | None = None) -> None:
        """Start dragging handle ``index`` (what the front end's "start" message does).

        Enters ``model.interaction("Drag handle <name>")``; an open drag is ended first.
        """
        model = self._model
        with self._drag_lock:
            self.end_drag()
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
            if self._watchdog is not None:
                self._watchdog.cancel()
                self._watchdog = None
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

    def _start_watchdog(self, delay: float) -> None:
        self._watchdog = threading.Timer(delay, self._on_watchdog)
        self._watchdog.daemon = True
        self._watchdog.start()

    def _on_watchdog(self) -> None:
        try:
            with self._drag_lock:
                if self._drag is None:
                    return
                idle = time.monotonic() - self._last_drag_msg
                if idle < DRAG_WATCHDOG_S:
                    self._start_watchdog(DRAG_WATCHDOG_S - idle)
                    return
            self.end_drag()
        except Exception as exc:
            self.errors.report("ending an abandoned handle drag", exc)

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
        from workbench.handle_presets import mirror_vertices
        from workbench.model import HandleSet

        model = self._model
        self.end_drag()
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
        self.end_drag()
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
        elif kind == "handle":
            self._on_handle_msg(content)
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
                    ms = self.drag_to(content["position"])
                finally:
                    self._drag_seq = None
            elif phase == "end":
                try:
                    if content.get("position") is not None and self._drag is not None:
                        ms = self.drag_to(content["position"])
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

    def _push_geometry_event(self, final: bool = True, *_args: Any) -> None:
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
                self._faces = _u32_bytes(faces.reshape(-1))
                self._topology = self._topology + 1
            self._positions = _f32_bytes(pos)
            self._version = self._version + 1
        self.updates_sent["full"] += 1
