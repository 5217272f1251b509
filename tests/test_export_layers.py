"""Exports reproduce ``FaceModel.evaluate_at`` with every editing layer (core, no consumers).

A tiny hand-made model (an 8 x 8 quad grid, three local shapes) gets every
layer the workbench has: region weights, handles (static or keyed), paint of
a saved expression and of a blendshape, and a registered layer that is not
linear in the weights (it must be baked). The compact encoding
(:class:`workbench.export.encoding.MeshEncoding`) must give ``evaluate_at``
at any time, the glTF weights sampler must play the clamped weights exactly,
and every export file gets the permissions of a normal new file.
"""

from __future__ import annotations

import json
import logging
import os
import struct
from pathlib import Path

import numpy as np
import pytest
from grid_meshes import grid_polygons

from workbench.animation.curves import Key, Track
from workbench.animation.tracks import Timeline
from workbench.core.pipeline import FunctionLayer
from workbench.export import ExportResult, export
from workbench.export.encoding import MeshEncoding, crossing_times, curve_range
from workbench.export.gltf import Curve, merge_curves
from workbench.methods.handles.facet import HANDLES_TRACK as HANDLES
from workbench.methods.paint.painting import Brush
from workbench.methods.regions.blend import RegionWeights
from workbench.methods.regions.tracks import region_track_name
from workbench.model import BlendShape, FaceModel, ModelMetadata

TIMES = np.linspace(-0.2, 2.2, 49)  # before, inside and after the keys, on and off frames


def _bump(V: np.ndarray, cx: float, cy: float) -> np.ndarray:
    return np.exp(-((V[:, 0] - cx) ** 2 + (V[:, 1] - cy) ** 2) / 2.0)


def make_model() -> FaceModel:
    """8 x 8 quads in z = 0, units cm; shapes a (bump), b (bump + shear, range [-1, 1]), c (masked)."""
    V, polys = grid_polygons(8, 8)
    n = V.shape[0]
    a = np.zeros((n, 3), np.float32)
    a[:, 2] = _bump(V, 2, 2)
    b = np.zeros((n, 3), np.float32)
    b[:, 2] = _bump(V, 6, 6)
    b[:, 0] = 0.3 * _bump(V, 6, 6)
    c = np.zeros((n, 3), np.float32)
    c[:, 1] = 0.5 * _bump(V, 2, 6)
    return FaceModel(
        V,
        None,
        [
            BlendShape("a", a),
            BlendShape("b", b, slider_min=-1.0, slider_max=1.0),
            BlendShape("c", c, vertex_mask=np.linspace(0, 1, n)),
        ],
        polygons=polys,
        metadata=ModelMetadata(name="grid", units="cm"),
    )


def keyed(model: FaceModel) -> None:
    """Three weight keys (Bézier); b's user tangent overshoots its slider range."""
    for t, w in ((0.0, {"a": 0.0, "b": -0.5}), (1.0, {"a": 1.0, "b": 0.9}), (2.0, {"a": 0.3, "b": 0.0})):
        model.set_weights(w)
        model.timeline.key_weights(t, ["a", "b"])
    model.timeline.set(model.tracks.set_tangents("weights/b", 1, in_tangent=3.0, out_tangent=3.0))


def add_layers(model: FaceModel, *, keyed_handles: bool, regions: bool = True) -> None:
    model.handles.add(20)
    model.handles.add(50)
    model.handles.set_offsets([[0.0, 0.0, 0.4], [0.2, -0.1, 0.0]])
    if keyed_handles:
        model.handles.key(0.0, "linear")
        model.handles.set_offsets([[0.1, 0.0, -0.3], [0.0, 0.0, 0.0]])
        model.handles.key(1.5)
        model.handles.set_offsets([[0.0, 0.2, 0.1], [0.1, 0.1, 0.1]])
        model.handles.key(2.0)
    model.set_weights({"a": 0.8, "c": 1.0})
    model.expressions.save("smile")
    model.set_weights({"a": 0.0, "c": 0.25})  # c stays unkeyed at 0.25
    model.paint_stroke("smile", [30, 31], Brush(radius=2.0, opacity=0.7))
    model.paint.flood("b", 0.4, vertices=np.arange(60, 70))
    if regions:
        st = model.segment_regions(0.25, levels=1, min_region_size=0.0)
        rw = RegionWeights.from_global(model, st.regions, 0, [0.5, -0.2, 0.7])
        model.regions.set_weights(rw.with_region(0, {"a": 1.0}))


