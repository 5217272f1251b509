"""The glTF document of a model and its timeline: mesh, morph targets and the animation's channels.

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
  :mod:`workbench.export.encoding`): exactly the delta where nothing is painted and no
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
  curve crosses a bound (:func:`~workbench.export.gltf.sampler._add_crossings`) and the pieces outside are
  written as the constant bound: the sampler keeps its interpolation (LINEAR
  or CUBICSPLINE) and stays exact, with no per-frame resampling.
* One animation: a ``weights`` channel on the mesh node (one sampler for all
  targets, as glTF requires) and, when the head pose is keyed, ``translation``
  and ``rotation`` channels on the same node (metres; quaternions slerped).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pygltflib
from numpy.typing import NDArray

from workbench.animation.curves import HEAD_POSE, Key, Track
from workbench.animation.tracks import Timeline
from workbench.export.base import LayerReport
from workbench.export.encoding import MeshEncoding
from workbench.export.gltf.buffers import _ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER, _Blob
from workbench.export.gltf.sampler import Curve, SamplerData, merge_curves

if TYPE_CHECKING:
    from workbench.model import FaceModel


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
