"""Corrective (combination) shapes (issue 15, item 9): weight = product of the drivers' weights.

Evaluated in the one pipeline (live, ``evaluate_at``, after ``set_time``),
following the drivers' keys, exported exactly at every frame (glTF read back
through its accessors and sampler, USD, CSV, point caches), undoable, saved.
"""

from __future__ import annotations

import csv
import json
import struct
import zipfile
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from grid_meshes import grid_polygons

import workbench
from workbench.animation.tracks import Timeline
from workbench.core.families import derive_weights
from workbench.core.manifest import WorkbenchFileError
from workbench.core.shapes import ModelError
from workbench.export import export
from workbench.export.encoding import MeshEncoding
from workbench.methods.shapes.correctives import Correctives
from workbench.model import BlendShape, FaceModel, ModelMetadata

DATA = Path(__file__).parent / "data" / "main_v2"


def _bump(V: np.ndarray, cx: float, cy: float) -> np.ndarray:
    return np.exp(-((V[:, 0] - cx) ** 2 + (V[:, 1] - cy) ** 2) / 2.0)


def grid_model() -> FaceModel:
    """8 x 8 quads (cm); a, b (range [-1, 1]) and c move bumps; ab is a corrective of a and b."""
    V, polys = grid_polygons(8, 8)
    n = len(V)
    d = {}
    for name, (cx, cy, axis) in {"a": (2, 2, 2), "b": (6, 6, 2), "c": (2, 6, 1), "ab": (4, 4, 2)}.items():
        d[name] = np.zeros((n, 3), np.float32)
        d[name][:, axis] = _bump(V, cx, cy)
    m = FaceModel(V, None, [BlendShape("a", d["a"]), BlendShape("b", d["b"], slider_min=-1.0, slider_max=1.0),
                            BlendShape("c", d["c"])], polygons=polys, metadata=ModelMetadata(name="grid", units="cm"))
    m.shape_tools.add_corrective("ab", ["a", "b"], delta=d["ab"])
    return m


def keyed(model: FaceModel, interp: str = "bezier", fps: float = 10.0) -> Timeline:
    """Keys on the drivers (b's Bézier overshoots its range) and on c; none on the corrective."""
    tl = Timeline(fps=fps, start=0.0, end=2.0)
    for t, a, b in ((0.0, 0.0, -0.5), (0.7, 1.0, 0.9), (1.3, 0.4, 1.0), (2.0, 0.3, 0.0)):
        tl = tl.add_key("weights/a", t, a, interpolation=interp).add_key("weights/b", t, b, interpolation=interp)
    tl = tl.add_key("weights/c", 0.0, 0.0, interpolation=interp).add_key("weights/c", 1.5, 1.0, interpolation=interp)
    if interp == "bezier":
        tl = tl.set_tangents("weights/b", 1, in_tangent=3.0, out_tangent=3.0)
    model.timeline.set(tl)
    return tl


# ------------------------------------------------------------------ glTF read-back
def _accessor(g: pygltflib.GLTF2, blob: bytes, i: int) -> np.ndarray:
    a = g.accessors[i]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[a.type]
    dt = {pygltflib.FLOAT: "<f4", pygltflib.UNSIGNED_INT: "<u4"}[a.componentType]
    out = np.zeros((a.count, width), dt)
    if a.bufferView is not None:
        bv = g.bufferViews[a.bufferView]
        out[:] = np.frombuffer(blob, dt, a.count * width, bv.byteOffset + (a.byteOffset or 0)).reshape(-1, width)
    if a.sparse is not None:
        sp = a.sparse
        ib, vb = g.bufferViews[sp.indices.bufferView], g.bufferViews[sp.values.bufferView]
        idx = np.frombuffer(blob, "<u4", sp.count, ib.byteOffset + (sp.indices.byteOffset or 0))
        out[idx] = np.frombuffer(blob, dt, sp.count * width, vb.byteOffset + (sp.values.byteOffset or 0)).reshape(-1, width)
    return out


