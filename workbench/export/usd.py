"""USD export with UsdSkel blend shapes (usd-core, imported lazily as ``pxr``).

Layout (``metersPerUnit = 1``, ``upAxis = Y``, positions in metres,
``timeCodesPerSecond = framesPerSecond = fps``, time code = ``t * fps``)::

    /Face                 SkelRoot (default prim); head pose as xformOp:translate
                          + xformOp:orient time samples per frame (when keyed)
    /Face/Skel            Skeleton with zero joints; skel:animationSource -> Anim
    /Face/Skel/Anim       SkelAnimation: blendShapes (tokens) and blendShapeWeights
                          time samples, one per frame
    /Face/Mesh            Mesh (original polygons), SkelBindingAPI: skel:skeleton,
                          skel:blendShapes, skel:blendShapeTargets
    /Face/Mesh/<shape>    BlendShape: offsets (metres) + pointIndices (moving vertices)

Every frame evaluates to :meth:`FaceModel.evaluate_at` (all editing layers),
through the decomposition of :class:`workbench.export.encoding.MeshEncoding`:

* one blend shape per model shape (its masked delta scaled per vertex by
  ``(1 − P)(1 − S_R)``, painted weight and region coverage; the plain delta where
  nothing is painted), weight = the shape's weight (clamped to its slider
  range, muted shapes 0; a corrective shape's weight is the product of its
  drivers' weights, :meth:`MeshEncoding.weights`, exact at every frame);
* ``layer_static`` (weight 1 at every frame) when the layers add a constant:
  region constant, painted expressions, unkeyed handle offsets;
* ``handle_basis<i>`` (``<prefix>_basis<i>`` of any layer with keyed linear
  controls) when the handle offsets are keyed: the shell displacement of one
  basis vector of the keyed offsets' span, weight in ``[0, 1]`` per frame;
* layers that are not linear in the keyed quantities (wrinkles, anything
  registered later) are baked: the Mesh ``points`` get one time sample per
  frame, ``neutral + those layers``; UsdSkel adds the blend shapes on top.
  Without such layers ``points`` is the neutral, unanimated.

USD has no cubic interpolation for weights, so weights are written per frame
(linear in between, as USD interpolates time samples).

``bake=True`` writes no skeleton: ``/Face`` is an Xform and ``/Face/Mesh`` a
Mesh with fully evaluated ``points`` per frame (for tools without UsdSkel).

Blend-shape prim names are target names made into valid identifiers (the
original name is kept in customData ``workbench:shapeName``, or
``workbench:layerTarget`` for the layer targets).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.animation.tracks import Timeline
from workbench.export.base import ExportError, ExportResult, LayerReport, atomic_path
from workbench.export.encoding import MeshEncoding

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["write"]

ROOT = "/Face"
SKEL = "/Face/Skel"
ANIM = "/Face/Skel/Anim"
MESH = "/Face/Mesh"


def _pxr() -> Any:
    try:
        import pxr
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ExportError("USD export needs usd-core: pip install usd-core") from exc
    return pxr


def _prim_names(names: list[str], Tf: Any) -> list[str]:
    out: list[str] = []
    seen: set[str] = set()
    for n in names:
        base = Tf.MakeValidIdentifier(n)
        cand, i = base, 1
        while cand in seen:
            cand = f"{base}_{i}"
            i += 1
        seen.add(cand)
        out.append(cand)
    return out


def write(
    model: FaceModel, timeline: Timeline, path: Path, *, bake: bool = False
) -> ExportResult:
    """Write ``.usd`` (crate), ``.usdc`` or ``.usda`` atomically (see module docstring)."""
    pxr = _pxr()
    Gf, Tf, Usd, UsdGeom, UsdSkel, Vt = pxr.Gf, pxr.Tf, pxr.Usd, pxr.UsdGeom, pxr.UsdSkel, pxr.Vt
    enc = MeshEncoding(model, timeline)
    mpu = model.metadata.metres_per_unit
    times = timeline.frame_times()
    codes = times * timeline.fps
    fps = timeline.fps
    enc.fold_constant_baked(times)

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(float(codes[0]))
    stage.SetEndTimeCode(float(codes[-1]))

    root = (UsdGeom.Xform if bake else UsdSkel.Root).Define(stage, ROOT)
    stage.SetDefaultPrim(root.GetPrim())
    if timeline.head_pose is not None:
        P = timeline.head_pose.sample(times)
        xf = UsdGeom.Xformable(root.GetPrim())
        t_op = xf.AddTranslateOp()
        o_op = xf.AddOrientOp()
        for c, p in zip(codes, P, strict=True):
            tc = Usd.TimeCode(float(c))
            t_op.Set(Gf.Vec3d(*(float(x) * mpu for x in p[:3])), tc)
            o_op.Set(Gf.Quatf(float(p[6]), Gf.Vec3f(float(p[3]), float(p[4]), float(p[5]))), tc)

    mesh = UsdGeom.Mesh.Define(stage, MESH)
    polys = model.polygons
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(polys.sizes.astype(np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(polys.indices.astype(np.int32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    neutral = (np.asarray(model.vertices, np.float64) * mpu).astype(np.float32)
    points = mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(neutral))
    lo, hi = neutral.min(axis=0), neutral.max(axis=0)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([lo, hi]).astype(np.float32)))

    if bake:
        for c, t in zip(codes, times, strict=True):
            pts = enc.local_points([t])[0].astype(np.float64) * mpu
            points.Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)), Usd.TimeCode(float(c)))
        enc.baked_report(times, "per-frame points")
        enc.all_baked_report("bake=True: in the per-frame points")
        return _save(stage, path, enc.layers)

    skel = UsdSkel.Skeleton.Define(stage, SKEL)
    skel.CreateJointsAttr(Vt.TokenArray([]))
    anim = UsdSkel.Animation.Define(stage, ANIM)
    anim.CreateJointsAttr(Vt.TokenArray([]))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])

    # targets: shapes, then the layer targets (static, each controls layer's basis)
    names = list(model.shape_names)
    data = [enc.shape_targets[k] for k in range(len(names))]
    extra: list[str] = []
    if enc.static is not None:
        extra.append("layer:static")
        data.append(enc.static)
    for ctl in enc.controls:
        for i in range(ctl.targets.shape[0]):
            extra.append(f"{ctl.prefix}:basis{i}")
            data.append(ctl.targets[i])
    all_names = names + extra
    prim_names = _prim_names(all_names, Tf)
    tokens = Vt.TokenArray(prim_names)
    anim.CreateBlendShapesAttr(tokens)
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateBlendShapesAttr(tokens)
    targets = []
    for k, (name, pname) in enumerate(zip(all_names, prim_names, strict=True)):
        d = data[k]
        idx = np.flatnonzero(np.any(d != 0, axis=1)).astype(np.int32)
        bs = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(pname))
        off = (d[idx].astype(np.float64) * mpu).astype(np.float32)
        bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(off))
        bs.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(idx))
        key = "workbench:shapeName" if k < len(names) else "workbench:layerTarget"
        bs.GetPrim().SetCustomDataByKey(key, name)
        targets.append(bs.GetPath())
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)

    cols = [enc.weights(times)]
    if enc.static is not None:
        cols.append(np.ones((times.size, 1)))
    cols += [enc.control_weights(ctl, times) for ctl in enc.controls]
    W = np.concatenate(cols, axis=1).astype(np.float32)
    wattr = anim.CreateBlendShapeWeightsAttr()
    for c, w in zip(codes, W, strict=True):
        wattr.Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(w)), Usd.TimeCode(float(c)))

    baked = [enc.baked(float(t)) for t in times]
    if any(b is not None for b in baked):
        for c, b in zip(codes, baked, strict=True):
            pts = neutral if b is None else neutral + (b.astype(np.float64) * mpu).astype(np.float32)
            points.Set(Vt.Vec3fArray.FromNumpy(pts), Usd.TimeCode(float(c)))
    enc.baked_report(times, "Mesh points time samples (neutral + baked layers), blend shapes on top")
    return _save(stage, path, enc.layers)


def _save(stage: Any, path: Path, layers: list[LayerReport]) -> ExportResult:
    suffix = path.suffix.lower()
    if suffix not in (".usd", ".usda", ".usdc"):
        raise ExportError(f"{path.name}: USD files end in .usd, .usda or .usdc")
    with atomic_path(path) as tmp:
        # Export infers the file format from the temporary name's suffix
        if not stage.GetRootLayer().Export(str(tmp)):
            raise ExportError(f"{path.name}: USD could not write the layer")
    return ExportResult([path], layers)