def wobble(model: FaceModel) -> np.ndarray | None:
    """A registered layer quadratic in the weights (like wrinkles: not linear)."""
    w = model.weights["a"]
    d = np.zeros((model.n_vertices, 3), np.float32)
    d[:, 2] = (w * w) * 0.1 * np.sin(model.vertices[:, 0])
    return d if w else None


def _evaluate_at(model: FaceModel, times) -> np.ndarray:
    return np.stack([model.evaluate_at(float(t)) for t in times])


@pytest.mark.parametrize("keyed_handles", [False, True])
def test_encoding_reproduces_evaluate_at_with_every_layer(keyed_handles):
    m = make_model()
    add_layers(m, keyed_handles=keyed_handles)
    keyed(m)
    m.register_layer(FunctionLayer("wobble", wobble))
    enc = MeshEncoding(m, m.tracks)
    kinds = {r.name: r.encoding for r in enc.layers}
    # the wrinkles and enhance layers are there in every model; unfitted / off they are written as nothing
    assert kinds == {"regions": "linear", "handles": "linear", "paint": "linear", "wrinkles": "inactive",
                     "enhance": "inactive", "wobble": "baked"}
    assert enc.baked_layers == ("wobble",)
    # every layer really moves the face here (else the test would prove little)
    for name in ("regions", "handles", "paint", "wobble"):
        d = m.layers_at(0.6, [name])[name]
        assert d is not None and np.abs(d).max() > 1e-3, name
    np.testing.assert_allclose(enc.points(TIMES), _evaluate_at(m, TIMES), atol=2e-6, rtol=0)
    if keyed_handles:
        # three keys with different poses, linear then Bézier: far fewer targets than 3 x h = 6
        (ctl,) = enc.controls
        assert ctl.layer == "handles" and 1 <= ctl.targets.shape[0] <= 6
        w = enc.control_weights(ctl, np.linspace(-1, 3, 401))
        assert w.min() >= -1e-9 and w.max() <= 1 + 1e-9
        assert w.min() < 1e-6 and w.max() > 1 - 1e-6  # mapped onto the full [0, 1]
    else:
        assert enc.controls[0].targets.shape[0] == 0  # the static offsets are in the constant target


def test_encoding_with_a_timeline_other_than_the_models(tmp_path):
    m = make_model()
    add_layers(m, keyed_handles=False)
    tl = Timeline(fps=24.0, start=0.0, end=1.0).add_key("weights/b", 0.0, 0.2).add_key("weights/b", 1.0, -0.7)
    tl = tl.add_key(HANDLES, 0.0, np.zeros((2, 3))).add_key(HANDLES, 1.0, [[0.3, 0.0, 0.0], [0.0, 0.0, 0.2]])
    enc = MeshEncoding(m, tl)
    want = np.stack([m.evaluate_at(t, tl) for t in TIMES])
    np.testing.assert_allclose(enc.points(TIMES), want, atol=2e-6, rtol=0)
    # and the model's own animation is untouched by exporting another one
    before = m.evaluate().copy()
    export(m, tl, tmp_path / "x.glb")
    np.testing.assert_array_equal(m.evaluate(), before)