def play_glb(path: Path, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str], str]:
    """What a glTF player shows at ``times`` (float32 seconds): positions (F, n, 3), weights (F, m), names, mode."""
    g = pygltflib.GLTF2.load(str(path))
    blob = g.binary_blob()
    prim = g.meshes[0].primitives[0]
    P = _accessor(g, blob, prim.attributes.POSITION).astype(np.float64)
    T = np.stack([_accessor(g, blob, t["POSITION"]) for t in prim.targets]).astype(np.float64)
    m = len(prim.targets)
    anim = g.animations[0]
    (s,) = [anim.samplers[c.sampler] for c in anim.channels if c.target.path == "weights"]
    ts = _accessor(g, blob, s.input)[:, 0].astype(np.float64)
    out = _accessor(g, blob, s.output)[:, 0].astype(np.float64)
    if s.interpolation == "CUBICSPLINE":
        o = out.reshape(-1, 3, m)
        a, v, b = o[:, 0], o[:, 1], o[:, 2]
    else:
        v = out.reshape(-1, m)
    W = np.empty((len(times), m))
    for f, t in enumerate(np.asarray(times, np.float32).astype(np.float64)):
        if t <= ts[0] or t >= ts[-1]:
            W[f] = v[0] if t <= ts[0] else v[-1]
            continue
        k = int(np.searchsorted(ts, t, side="right") - 1)
        dt = ts[k + 1] - ts[k]
        u = (t - ts[k]) / dt
        if s.interpolation == "STEP":
            W[f] = v[k]
        elif s.interpolation == "LINEAR":
            W[f] = (1 - u) * v[k] + u * v[k + 1]
        else:
            W[f] = ((2 * u**3 - 3 * u**2 + 1) * v[k] + (u**3 - 2 * u**2 + u) * dt * b[k]
                    + (-2 * u**3 + 3 * u**2) * v[k + 1] + (u**3 - u**2) * dt * a[k + 1])
    return P[None] + np.einsum("fm,mnc->fnc", W, T), W, g.meshes[0].extras["targetNames"], s.interpolation


def _product(model: FaceModel, t: float) -> float:
    """The corrective's weight computed by hand from the keyed drivers at ``t``."""
    smp = model.tracks.evaluate(t).weights
    a = min(max(smp["a"], 0.0), 1.0)
    b = min(max(smp["b"], -1.0), 1.0)
    return min(max(a * b, 0.0), 1.0)


# ------------------------------------------------------------------ the weight
def test_weight_is_the_product_of_the_drivers_live() -> None:
    m = grid_model()
    assert m.shape_tools.correctives == {"ab": ("a", "b")}
    m.set_weights({"a": 0.5, "b": 0.8, "ab": 0.9})  # the corrective's own weight is ignored
    assert m.weights["ab"] == 0.5 * 0.8 and m.view().weights["ab"] == 0.5 * 0.8
    assert m.weight_vector()[m.shape_names.index("ab")] == np.float32(0.4)
    want = m.vertices32 + sum(np.float32(m.weights[s.name]) * s.delta for s in m.shapes)
    np.testing.assert_allclose(m.evaluate(), want, atol=1e-6)
    # clamped into the corrective's own range; a negative driver gives 0 here
    m.set_weight("b", -1.0)
    assert m.weights["ab"] == 0.0
    m.set_shape_range("ab", -1.0, 1.0)
    assert m.weights["ab"] == -0.5
    # a muted driver plays nothing, so neither does its combination
    m.set_shape_mute("a", True)
    assert m.weights["ab"] == 0.0
    m.set_shape_mute("a", False)
    m.set_shape_mute("ab", True)
    assert m.weight_vector()[m.shape_names.index("ab")] == 0.0


def test_drivers_change_the_evaluation_at_once() -> None:
    # the blend's cache is keyed on the rules too: new drivers, new mesh, no stale cache
    m = grid_model()
    m.set_weights({"a": 1.0, "b": 0.5, "c": 0.25})
    first = m.evaluate().copy()
    m.shape_tools.set_drivers("ab", ["a", "c"])
    assert m.weights["ab"] == 0.25
    assert not np.array_equal(m.evaluate(), first)
    assert m.undo() == "Drive ab by a × c"
    np.testing.assert_array_equal(m.evaluate(), first)
    m.redo()
    assert m.weights["ab"] == 0.25


