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

USD has no cubic interpolation for weights, so weights are written per frame
(linear in between, as USD interpolates time samples). When the handle layer
moves the mesh, the Mesh ``points`` get one time sample per frame
(``neutral + handle displacement``); UsdSkel adds the blend shapes on top, so
the evaluated mesh equals :class:`workbench.tracks.MeshSampler.local_points`.

``bake=True`` writes no skeleton: ``/Face`` is an Xform and ``/Face/Mesh`` a
Mesh with fully evaluated ``points`` per frame (for tools without UsdSkel).

Muted shapes get weight 0. Blend-shape prim names are shape names made into
valid identifiers (the original name is kept in customData
``workbench:shapeName``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.export import ExportError, atomic_path
from workbench.tracks import MeshSampler, Timeline

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
) -> list[Path]:
    """Write ``.usd`` (crate), ``.usdc`` or ``.usda`` atomically (see module docstring)."""
    pxr = _pxr()
    Gf, Tf, Usd, UsdGeom, UsdSkel, Vt = pxr.Gf, pxr.Tf, pxr.Usd, pxr.UsdGeom, pxr.UsdSkel, pxr.Vt
    sampler = MeshSampler(model, timeline)
    mpu = model.metadata.metres_per_unit
    times = timeline.frame_times()
    codes = times * timeline.fps
    fps = timeline.fps

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
            pts = sampler.local_points([t])[0].astype(np.float64) * mpu
            points.Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)), Usd.TimeCode(float(c)))
        return _save(stage, path)

    skel = UsdSkel.Skeleton.Define(stage, SKEL)
    skel.CreateJointsAttr(Vt.TokenArray([]))
    anim = UsdSkel.Animation.Define(stage, ANIM)
    anim.CreateJointsAttr(Vt.TokenArray([]))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])

    names = list(model.shape_names)
    prim_names = _prim_names(names, Tf)
    tokens = Vt.TokenArray(prim_names)
    anim.CreateBlendShapesAttr(tokens)
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateBlendShapesAttr(tokens)
    targets = []
    for k, (name, pname) in enumerate(zip(names, prim_names, strict=True)):
        d = sampler.deltas[k]
        idx = np.flatnonzero(np.any(d != 0, axis=1)).astype(np.int32)
        bs = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(pname))
        off = (d[idx].astype(np.float64) * mpu).astype(np.float32)
        bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(off))
        bs.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(idx))
        bs.GetPrim().SetCustomDataByKey("workbench:shapeName", name)
        targets.append(bs.GetPath())
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)

    W = sampler.weights(times).astype(np.float32)
    wattr = anim.CreateBlendShapeWeightsAttr()
    for c, w in zip(codes, W, strict=True):
        wattr.Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(w)), Usd.TimeCode(float(c)))

    if sampler.has_handle_layer:
        offsets = sampler.handle_offsets(times)
        for c, o in zip(codes, offsets, strict=True):
            pts = neutral + (sampler.handle_displacement(o).astype(np.float64) * mpu).astype(np.float32)
            points.Set(Vt.Vec3fArray.FromNumpy(pts), Usd.TimeCode(float(c)))
    return _save(stage, path)


def _save(stage: Any, path: Path) -> list[Path]:
    suffix = path.suffix.lower()
    if suffix not in (".usd", ".usda", ".usdc"):
        raise ExportError(f"{path.name}: USD files end in .usd, .usda or .usdc")
    with atomic_path(path) as tmp:
        # Export infers the file format from the temporary name's suffix
        if not stage.GetRootLayer().Export(str(tmp)):
            raise ExportError(f"{path.name}: USD could not write the layer")
    return [path]
