"""glTF 2.0 (.glb / .gltf) export: morph targets and a weights animation.

What is written
---------------
The mesh of :class:`workbench.export.encoding.MeshEncoding` — every frame
plays :meth:`FaceModel.evaluate_at` (blend + region, handle, paint and any
registered layers) within float32 round-off:

* One mesh, one primitive: ``POSITION`` (neutral, metres, with min/max) and
  ``indices`` (the original polygons fan-triangulated). No normals: viewers
  compute them, and morphing them correctly would need per-target normals.
* One morph target per blendshape, named by the shape (names in
  ``mesh.extras.targetNames``, the convention Blender and three.js read),
  driven by the shape's weight. Its data is the masked delta times
  ``(1 − P)(1 − S_R)`` (painted weight and region coverage, see
  :mod:`.encoding`): exactly the delta where nothing is painted and no
  region weights are set. Stored as a sparse accessor when fewer than half
  the vertices move.
* A corrective (combination) shape (:mod:`workbench.methods.shapes.correctives`)
  is an ordinary target whose weight is the product of its drivers' clamped
  weights, clamped to its own range — not a keyed curve, so it is written as
  its own column of the sampler with knots at every frame of the timeline
  (added to the merged key times; splitting the other curves there changes
  nothing): the value at each knot is the product itself (exact at every
  frame) and, for ``CUBICSPLINE``, the tangents are the product rule's, so
  between frames a cubic Hermite follows the product (a polynomial of higher
  degree) closely. In a ``STEP`` sampler a product of steps is a step: exact
  at every time, no knots added.
* ``layer:static`` (weight 1, constant) when the layers add a constant: the
  region constant ``(1 − P) C_R``, the painted expressions ``Σ_e W_e D_e``, and the
  handle layer when its offsets are not keyed — one target instead of one per
  handle and axis.
* ``handle:basis<i>`` when the handle offsets are keyed: the shell
  displacement is linear in the offsets, ``D(o) = B o``
  (:mod:`workbench.methods.handles.shell`), and the keyed offsets live in the span of the
  keys' values and tangents; one target per basis vector of that span
  (usually one per distinct key pose, never more than ``3 × h``), weights
  mapped onto ``[0, 1]`` over their exact range (so Blender, which clamps
  shape-key values to ``[0, 1]``, plays them too). Any interpolation of the
  offsets carries over unchanged.
* ``layer:frame<NNNN>``, one per frame, only for layers that are not linear in
  the keyed quantities (wrinkles, other registered layers): the baked sum of
  those layers at that frame (sparse when it moves few vertices), driven by a
  LINEAR "hat" weight that is 1 at its frame and 0 at the neighbouring frames
  — exact at every frame, linearly interpolated in between. If they are the
  same at every frame they go into ``layer:static`` instead. This is the one
  encoding that grows with the length of the animation; USD (baked
  ``points``) or PC2/MDD are the compact alternative for such layers.
* Keyed weights outside a shape's slider range are clamped by the workbench
  (``set_time``); glTF cannot clamp a curve, so a knot is inserted wherever a
  curve crosses a bound (:func:`_add_crossings`) and the pieces outside are
  written as the constant bound: the sampler keeps its interpolation (LINEAR
  or CUBICSPLINE) and stays exact, with no per-frame resampling.
* One animation: a ``weights`` channel on the mesh node (one sampler for all
  targets, as glTF requires) and, when the head pose is keyed, ``translation``
  and ``rotation`` channels on the same node (metres; quaternions slerped).

Sampler construction (exact, no resampling unless ``bake=True``)
-----------------------------------------------------------------
glTF has one sampler for all morph weights, so the key times of every weight
track are merged. The sampler's interpolation is ``STEP`` if every segment is
step, ``CUBICSPLINE`` if any is Bézier, else ``LINEAR``. At every merged time
the value and the left/right derivatives of each curve are written; since our
Bézier segments are cubic polynomials of ``t`` (:mod:`workbench.animation.curves`),
splitting one at an extra time with the true derivatives reproduces it
exactly, and a linear segment is a cubic with both tangents equal to its
slope. glTF ``CUBICSPLINE`` stores per key ``(a_k, v_k, b_k)`` with
``p(t) = h00 v_k + h10 Δ b_k + h01 v_{k+1} + h11 Δ a_{k+1}`` (spec, Appendix C),
so ``b_k`` = our out-slope and ``a_{k+1}`` = our in-slope (value per second).
A *step* segment inside a LINEAR/CUBICSPLINE sampler is written as a hold
followed by a ramp over the last ``ε = min(1e-4 s, gap/4)`` before the next
key (glTF cannot jump inside a non-STEP sampler); that ramp is the only place
the file differs from :meth:`Timeline.evaluate`. Times are float32 seconds.
Negative key times are rejected (glTF animations start at 0 or later).

Written with pygltflib (objects + binary blob). Its pitfall: accessors default
to ``byteOffset=0``, which is invalid for a sparse accessor without a
bufferView, so it is set to None there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pygltflib
from numpy.typing import NDArray

from workbench.animation.curves import HEAD_POSE, Key, Track
from workbench.animation.tracks import Timeline
from workbench.export.base import ExportError, ExportResult, LayerReport, atomic_write_bytes
from workbench.export.encoding import MeshEncoding, crossing_times

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["Curve", "SamplerData", "build_gltf", "merge_curves", "write"]

_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_STEP_EPS = 1e-4


@dataclass(frozen=True, eq=False)
class Curve:
    """One scalar curve for a sampler: a component (or a linear combination) of a track, or a constant.

    ``value(t) = scale * track.sample(t)[:, component] + offset``, or with
    ``coeffs`` ``scale * track.sample(t) @ coeffs + offset``; without a track
    ``scale * constant``. ``clamp`` = ``(lo, hi)`` clips the written values
    (used only where values are resampled at frames). With ``factors`` the
    curve is their product (a corrective shape's weight), then clamped.
    """

    track: Track | None
    component: int = 0
    constant: float = 0.0
    scale: float = 1.0
    coeffs: NDArray[np.float64] | None = None
    offset: float = 0.0
    clamp: tuple[float, float] | None = None
    factors: tuple[Curve, ...] = ()

    def leaves(self) -> list[Curve]:
        """The curves this one is made of (itself, or its factors')."""
        return [leaf for f in self.factors for leaf in f.leaves()] if self.factors else [self]

    def _combine(self, arr: NDArray[np.float64]) -> NDArray[np.float64]:
        col = arr @ self.coeffs if self.coeffs is not None else arr[:, self.component]
        return self.scale * col

    def sample(self, times: NDArray[np.float64]) -> NDArray[np.float64]:
        """Values at ``times`` (clamped if ``clamp``)."""
        ts = np.asarray(times, np.float64).reshape(-1)
        if self.factors:
            # the same operations, in the same order, as workbench.core.families.derive_weights
            w: NDArray[np.float64] = np.ones(ts.size)
            for f in self.factors:
                w = w * f.sample(ts)
            return w if self.clamp is None else np.clip(w, *self.clamp)
        if self.track is None:
            return np.full(ts.size, self.scale * self.constant)
        v = self._combine(self.track.sample(ts)) + self.offset
        return v if self.clamp is None else np.clip(v, *self.clamp)


@dataclass(frozen=True)
class SamplerData:
    """Arrays of one glTF animation sampler.

    Attributes
    ----------
    times : (K,) float
    interpolation : {"STEP", "LINEAR", "CUBICSPLINE"}
    values, in_tangents, out_tangents : (K, m) float
        Per key and curve (tangents are per second; used for CUBICSPLINE).
    """

    times: NDArray[np.float64]
    interpolation: str
    values: NDArray[np.float64]
    in_tangents: NDArray[np.float64]
    out_tangents: NDArray[np.float64]

    def output(self) -> NDArray[np.float32]:
        """Flat float32 sampler output in glTF order (with in/out tangents for CUBICSPLINE)."""
        if self.interpolation == "CUBICSPLINE":
            out = np.stack([self.in_tangents, self.values, self.out_tangents], axis=1)
            return out.astype(np.float32).reshape(-1)
        return self.values.astype(np.float32).reshape(-1)


def _segment_codes(tr: Track) -> set[str]:
    # the last key's interpolation governs no segment
    return set(tr.interpolations[:-1]) if len(tr) > 1 else set()


def merge_curves(
    curves: list[Curve],
    *,
    bake_times: NDArray[np.float64] | None = None,
    rotation_track: Track | None = None,
    knots: NDArray[np.float64] | None = None,
) -> SamplerData | None:
    """Merge scalar curves onto one glTF sampler (see module docstring).

    Parameters
    ----------
    curves : list of Curve
        The sampler's output columns.
    bake_times : (F,) float, optional
        Resample at these times with LINEAR instead of merging keys.
    knots : (F,) float, optional
        Extra key times (the frames) when a product curve (``factors``) is
        animated and the sampler is not STEP: the product is exact there.
    rotation_track : Track, optional
        If given, ``curves`` are its quaternion components: interpolation is
        STEP or LINEAR (glTF slerps rotations, like :class:`Track`).

    Returns
    -------
    SamplerData or None
        None when no curve is animated.
    """
    leaves = [leaf for c in curves for leaf in c.leaves()]
    tracks: dict[int, Track] = {id(c.track): c.track for c in leaves if c.track is not None}
    if not tracks:
        return None
    animated_products = any(c.factors and any(leaf.track is not None for leaf in c.leaves()) for c in curves)
    if bake_times is not None:
        times = np.asarray(bake_times, np.float64)
        mode = "LINEAR"
    else:
        orig = set().union(*(_segment_codes(t) for t in tracks.values()))
        codes = orig
        if rotation_track is not None:
            codes = {"step"} if codes <= {"step"} else {"linear"}
        if not codes or codes == {"step"}:
            mode = "STEP"
        elif "bezier" in codes:
            mode = "CUBICSPLINE"
        else:
            mode = "LINEAR"
        times = np.unique(np.concatenate([t.times for t in tracks.values()]))
        if mode != "STEP" and animated_products and knots is not None and knots.size:
            lo, hi = times[0], times[-1]
            fr = np.asarray(knots, np.float64)
            # frames inside the keyed range (outside it every track holds its end value)
            times = np.unique(np.concatenate([times, fr[(fr > lo) & (fr < hi)]]))
            times = _drop_close(times, np.unique(np.concatenate([t.times for t in tracks.values()])))
        if mode != "STEP":
            times = _add_crossings(times, leaves)
        if mode != "STEP" and "step" in orig:
            # hold-then-ramp knots just before the end of every step segment
            gaps = np.diff(times)
            eps = min(_STEP_EPS, float(gaps.min()) / 4.0) if gaps.size else _STEP_EPS
            extra = [
                tr.times[i + 1] - eps
                for tr in tracks.values()
                for i in range(len(tr) - 1)
                if tr.keys[i].interpolation == "step"
            ]
            times = np.unique(np.concatenate([times, np.asarray(extra)]))
    if times.size and times[0] < 0:
        raise ExportError(f"glTF animation times must be >= 0; the first key is at {times[0]:g} s")
    K, m = times.size, len(curves)
    V = np.zeros((K, m))
    A = np.zeros((K, m))
    B = np.zeros((K, m))
    cache: dict[int, tuple[NDArray[np.float64], ...]] = {}
    for j, c in enumerate(curves):
        V[:, j], A[:, j], B[:, j] = _column(c, times, mode, cache)
    return SamplerData(times, mode, V, A, B)


def _column(
    c: Curve, times: NDArray[np.float64], mode: str, cache: dict[int, tuple[NDArray[np.float64], ...]]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Values, in-slopes and out-slopes of one curve at ``times`` (clamped where it clamps)."""
    K = times.size
    if c.factors:
        # product rule, factor by factor: (v f)' = v' f + v f'; values as derive_weights multiplies
        v, a, b = np.ones(K), np.zeros(K), np.zeros(K)
        for f in c.factors:
            fv, fa, fb = _column(f, times, mode, cache)
            a, b, v = a * fv + v * fa, b * fv + v * fb, v * fv
        if c.clamp is not None:
            _clamp_column(v, a, b, *c.clamp)
        return v, a, b
    if c.track is None:
        return np.full(K, c.scale * c.constant), np.zeros(K), np.zeros(K)
    key = id(c.track)
    if key not in cache:
        tr = c.track
        vals = tr.sample(times)
        if mode == "CUBICSPLINE":
            left, right = tr.derivatives(times, "left"), tr.derivatives(times, "right")
            left, right = _step_ramps(tr, times, vals, left, right)
        else:
            left = right = np.zeros_like(vals)
        cache[key] = (vals, left, right)
    vals, left, right = cache[key]
    v = c._combine(vals) + c.offset
    a = c._combine(left)
    b = c._combine(right)
    if c.clamp is not None:
        _clamp_column(v, a, b, *c.clamp)
    return v, a, b


def _drop_close(times: NDArray[np.float64], keys: NDArray[np.float64]) -> NDArray[np.float64]:
    """``times`` without the added knots that float32 cannot tell from the previous knot (keys win)."""
    f32 = times.astype(np.float32)
    orig = np.isin(times, keys)
    kept: list[int] = []
    for i in range(times.size):
        if kept and f32[i] <= f32[kept[-1]]:
            if not orig[i]:
                continue
            if not orig[kept[-1]]:
                kept.pop()
        kept.append(i)
    return times[kept]


def _add_crossings(times: NDArray[np.float64], curves: list[Curve]) -> NDArray[np.float64]:
    """``times`` plus the times where a clamped curve crosses its bounds.

    With a knot at every crossing, each piece between knots is either inside
    the range (the curve itself) or outside (the constant bound), so clamping
    is exact in a LINEAR/CUBICSPLINE sampler. Crossings closer than float32
    resolution to another knot are dropped (times are stored as float32).
    """
    extra: list[float] = []
    for c in curves:
        if c.clamp is not None and c.track is not None and c.coeffs is None and c.track.values.shape[1] == 1:
            lo, hi = ((x - c.offset) / c.scale for x in c.clamp)
            extra += crossing_times(c.track, (lo, hi))
    if not extra:
        return times
    out = np.unique(np.concatenate([times, np.asarray(extra)]))
    f32 = out.astype(np.float32)
    orig = np.isin(out, times)
    kept: list[int] = []
    for i in range(out.size):
        if kept and f32[i] <= f32[kept[-1]]:
            if not orig[i]:
                continue  # a crossing on top of the previous knot
            if not orig[kept[-1]]:
                kept.pop()  # the previous one was a crossing: the key wins
        kept.append(i)
    return out[kept]


def _clamp_column(
    v: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64], lo: float, hi: float
) -> None:
    """Clamp one sampler column in place: values to ``[lo, hi]``, tangents 0 on the clamped side."""
    tol = 1e-9 * max(1.0, abs(lo), abs(hi))
    above, below = v > hi + tol, v < lo - tol
    at_hi, at_lo = np.abs(v - hi) <= tol, np.abs(v - lo) <= tol
    # at the upper bound the curve is inside on the left if it comes up (a >= 0),
    # and on the right if it goes down (b <= 0); mirrored at the lower bound
    a[:] = np.where(above | below, 0.0, np.where(at_hi, np.maximum(a, 0.0), np.where(at_lo, np.minimum(a, 0.0), a)))
    b[:] = np.where(above | below, 0.0, np.where(at_hi, np.minimum(b, 0.0), np.where(at_lo, np.maximum(b, 0.0), b)))
    v[:] = np.clip(v, lo, hi)


def _step_ramps(
    tr: Track,
    times: NDArray[np.float64],
    vals: NDArray[np.float64],
    left: NDArray[np.float64],
    right: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tangents of the short linear ramp that ends each step segment in a cubic sampler."""
    left, right = left.copy(), right.copy()
    for i in range(len(tr) - 1):
        if tr.keys[i].interpolation != "step":
            continue
        end = int(np.searchsorted(times, tr.times[i + 1]))
        if end == 0:
            continue
        start = end - 1  # the knot just before the key (inserted by merge_curves)
        slope = (vals[end] - vals[start]) / (times[end] - times[start])
        right[start] = slope
        left[end] = slope
    return left, right


# ------------------------------------------------------------------ file building
class _Blob:
    """Accumulates the binary buffer and the bufferViews/accessors that point into it."""

    def __init__(self, gltf: pygltflib.GLTF2) -> None:
        self.gltf = gltf
        self.chunks: list[bytes] = []
        self.size = 0

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = (-self.size) % 4
        if pad:
            self.chunks.append(b"\0" * pad)
            self.size += pad
        self.gltf.bufferViews.append(
            pygltflib.BufferView(buffer=0, byteOffset=self.size, byteLength=len(data), target=target)
        )
        self.chunks.append(data)
        self.size += len(data)
        return len(self.gltf.bufferViews) - 1

    def accessor(
        self,
        array: NDArray[Any],
        type_: str,
        *,
        target: int | None = None,
        minmax: bool = False,
    ) -> int:
        a = np.ascontiguousarray(array)
        ctype = {np.dtype(np.float32): pygltflib.FLOAT, np.dtype(np.uint32): pygltflib.UNSIGNED_INT}[
            a.dtype
        ]
        count = a.shape[0]
        acc = pygltflib.Accessor(
            bufferView=self.view(a.tobytes(), target),
            componentType=ctype,
            count=count,
            type=type_,
        )
        if minmax:
            flat = a.reshape(count, -1)
            acc.min = [float(x) for x in flat.min(axis=0)]
            acc.max = [float(x) for x in flat.max(axis=0)]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def sparse_vec3(self, delta: NDArray[np.float32]) -> int:
        """A VEC3 float accessor of ``len(delta)`` elements storing only the non-zero rows."""
        n = delta.shape[0]
        nz = np.flatnonzero(np.any(delta != 0, axis=1)).astype(np.uint32)
        if nz.size == 0:
            nz = np.zeros(1, np.uint32)  # sparse.count must be >= 1
        vals = np.ascontiguousarray(delta[nz], np.float32)
        # min/max over *all* elements, zeros included (validator rule)
        full_min = np.minimum(vals.min(axis=0), 0.0) if nz.size < n else vals.min(axis=0)
        full_max = np.maximum(vals.max(axis=0), 0.0) if nz.size < n else vals.max(axis=0)
        acc = pygltflib.Accessor(
            componentType=pygltflib.FLOAT,
            count=n,
            type=pygltflib.VEC3,
            min=[float(x) for x in full_min],
            max=[float(x) for x in full_max],
            sparse=pygltflib.Sparse(
                count=int(nz.size),
                indices=pygltflib.AccessorSparseIndices(
                    bufferView=self.view(nz.tobytes()), componentType=pygltflib.UNSIGNED_INT
                ),
                values=pygltflib.AccessorSparseValues(bufferView=self.view(vals.tobytes())),
            ),
        )
        acc.byteOffset = None  # pygltflib writes 0, invalid without a bufferView
        acc.sparse.indices.byteOffset = None
        acc.sparse.values.byteOffset = None
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def data(self) -> bytes:
        pad = (-self.size) % 4
        return b"".join(self.chunks) + b"\0" * pad


def build_gltf(
    model: FaceModel, timeline: Timeline, *, bake: bool = False, sparse: bool = True
) -> tuple[pygltflib.GLTF2, bytes]:
    """The glTF document and its binary buffer (see module docstring).

    Returns
    -------
    gltf : pygltflib.GLTF2
    blob : bytes
        Contents of buffer 0.
    """
    gltf, data, _ = _build(model, timeline, bake=bake, sparse=sparse)
    return gltf, data


def _hat_track(times: NDArray[np.float64], f: int) -> Track:
    """A LINEAR weight track that is 1 at frame ``f`` and 0 at its neighbours."""
    keys = [Key(float(times[f]), 1.0, "linear")]
    if f > 0:
        keys.insert(0, Key(float(times[f - 1]), 0.0, "linear"))
    if f + 1 < times.size:
        keys.append(Key(float(times[f + 1]), 0.0, "linear"))
    return Track(f"weights/layer:frame{f}", tuple(keys))


def _build(
    model: FaceModel, timeline: Timeline, *, bake: bool = False, sparse: bool = True
) -> tuple[pygltflib.GLTF2, bytes, list[LayerReport]]:
    enc = MeshEncoding(model, timeline)
    frames = timeline.frame_times()
    enc.fold_constant_baked(frames)
    mpu = model.metadata.metres_per_unit
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0", generator="Facial Editing Workbench"),
        scene=0,
    )
    blob = _Blob(gltf)

    V = (np.asarray(model.vertices, np.float64) * mpu).astype(np.float32)
    tris, _ = model.polygons.triangulate()
    pos = blob.accessor(V, pygltflib.VEC3, target=_ARRAY_BUFFER, minmax=True)
    idx = blob.accessor(
        tris.astype(np.uint32).reshape(-1), pygltflib.SCALAR, target=_ELEMENT_ARRAY_BUFFER
    )

    names: list[str] = []
    targets: list[dict[str, int]] = []
    curves: list[Curve] = []
    n = V.shape[0]

    def add_target(delta: NDArray[Any], name: str, curve: Curve) -> None:
        d = (np.asarray(delta, np.float64) * mpu).astype(np.float32)
        moving = int(np.count_nonzero(np.any(d != 0, axis=1)))
        if sparse and moving * 2 < n:
            acc = blob.sparse_vec3(d)
        else:
            acc = blob.accessor(d, pygltflib.VEC3, target=_ARRAY_BUFFER, minmax=True)
        targets.append({"POSITION": acc})
        names.append(name)
        curves.append(curve)

    weight_tracks = timeline.weight_tracks
    shape_index = {s.name: k for k, s in enumerate(model.shapes)}

    def weight_curve(k: int) -> Curve:
        s = model.shapes[k]
        if s.mute:
            return Curve(None, constant=0.0)
        drivers = enc.weight_products.get(s.name)
        if drivers is not None:  # a corrective: the product of its drivers' played weights
            factors = tuple(
                weight_curve(shape_index[d]) if d in shape_index else Curve(None, constant=0.0) for d in drivers
            )
            return Curve(None, factors=factors, clamp=(s.slider_min, s.slider_max))
        if s.name in weight_tracks:
            return Curve(weight_tracks[s.name], clamp=(s.slider_min, s.slider_max))
        return Curve(None, constant=float(enc.static_weights[k]))

    for k, s in enumerate(model.shapes):
        add_target(enc.shape_targets[k], s.name, weight_curve(k))

    if enc.static is not None:
        add_target(enc.static, "layer:static", Curve(None, constant=1.0))
    for ctl in enc.controls:
        for i in range(ctl.targets.shape[0]):
            add_target(
                ctl.targets[i],
                f"{ctl.prefix}:basis{i}",
                Curve(ctl.track, coeffs=ctl.coeffs[:, i], offset=float(ctl.shift[i])),
            )
    for f, t in enumerate(frames):
        b = enc.baked(float(t))
        if b is not None:
            frame_no = round(float(t) * timeline.fps)
            add_target(b, f"layer:frame{frame_no:04d}", Curve(_hat_track(frames, f)))
    enc.baked_report(frames, "per-frame morph targets layer:frame<N> with LINEAR hat weights")

    t0 = timeline.start
    initial = [float(c.sample(np.array([t0]))[0]) for c in curves]
    mesh = pygltflib.Mesh(
        name=model.metadata.name or "face",
        primitives=[
            pygltflib.Primitive(
                attributes=pygltflib.Attributes(POSITION=pos),
                indices=idx,
                mode=pygltflib.TRIANGLES,
                targets=targets or None,
            )
        ],
        weights=initial or None,
        extras={"targetNames": names} if names else {},
    )
    gltf.meshes.append(mesh)
    node = pygltflib.Node(name=model.metadata.name or "face", mesh=0)
    gltf.nodes.append(node)
    gltf.scenes.append(pygltflib.Scene(nodes=[0]))

    bake_times = frames if bake else None
    layers = list(enc.layers)
    anim = pygltflib.Animation(name="timeline", samplers=[], channels=[])

    def add_channel(data: SamplerData | None, path: str, type_: str, width: int) -> None:
        if data is None:
            return
        inp = blob.accessor(data.times.astype(np.float32), pygltflib.SCALAR, minmax=True)
        out_flat = data.output()
        out_arr = out_flat if type_ == pygltflib.SCALAR else out_flat.reshape(-1, width)
        out = blob.accessor(out_arr, type_)
        anim.samplers.append(
            pygltflib.AnimationSampler(input=inp, output=out, interpolation=data.interpolation)
        )
        anim.channels.append(
            pygltflib.AnimationChannel(
                sampler=len(anim.samplers) - 1,
                target=pygltflib.AnimationChannelTarget(node=0, path=path),
            )
        )

    if names:
        add_channel(merge_curves(curves, bake_times=bake_times, knots=frames), "weights", pygltflib.SCALAR, 1)

    hp = timeline.tracks.get(HEAD_POSE)
    if hp is not None:
        first = hp.sample([t0])[0]
        node.translation = [float(x) * mpu for x in first[:3]]
        node.rotation = [float(x) for x in first[3:]]
        tr_curves = [Curve(hp, component=a, scale=mpu) for a in range(3)]
        add_channel(merge_curves(tr_curves, bake_times=bake_times), "translation", pygltflib.VEC3, 3)
        rot_curves = [Curve(hp, component=3 + a) for a in range(4)]
        add_channel(
            merge_curves(rot_curves, bake_times=bake_times, rotation_track=hp),
            "rotation",
            pygltflib.VEC4,
            4,
        )
    if anim.channels:
        gltf.animations.append(anim)
    data = blob.data()
    gltf.buffers.append(pygltflib.Buffer(byteLength=len(data)))
    return gltf, data, layers


def _glb_bytes(gltf: pygltflib.GLTF2, data: bytes) -> bytes:
    """Pack a GLB container (12-byte header, padded JSON chunk, BIN chunk)."""
    import struct

    js = gltf.to_json(separators=(",", ":")).encode("utf-8")
    js += b" " * ((-len(js)) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(data), 0x004E4942) + data
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def write(
    model: FaceModel,
    timeline: Timeline,
    path: Path,
    *,
    bake: bool = False,
    sparse: bool = True,
) -> ExportResult:
    """Write a .glb (one file) or .gltf (+ ``<stem>.bin``) atomically.

    Parameters
    ----------
    bake : bool
        Resample every curve at each frame (LINEAR) instead of writing keys.
    sparse : bool
        Store blendshape targets that move few vertices as sparse accessors.
    """
    gltf, data, layers = _build(model, timeline, bake=bake, sparse=sparse)
    if path.suffix.lower() == ".gltf":
        bin_path = path.with_suffix(".bin")
        gltf.buffers[0].uri = bin_path.name
        atomic_write_bytes(bin_path, data)
        atomic_write_bytes(path, gltf.to_json(indent=1).encode("utf-8"))
        return ExportResult([path, bin_path], layers)
    atomic_write_bytes(path, _glb_bytes(gltf, data))
    return ExportResult([path], layers)