@pytest.mark.parametrize("interp", ["bezier", "linear", "step"])
def test_keyed_drivers_drive_the_corrective_at_every_frame(interp: str) -> None:
    m = grid_model()
    tl = keyed(m, interp)
    k = m.shape_names.index("ab")
    times = np.concatenate([tl.frame_times(), np.linspace(-0.3, 2.3, 27)])
    enc = MeshEncoding(m, tl)
    W = enc.weights(times)
    for f, t in enumerate(times):
        w = m.view_at(t).weights["ab"]
        assert w == _product(m, t), t
        assert W[f, k] == w, t  # the exporters' weights, bit for bit
        m.set_time(t)
        assert m.weights["ab"] == w
        np.testing.assert_array_equal(m.evaluate(), m.evaluate_at(t))
    assert np.ptp(W[:, k]) > 0.5  # it really moves


def test_derive_weights_is_one_function_for_floats_and_frames() -> None:
    m = grid_model()
    rng = np.random.default_rng(0)
    cols = {"a": rng.random(50), "b": rng.uniform(-1, 1, 50), "c": rng.random(50), "ab": np.zeros(50)}
    many = derive_weights(m.shapes, cols, m.view().slots)
    for f in range(50):
        one = derive_weights(m.shapes, {k: float(v[f]) for k, v in cols.items()}, m.view().slots)
        assert one["ab"] == many["ab"][f]


# ------------------------------------------------------------------ edits and errors
def test_add_corrective_defaults_to_an_empty_shape_to_sculpt() -> None:
    m = workbench.load_sample("head")
    before = m.evaluate().copy()
    shape = m.shape_tools.add_corrective(None, ["jawOpen", "mouthSmileLeft"])
    assert shape.name == "jawOpen_mouthSmileLeft" and not np.any(shape.delta)
    assert m.shape_tools.drivers(shape.name) == ("jawOpen", "mouthSmileLeft")
    np.testing.assert_array_equal(m.evaluate(), before)
    assert m.undo() == "Add corrective jawOpen_mouthSmileLeft"
    assert "jawOpen_mouthSmileLeft" not in m.shape_names and not m.shape_tools.correctives
    m.redo()
    assert m.shape_tools.is_corrective("jawOpen_mouthSmileLeft")


def test_corrective_from_the_handles_sculpt() -> None:
    m = workbench.load_sample("head")
    m.handles.add(100)
    m.handles.add(2000)
    m.set_weights({"jawOpen": 1.0, "mouthSmileLeft": 0.5})
    m.handles.set_offsets([[0.0, 0.02, 0.0], [0.01, 0.0, 0.0]])
    sculpted = m.evaluate().copy()
    fix = m.layer_displacement("handles")
    m.shape_tools.add_corrective("fix", ["jawOpen", "mouthSmileLeft"], delta="handles")
    assert not np.any(m.handles.offsets)
    np.testing.assert_allclose(m.shape("fix").delta * np.float32(0.5), fix, atol=1e-7)  # played at 1 x 0.5
    np.testing.assert_allclose(m.evaluate(), sculpted, atol=2e-6)  # the look is kept
    assert m.undo() == "Add corrective fix"
    np.testing.assert_array_equal(m.evaluate(), sculpted)
    m.set_weight("mouthSmileLeft", 0.0)
    with pytest.raises(ModelError, match="needs the drivers posed"):
        m.shape_tools.add_corrective("fix", ["jawOpen", "mouthSmileLeft"], delta="handles")


