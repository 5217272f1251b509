"""Our USD files evaluated by UsdSkel itself (Cache → bindings → blend-shape weights → points)."""

from __future__ import annotations

import numpy as np
import pytest
from consumer_timelines import (
    expected_points,
    expression_timeline,
    with_handle_keys,
    with_head_pose,
)

from workbench.export import export

FRAMES = [0, 7, 15, 22, 30, 44, 60]


def usdskel_points(pxr, path, frames):
    """Deformed mesh points at ``frames`` computed by UsdSkel, plus the stage metadata."""
    Usd, UsdGeom, UsdSkel = pxr.Usd, pxr.UsdGeom, pxr.UsdSkel
    stage = Usd.Stage.Open(str(path))
    root = UsdSkel.Root(stage.GetDefaultPrim())
    assert root, "default prim is not a SkelRoot"
    cache = UsdSkel.Cache()
    pred = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
    cache.Populate(root, pred)
    bindings = cache.ComputeSkelBindings(root, pred)
    assert len(bindings) == 1
    binding = bindings[0]
    anim = cache.GetSkelQuery(binding.GetSkeleton()).GetAnimQuery()
    (skinning,) = binding.GetSkinningTargets()
    prim = skinning.GetPrim()
    bsq = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
    mapper = skinning.GetBlendShapeMapper()
    point_indices = bsq.ComputeBlendShapePointIndices()
    offsets = bsq.ComputeSubShapePointOffsets()
    out = []
    for f in frames:
        tc = Usd.TimeCode(f)
        weights = anim.ComputeBlendShapeWeights(tc)
        weights = mapper.Remap(weights) if mapper is not None and not mapper.IsNull() else weights
        sub, bidx, sidx = bsq.ComputeSubShapeWeights(weights)
        points = UsdGeom.Mesh(prim).GetPointsAttr().Get(tc)
        assert bsq.ComputeDeformedPoints(sub, bidx, sidx, point_indices, offsets, points)
        out.append(np.array(points))
    return stage, np.stack(out)


@pytest.mark.parametrize("suffix", [".usda", ".usd"])
def test_usdskel_blend_shapes_give_our_points(usd, head, tmp_path, suffix):
    tl = expression_timeline("cubic")
    (p,) = export(head, tl, tmp_path / f"face{suffix}")
    stage, pts = usdskel_points(usd, p, FRAMES)
    ours = expected_points(head, tl, np.array(FRAMES) / tl.fps)
    np.testing.assert_allclose(pts, ours, atol=1e-5, rtol=0)
    assert np.abs(pts[2] - pts[0]).max() > 1e-3  # it really animates
    UsdGeom = usd.UsdGeom
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 30.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 60.0)
    mesh = stage.GetPrimAtPath("/Face/Mesh")
    names = usd.UsdSkel.BindingAPI(mesh).GetBlendShapesAttr().Get()
    assert list(names) == head.shape_names


def test_usdskel_with_handle_layer_and_head_pose(usd, head_with_handles, tmp_path):
    m = head_with_handles
    tl = with_head_pose(with_handle_keys(expression_timeline("linear"), "linear"))
    (p,) = export(m, tl, tmp_path / "face.usdc")
    stage, pts = usdskel_points(usd, p, FRAMES)
    times = np.array(FRAMES) / tl.fps
    np.testing.assert_allclose(pts, expected_points(m, tl, times, head_pose=False), atol=1e-5, rtol=0)
    world_expected = expected_points(m, tl, times)
    # the head pose is the SkelRoot transform
    Usd, UsdGeom = usd.Usd, usd.UsdGeom
    for f in FRAMES:
        M = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/Face")).ComputeLocalToWorldTransform(Usd.TimeCode(f)))
        world = pts[FRAMES.index(f)] @ M[:3, :3] + M[3, :3]  # USD matrices are row-vector style
        np.testing.assert_allclose(world, world_expected[FRAMES.index(f)], atol=1e-5)


def test_baked_usd_points(usd, head, tmp_path):
    tl = expression_timeline("cubic")
    (p,) = export(head, tl, tmp_path / "baked.usda", bake=True)
    stage = usd.Usd.Stage.Open(str(p))
    attr = usd.UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
    ours = expected_points(head, tl, np.array(FRAMES) / tl.fps)
    for i, f in enumerate(FRAMES):
        np.testing.assert_allclose(np.array(attr.Get(usd.Usd.TimeCode(f))), ours[i], atol=1e-5)
