"""The GPU path of the viewport: the rig is uploaded once, updates send only weights.

The browser evaluates the linear part of the rig itself (``widgets/js/src/viewport/
gpu_morph.js``); the kernel sends, per slider tick, marker drag update or
playback frame, only the parameters::

    p = M · ( base + a(v) · Σ_k w_k δ_k(v) + c(v) · B(v) u_H )
    base = neutral + r(v)

* ``w`` (k,) the shapes' effective weights (derived corrective weights, muted
  shapes 0: :meth:`StateView.weight_vector`), ``u_H`` (H_u, 3) the controls of
  the first linear layer that has a basis (its control offsets per basis
  column, ``layer.control_basis(view)``), ``M`` the rigid head pose;
* ``δ`` the shapes' deltas, vertex-major and sparse (only the vertices a shape
  moves: per vertex ``(offset, count)`` into ``(dx, dy, dz, shape)`` entries),
  half floats when that rounds no vertex by more than :data:`HALF_TOLERANCE` of
  the face size at the largest slider value, else floats; ``B`` that layer's
  basis for its current controls (a linear shell's, Bickel 2008 §4);
* ``a(v)``, ``c(v)`` per-vertex gains: each linear layer says how much of the
  motion below it a vertex keeps (:mod:`workbench.core.linear`; e.g. a local blend
  keeps its background, Joshi 2003, or ``1 - Σ_e W_e`` under weight maps,
  Pighin 1998 §4.2); ``a`` is the product over all of them, ``c`` over those
  above the controls layer;
* ``r(v)`` the *residual*: whatever the kernel's ``evaluate()`` holds beyond
  that linear part — the linear layers' constant terms and the nonlinear
  layers (e.g. pose-space detail). The kernel computes it from
  its own evaluation, so Python stays the truth: any layer this model does not
  describe lands in ``r`` and is streamed as sparse rows, exactly like today's
  patches. During an interaction rows are re-sent only when they moved more
  than the drag tolerance; after it they agree with ``evaluate()`` to float
  rounding (:data:`RESIDUAL_FLOOR`).

Transfer protocol (added to :mod:`widgets.viewport.sync`'s):

* traits, once per change: ``_gpu_neutral`` (f32 n*3), ``_gpu_morph_index``
  (u32 n*2), ``_gpu_morph_entries`` (f32 or f16 nnz*4), ``_gpu_basis`` (f32,
  n * ceil(H_u/4) * 4), ``_gpu_gain`` (f32 n*2), ``_gpu_residual`` (f32 n*3,
  also kept current silently for a reloaded page), ``_gpu_params`` (f32: k
  weights, H_u*3 offsets, 16 head matrix, column-major), ``_gpu_meta``;
* a custom message ``{"type": "gpu_params", "version"[, "seq"], "count"}`` with
  buffers ``[params f32, residual ids u32 (c), residual rows f32 (c*3)]`` per
  update: ``4 (k + 3 H_u + 16)`` bytes plus changed residual rows.

Playback in the browser (:meth:`GpuSync.prepare_clip`, used by
``widgets/timeline/playback.py``): the parameters of every frame of the timeline
at its fps, ``_gpu_clip`` (f32, frames x (k + 3 H_u + 16)) with ``_gpu_clip_meta``
``{"version", "frames", "fps", "start", "width"}``, uploaded when playback starts
and the timeline changed since; then ``{"type": "gpu_play", "time", "loop",
"end"}`` starts the browser's own clock and ``{"type": "gpu_stop"}`` stops it
(the kernel then sets the final time once, which sends the exact parameters).
Only when the residual is the same at sampled frames (no animated nonlinear
layer): otherwise playback stays in the kernel, which then sends parameters
and residual rows per frame.

The page moves the face before the kernel answers (``gpu_local.js``): the shape
sliders a view follows (``Viewport.follow_sliders``, trait ``_weight_slider_ids``)
and marker drags change the parameters in the page at once; ``_gpu_meta`` gives
it the shapes' order (``names``), the rules of the played weights (``local``:
muted shapes, correctives as products of their drivers, :func:`local_weight_rules`)
and the basis column of each control (``columns``). The kernel's parameters
follow and win. While parameters change, a view whose full frame is slow draws
a simplified face evaluated at its own vertices (``gpu_draft.js``,
``Viewport.fast_interaction``) and the full mesh once the changes pause.

``_gpu_mode`` is ``"gpu"`` while the kernel sends parameters and ``"stream"``
while it streams vertex rows. The kernel starts streaming and switches when a
view says ``{"type": "gpu_ready"}`` (it has WebGL2 float render targets); it
streams again for ``Viewport.gpu = False`` or when any view says
``{"type": "gpu_unavailable", "reason"}``. A viewport that no browser shows
(kernel-only use, tests) never uploads the rig.
"""