def test_errors_name_the_argument() -> None:
    m = grid_model()
    st = m.shape_tools
    with pytest.raises(ModelError, match="drivers of 'x' must name different shapes, got \\['a', 'a'\\]"):
        st.add_corrective("x", ["a", "a"])
    with pytest.raises(ModelError, match="must name two or more shapes"):
        st.add_corrective("x", ["a"])
    with pytest.raises(ModelError, match="must be a list of two or more shape names"):
        st.add_corrective("x", "a")
    with pytest.raises(KeyError, match="drivers: no blendshape named 'zz'"):
        st.add_corrective("x", ["a", "zz"])
    with pytest.raises(ModelError, match="'ab' is a corrective itself"):
        st.add_corrective("x", ["ab", "c"])
    with pytest.raises(ModelError, match="name: a blendshape named 'c' already exists"):
        st.add_corrective("c", ["a", "b"])
    with pytest.raises(ModelError, match="delta must be \\(81, 3\\)"):
        st.add_corrective("x", ["a", "b"], delta=np.zeros((3, 3)))
    with pytest.raises(ModelError, match="a corrective cannot drive itself"):
        st.set_drivers("c", ["c", "a"])
    with pytest.raises(ModelError, match="'a' drives the corrective 'ab', so it cannot be one"):
        st.set_drivers("a", ["b", "c"])
    with pytest.raises(KeyError, match="'c' is not a corrective"):
        st.remove_corrective("c")
    with pytest.raises(ModelError, match="'a' drives the corrective 'ab'"):
        st.split("a")
    with pytest.raises(ModelError, match="correctives: expected a Correctives mapping"):
        m.set_slot("correctives", 3, "x")
    assert m.undo() == "Add corrective ab"  # nothing above was recorded


def test_remove_corrective_and_undo_redo_identities() -> None:
    m = grid_model()
    tl = keyed(m, "linear")
    m.timeline.set(tl.add_key("weights/ab", 0.0, 0.3))  # a stray key on the corrective: ignored, then removed
    at = np.stack([m.evaluate_at(t) for t in tl.frame_times()])
    m.shape_tools.remove_corrective("ab")
    assert "ab" not in m.shape_names and "ab" not in m.tracks.weight_tracks
    assert m.undo() == "Remove corrective ab"
    np.testing.assert_array_equal(np.stack([m.evaluate_at(t) for t in tl.frame_times()]), at)
    m.redo()
    m.undo()
    m.shape_tools.remove_corrective("ab", keep_shape=True)
    assert "ab" in m.shape_names and not m.shape_tools.correctives
    m.undo()
    assert m.shape_tools.correctives == {"ab": ("a", "b")}


def test_split_and_mirror_carry_the_drivers() -> None:
    m = workbench.load_sample("head")
    st = m.shape_tools
    st.add_corrective(None, ["jawOpen", "mouthSmileLeft"], delta=0.1 * m.shape("jawOpen").delta)
    assert st.mirror("jawOpen_mouthSmileLeft") == "jawOpen_mouthSmileRight"
    assert st.drivers("jawOpen_mouthSmileRight") == ("jawOpen", "mouthSmileRight")
    st.add_corrective("jawBrow", ["jawOpen", "browInnerUp"], delta=0.1 * m.shape("browInnerUp").delta)
    left, right = st.split("jawBrow")
    assert st.drivers(left) == st.drivers(right) == ("jawOpen", "browInnerUp") and "jawBrow" not in st.correctives
    m.set_weights({"jawOpen": 0.5, "browInnerUp": 0.5})
    assert m.weights[left] == m.weights[right] == 0.25


def test_a_removed_driver_leaves_the_corrective_silent_until_undone(tmp_path: Path) -> None:
    m = grid_model()
    m.set_weights({"a": 1.0, "b": 1.0})
    assert m.weights["ab"] == 1.0
    m.remove_shape("b")  # the core's plain edit does not know about correctives
    assert m.weights["ab"] == 0.0
    m.save(tmp_path / "m.fwb")
    assert not workbench.load(tmp_path / "m.fwb").shape_tools.correctives  # dangling rules are not saved
    m.undo()
    assert m.weights["ab"] == 1.0