def test_paint_layer_is_the_documented_linear_form():
    # paint = sum_e W_e D_e - (sum_e W_e) (blend + handles), as the encoding assumes
    m = make_model()
    add_layers(m, keyed_handles=False, regions=False)
    m.set_weights({"a": 0.4, "b": -0.3})
    mix = m.paint
    P = mix.mix.total(m.n_vertices).astype(np.float64)
    C = sum(w.astype(np.float64)[:, None] * (m.expressions[e].displacement if e in m.expressions
                                              else m.shape(e).effective_delta()) for e, w in mix.items())
    base = m.blended().astype(np.float64) - m.vertices + m.handles.displacement()
    np.testing.assert_allclose(m.paint.displacement(), C - P[:, None] * base, atol=1e-6)


def test_unkeyed_handles_are_one_target_in_the_glb(tmp_path):
    from pygltflib import GLTF2

    m = make_model()
    add_layers(m, keyed_handles=False, regions=False)
    keyed(m)
    res = export(m, m.tracks, tmp_path / "f.glb")
    names = GLTF2.load(str(res[0])).meshes[0].extras["targetNames"]
    assert names == ["a", "b", "c", "layer:static"]
    assert isinstance(res, ExportResult) and res.by_encoding("linear") == ["handles", "paint"]


def test_baked_layer_is_reported_and_logged(tmp_path, caplog):
    from pygltflib import GLTF2

    m = make_model()
    keyed(m)
    m.register_layer(FunctionLayer("wobble", wobble))
    with caplog.at_level(logging.INFO, logger="workbench.export"):
        res = export(m, m.tracks.replace(fps=4.0), tmp_path / "f.glb")
    assert res.by_encoding("baked") == ["wobble"]
    assert any(r.levelname == "WARNING" and "wobble" in r.message for r in caplog.records)
    names = GLTF2.load(str(res[0])).meshes[0].extras["targetNames"]
    # 9 frames at 4 fps over 2 s; a = 0 at frame 0, so the layer is zero there
    assert names[3:] == [f"layer:frame{f:04d}" for f in range(1, 9)]
    res = export(m, m.tracks, tmp_path / "f.csv")
    assert res.by_encoding("omitted") == ["wobble"]


def test_region_weights_made_before_a_shape_was_added_export_as_the_global_blend():
    """Stale region weights (the shape list changed since) play the global blend in every path."""
    m = make_model()
    add_layers(m, keyed_handles=False)
    keyed(m)
    st = m.regions.state
    assert st.weights is not None and np.abs(m.layers_at(0.5, ["regions"])["regions"]).max() > 0
    m.add_shape("late", np.full((m.n_vertices, 3), 0.01, np.float32))
    assert tuple(m.regions.state.weights.shape_names) != tuple(m.shape_names)
    assert m.layers_at(0.5, ["regions"])["regions"] is None
    enc = MeshEncoding(m, m.tracks)
    assert {r.name: r.encoding for r in enc.layers}["regions"] == "inactive"
    np.testing.assert_allclose(enc.points(TIMES), _evaluate_at(m, TIMES), atol=2e-6, rtol=0)