from __future__ import annotations

import json
import time
import weakref
from collections import deque
from typing import Any

import numpy as np

from widgets.viewport.common import (
    SPARSE_FRACTION,
    assign_synced,
    changed_rows,
    f32_bytes,
    store_silently,
    u32_bytes,
)
from workbench.animation.family import head_matrix
from workbench.core.families import weight_products
from workbench.core.linear import decompose, is_linear

#: every GpuSync of a connected viewport (the timeline's playback looks for its model's)
_SYNCS: weakref.WeakSet[GpuSync] = weakref.WeakSet()

#: frames whose residual is checked before the browser plays a clip on its own
CLIP_CHECK_FRAMES = 5


def clip_players(model: Any) -> list[GpuSync]:
    """The GPU viewports of ``model`` that can play its timeline in the browser now."""
    return [g for g in list(_SYNCS) if g.model is model and g.sync.connected and g.active
            and g.widget._gpu_mode == "gpu"]

#: half floats for the deltas only when no vertex moves by more than this fraction of the
#: face size (the neutral's bounding-box diagonal) through the rounding, at the largest
#: slider value: well below the GPU = kernel tolerance of 1e-5
HALF_TOLERANCE = 1e-6

#: after an interaction, residual rows are re-sent when they changed by more than this
#: fraction of the face size (float32 rounding of the two evaluation orders: ~1e-7), a tenth
#: of the GPU = kernel tolerance
RESIDUAL_FLOOR = 1e-6