# ------------------------------------------------------------------ files
def test_save_load_round_trip(tmp_path: Path) -> None:
    m = grid_model()
    keyed(m, "bezier")
    m.shape_tools.add_corrective("abc", ["a", "b", "c"], delta=0.5 * m.shape("ab").delta)
    m.save(tmp_path / "m.fwb")
    back = workbench.load(tmp_path / "m.fwb")
    assert back.shape_tools.correctives == {"ab": ("a", "b"), "abc": ("a", "b", "c")}
    assert isinstance(back.slot("correctives"), Correctives) and not back.can_undo
    for t in (0.0, 0.35, 1.0, 1.9):
        np.testing.assert_array_equal(back.evaluate_at(t), m.evaluate_at(t))
    with zipfile.ZipFile(tmp_path / "m.fwb") as zf:
        manifest = json.loads(zf.read("manifest.json"))
    assert manifest["correctives"] == [{"name": "ab", "drivers": ["a", "b"]},
                                       {"name": "abc", "drivers": ["a", "b", "c"]}]


@pytest.mark.parametrize("name", ["handles", "regions_paint", "timeline"])
def test_older_files_load_without_correctives(name: str) -> None:
    model = workbench.load(DATA / f"{name}.fwb")
    assert not model.shape_tools.correctives


