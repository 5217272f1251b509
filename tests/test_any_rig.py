"""Tools on a rig that is not ARKit-52 by name: suffixed sides, split halves, missing shapes (issue 15, item 4)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import workbench
from workbench.arkit import rig_weights, split_half_of
from workbench.methods.wrinkles.examples import EXAMPLE_POSES, example_poses_for
from workbench.methods.wrinkles.family import fit_sample_wrinkles
from workbench.model import BlendShape, FaceModel

SPLIT = ("browInnerUp", "cheekPuff", "jawOpen")


def suffixed(name: str) -> str:
    for side, suffix in (("Left", "_L"), ("Right", "_R")):
        if name.endswith(side):
            return name[: -len(side)] + suffix
    return name


def studio_rig(base: FaceModel) -> FaceModel:
    """The sample head as another studio would ship it: `_L/_R` names, three shapes split, no tongue."""
    x = base.vertices[:, 0]
    left = np.clip(0.5 + x / 0.2, 0.0, 1.0)  # a 2 cm smooth band across the mid-plane
    shapes = []
    for s in base.shapes:
        if s.name == "tongueOut":
            continue
        if s.name in SPLIT:
            shapes.append(BlendShape(f"{s.name}_L", s.delta * left[:, None].astype(np.float32)))
            shapes.append(BlendShape(f"{s.name}_R", s.delta - shapes[-1].delta))
        else:
            shapes.append(BlendShape(suffixed(s.name), s.delta))
    return FaceModel(base.vertices, base.faces, shapes, polygons=base.polygons,
                     component_labels=base.component_labels, component_names=base.component_names,
                     metadata=base.metadata)


def test_names_resolve_by_meaning() -> None:
    assert split_half_of("browInnerUp_L") == ("browInnerUp", "left")
    assert split_half_of("eyeBlink_L") is None  # a sided ARKit shape, not a half
    w, missing = rig_weights({"browInnerUp": 0.7, "mouthSmileLeft": 0.4, "tongueOut": 1.0},
                             ["browInnerUp_L", "browInnerUp_R", "mouthSmile_L", "jawOpen"])
    assert w == {"browInnerUp_L": 0.7, "browInnerUp_R": 0.7, "mouthSmile_L": 0.4}
    assert missing == ["tongueOut"]


def test_wrinkles_fit_on_a_studio_rig_and_match_the_arkit_head(caplog: pytest.LogCaptureFixture) -> None:
    head = workbench.load_sample("head")
    rig = studio_rig(head)
    poses, skipped = example_poses_for(rig.shape_names)
    assert set(poses) == set(EXAMPLE_POSES) and not skipped
    fit_sample_wrinkles(head)
    rig.handles.set(head.handles.value)  # the same handles, so the shells are the same
    fit_sample_wrinkles(rig)
    assert rig.wrinkles.example_names == head.wrinkles.example_names
    np.testing.assert_allclose(rig.wrinkles.pose_space.train_values, head.wrinkles.pose_space.train_values,
                               atol=1e-5)
    # a brow drag wrinkles the rig's forehead as it does the head's
    for m in (head, rig):
        m.move_handle(m.handles.names.index("brows_L_2"), [0.0, 0.05, 0.0])
    np.testing.assert_allclose(rig.evaluate(), head.evaluate(), atol=1e-5)


def test_a_rig_that_cannot_express_the_poses_gets_a_clear_report() -> None:
    head = workbench.load_sample("head")
    keep = [s for s in head.shapes if s.name.startswith("eye")]
    eyes_only = FaceModel(head.vertices, head.faces, keep, component_labels=head.component_labels,
                          component_names=head.component_names, metadata=head.metadata)
    _, skipped = example_poses_for(eyes_only.shape_names)
    assert "brow_raise" in skipped and "browInnerUp" in skipped["brow_raise"]
    with pytest.raises(ValueError, match="example poses can be built on this rig"):
        fit_sample_wrinkles(eyes_only)


def test_partly_expressible_poses_are_built_and_reported(caplog: pytest.LogCaptureFixture) -> None:
    head = workbench.load_sample("head")
    no_funnel = FaceModel(head.vertices, head.faces, [s for s in head.shapes if s.name != "mouthFunnel"],
                          component_labels=head.component_labels, component_names=head.component_names,
                          metadata=head.metadata)
    with caplog.at_level(logging.WARNING):
        fit_sample_wrinkles(no_funnel)
    assert "pucker" in no_funnel.wrinkles.example_names
    assert "mouthFunnel" in caplog.text