def test_keyed_region_weights_are_baked_per_frame_and_reported(tmp_path):
    from pygltflib import GLTF2

    m = make_model()
    add_layers(m, keyed_handles=True)
    keyed(m)
    r0 = m.regions.regions.names[0][0]
    tl = m.tracks.add_key(region_track_name(0, r0), 0.0, [0.0, 0.5, 1.0], interpolation="linear")
    m.timeline.set(tl.add_key(region_track_name(0, r0), 2.0, [1.0, -0.5, 0.0], interpolation="linear"))
    enc = MeshEncoding(m, m.tracks)
    kinds = {r.name: r.encoding for r in enc.layers}
    assert kinds == {"regions": "baked", "handles": "linear", "paint": "linear", "wrinkles": "inactive",
                     "enhance": "inactive"}
    assert enc.baked_layers == ("regions",)
    # the keyed region weights replace the static ones and vary over time
    d0, d2 = (m.layers_at(t, ["regions"])["regions"] for t in (0.0, 2.0))
    assert d0 is not None and d2 is not None and np.abs(d2 - d0).max() > 1e-2
    # baked through layers_at: exact at any time, not only at frames
    np.testing.assert_allclose(enc.points(TIMES), _evaluate_at(m, TIMES), atol=2e-6, rtol=0)
    tl = m.tracks.replace(fps=4.0)
    res = export(m, tl, tmp_path / "r.glb")
    (rep,) = [r for r in res.layers if r.name == "regions"]
    assert rep.encoding == "baked" and rep.detail.startswith("region weights keyed on level 0 (1 region tracks)")
    names = GLTF2.load(str(res[0])).meshes[0].extras["targetNames"]
    assert [n for n in names if n.startswith("layer:frame")] == [f"layer:frame{f:04d}" for f in range(9)]
    want = np.stack([m.evaluate_at(t, tl) for t in tl.frame_times()]) * m.metadata.metres_per_unit
    np.testing.assert_allclose(_read_pc2(export(m, tl, tmp_path / "r.pc2")[0]), want, atol=1e-7)


def test_constant_extra_layer_is_folded_into_the_static_target(tmp_path):
    from pygltflib import GLTF2

    m = make_model()
    keyed(m)
    m.register_layer(FunctionLayer("lift", lambda model: np.full((model.n_vertices, 3), 0.01, np.float32)))
    res = export(m, m.tracks, tmp_path / "f.glb")
    assert GLTF2.load(str(res[0])).meshes[0].extras["targetNames"] == ["a", "b", "c", "layer:static"]
    assert res.by_encoding("baked") == []


# ------------------------------------------------------------------ weights sampler
def _play(data, times: np.ndarray) -> np.ndarray:
    """Evaluate a glTF sampler (spec Appendix C) at ``times``."""
    T = data.times.astype(np.float32).astype(np.float64)
    V = data.values
    out = np.empty((times.size, V.shape[1]))
    for i, t in enumerate(times):
        if t <= T[0]:
            out[i] = V[0]
            continue
        if t >= T[-1]:
            out[i] = V[-1]
            continue
        k = int(np.searchsorted(T, t, side="right") - 1)
        dt = T[k + 1] - T[k]
        u = (t - T[k]) / dt
        if data.interpolation == "STEP":
            out[i] = V[k]
        elif data.interpolation == "LINEAR":
            out[i] = (1 - u) * V[k] + u * V[k + 1]
        else:
            h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
            h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
            out[i] = (h00 * V[k] + h10 * dt * data.out_tangents[k] + h01 * V[k + 1]
                      + h11 * dt * data.in_tangents[k + 1])
    return out


@pytest.mark.parametrize("interp", ["bezier", "linear"])
def test_clamped_weights_are_exact_in_the_sampler(interp):
    peak = 0.9 if interp == "bezier" else 1.3  # Bézier: the user tangent overshoots 1
    tr = Track("weights/b", (Key(0.0, -0.5, interp), Key(1.0, peak, interp), Key(2.0, -1.4, interp)))
    tr = Track(tr.name, (tr.keys[0], tr.keys[1].replace(in_tangent=np.array(3.0), out_tangent=np.array(3.0),
                                                        tangent_mode="user"), tr.keys[2]))
    raw = tr.sample(np.linspace(0, 2, 2001))[:, 0]
    assert raw.max() > 1.0 and raw.min() < -1.0
    data = merge_curves([Curve(tr, clamp=(-1.0, 1.0))])
    assert data is not None and data.interpolation == ("CUBICSPLINE" if interp == "bezier" else "LINEAR")
    ts = np.linspace(-0.5, 2.5, 3001)
    np.testing.assert_allclose(_play(data, ts)[:, 0], np.clip(tr.sample(ts)[:, 0], -1, 1), atol=1e-6)
    assert len(crossing_times(tr, (-1.0, 1.0))) >= 2


