"""Animation import (CSV, glTF) and the CSV/glTF round trips with our exporters."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from workbench.animation.importers import (
    AnimationImportError,
    map_shape_names,
    read_animation,
    read_gltf_animation,
    read_weights_csv,
    reduce_keys,
)
from workbench.animation.tracks import Timeline
from workbench.core.polygons import Polygons
from workbench.export import ExportError, export
from workbench.export.gltf import _glb_bytes, build_gltf
from workbench.model import BlendShape, FaceModel

SHAPES = ["eyeBlinkLeft", "jawOpen", "mouthSmileRight"]


@pytest.fixture
def arkit_model() -> FaceModel:
    """A flat 2x2-quad grid (9 vertices) with three random ARKit-named shapes."""
    xs, ys = np.meshgrid(np.arange(3.0), np.arange(3.0))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(9)], axis=1)
    polys = Polygons.from_lists(
        [[j * 3 + i, j * 3 + i + 1, j * 3 + i + 4, j * 3 + i + 3] for j in range(2) for i in range(2)]
    )
    rng = np.random.default_rng(0)
    shapes = [BlendShape(n, rng.normal(size=(9, 3)).astype(np.float32)) for n in SHAPES]
    return FaceModel(V, None, shapes, polygons=polys)


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# ------------------------------------------------------------------------- names
def test_names_map_exactly_then_by_arkit_meaning():
    m = map_shape_names(["EyeBlinkLeft", "jawOpen", "eyeBlink_R", "HeadYaw"], SHAPES)
    assert m == {"EyeBlinkLeft": "eyeBlinkLeft", "jawOpen": "jawOpen", "eyeBlink_R": None, "HeadYaw": None}


def test_two_columns_for_one_shape_is_an_error():
    with pytest.raises(AnimationImportError, match="both map to shape 'jawOpen'"):
        map_shape_names(["JawOpen", "jaw_open"], SHAPES)


# ------------------------------------------------------------------ Live Link Face
LLF = (
    "Timecode,BlendShapeCount,EyeBlinkLeft,JawOpen,MouthSmileRight,HeadYaw\n"
    "00:00:01:00.000,3,0.1,0.0,0.5,0.3\n"
    "00:00:01:01.000,3,0.2,0.5,0.5,0.3\n"
    "00:00:01:02.500,3,0.3,1.0,0.5,0.3\n"
)


def test_live_link_face_csv(tmp_path):
    tl = read_weights_csv(write(tmp_path, "take.csv", LLF), SHAPES)
    assert tl.fps == 60
    jaw = tl.tracks["weights/jawOpen"]
    assert jaw.times == pytest.approx([0.0, 1 / 60, 2.5 / 60])
    assert jaw.values[:, 0] == pytest.approx([0.0, 0.5, 1.0])
    assert jaw.interpolations == ("linear",) * 3
    assert set(tl.weight_tracks) == set(SHAPES)  # HeadYaw is skipped, not a shape
    assert tl.evaluate(0.5 / 60).weights["jawOpen"] == pytest.approx(0.25)


def test_key_reduction_drops_redundant_rows(tmp_path):
    tl = read_weights_csv(write(tmp_path, "take.csv", LLF), SHAPES, tolerance=1e-6)
    assert len(tl.tracks["weights/mouthSmileRight"]) == 2  # constant
    assert len(tl.tracks["weights/eyeBlinkLeft"]) == 3  # not collinear in time (uneven spacing)


# ---------------------------------------------------------------- plain CSV errors
def test_unknown_shape_column_names_the_column(tmp_path):
    p = write(tmp_path, "w.csv", "time,jawOpen,browWiggle\n0,0,0\n")
    with pytest.raises(AnimationImportError, match=r"w.csv: unknown shape names in columns \['browWiggle'\]"):
        read_weights_csv(p, SHAPES)
    tl = read_weights_csv(p, SHAPES, on_unknown="ignore")
    assert list(tl.weight_tracks) == ["jawOpen"]


def test_nan_weight_names_line_and_column(tmp_path):
    p = write(tmp_path, "w.csv", "time,jawOpen,eyeBlinkLeft\n0,0,0\n0.1,nan,0\n")
    with pytest.raises(AnimationImportError, match=r"line 3, column 'jawOpen': value is nan"):
        read_weights_csv(p, SHAPES)


def test_non_numeric_value(tmp_path):
    p = write(tmp_path, "w.csv", "time,jawOpen\n0,abc\n")
    with pytest.raises(AnimationImportError, match=r"line 2, column 'jawOpen': 'abc' is not a number"):
        read_weights_csv(p, SHAPES)


def test_non_increasing_time_names_the_line(tmp_path):
    p = write(tmp_path, "w.csv", "time,jawOpen\n0,0\n0.5,1\n0.5,0\n")
    with pytest.raises(AnimationImportError, match=r"line 4: time 0.5 s does not come after line 3"):
        read_weights_csv(p, SHAPES)


def test_ragged_row_and_missing_time_column(tmp_path):
    with pytest.raises(AnimationImportError, match="line 2: has 1 fields, the header has 2"):
        read_weights_csv(write(tmp_path, "a.csv", "time,jawOpen\n0\n"), SHAPES)
    with pytest.raises(AnimationImportError, match="header must start with a time column"):
        read_weights_csv(write(tmp_path, "b.csv", "jawOpen,time\n0,0\n"), SHAPES)
    with pytest.raises(AnimationImportError, match="is not HH:MM:SS:FF"):
        read_weights_csv(write(tmp_path, "c.csv", "Timecode,JawOpen\n1:2,0\n"), SHAPES)


def test_milliseconds_column_and_fps_estimate(tmp_path):
    p = write(tmp_path, "ms.csv", "time_ms,jaw_open\n0,0\n40,1\n80,0\n")
    tl = read_weights_csv(p, SHAPES)
    assert tl.tracks["weights/jawOpen"].times == pytest.approx([0, 0.04, 0.08])
    assert tl.fps == pytest.approx(25.0)


def test_face_cap_text(tmp_path):
    head = "0,0,0,0,0,0,0,0,0,0"
    text = (
        "info,Face Cap\n"
        "bs,eyeBlink_L,jawOpen,mouthSmile_R\n"
        f"k,1000,{head},0.1,0.2,0.3\n"
        f"k,1033,{head},0.4,0.5,0.6\n"
    )
    tl = read_weights_csv(write(tmp_path, "cap.txt", text), SHAPES)
    blink = tl.tracks["weights/eyeBlinkLeft"]
    assert blink.times == pytest.approx([0.0, 0.033])
    assert blink.values[:, 0] == pytest.approx([0.1, 0.4])


# ------------------------------------------------------------------ key reduction
def test_reduce_keys_bound_holds_and_lines_collapse():
    t = np.linspace(0, 2, 121)
    v = np.sin(3 * t)
    keep = reduce_keys(t, v, 0.01)
    assert keep[0] == 0 and keep[-1] == 120 and keep.size < 40
    assert np.abs(np.interp(t, t[keep], v[keep]) - v).max() <= 0.01
    assert reduce_keys(t, 2 * t + 1, 1e-9).tolist() == [0, 120]


# --------------------------------------------------------------------- round trips
def _keyed(fps=30.0) -> Timeline:
    tl = Timeline(fps=fps, start=0.0, end=1.0)
    for s, vals in zip(SHAPES, [(0, 1, 0.25), (0.5, 0.0, 1.0), (0, 0.3, 0.3)], strict=True):
        for t, v in zip((0.0, 0.5, 1.0), vals, strict=True):
            tl = tl.add_key("weights/" + s, t, v)
    return tl


@pytest.mark.parametrize("style", ["plain", "livelink"])
def test_csv_round_trip(arkit_model, tmp_path, style):
    tl = _keyed()
    (p,) = export(arkit_model, tl, tmp_path / "w.csv", style=style)
    back = read_animation(p, arkit_model.shape_names, fps=30.0)
    times = tl.frame_times()
    assert back.weight_matrix(SHAPES, times) == pytest.approx(tl.weight_matrix(SHAPES, times), abs=1e-8)
    # in between frames the import is linear between the frame samples
    assert len(back.tracks["weights/jawOpen"]) == times.size


def test_gltf_animation_round_trip_is_exact_for_bezier_keys(arkit_model, tmp_path):
    tl = _keyed()
    tl = tl.set_tangents("weights/jawOpen", 1, in_tangent=-2.0, out_tangent=3.0)
    export(arkit_model, tl, tmp_path / "a.glb")
    back = read_gltf_animation(tmp_path / "a.glb", arkit_model.shape_names)
    t = np.linspace(0, 1, 41)
    assert back.weight_matrix(SHAPES, t) == pytest.approx(tl.weight_matrix(SHAPES, t), abs=1e-6)
    assert back.tracks["weights/jawOpen"].interpolations[0] == "bezier"


def test_gltf_linear_and_step_keys_come_back_as_such(arkit_model, tmp_path):
    tl = Timeline().add_key("weights/jawOpen", 0.0, 0.0, interpolation="step")
    tl = tl.add_key("weights/jawOpen", 1.0, 1.0, interpolation="step")
    export(arkit_model, tl, tmp_path / "s.glb")
    back = read_gltf_animation(tmp_path / "s.glb", SHAPES)
    assert back.tracks["weights/jawOpen"].interpolations == ("step", "step")
    lin = tl.set_interpolation("weights/jawOpen", None, "linear")
    export(arkit_model, lin, tmp_path / "l.gltf")
    assert read_animation(tmp_path / "l.gltf", SHAPES).evaluate(0.25).weights["jawOpen"] == pytest.approx(0.25)


def _broken_glb(arkit_model, tmp_path: Path, times=None, value=None) -> Path:
    gltf, data = build_gltf(arkit_model, _keyed().set_interpolation("weights/jawOpen", None, "linear"))
    buf = bytearray(data)
    s = gltf.animations[0].samplers[0]
    if times is not None:
        bv = gltf.bufferViews[gltf.accessors[s.input].bufferView]
        buf[bv.byteOffset : bv.byteOffset + 4 * len(times)] = struct.pack(f"<{len(times)}f", *times)
    if value is not None:
        bv = gltf.bufferViews[gltf.accessors[s.output].bufferView]
        buf[bv.byteOffset : bv.byteOffset + 4] = struct.pack("<f", value)
    p = tmp_path / "broken.glb"
    p.write_bytes(_glb_bytes(gltf, bytes(buf)))
    return p


def test_gltf_non_increasing_times_are_reported(arkit_model, tmp_path):
    p = _broken_glb(arkit_model, tmp_path, times=[0.0, 0.5, 0.5])
    with pytest.raises(AnimationImportError, match=r"samplers\[0\].input: key 2 time 0.5 s does not come after key 1"):
        read_gltf_animation(p, SHAPES)


def test_gltf_nan_weights_are_reported(arkit_model, tmp_path):
    p = _broken_glb(arkit_model, tmp_path, value=float("nan"))
    with pytest.raises(AnimationImportError, match="NaN/inf"):
        read_gltf_animation(p, SHAPES)


def test_gltf_unknown_target_names(arkit_model, tmp_path):
    export(arkit_model, _keyed(), tmp_path / "a.glb")
    with pytest.raises(AnimationImportError, match=r"unknown shape names in columns \['mouthSmileRight'\]"):
        read_gltf_animation(tmp_path / "a.glb", ["eyeBlinkLeft", "jawOpen"])


def test_gltf_file_without_animation(arkit_model, tmp_path):
    export(arkit_model, Timeline(), tmp_path / "still.glb")
    with pytest.raises(AnimationImportError, match="no animations"):
        read_gltf_animation(tmp_path / "still.glb", SHAPES)


def test_export_rejects_unknown_shapes_and_suffix(arkit_model, tmp_path):
    with pytest.raises(ExportError, match="unknown shape names"):
        export(arkit_model, Timeline().add_key("weights/nope", 0.0, 1.0), tmp_path / "a.glb")
    with pytest.raises(ExportError, match="cannot tell the format"):
        export(arkit_model, _keyed(), tmp_path / "a.xyz")
    with pytest.raises(ExportError, match=">= 0"):
        export(arkit_model, Timeline().add_key("weights/jawOpen", -1.0, 1.0).add_key("weights/jawOpen", 1.0, 0.0), tmp_path / "n.glb")


def test_failed_export_leaves_no_file(arkit_model, tmp_path):
    with pytest.raises(ExportError):
        export(arkit_model, Timeline().add_key("weights/jawOpen", -1.0, 1.0).add_key("weights/jawOpen", 1.0, 0.0), tmp_path / "n.glb")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------- several meshes, unnamed targets
def _two_animated_nodes(arkit_model, *, differ: bool, named: bool = True) -> tuple[object, bytes]:
    """The exported file with a second node drawing the same mesh, animated by its own channel."""
    import copy

    gltf, data = build_gltf(arkit_model, _keyed().set_interpolation("weights/jawOpen", None, "linear"))
    buf = bytearray(data)
    ch = next(c for c in gltf.animations[0].channels if c.target.path == "weights")
    node = copy.deepcopy(gltf.nodes[ch.target.node])
    gltf.nodes.append(node)
    gltf.scenes[0].nodes.append(len(gltf.nodes) - 1)
    sampler = copy.deepcopy(gltf.animations[0].samplers[ch.sampler])
    if differ:  # a copy of the output accessor with its first value changed
        acc = copy.deepcopy(gltf.accessors[sampler.output])
        bv = copy.deepcopy(gltf.bufferViews[acc.bufferView])
        start = bv.byteOffset
        chunk = bytearray(buf[start : start + bv.byteLength])
        chunk[0:4] = struct.pack("<f", 0.123)
        while len(buf) % 4:
            buf.append(0)
        bv.byteOffset = len(buf)
        buf += chunk
        gltf.buffers[0].byteLength = len(buf)
        gltf.bufferViews.append(bv)
        acc.bufferView = len(gltf.bufferViews) - 1
        acc.byteOffset = 0
        gltf.accessors.append(acc)
        sampler.output = len(gltf.accessors) - 1
    gltf.animations[0].samplers.append(sampler)
    new = copy.deepcopy(ch)
    new.target.node = len(gltf.nodes) - 1
    new.sampler = len(gltf.animations[0].samplers) - 1
    gltf.animations[0].channels.append(new)
    if not named:
        for m in gltf.meshes:
            m.extras = {}
    return gltf, bytes(buf)


def test_gltf_meshes_that_share_a_shape_and_key_it_alike_load(arkit_model, tmp_path):
    gltf, data = _two_animated_nodes(arkit_model, differ=False)
    p = tmp_path / "two.glb"
    p.write_bytes(_glb_bytes(gltf, data))
    tl = read_gltf_animation(p, SHAPES)
    t = np.linspace(0, 1, 11)
    ref = _keyed().set_interpolation("weights/jawOpen", None, "linear")
    assert tl.weight_matrix(SHAPES, t) == pytest.approx(ref.weight_matrix(SHAPES, t), abs=1e-6)


def test_gltf_meshes_that_key_a_shared_shape_differently_are_refused(arkit_model, tmp_path):
    gltf, data = _two_animated_nodes(arkit_model, differ=True)
    p = tmp_path / "two.glb"
    p.write_bytes(_glb_bytes(gltf, data))
    with pytest.raises(AnimationImportError, match=r"channels\[\d+\]: animates '\w+' differently"):
        read_gltf_animation(p, SHAPES)


def test_gltf_animation_without_target_names_uses_the_readers_names(arkit_model, tmp_path):
    gltf, data = build_gltf(arkit_model, _keyed().set_interpolation("weights/jawOpen", None, "linear"))
    for m in gltf.meshes:
        m.extras = {}
    p = tmp_path / "unnamed.glb"
    p.write_bytes(_glb_bytes(gltf, data))
    names = [f"target_{i}" for i in range(len(gltf.meshes[0].primitives[0].targets))]
    tl = read_gltf_animation(p, names, on_unknown="ignore")
    jaw = SHAPES.index("jawOpen")
    ref = _keyed().set_interpolation("weights/jawOpen", None, "linear")
    t = np.linspace(0, 1, 5)
    got = tl.weight_matrix(names, t)[:, jaw]
    assert got == pytest.approx(ref.weight_matrix(SHAPES, t)[:, jaw], abs=1e-6)


def test_reduce_keys_jointly_is_the_union_over_columns_each_with_its_tolerance() -> None:
    from workbench.animation.importers import reduce_keys_jointly

    t = np.arange(6.0)
    straight = 2.0 * t  # a line: only its ends
    kinked = np.array([0.0, 1.0, 2.0, 0.0, 0.0, 0.0])  # a corner at 2 and at 3
    V = np.stack([straight, kinked], axis=1)
    assert reduce_keys_jointly(t, V, 0.1).tolist() == [0, 2, 3, 5]
    # a tolerance wider than the corners: only the ends, for that column
    assert reduce_keys_jointly(t, V, [0.1, 5.0]).tolist() == [0, 5]