@pytest.mark.parametrize(
    ("entries", "field", "problem"),
    [
        ([{"name": "zz", "drivers": ["a", "b"]}], "correctives[0].name", "'zz' is not a saved shape"),
        ([{"name": "ab", "drivers": ["a", "zz"]}], "correctives[0].drivers[1]", "'zz' is not a saved shape"),
        ([{"name": "ab", "drivers": ["a"]}], "correctives[0].drivers", "two or more"),
        ([{"name": "ab", "drivers": ["a", "a"]}], "correctives[0].drivers[1]", "duplicate name 'a'"),
        ([{"name": "ab", "drivers": ["a", "b"]}, {"name": "c", "drivers": ["ab", "b"]}],
         "correctives[1].drivers", "'ab' is a corrective itself"),
        ({"ab": ["a", "b"]}, "correctives", "expected a list"),
        ([{"name": "ab"}], "correctives[0]", "drivers"),
    ],
)
def test_malformed_correctives_are_refused_naming_the_field(
    tmp_path: Path, entries: object, field: str, problem: str
) -> None:
    m = grid_model()
    m.save(tmp_path / "ok.fwb")
    bad = tmp_path / "bad.fwb"
    with zipfile.ZipFile(tmp_path / "ok.fwb") as zin, zipfile.ZipFile(bad, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "manifest.json":
                man = json.loads(data)
                man["correctives"] = entries
                data = json.dumps(man).encode()
            zout.writestr(info.filename, data)
    with pytest.raises(WorkbenchFileError) as exc:
        workbench.load(bad)
    assert field in str(exc.value) and problem in str(exc.value)


# ------------------------------------------------------------------ exports
@pytest.mark.parametrize("interp", ["bezier", "linear", "step"])
def test_gltf_plays_the_corrective_exactly_at_every_frame(tmp_path: Path, interp: str) -> None:
    m = grid_model()
    tl = keyed(m, interp)
    m.paint.flood("c", 0.3, vertices=np.arange(30, 50))  # shape targets scaled by (1 - painted weight)
    (path,) = export(m, tl, tmp_path / "c.glb")
    frames = tl.frame_times()
    got, W, names, mode = play_glb(path, frames)
    assert mode == {"bezier": "CUBICSPLINE", "linear": "LINEAR", "step": "STEP"}[interp]
    k = names.index("ab")
    want_w = np.array([m.view_at(t).weights["ab"] for t in frames])
    np.testing.assert_array_equal(W[:, k], want_w.astype(np.float32))  # the product, as float32
    want = np.stack([m.evaluate_at(t) for t in frames]).astype(np.float64) * m.metadata.metres_per_unit
    err = np.abs(got - want).max()
    assert err <= 2e-8, err  # float32 round-off of cm -> m positions
    if interp == "step":
        # a product of steps is a step: exact between frames too
        mids = frames[:-1] + 0.37 / tl.fps
        _, Wm, _, _ = play_glb(path, mids)
        np.testing.assert_array_equal(Wm[:, k], [np.float32(m.view_at(t).weights["ab"]) for t in mids])


def test_gltf_baked_and_unkeyed_drivers(tmp_path: Path) -> None:
    m = grid_model()
    tl = keyed(m, "bezier")
    (path,) = export(m, tl, tmp_path / "b.glb", bake=True)
    frames = tl.frame_times()
    got, _W, _names, mode = play_glb(path, frames)
    assert mode == "LINEAR"
    want = np.stack([m.evaluate_at(t) for t in frames]) * m.metadata.metres_per_unit
    np.testing.assert_allclose(got, want, atol=2e-8, rtol=0)
    # drivers not keyed: the corrective is a constant weight, no animation needed for it
    m2 = grid_model()
    m2.set_weights({"a": 0.5, "b": 0.6})
    m2.timeline.set(Timeline(fps=4.0, start=0.0, end=1.0).add_key("weights/c", 0.0, 0.0).add_key("weights/c", 1.0, 1.0))
    (p2,) = export(m2, m2.tracks, tmp_path / "u.glb")
    got2, W2, names2, _ = play_glb(p2, m2.tracks.frame_times())
    assert np.all(W2[:, names2.index("ab")] == np.float32(0.3))
    np.testing.assert_allclose(got2, np.stack([m2.evaluate_at(t) for t in m2.tracks.frame_times()]) * 0.01,
                               atol=2e-8, rtol=0)


def test_gltf_on_the_sample_head(tmp_path: Path) -> None:
    m = workbench.load_sample("head")
    m.shape_tools.add_corrective(None, ["jawOpen", "mouthSmileLeft"], delta=0.3 * m.shape("mouthSmileLeft").delta)
    tl = Timeline(fps=24.0, start=0.0, end=2.0)
    for t, j, s in ((0.0, 0.0, 0.3), (1.0, 1.0, 0.9), (2.0, 0.2, 0.1)):
        tl = tl.add_key("weights/jawOpen", t, j).add_key("weights/mouthSmileLeft", t, s)
    m.timeline.set(tl)
    (path,) = export(m, tl, tmp_path / "head.glb")
    frames = tl.frame_times()
    got, _W, names, mode = play_glb(path, frames)
    assert mode == "CUBICSPLINE"
    want = np.stack([m.evaluate_at(t) for t in frames]).astype(np.float64) * m.metadata.metres_per_unit
    assert np.abs(got - want).max() <= 2e-7  # dm -> m in float32
    # between frames the cubic Hermite follows the product closely
    mids = frames[:-1] + 0.5 / tl.fps
    _, Wm, _, _ = play_glb(path, mids)
    k = names.index("jawOpen_mouthSmileLeft")
    assert np.abs(Wm[:, k] - [m.view_at(t).weights[names[k]] for t in mids]).max() < 1e-5


def test_csv_usd_and_point_caches(tmp_path: Path) -> None:
    m = grid_model()
    tl = keyed(m, "bezier", fps=5.0)
    frames = tl.frame_times()
    (p,) = export(m, tl, tmp_path / "w.csv")
    with open(p, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["time", "a", "b", "c", "ab"]
    col = np.array([float(r[4]) for r in rows[1:]])
    np.testing.assert_array_equal(col, [float(f"{m.view_at(t).weights['ab']:.9g}") for t in frames])
    assert np.ptp(col) > 0.5
    data = export(m, tl, tmp_path / "f.pc2")[0].read_bytes()
    _, _, points, _, _, samples = struct.unpack_from("<12siiffi", data, 0)
    pc2 = np.frombuffer(data, "<f4", offset=32).reshape(samples, points, 3)
    want = np.stack([m.evaluate_at(t) for t in frames]) * m.metadata.metres_per_unit
    np.testing.assert_allclose(pc2, want, atol=1e-7)
    pxr = pytest.importorskip("pxr")
    (u,) = export(m, tl, tmp_path / "f.usda")
    stage = pxr.Usd.Stage.Open(str(u))
    anim = pxr.UsdSkel.Animation(stage.GetPrimAtPath("/Face/Skel/Anim"))
    names = list(anim.GetBlendShapesAttr().Get())
    k = names.index("ab")
    for t in frames:
        w = anim.GetBlendShapeWeightsAttr().Get(pxr.Usd.TimeCode(t * tl.fps))
        assert w[k] == np.float32(m.view_at(t).weights["ab"])
