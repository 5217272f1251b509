"""Our .glb files under the Khronos glTF-Validator and three.js (GLTFLoader + AnimationMixer)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from consumer_timelines import (
    SAMPLE_TIMES,
    expected_points,
    expression_timeline,
    played_weights,
    with_handle_keys,
    with_head_pose,
)

from workbench.export import export


def _interp(path) -> list[str]:
    from pygltflib import GLTF2

    g = GLTF2.load(str(path))
    return [s.interpolation for a in g.animations for s in a.samplers]


@pytest.fixture(scope="module")
def files(head, head_with_handles, tmp_path_factory):
    d = tmp_path_factory.mktemp("gltf")
    out = {
        "linear": export(head, expression_timeline("linear"), d / "linear.glb")[0],
        "cubic": export(head, expression_timeline("cubic"), d / "cubic.glb")[0],
        "baked": export(head, expression_timeline("cubic"), d / "baked.glb", bake=True)[0],
        "pose": export(head, with_head_pose(expression_timeline("linear")), d / "pose.glb")[0],
        "handles": export(
            head_with_handles, with_handle_keys(expression_timeline("cubic")), d / "handles.glb"
        )[0],
    }
    return out


def test_samplers_are_what_we_claim(files):
    assert _interp(files["linear"]) == ["LINEAR"]
    assert _interp(files["cubic"]) == ["CUBICSPLINE"]
    assert _interp(files["baked"]) == ["LINEAR"]
    assert _interp(files["pose"]) == ["LINEAR", "LINEAR", "LINEAR"]  # weights, translation, rotation


def test_validator_reports_no_errors_and_no_warnings(node_tools, files):
    report = node_tools("validate.mjs", *map(str, files.values()))
    for path, r in report.items():
        assert (r["numErrors"], r["numWarnings"]) == (0, 0), (path, r["messages"])


def test_target_names_are_the_shape_names(node_tools, head, files):
    # the validator does not check extras; three.js turns them into morphTargetDictionary
    got = node_tools("three_sample.mjs", str(files["linear"]), "[0]")
    assert got["targetNames"] == head.shape_names


@pytest.mark.parametrize("kind", ["linear", "cubic"])
def test_three_js_mixer_weights_equal_timeline(node_tools, head, files, kind):
    tl = expression_timeline(kind)
    got = node_tools("three_sample.mjs", str(files[kind]), json.dumps(SAMPLE_TIMES))
    ours = played_weights(head, tl, SAMPLE_TIMES)
    theirs = np.array(got["weights"])
    assert theirs.shape == ours.shape
    np.testing.assert_allclose(theirs, ours, atol=1e-6, rtol=0)
    # the curves are not trivially constant
    assert np.ptp(theirs[:, head.shape_names.index("eyeBlinkLeft")]) > 0.5
    # and match Timeline.evaluate, the public per-time API, clamped to the slider range
    # as the workbench plays it (the user tangents of "cubic" overshoot 1 after t=0.75)
    for i, t in enumerate(SAMPLE_TIMES):
        for name, w in tl.evaluate(t).weights.items():
            assert theirs[i, head.shape_names.index(name)] == pytest.approx(min(max(w, 0.0), 1.0), abs=1e-6)


def test_clamped_weights_stay_cubic_and_exact_between_frames(node_tools, head, files):
    # eyeBlinkLeft leaves [0, 1] in the "cubic" timeline: knots at the crossings keep the
    # sampler CUBICSPLINE and the clamped curve exact at any time, not only at frames
    tl = expression_timeline("cubic")
    raw = tl.tracks["weights/eyeBlinkLeft"].sample(np.linspace(0.75, 1.5, 301))[:, 0]
    assert raw.max() > 1.01  # the test would be vacuous otherwise
    times = np.linspace(0.75, 1.5, 37).tolist()
    got = np.array(node_tools("three_sample.mjs", str(files["cubic"]), json.dumps(times))["weights"])
    np.testing.assert_allclose(got, played_weights(head, tl, times), atol=1e-6, rtol=0)


def test_baked_file_matches_at_frames(node_tools, head, files):
    tl = expression_timeline("cubic")
    frames = tl.frame_times()[::7].tolist()
    got = node_tools("three_sample.mjs", str(files["baked"]), json.dumps(frames))
    np.testing.assert_allclose(np.array(got["weights"]), played_weights(head, tl, frames), atol=1e-6)


def test_three_js_head_pose_and_positions(node_tools, head, files):
    tl = with_head_pose(expression_timeline("linear"))
    times = [0.0, 0.4, 1.0, 1.3, 2.0]
    got = node_tools("three_sample.mjs", str(files["pose"]), json.dumps(times), "positions")
    P = tl.head_pose.sample(times)
    mpu = head.metadata.metres_per_unit
    np.testing.assert_allclose(np.array(got["position"]), P[:, :3] * mpu, atol=1e-6)
    q = np.array(got["quaternion"])
    sign = np.sign(np.sum(q * P[:, 3:], axis=1, keepdims=True))
    np.testing.assert_allclose(q * sign, P[:, 3:], atol=1e-6)
    theirs = np.array(got["points"]).reshape(len(times), -1, 3)
    np.testing.assert_allclose(theirs, expected_points(head, tl, times), atol=1e-6)


def test_handle_layer_targets_reproduce_the_shell_deformation(node_tools, head_with_handles, files):
    m = head_with_handles
    tl = with_handle_keys(expression_timeline("cubic"))
    times = [0.0, 0.3, 0.75, 1.0, 1.6, 2.0]
    got = node_tools("three_sample.mjs", str(files["handles"]), json.dumps(times), "positions")
    names = got["targetNames"]
    assert names[: len(m.shape_names)] == m.shape_names
    # the three keys are rest, o1 and 0.5 o1 with flat tangents: one basis target, not 3 x 3
    assert names[len(m.shape_names) :] == ["handle:basis0"]
    w = np.array(got["weights"])[:, len(m.shape_names) :]
    assert w.min() >= -1e-6 and w.max() <= 1 + 1e-6  # Blender clamps shape keys to [0, 1]
    theirs = np.array(got["points"]).reshape(len(times), -1, 3)
    ours = expected_points(m, tl, times)
    np.testing.assert_allclose(theirs, ours, atol=1e-6)
    # the handle layer really moves the face in this test
    assert np.abs(ours[3] - expected_points(m, expression_timeline("cubic"), [1.0])[0]).max() > 1e-3