def test_curve_range_is_exact():
    rng = np.random.default_rng(3)
    keys = tuple(Key(float(t), rng.normal(size=(2, 3)), interp)
                 for t, interp in zip([0.0, 0.4, 1.1, 1.5, 2.0], ["bezier", "linear", "bezier", "step", "bezier"],
                                      strict=True))
    tr = Track(HANDLES, keys)
    Q = rng.normal(size=(6, 3))
    lo, hi = curve_range(tr, Q)
    dense = tr.sample(np.linspace(-1, 3, 40001)) @ Q
    np.testing.assert_allclose(lo, dense.min(axis=0), atol=1e-6)
    np.testing.assert_allclose(hi, dense.max(axis=0), atol=1e-6)


# ------------------------------------------------------------------ formats and permissions
def _read_pc2(p: Path) -> np.ndarray:
    data = p.read_bytes()
    _, _, points, _, _, samples = struct.unpack_from("<12siiffi", data, 0)
    return np.frombuffer(data, "<f4", offset=32).reshape(samples, points, 3)


def test_point_caches_and_obj_play_every_layer(tmp_path):
    m = make_model()
    add_layers(m, keyed_handles=True)
    keyed(m)
    m.register_layer(FunctionLayer("wobble", wobble))
    tl = m.tracks.replace(fps=5.0)
    want = np.stack([m.evaluate_at(t, tl) for t in tl.frame_times()]) * m.metadata.metres_per_unit
    np.testing.assert_allclose(_read_pc2(export(m, tl, tmp_path / "f.pc2")[0]), want, atol=1e-7)
    data = export(m, tl, tmp_path / "f.mdd")[0].read_bytes()
    np.testing.assert_allclose(np.frombuffer(data, ">f4", offset=8 + 4 * 11).reshape(11, -1, 3), want, atol=1e-7)
    objs = export(m, tl.replace(end=0.4), tmp_path / "seq" / "f.obj")
    v = [[float(x) for x in line.split()[1:]] for line in objs[2].read_text().splitlines() if line.startswith("v ")]
    np.testing.assert_allclose(np.array(v), want[2], atol=1e-7)


def test_csv_weights_are_what_the_model_plays(tmp_path):
    m = make_model()
    keyed(m)
    tl = m.tracks
    (p,) = export(m, tl, tmp_path / "w.csv")
    rows = np.loadtxt(p, delimiter=",", skiprows=1)
    for row in rows:
        m.set_time(row[0])
        np.testing.assert_allclose(row[1:], [m.weights[n] for n in m.shape_names], atol=1e-7)


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_exports_get_normal_file_permissions(tmp_path, umask):
    m = make_model()
    add_layers(m, keyed_handles=False, regions=False)
    keyed(m)
    old = os.umask(umask)
    try:
        written: list[Path] = []
        for name in ("f.glb", "f.gltf", "f.pc2", "f.mdd", "f.csv", "seq/f.obj"):
            written += export(m, m.tracks.replace(fps=2.0), tmp_path / name)
        try:
            import pxr  # noqa: F401
        except ImportError:
            pass
        else:
            for name in ("f.usda", "f.usdc"):
                written += export(m, m.tracks, tmp_path / name)
    finally:
        os.umask(old)
    assert len(written) >= 10
    for p in written:
        assert p.stat().st_mode & 0o777 == 0o666 & ~umask, (p.name, oct(p.stat().st_mode))
    assert not [p for p in tmp_path.rglob(".*tmp*")]  # no temporary files left


def test_report_is_json_friendly(tmp_path):
    m = make_model()
    add_layers(m, keyed_handles=True, regions=False)
    keyed(m)
    res = export(m, m.tracks, tmp_path / "f.glb")
    json.dumps([r.__dict__ for r in res.layers])
    assert [r.name for r in res.layers] == ["regions", "handles", "paint", "wrinkles", "enhance"]