def morph_csr(deltas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertex-major sparse deltas: ``index`` (n, 2) uint32 (offset, count), ``entries`` (nnz, 4).

    ``entries[i] = (dx, dy, dz, shape)`` for every shape that moves the vertex.
    """
    D = np.asarray(deltas, np.float32)
    k, n = D.shape[0], D.shape[1]
    if k == 0:
        return np.zeros((n, 2), np.uint32), np.zeros((0, 4), np.float32)
    moves = (D != 0).any(axis=2)  # (k, n)
    v, s = np.nonzero(moves.T)  # sorted by vertex, then shape
    entries = np.empty((v.size, 4), np.float32)
    entries[:, :3] = D[s, v]
    entries[:, 3] = s
    counts = np.bincount(v, minlength=n).astype(np.uint32)
    index = np.empty((n, 2), np.uint32)
    index[:, 1] = counts
    index[:, 0] = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.uint32)
    return index, entries


def half_ok(entries: np.ndarray, max_weight: float, size: float) -> bool:
    """Do half floats keep every delta within :data:`HALF_TOLERANCE` of ``size``?"""
    if not entries.size:
        return True
    xyz = entries[:, :3]
    if np.abs(xyz).max() > 60000 or entries[:, 3].max() > 2048:
        return False
    err = np.abs(xyz.astype(np.float16).astype(np.float32) - xyz).max()
    return bool(err * max(max_weight, 1.0) <= HALF_TOLERANCE * size)


def local_weight_rules(view: Any) -> dict[str, Any]:
    """How the page turns slider values into played weights (``gpu_local.js``).

    ``{"mute": [shape index], "products": [[shape, [driver indices], lo, hi]]}``: a
    muted shape plays 0, a derived shape the product of its drivers clamped to its
    slider range (:func:`workbench.core.families.derive_weights`).
    """
    names = list(view.shape_names)
    index = {nm: i for i, nm in enumerate(names)}
    shapes = list(view.shapes)
    products = []
    for name, drivers in weight_products(view.slots).items():
        if name in index and all(d in index for d in drivers):
            s = shapes[index[name]]
            products.append([index[name], [index[d] for d in drivers],
                             float(s.slider_min), float(s.slider_max)])
    return {"mute": [i for i, s in enumerate(shapes) if s.mute], "products": sorted(products)}


def linear_layers(model: Any, view: Any) -> tuple[np.ndarray, Any]:
    """``(gains, controls)``: what the page evaluates of the model's layers, asked of the layers.

    ``gains`` (n, 2) float32 ``(a, c)``: how much of the global blend and of the
    controls layer's displacement each vertex keeps (the product of the gains
    of the linear layers above each, :func:`workbench.core.linear.decompose`);
    ``controls`` the first linear layer with keyed controls and a basis (a
    linear shell), or None. Whatever else the layers add is in the residual.
    """
    n = model.n_vertices
    dec = decompose(model.pipeline.layers, view, None, n=n, constants=False)
    layer = None
    c = np.ones(n, np.float64)
    for name, _, gain in dec.controls:
        candidate = model.pipeline.layer(name)
        if hasattr(candidate, "control_basis"):
            layer, c = candidate, gain
            break
    out = np.empty((n, 2), np.float32)
    out[:, 0] = dec.shape_gain
    out[:, 1] = c
    return out, layer


def linear_key(model: Any, view: Any) -> tuple[Any, ...]:
    """The versions of what the linear layers read: equal keys, equal gains and controls."""
    return tuple((layer.name, *(view.version(r) for r in (layer.reads or ())))
                 for layer in model.pipeline.layers if is_linear(layer))


class GpuSync:
    """The GPU half of :class:`~widgets.viewport.sync.SceneSync` (same widget, same locks)."""

    def __init__(self, sync: Any) -> None:
        self.sync = sync
        self.widget = sync.widget
        self.model = sync.model
        #: why the front end cannot evaluate on the GPU ("" = it can, or has not said)
        self.unavailable = ""
        #: a view said it can evaluate the rig ("gpu_ready")
        self.ready = False
        V = np.asarray(self.model.vertices, np.float64)
        self.size = float(np.linalg.norm(np.ptp(V, axis=0))) if V.size else 1.0
        self.neutral = np.asarray(V, np.float32)
        self.morph_key: Any = None
        self.basis_key: Any = None
        self.gain_key: Any = None
        self.gain: np.ndarray | None = None
        #: the linear layer whose controls the page evaluates with the basis (a linear shell), or None
        self.controls_layer: Any = None
        self.columns: np.ndarray | None = None  # basis column of each control
        self.hu = 0
        self.k = 0
        self.residual: np.ndarray | None = None  # what the front end has (n, 3)
        self.residual_stale = False
        #: bytes of each gpu_params message (JSON + buffers), for tests and benchmarks
        self.payload: deque[int] = deque(maxlen=512)
        self.updates_sent = {"params": 0, "rig": 0, "basis": 0, "gain": 0, "residual_rows": 0}
        self.upload_ms: deque[float] = deque(maxlen=64)
        self.clip_key: Any = None
        self.clip_ok = False
        #: why the last clip could not play in the browser ("" = it could)
        self.clip_reason = ""
        _SYNCS.add(self)

    @property
    def active(self) -> bool:
        return bool(self.widget.gpu) and self.ready and not self.unavailable

    # ------------------------------------------------------------------ the rig
    def ensure_rig(self, view: Any, final: bool = True) -> None:
        """Send the neutral + deltas, the shell basis and the gains when they changed.

        Not ``final`` (mid-interaction, e.g. a brush stroke): the gains stay as they are
        and the residual carries the difference, as sparse rows; the exact update after
        the interaction sends them.
        """
        model, w = self.model, self.widget
        n = model.n_vertices
        key = (view.version("shapes"), n, len(view.shape_names))
        if key != self.morph_key:
            t0 = time.perf_counter()
            index, entries = morph_csr(view.effective_deltas)
            wmax = max((max(abs(s.slider_min), abs(s.slider_max)) for s in view.shapes), default=1.0)
            half = half_ok(entries, wmax, self.size)
            data = entries.astype("<f2").tobytes() if half else f32_bytes(entries)
            self.neutral = np.asarray(view.vertices32, np.float32)
            self.k = len(view.shape_names)
            with w.hold_sync():
                assign_synced(w, _gpu_neutral=f32_bytes(self.neutral), _gpu_morph_index=u32_bytes(index),
                              _gpu_morph_entries=data)
                self.morph_key = key
                self.set_meta(half=half, nnz=int(entries.shape[0]), k=self.k, n=n,
                              names=list(view.shape_names),
                              morph=int(w._gpu_meta.get("morph", 0)) + 1)
            self.residual = None  # re-sent whole below
            self.sync.log_sent(f"rig morph {w._gpu_meta.get('morph')}", w._version)
            self.updates_sent["rig"] += 1
            self.upload_ms.append((time.perf_counter() - t0) * 1e3)
        local = local_weight_rules(view)
        if local != w._gpu_meta.get("local"):
            self.set_meta(local=local)
        # the gains and the controls layer, when a linear layer's inputs changed
        gkey = linear_key(model, view)
        if gkey != self.gain_key and (final or self.gain is None):
            gain, self.controls_layer = linear_layers(model, view)
            self.gain_key = gkey
            if self.gain is None or not np.array_equal(gain, self.gain):
                self.gain = gain
                with w.hold_sync():
                    assign_synced(w, _gpu_gain=f32_bytes(gain))
                    self.set_meta(gain=int(w._gpu_meta.get("gain", 0)) + 1)
                self.updates_sent["gain"] += 1
        ctl = self.controls_layer
        controls = None if ctl is None else ctl.controls(view, None)
        basis = None if controls is None else ctl.control_basis(view)
        bkey = None if basis is None else (ctl.name, basis[0])
        if bkey != self.basis_key:
            t0 = time.perf_counter()
            if basis is None:
                self.hu, self.columns = 0, None
                data = b""
            else:
                _, B, columns = basis
                self.hu, self.columns = int(B.shape[1]), np.asarray(columns)
                hq = (self.hu + 3) // 4
                P = np.zeros((n, hq * 4), np.float32)
                P[:, : self.hu] = B
                data = P.tobytes()
            with w.hold_sync():
                assign_synced(w, _gpu_basis=data)
                self.basis_key = bkey
                self.set_meta(hu=self.hu, basis=int(w._gpu_meta.get("basis", 0)) + 1,
                              columns=[] if self.columns is None else self.columns.tolist())
            self.updates_sent["basis"] += 1
            self.upload_ms.append((time.perf_counter() - t0) * 1e3)

    def set_meta(self, **kv: Any) -> None:
        self.widget._gpu_meta = {**self.widget._gpu_meta, **kv}

    # --------------------------------------------------------------- parameters
    def params(self, view: Any) -> np.ndarray:
        """f32: the k weights, the H_u x 3 offsets per basis column, the head matrix (column-major).

        The head matrix is the view's pose when one is shown (the Live tab), else the model's.
        """
        params = self.frame_params(view)
        if self.sync.view_pose is not None:
            params[-16:] = self.sync.view_pose.T.reshape(-1)
        return params

    def linear(self, view: Any) -> np.ndarray:
        """The kernel's float32 version of the part the GPU evaluates (before the head pose)."""
        model = self.model
        assert self.gain is not None
        G = np.asarray(model.blended(), np.float32) - self.neutral
        lin = self.neutral + self.gain[:, :1] * G
        ctl = self.controls_layer
        if self.hu and ctl is not None:
            c = ctl.controls(view, None)
            if c is not None and np.any(c.values):
                lin += self.gain[:, 1:] * model.layer_displacement(ctl.name)
        return lin

    def push(self, tolerance: float, full: bool) -> None:
        """Send the parameters (and changed residual rows); ``full``: every trait instead."""
        model, w = self.model, self.widget
        view = model.view()
        self.ensure_rig(view, final=tolerance == 0)
        params = self.params(view)
        local = np.asarray(model.evaluate(posed=False), np.float32)
        residual = local - self.linear(view)
        floor = RESIDUAL_FLOOR * self.size
        if full or self.residual is None or self.residual.shape != residual.shape:
            self.residual = residual.copy()
            version = w._version + 1
            with w.hold_sync():
                assign_synced(w, _gpu_residual=f32_bytes(residual), _gpu_params=params.tobytes())
                w._gpu_mode = "gpu"
                w._version = version
            self.sync.log_sent("gpu full", version)
            self.residual_stale = False
            return
        ids = changed_rows(residual, self.residual, max(tolerance, floor))
        rows = residual[ids]
        if ids.size >= SPARSE_FRACTION * residual.shape[0]:
            # e.g. a layer switched on: the whole residual, once, as a trait
            self.residual = residual.copy()
            with w.hold_sync():
                assign_synced(w, _gpu_residual=f32_bytes(residual), _gpu_params=params.tobytes())
                w._version = w._version + 1
            self.sync.log_sent("gpu residual", w._version)
            return
        self.residual[ids] = rows
        version = w._version + 1
        store_silently(w, _version=version, _gpu_params=params.tobytes())
        if ids.size:
            self.residual_stale = True
        if tolerance == 0 and self.residual_stale:
            # silent: a reloaded page gets the current residual (not mid-drag: 1 MB at 80k)
            store_silently(w, _gpu_residual=f32_bytes(self.residual))
            self.residual_stale = False
        content: dict[str, Any] = {"type": "gpu_params", "version": version, "count": int(ids.size),
                                   "k": self.k, "hu": self.hu}
        if self.sync.patch_seq is not None:
            content["seq"] = self.sync.patch_seq
        buffers = [params.tobytes(), u32_bytes(ids), f32_bytes(rows)]
        w.send(content, buffers=buffers)
        self.sync.log_sent("params", version)
        self.payload.append(len(json.dumps(content)) + sum(len(b) for b in buffers))
        self.updates_sent["params"] += 1
        self.updates_sent["residual_rows"] += int(ids.size)

    # ------------------------------------------------------------------- playback
    def frame_params(self, view: Any) -> np.ndarray:
        """The parameters of a sampled view (weights, shell offsets, head pose)."""
        wv = view.weight_vector()
        uH = np.zeros((self.hu, 3), np.float64)
        ctl = self.controls_layer
        c = None if ctl is None or not self.hu else ctl.controls(view, None)
        if c is not None and self.columns is not None and len(c.values) == self.columns.size:
            np.add.at(uH, self.columns, c.values)
            uH /= np.maximum(np.bincount(self.columns, minlength=self.hu), 1)[:, None]
        M = head_matrix(view)
        M = np.eye(4) if M is None else np.asarray(M, np.float64)
        return np.concatenate([wv, uH.reshape(-1), M.T.reshape(-1)]).astype("<f4")

    def prepare_clip(self) -> bool:
        """Upload the timeline's per-frame parameters if they changed; True when the browser can play it."""
        model, w = self.model, self.widget
        with model.lock:
            if not self.active or self.residual is None or self.gain is None:
                self.clip_reason = "the view does not evaluate on the GPU"
                return False
            tl = model.timeline.value
            view = model.view()
            key = (id(tl), tl.fps, tl.start, tl.end, self.morph_key, self.basis_key, self.gain_key,
                   view.version("weights"), linear_key(model, view))
            if key == self.clip_key:
                return self.clip_ok
            self.clip_key, self.clip_ok = key, False
            fps, start, end = float(tl.fps), float(tl.start), float(tl.end)
            if not (end > start and fps > 0):
                self.clip_reason = "nothing to play"
                return False
            frames = int(np.floor((end - start) * fps + 1e-6)) + 1
            times = start + np.arange(frames) / fps
            # the browser adds the residual it has: only when no layer it leaves to the
            # kernel is animated (sample a few frames)
            tol = max(self.sync.tolerance, RESIDUAL_FLOOR * self.size)
            for t in np.linspace(start, end, CLIP_CHECK_FRAMES):
                ev = model.evaluation_at(float(t))
                G = np.asarray(ev.blend, np.float32) - self.neutral
                lin = self.neutral + self.gain[:, :1] * G
                sh = None if self.controls_layer is None else ev.displacements.get(self.controls_layer.name)
                if sh is not None and self.hu:
                    lin += self.gain[:, 1:] * sh
                r = np.asarray(ev.mesh, np.float32) - lin
                if np.abs(r - self.residual).max() > tol:
                    self.clip_reason = f"a layer the GPU does not evaluate changes over time (t = {t:.2f} s)"
                    return False
            clip = np.stack([self.frame_params(model.view_at(float(t))) for t in times])
            version = int(w._gpu_meta.get("clip", 0)) + 1
            with w.hold_sync():
                w._gpu_clip = clip.tobytes()
                w._gpu_clip_meta = {"version": version, "frames": frames, "fps": fps,
                                    "start": start, "width": int(clip.shape[1])}
                self.set_meta(clip=version)
            self.clip_ok, self.clip_reason = True, ""
            return True

    def play(self, time: float, end: float, loop: bool) -> None:
        """Start the browser's clock at ``time`` (seconds of the timeline)."""
        self.widget.send({"type": "gpu_play", "time": float(time), "end": float(end), "loop": bool(loop)})

    def stop(self) -> None:
        self.widget.send({"type": "gpu_stop"})

    def reset(self) -> None:
        """Forget what the front end has (a new topology, or back from streaming)."""
        self.morph_key = self.basis_key = self.gain_key = None
        self.gain = None
        self.residual = None
        self.clip_key = None
