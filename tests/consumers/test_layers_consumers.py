"""Edited heads (moved handles, painted expression, regions, wrinkles, enhanced) played by real consumers.

The reference is always ``model.evaluate_at(t)`` — what the workbench shows at
time ``t`` with every editing layer — in metres. The consumers: the Khronos
glTF-Validator, three.js (GLTFLoader + AnimationMixer, CPU morphing in Node),
UsdSkel's own evaluation, and minimal PC2/MDD readers written from the layouts.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from consumer_timelines import expected_points
from edited_models import (
    SAMPLE_TIMES,
    enhanced_head,
    fitted_head,
    painted_head,
    regions_head,
    replayed_head,
    wrinkled_head,
)
from test_usd_consumer import usdskel_points

from workbench.export import export

MODELS = {"painted": painted_head, "regions": regions_head, "wrinkles": wrinkled_head, "enhanced": enhanced_head,
          "replayed": replayed_head}
#: three.js sample times per model: the wrinkle and enhance layers are baked per frame, so frames only
THREE_TIMES = {"painted": SAMPLE_TIMES, "regions": SAMPLE_TIMES, "wrinkles": [0.0, 0.2, 0.5, 0.8, 1.0],
               "enhanced": [0.0, 0.2, 0.5, 0.8, 1.0], "replayed": [0.0, 0.2, 0.5, 0.8, 1.0]}
FRAMES = [0, 6, 11, 15, 24, 30]


@pytest.fixture(scope="module")
def models():
    return {name: build() for name, build in MODELS.items()}


@pytest.fixture(scope="module")
def files(models, tmp_path_factory):
    d = tmp_path_factory.mktemp("layers")
    out = {}
    for name, m in models.items():
        for suffix in (".glb", ".usda", ".pc2", ".mdd"):
            out[name, suffix] = export(m, m.tracks, d / f"{name}{suffix}")
    return out


def test_the_layers_really_move_the_face(models):
    # without them the consumer checks below would not prove the layers are exported
    for name, layers in (("painted", ["handles", "paint"]), ("regions", ["regions", "handles", "paint"]),
                         ("wrinkles", ["wrinkles"]), ("enhanced", ["enhance"]), ("replayed", ["handles", "wrinkles"])):
        m = models[name]
        for layer, d in m.layers_at(0.5, layers).items():
            assert d is not None and np.abs(d).max() * m.metadata.metres_per_unit > 5e-4, (name, layer)


def test_reports_say_how_each_layer_was_written(files):
    enc = {name: {r.name: r.encoding for r in files[name, ".glb"].layers} for name in MODELS}
    # every model has the wrinkles and enhance layers; unfitted / switched off they are written as nothing
    assert enc["painted"] == {"regions": "inactive", "handles": "linear", "paint": "linear", "wrinkles": "inactive",
                              "enhance": "inactive"}
    assert enc["regions"] == {"regions": "linear", "handles": "linear", "paint": "linear", "wrinkles": "inactive",
                              "enhance": "inactive"}
    assert enc["wrinkles"]["wrinkles"] == "baked"
    assert enc["enhanced"]["enhance"] == "baked"
    assert enc["replayed"]["handles"] == "linear" and enc["replayed"]["wrinkles"] == "baked"
    assert {r.name: r.encoding for r in files["painted", ".pc2"].layers}["paint"] == "baked"


def test_validator_reports_no_errors_and_no_warnings(node_tools, files):
    paths = [str(files[name, ".glb"][0]) for name in MODELS]
    report = node_tools("validate.mjs", *paths)
    for path, r in report.items():
        assert (r["numErrors"], r["numWarnings"]) == (0, 0), (path, r["messages"])


def test_compact_targets(node_tools, models, files):
    m = models["painted"]
    got = node_tools("three_sample.mjs", str(files["painted", ".glb"][0]), "[0]")
    # the 71 unkeyed handles + the paint are ONE constant target (was 3 x 71 dense targets)
    assert got["targetNames"] == [*m.shape_names, "layer:static"]
    assert files["painted", ".glb"][0].stat().st_size < 2_000_000
    got = node_tools("three_sample.mjs", str(files["regions", ".glb"][0]), "[0]")
    extra = got["targetNames"][len(m.shape_names):]
    assert extra[0] == "layer:static" and 1 <= len(extra) - 1 <= 9  # 3 keys: at most 3 x 3 basis targets
    assert all(n.startswith("handle:basis") for n in extra[1:])


@pytest.mark.parametrize("name", list(MODELS))
def test_three_js_positions_equal_evaluate_at(node_tools, models, files, name):
    m = models[name]
    times = THREE_TIMES[name]
    got = node_tools("three_sample.mjs", str(files[name, ".glb"][0]), json.dumps(times), "positions")
    theirs = np.array(got["points"]).reshape(len(times), -1, 3)
    ours = expected_points(m, m.tracks, times)
    np.testing.assert_allclose(theirs, ours, atol=1e-5, rtol=0)
    # the animation is not trivially constant
    assert np.abs(ours[2] - ours[0]).max() > 1e-3


@pytest.mark.parametrize("name", list(MODELS))
def test_usdskel_points_equal_evaluate_at(usd, models, files, name):
    m = models[name]
    _, pts = usdskel_points(usd, files[name, ".usda"][0], FRAMES)
    # UsdSkel evaluates the mesh; a keyed head pose (the replay's) is on the root prim's xform
    ours = expected_points(m, m.tracks, np.array(FRAMES) / m.tracks.fps, head_pose=False)
    np.testing.assert_allclose(pts, ours, atol=1e-5, rtol=0)


def test_baked_usd_points_equal_evaluate_at(usd, models, tmp_path):
    m = models["regions"]
    (p,) = export(m, m.tracks, tmp_path / "baked.usdc", bake=True)
    stage = usd.Usd.Stage.Open(str(p))
    attr = usd.UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
    ours = expected_points(m, m.tracks, np.array(FRAMES) / m.tracks.fps)
    for i, f in enumerate(FRAMES):
        np.testing.assert_allclose(np.array(attr.Get(usd.Usd.TimeCode(f))), ours[i], atol=1e-5, rtol=0)


@pytest.mark.parametrize("name", list(MODELS))
def test_point_caches_equal_evaluate_at(models, files, name):
    m = models[name]
    ours = expected_points(m, m.tracks, m.tracks.frame_times())
    data = files[name, ".pc2"][0].read_bytes()
    _, _, points, _, _, samples = struct.unpack_from("<12siiffi", data, 0)
    pc2 = np.array(struct.unpack_from(f"<{samples * points * 3}f", data, 32)).reshape(samples, points, 3)
    np.testing.assert_allclose(pc2, ours, atol=1e-5, rtol=0)
    data = files[name, ".mdd"][0].read_bytes()
    frames, points = struct.unpack_from(">ii", data, 0)
    mdd = np.array(struct.unpack_from(f">{frames * points * 3}f", data, 8 + 4 * frames)).reshape(frames, points, 3)
    np.testing.assert_allclose(mdd, ours, atol=1e-5, rtol=0)


# ------------------------------------------------------------------ a keyed marker fit
@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    m = fitted_head()
    d = tmp_path_factory.mktemp("fit")
    return m, {suffix: export(m, m.tracks, d / f"fit{suffix}") for suffix in (".glb", ".usda")}


def test_keyed_marker_fit_glb_validates_and_reports_baked_regions(node_tools, fitted):
    _, files = fitted
    assert {r.name: r.encoding for r in files[".glb"].layers}["regions"] == "baked"
    path = str(files[".glb"][0])
    report = node_tools("validate.mjs", path)
    assert (report[path]["numErrors"], report[path]["numWarnings"]) == (0, 0), report[path]["messages"]


def test_three_js_plays_the_keyed_marker_fit(node_tools, fitted):
    m, files = fitted
    fps = m.tracks.fps
    frames = [0, 3, 4, 9]  # the region layer is baked per frame: exact at frames
    times = [f / fps for f in frames]
    got = node_tools("three_sample.mjs", str(files[".glb"][0]), json.dumps(times), "positions")
    theirs = np.array(got["points"]).reshape(len(times), -1, 3)
    ours = expected_points(m, m.tracks, times)
    np.testing.assert_allclose(theirs, ours, atol=1e-5, rtol=0)
    # the fitted regions and the head turn really move the face between these frames
    assert np.abs(ours[3] - ours[0]).max() > 1e-3


def test_usdskel_plays_the_keyed_marker_fit(usd, fitted):
    m, files = fitted
    frames = [0, 4, 9]
    _, pts = usdskel_points(usd, files[".usda"][0], frames)
    # UsdSkel evaluates the mesh; the head pose is on the root prim's xform
    ours = expected_points(m, m.tracks, np.array(frames) / m.tracks.fps, head_pose=False)
    np.testing.assert_allclose(pts, ours, atol=1e-5, rtol=0)
