"""What the viewport ships to the browser: geometry, surface tint, markers, feature graph.

:class:`SceneSync` owns what the front end was last sent and decides, on every
model event, between a full buffer and a patch. It writes the widget's synced
traits and sends its custom messages; it never changes the model.

Transfer protocol (binary only, never JSON lists):

* ``_faces`` (uint32, m*3) and ``_labels`` (uint16, n) once per topology;
* ``_positions`` (float32, n*3): the full buffer, on load and whenever at least
  a third of the vertices changed;
* a custom message ``{"type": "patch", "version": v[, "seq": s]}`` with buffers
  ``[ids uint32 (k), values float32 (k*3)]`` when fewer than a third changed;
  ``_positions`` is then updated *without* a sync message so that a reloaded
  page still gets the current full state. ``seq`` is the gesture message whose
  edit the patch shows (the front end may send its next update on it).
* The surface tint (a per-vertex weight in [0, 1] a tool shows):
  ``_tint`` (float32 n, or empty) plus ``{"type": "tint_patch", "version"}``
  messages with buffers ``[ids uint32, weights float32]``, the same scheme
  with ``_tint_version``. It comes from a stroke handler's ``overlay()`` while
  one is set, else from the current tool, else from the first tool that has one
  (``Tool.tint``).
* Markers: ``_markers`` (uint32 h) and ``_marker_mirror`` (int32 h, or empty),
  from the current tool, else the first tool that has some (``Tool.markers``), re-sent when they
  change; ``Viewport.markers = ids`` shows others until then.

During an interaction (``deformed(False)``) a vertex is re-sent only when it
moved more than :data:`~widgets.viewport.common.DRAG_TOLERANCE` of the mesh's
size since the front end last got it (a shell basis moves almost every vertex
by a tiny amount); the final event of the interaction sends the
exact positions.

GPU mode (``Viewport.gpu``, the default, when the front end can): after the full
buffer, updates are the parameters of the rig the browser evaluates itself
(:mod:`widgets.viewport.gpu`: weights, shell offsets, head pose, changed
residual rows) instead of vertex rows; ``_positions`` is then kept current
silently after each exact update, for a reloaded page.

While a gesture message runs several edits (the dabs of one stroke message),
:meth:`SceneSync.held` turns model events into one tint + geometry update
sent after the last edit.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from widgets.viewport.common import (
    DRAG_TOLERANCE,
    SPARSE_FRACTION,
    STRAIN_TOLERANCE,
    assign_synced,
    changed_rows,
    f32_bytes,
    neutral_bounds,
    store_silently,
    u32_bytes,
)
from widgets.viewport.gpu import GpuSync
from workbench.geometry.parts import model_part_roles, part_material


class SceneSync:
    """Keeps one :class:`~widgets.viewport.Viewport`'s front end in step with its model.

    Parameters
    ----------
    widget : Viewport
        Whose traits are written and whose ``send`` is used.
    model : FaceModel
    """

    def __init__(self, widget: Any, model: Any) -> None:
        self.widget = widget
        self.model = model
        self.connected = False
        self.last: np.ndarray | None = None  # what the front end has, (n, 3) float32
        self.last_faces: np.ndarray | None = None
        self.faces_ref: np.ndarray | None = None
        self.positions_stale = False
        size = np.ptp(np.asarray(model.vertices), axis=0) if model.n_vertices else np.zeros(3)
        self.tolerance = float(DRAG_TOLERANCE * np.linalg.norm(size))
        self.updates_sent = {"full": 0, "patch": 0}
        #: kernel-side ms per geometry update (diff + serialise + send), for benchmarks
        self.push_ms: deque[float] = deque(maxlen=256)
        self.last_push_ms = 0.0
        #: the last geometry updates sent, (ms, kind, version): what a resync report is read against
        self.sent_log: deque[tuple[int, str, int]] = deque(maxlen=24)
        #: seq of the gesture message being applied (sent with its geometry patch)
        self.patch_seq: Any = None
        self._hold = 0
        self._pending = False
        #: (4, 4) head pose drawn instead of the model's (:meth:`Viewport.show_head_pose`), or None
        self.view_pose: np.ndarray | None = None
        # surface tint
        self.tint_last: np.ndarray | None = None  # weights the front end has (None = empty)
        self.tint_last_ref: Any = None  # the array they came from
        self.tint_updates_sent = {"full": 0, "patch": 0}
        #: returns the tint of a stroke handler, or None to ask the tools
        self.tint_source: Any = None
        #: the tools' markers as last sent (bytes of the ids, of the mirror links)
        self.markers_sent: tuple[bytes, bytes] | None = None
        # feature graph
        self.strain_sent: np.ndarray | None = None
        self.strain_pending: np.ndarray | None = None
        self.feature_updates_sent = 0
        #: the GPU path (parameters instead of vertex rows)
        self.gpu = GpuSync(self)

    # ------------------------------------------------------------------ batching
    @contextmanager
    def held(self) -> Iterator[None]:
        """Run several edits; send one tint + geometry update after the last."""
        self._hold += 1
        try:
            yield
        finally:
            self._hold -= 1
        if self._pending and not self._hold:
            self._pending = False
            self.sync_tint()
            self.push_geometry_event(False)

    @contextmanager
    def patching(self, seq: Any) -> Iterator[None]:
        """Geometry patches sent inside carry gesture message ``seq`` (the front end's early ack)."""
        old, self.patch_seq = self.patch_seq, seq
        try:
            yield
        finally:
            self.patch_seq = old

    # ------------------------------------------------------------------ geometry
    def push_geometry_event(self, final: bool = True, *_args: Any) -> None:
        """A model event: send what changed (exactly when ``final``, else within the tolerance)."""
        if self._hold:
            self._pending = True
            return
        t0 = time.perf_counter()
        self.push_geometry(force_full=False, tolerance=0.0 if final else self.tolerance)
        ms = (time.perf_counter() - t0) * 1e3
        self.last_push_ms = ms
        self.push_ms.append(ms)

    def shown_positions(self) -> np.ndarray:
        """(n, 3) float32 the view draws: ``evaluate()``, or the unposed face under :attr:`view_pose`."""
        M = self.view_pose
        if M is None:
            return np.asarray(self.model.evaluate(), dtype=np.float32)
        local = np.asarray(self.model.evaluate(posed=False), dtype=np.float64)
        return np.asarray(local @ M[:3, :3].T + M[:3, 3], dtype=np.float32)

    def shown_matrix(self) -> np.ndarray:
        """(4, 4) rigid transform the view applies last (the view pose, else the model's head pose)."""
        return self.model.head_matrix() if self.view_pose is None else self.view_pose.copy()

    def push_geometry(self, force_full: bool, tolerance: float = 0.0) -> None:
        model, w = self.model, self.widget
        # Model lock: read a consistent evaluate() (the UI thread makes updates one at a time).
        with model.lock:
            if not self.connected:
                return
            pos = self.shown_positions()
            faces = model.faces
            topo_changed = (
                self.last is None
                or self.last.shape != pos.shape
                or self.last_faces is None
                or self.last_faces.shape != faces.shape
                # the model keeps one read-only faces array: identity is the cheap test
                or (faces is not self.faces_ref and not np.array_equal(self.last_faces, faces))
            )
            self.faces_ref = faces
            gpu = self.gpu.active
            if topo_changed or force_full or gpu != (w._gpu_mode == "gpu"):
                if topo_changed:
                    self.gpu.reset()
                self.send_full(pos, faces if topo_changed else None)
                if gpu:
                    self.gpu.push(0.0, full=True)
                return
            if gpu:
                self.gpu.push(tolerance, full=False)
                # what a reloaded page gets: the exact positions, not mid-interaction
                self.last = pos
                self.positions_stale = True
                if tolerance == 0:
                    self.store_positions_silently()
                return
            assert self.last is not None
            changed = changed_rows(pos, self.last, tolerance)
            if changed.size == 0:
                if tolerance == 0 and self.positions_stale:
                    self.store_positions_silently()
                return
            if changed.size >= SPARSE_FRACTION * pos.shape[0]:
                self.send_full(pos, None)
                return
            self.last[changed] = pos[changed]
            version = w._version + 1
            store_silently(w, _version=version)
            if tolerance == 0:
                self.store_positions_silently()
            else:
                # Mid-interaction: skip re-serialising the whole buffer on every drag
                # frame (1 MB at 100k); the exact final update of the interaction does it.
                self.positions_stale = True
            content: dict[str, Any] = {"type": "patch", "version": version, "count": int(changed.size)}
            if self.patch_seq is not None:
                content["seq"] = self.patch_seq
            w.send(content, buffers=[u32_bytes(changed), f32_bytes(pos[changed])])
            self.log_sent("patch", version)
            self.updates_sent["patch"] += 1

    def log_sent(self, kind: str, version: int) -> None:
        self.sent_log.append((int(time.monotonic() * 1e3), kind, int(version)))

    def resync(self, rig: bool = False) -> None:
        """The page lost track: send the full state (``rig``: the GPU rig too, which the page
        lacks when it missed the update that switched it to GPU mode)."""
        with self.model.lock:
            if rig:
                self.gpu.reset()
            self.push_geometry(force_full=True)

    def store_positions_silently(self) -> None:
        # Silent update: a page reload must get the current full buffer, but
        # syncing it would send the full buffer that patches avoid.
        assert self.last is not None
        store_silently(self.widget, _positions=f32_bytes(self.last))
        self.positions_stale = False

    def send_full(self, pos: np.ndarray, faces: np.ndarray | None) -> None:
        model, w = self.model, self.widget
        self.positions_stale = False
        self.last = pos.copy()
        with w.hold_sync():
            w._gpu_mode = "stream"  # GpuSync.push(full=True) switches it on with its state
            if faces is not None:
                self.last_faces = faces.copy()
                labels = np.asarray(model.component_labels)
                if labels.size and labels.max() >= 65535:
                    raise ValueError("Viewport: more than 65535 components are not supported")
                w._labels = labels.astype("<u2").tobytes()
                w._component_names = list(model.component_names)
                w._component_materials = [
                    part_material(role, name) for role, name in zip(model_part_roles(model), model.component_names, strict=True)
                ]
                w._up_axis = str(getattr(model.metadata, "up_axis", "+y"))
                w._neutral_bounds = neutral_bounds(model)
                w._faces = u32_bytes(faces.reshape(-1))
                w._topology = w._topology + 1
            assign_synced(w, _positions=f32_bytes(pos), _version=w._version + 1)
        self.log_sent("full", w._version)
        self.updates_sent["full"] += 1

    # -------------------------------------------------------------- surface tint
    def tint_weights(self) -> np.ndarray | None:
        """The tint to show: the stroke handler's, else the current tool's, else the first tool's that has one."""
        if self.tint_source is not None:
            ov = self.tint_source()
            return None if ov is None else np.asarray(ov, dtype=np.float32)
        for tool in self.widget.tools_current_first():
            weights = tool.tint()
            if weights is not None:
                return weights
        return None

    def sync_tint(self, *_args: Any) -> None:
        """Send the tint (full, or the vertices that changed) when it differs from the front end's."""
        if self._hold:
            self._pending = True
            return
        model, w = self.model, self.widget
        with model.lock:
            if not self.connected:
                return
            weights = self.tint_weights()
            last = self.tint_last
            if weights is None:
                if last is not None:
                    self.send_tint_full(None)
                return
            if last is None or last.shape != weights.shape:
                self.send_tint_full(weights)
                return
            if weights is self.tint_last_ref:
                return
            changed = np.flatnonzero(weights != last)
            self.tint_last_ref = weights
            if changed.size == 0:
                return
            if changed.size >= SPARSE_FRACTION * weights.shape[0]:
                self.send_tint_full(weights)
                return
            last[changed] = weights[changed]
            version = w._tint_version + 1
            # Silent: a reloaded page gets the current weights without a full sync here.
            store_silently(w, _tint_version=version, _tint=f32_bytes(last))
            w.send(
                {"type": "tint_patch", "version": version, "count": int(changed.size)},
                buffers=[u32_bytes(changed), f32_bytes(weights[changed])],
            )
            self.tint_updates_sent["patch"] += 1

    def send_tint_full(self, weights: np.ndarray | None) -> None:
        w = self.widget
        self.tint_last = None if weights is None else np.array(weights, dtype=np.float32)
        self.tint_last_ref = weights
        with w.hold_sync():
            assign_synced(w, _tint=b"" if weights is None else f32_bytes(weights),
                          _tint_version=w._tint_version + 1)
        self.tint_updates_sent["full"] += 1

    def resend_tint(self) -> None:
        """The front end lost track of the tint: send it whole."""
        with self.model.lock:
            self.tint_last = None
        self.sync_tint()

    # ------------------------------------------------------------------ markers
    def sync_markers(self, force: bool = False) -> None:
        """Send the tools' markers when they changed (``force``: also over display-only ones)."""
        w = self.widget
        with self.model.lock:
            found = next((m for m in (tool.markers() for tool in w.tools_current_first()) if m is not None), None)
            ids, mirror = found if found is not None else (np.zeros(0, np.uint32), np.zeros(0, np.int32))
            verts = u32_bytes(np.asarray(ids))
            links = np.ascontiguousarray(mirror, dtype="<i4").tobytes()
        if force or (verts, links) != self.markers_sent:
            self.markers_sent = (verts, links)
            with w.hold_sync():
                w._markers = verts
                w._marker_mirror = links
                if w.selected_marker >= len(verts) // 4:
                    w.selected_marker = -1

    # ------------------------------------------------------------- feature graph
    def set_feature_graph(self, pairs: np.ndarray) -> None:
        """Send edges (F, 2) and reset their strain to zero."""
        w = self.widget
        edges = u32_bytes(pairs.reshape(-1))
        zero = np.zeros(pairs.shape[0], np.float32)
        self.strain_pending = None
        self.strain_sent = zero
        with w.hold_sync():
            if edges != w._feature_edges:
                w._feature_edges = edges
            w._feature_strain = f32_bytes(zero)

    def set_feature_strain(self, f: np.ndarray) -> bool:
        """Send strain (F,) if visible and some edge changed enough; True when sent."""
        w = self.widget
        if not w.feature_graph:
            self.strain_pending = f.copy()
            return False
        self.strain_pending = None
        last = self.strain_sent
        if last is not None and last.shape == f.shape:
            moved = bool(f.size) and float(np.abs(f - last).max()) > STRAIN_TOLERANCE
            settled = not f.any() and bool(last.any())
            if not (moved or settled):
                return False
        self.strain_sent = f.copy()
        w._feature_strain = f32_bytes(f)
        self.feature_updates_sent += 1
        return True
