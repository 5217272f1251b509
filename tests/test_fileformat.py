"""Saved workbench files: round trip, atomicity, checksums, schema versions, bad input."""

from __future__ import annotations

import copy
import hashlib
import io
import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import workbench
from workbench.fileformat import SCHEMA_VERSION, WorkbenchFileError, read_manifest, save_model
from workbench.model import FaceModel, HandleSet

DATA = Path(__file__).parent / "data"


def _rewrite(src: Path, dst: Path, edit) -> None:
    """Copy a zip, letting ``edit(name, bytes) -> bytes`` change members."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, edit(info.filename, zin.read(info)))


def _edit_manifest(src: Path, dst: Path, change) -> None:
    def edit(name: str, data: bytes) -> bytes:
        if name != "manifest.json":
            return data
        m = json.loads(data)
        change(m)
        return json.dumps(m).encode()

    _rewrite(src, dst, edit)


@pytest.fixture
def saved(tiny_model: FaceModel, tmp_path: Path) -> Path:
    tiny_model.set_weights({"up": 0.5, "left": -0.25})
    tiny_model.set_shape_mask("left", np.linspace(0, 1, 9))
    tiny_model.handles.set(HandleSet([4], [[0.0, 0.0, 0.1]], ("centre",), [-1]))
    p = tmp_path / "face.fwb"
    tiny_model.save(p)
    return p


def test_round_trip_is_exact(tiny_model: FaceModel, saved: Path) -> None:
    m = workbench.load(saved)
    np.testing.assert_array_equal(m.vertices, tiny_model.vertices)
    np.testing.assert_array_equal(m.faces, tiny_model.faces)
    assert m.polygons.equals(tiny_model.polygons)
    np.testing.assert_array_equal(m.deltas, tiny_model.deltas)
    assert m.shape_names == tiny_model.shape_names
    assert dict(m.weights) == dict(tiny_model.weights)
    np.testing.assert_array_equal(m.shape("left").vertex_mask, tiny_model.shape("left").vertex_mask)
    assert m.shape("left").slider_min == -1.0
    np.testing.assert_array_equal(m.handles.offsets, tiny_model.handles.offsets)
    assert m.handles.names == ("centre",)
    np.testing.assert_array_equal(m.evaluate(), tiny_model.evaluate())
    assert not m.can_undo  # a loaded file starts a fresh history


def test_manifest_is_documented_json(saved: Path) -> None:
    m = read_manifest(saved)
    assert m["format"] == "face-workbench" and m["schema_version"] == SCHEMA_VERSION
    assert {"neutral", "faces", "deltas", "polygon_offsets"} <= set(m["arrays"])
    with zipfile.ZipFile(saved) as zf:
        assert all(i.compress_type == zipfile.ZIP_STORED for i in zf.infolist())
        assert not any(n.endswith((".pkl", ".pickle")) for n in zf.namelist())


def test_schema_v1_file_still_loads() -> None:
    """A file written by schema 1 (frozen in tests/data) must load in every later version."""
    m = workbench.load(DATA / "schema_v1_tiny.fwb")
    assert m.shape_names == ["up", "left"]
    assert m.weights["up"] == 0.5
    assert m.evaluate()[4, 2] == pytest.approx(0.5 + 0.1)  # blend + handle offset
    assert m.handles.vertices.tolist() == [4]


def test_wrong_checksum_is_refused(saved: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.fwb"

    def flip(name: str, data: bytes) -> bytes:
        if name == "arrays/deltas.npy":
            b = bytearray(data)
            b[-1] ^= 0x01
            return bytes(b)
        return data

    _rewrite(saved, bad, flip)
    with pytest.raises(WorkbenchFileError, match=r"bad\.fwb: arrays\.deltas: checksum mismatch"):
        workbench.load(bad)


def test_newer_schema_is_refused_with_upgrade_hint(saved: Path, tmp_path: Path) -> None:
    bad = tmp_path / "future.fwb"
    _edit_manifest(saved, bad, lambda m: m.update(schema_version=SCHEMA_VERSION + 1))
    with pytest.raises(WorkbenchFileError, match=r"schema_version.*upgrade face-workbench"):
        workbench.load(bad)


def test_huge_declared_shape_with_little_data(saved: Path, tmp_path: Path) -> None:
    bad = tmp_path / "huge.fwb"
    _edit_manifest(saved, bad, lambda m: m["arrays"]["deltas"].update(shape=[2, 10**9, 3]))
    with pytest.raises(WorkbenchFileError, match=r"arrays\.deltas\.shape: declares"):
        workbench.load(bad)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda m: m.pop("shapes"), r"bad\.fwb: shapes: missing"),
        (lambda m: m.update(format="other"), r"format: expected 'face-workbench'"),
        (lambda m: m["arrays"]["neutral"].update(dtype="|O"), r"arrays\.neutral\.dtype: expected '<f8'"),
        (
            lambda m: m["shapes"].append(dict(m["shapes"][0], name="extra")),
            r"arrays\.deltas\.shape: declares \[2, 9, 3\] but expected .* = \[3, 9, 3\]",
        ),
        (lambda m: m["shapes"][1].update(name="up"), r"shapes\[1\]\.name: duplicate blendshape name"),
        (lambda m: m["metadata"].update(units="furlong"), r"metadata\.units: expected one of"),
    ],
)
def test_malformed_manifest(saved: Path, tmp_path: Path, change, match: str) -> None:
    bad = tmp_path / "bad.fwb"
    _edit_manifest(saved, bad, change)
    with pytest.raises(WorkbenchFileError, match=match):
        workbench.load(bad)


def test_empty_and_non_zip_files(tmp_path: Path) -> None:
    empty = tmp_path / "empty.fwb"
    empty.write_bytes(b"")
    with pytest.raises(WorkbenchFileError, match=r"empty\.fwb: file: is empty"):
        workbench.load(empty)
    junk = tmp_path / "junk.fwb"
    junk.write_bytes(b"not a zip at all" * 10)
    with pytest.raises(WorkbenchFileError, match="bad zip"):
        workbench.load(junk)


def test_truncated_file(saved: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.fwb"
    cut.write_bytes(saved.read_bytes()[: saved.stat().st_size // 2])
    with pytest.raises(WorkbenchFileError, match=r"cut\.fwb"):
        workbench.load(cut)


def test_crash_mid_save_keeps_previous_file(
    tiny_model: FaceModel, saved: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = saved.read_bytes()

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    tiny_model.set_weight("up", 1.0)
    with pytest.raises(OSError, match="disk full"):
        save_model(tiny_model, saved)
    assert saved.read_bytes() == before
    assert [p.name for p in saved.parent.iterdir()] == [saved.name]  # temp file cleaned up
    assert workbench.load(saved).weights["up"] == 0.5


def test_expressions_paint_and_keys_round_trip(tiny_model: FaceModel, tmp_path: Path) -> None:
    from workbench.methods.paint.painting import Brush

    m = tiny_model
    m.handles.set(HandleSet([4], [[0.0, 0.0, 0.2]], ("centre",), [-1]))
    m.set_weight("left", 0.5)
    m.expressions.save("lean")
    m.reset_weights()
    m.handles.reset_offsets()
    m.paint.dab("lean", 3, Brush(radius=1.5, opacity=0.6))
    m.set_weight("up", 0.2)
    m.timeline.key_weights(0.0)
    m.key_expression(1.0, "lean", interpolation="linear")
    m.save(tmp_path / "full.fwb")
    g = workbench.load(tmp_path / "full.fwb")
    assert list(g.expressions) == ["lean"]
    e, f = g.expressions["lean"], m.expressions["lean"]
    np.testing.assert_array_equal(e.displacement, f.displacement)
    np.testing.assert_array_equal(e.handle_offsets, f.handle_offsets)
    assert dict(e.weights) == dict(f.weights)
    assert list(g.paint) == ["lean"]
    np.testing.assert_array_equal(g.paint["lean"], m.paint["lean"])
    assert g.tracks.to_json() == m.tracks.to_json()
    np.testing.assert_allclose(g.evaluate(), m.evaluate(), atol=1e-6)
    for t in (0.0, 0.3, 1.0):
        np.testing.assert_allclose(g.evaluate_at(t), m.evaluate_at(t), atol=1e-6)
    assert read_manifest(tmp_path / "full.fwb")["schema_version"] == 2


def test_timeline_naming_unknown_shapes_is_refused(saved: Path, tmp_path: Path) -> None:
    bad = tmp_path / "keys.fwb"
    tracks = {"fps": 30.0, "start": 0.0, "end": 1.0, "tracks": {"weights/ghost": [
        {"time": 0.0, "value": [1.0], "interpolation": "linear", "in_tangent": [0.0],
         "out_tangent": [0.0], "tangent_mode": "auto_clamped"}]}}
    _edit_manifest(saved, bad, lambda m: m.update(tracks=tracks))
    with pytest.raises(WorkbenchFileError, match=r"tracks: .*ghost"):
        workbench.load(bad)


def test_regions_and_region_weights_round_trip(tmp_path: Path) -> None:
    from workbench.methods.regions.blend import RegionWeights

    m = workbench.load_sample("head")
    st = m.segment_regions(0.25)
    m.regions.set_level(1)
    rw = RegionWeights.from_global(m, st.regions, 1).with_region(0, {"browInnerUp": 0.7})
    m.regions.set_weights(rw)
    m.save(tmp_path / "regions.fwb")
    g = workbench.load(tmp_path / "regions.fwb")
    assert g.regions.state is not None and g.regions.level == 1
    for lv in range(st.regions.n_levels):
        np.testing.assert_array_equal(g.regions.regions.labels[lv], st.regions.labels[lv])
        assert g.regions.regions.names[lv] == st.regions.names[lv]
    np.testing.assert_array_equal(g.regions.weights.values, rw.values)
    np.testing.assert_allclose(g.evaluate(), m.evaluate(), atol=1e-6)
    assert np.abs(g.evaluate() - g.blended()).max() > 1e-3  # the region weights do act


# ------------------------------------------------------------ malformed manifests
# Every malformed manifest must raise WorkbenchFileError "<file>: <JSON path>: <what was
# expected>", never a raw TypeError/AttributeError/StopIteration/..., and build nothing.


def _rich_model() -> FaceModel:
    """The 3x3-vertex grid with every saved feature: mask, handles, expression, paint, keys, regions."""
    from grid_meshes import grid_polygons

    from workbench.methods.paint.painting import Brush
    from workbench.methods.regions.blend import RegionWeights
    from workbench.model import BlendShape

    V, polys = grid_polygons(2, 2)
    up = np.zeros((9, 3), np.float32)
    up[4, 2] = 1.0
    left = np.zeros((9, 3), np.float32)
    left[[0, 3, 6], 0] = -0.5
    m = FaceModel(V, None, [BlendShape("up", up), BlendShape("left", left, -1.0, 2.0)], polygons=polys)
    m.set_shape_mask("left", np.linspace(0, 1, 9))
    m.handles.set(HandleSet([4], [[0.0, 0.0, 0.1]], ("centre",), [-1]))
    m.set_weight("left", 0.5)
    m.expressions.save("lean")
    m.reset_weights()
    m.paint.dab("lean", 3, Brush(radius=1.5, opacity=0.6))
    m.set_weight("up", 0.2)
    m.timeline.key_weights(0.0)
    m.key_expression(1.0, "lean", interpolation="linear")
    st = m.segment_regions(0.25)
    m.regions.set_weights(RegionWeights.from_global(m, st.regions, 0).with_region(0, {"up": 0.7}))
    return m


@pytest.fixture(scope="module")
def rich(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("rich") / "rich.fwb"
    _rich_model().save(p)
    return p


def test_rich_file_round_trips(rich: Path) -> None:
    g, m = workbench.load(rich), _rich_model()
    assert g.regions.state is not None and g.regions.weights is not None
    assert list(g.expressions) == ["lean"] and list(g.paint) == ["lean"]
    np.testing.assert_allclose(g.evaluate(), m.evaluate(), atol=1e-6)
    np.testing.assert_allclose(g.evaluate_at(0.5), m.evaluate_at(0.5), atol=1e-6)


def _set(*keys_and_value):
    """``_set("shapes", 0, "mask", True)``: a manifest edit setting one nested field."""
    *keys, last, value = keys_and_value

    def change(m):
        for k in keys:
            m = m[k]
        m[last] = value

    return change


def _delete(*keys):
    def change(m):
        for k in keys[:-1]:
            m = m[k]
        del m[keys[-1]]

    return change


ARRAY_ENTRY = {"file": "arrays/neutral.npy", "dtype": "<f8", "shape": [9, 3], "sha256": "0" * 64}


@pytest.mark.parametrize(
    ("change", "match"),
    [
        # np.dtype(<garbage>) used to raise a raw TypeError outside the try/except
        (_set("arrays", "neutral", "dtype", "garbage"), r"arrays\.neutral\.dtype: expected '<f8', got 'garbage'"),
        (_set("arrays", "neutral", "dtype", 7), r"arrays\.neutral\.dtype: expected a string, got a number 7"),
        (_set("arrays", "neutral", "dtype", None), r"arrays\.neutral\.dtype: expected a string, got null"),
        (_set("arrays", "neutral", "dtype", ["<f8"]), r"arrays\.neutral\.dtype: expected a string, got a list"),
        (_set("arrays", "neutral", "dtype", {"descr": "<f8"}), r"arrays\.neutral\.dtype: expected a string"),
        (_set("arrays", "deltas", "dtype", "<f8"), r"arrays\.deltas\.dtype: expected '<f4', got '<f8'"),
        # more shapes marked mask: true than mask rows: used to raise StopIteration
        (
            _set("shapes", 0, "mask", True),
            r"arrays\.masks\.shape: declares \[1, 9\] but expected \(shapes with mask true.*\[2, 9\]",
        ),
        (_set("shapes", 1, "mask", False), r"arrays\.masks\.shape: declares \[1, 9\] .*= \[0, 9\]"),
        # entries that are not JSON objects: used to raise AttributeError
        (_set("shapes", 1, [1, 2]), r"shapes\[1\]: expected an object, got a list \[1, 2\]"),
        (_set("shapes", 0, 3), r"shapes\[0\]: expected an object, got a number 3"),
        (_set("shapes", 0, None), r"shapes\[0\]: expected an object, got null"),
        (_set("metadata", "m"), r"metadata: expected an object, got a string \"m\""),
        (_set("metadata", []), r"metadata: expected an object, got a list"),
        (_set("expressions", 0, "lean"), r"expressions\[0\]: expected an object, got a string"),
        (_set("handles", ["centre"]), r"handles: expected an object, got a list"),
        (_set("regions", "yes"), r"regions: expected an object, got a string"),
        (_set("regions", "weights", 1), r"regions\.weights: expected an object, got a number"),
        (_set("tracks", []), r"tracks: expected an object, got a list"),
        (_set("tracks", "tracks", "weights/up", 0, 5), r"tracks\.tracks\[\"weights/up\"\]\[0\]: expected an object"),
        (_set("arrays", "faces", [1]), r"arrays\.faces: expected an object, got a list"),
        (_set("arrays", []), r"arrays: expected an object, got a list"),
        # booleans where numbers or strings are expected, and the other way round
        (_set("schema_version", True), r"schema_version: expected an integer >= 1, got a boolean true"),
        (_set("shapes", 0, "mask", "yes"), r"shapes\[0\]\.mask: expected true or false, got a string"),
        (_set("shapes", 0, "mask", 1), r"shapes\[0\]\.mask: expected true or false, got a number 1"),
        (_set("shapes", 0, "mute", None), r"shapes\[0\]\.mute: expected true or false, got null"),
        (_set("shapes", 0, "slider_min", False), r"shapes\[0\]\.slider_min: expected a number, got a boolean"),
        (_set("shapes", 0, "slider_max", "1"), r"shapes\[0\]\.slider_max: expected a number, got a string"),
        (_set("shapes", 0, "slider_max", -5), r"shapes\[0\]\.slider_max: expected a number greater than"),
        (_set("shapes", 0, "name", 5), r"shapes\[0\]\.name: expected a non-empty string, got a number"),
        (_set("shapes", 0, "name", " "), r"shapes\[0\]\.name: expected a non-empty string"),
        (_set("weights", "up", True), r"weights\.up: expected a number, got a boolean"),
        (_set("weights", "up", float("nan")), r"weights\.up: expected a finite number, got a number NaN"),
        (_set("weights", "ghost", 0.5), r"weights\.ghost: not a shape name"),
        (_set("weights", [0.5]), r"weights: expected an object, got a list"),
        (_set("components", "mesh"), r"components: expected a list, got a string"),
        (_set("components", []), r"components: expected at least one component name"),
        (_set("components", 0, 1), r"components\[0\]: expected a string, got a number"),
        (_set("handles", "names", "centre"), r"handles\.names: expected a list, got a string"),
        (_set("metadata", "provenance", [3]), r"metadata\.provenance\[0\]: expected an object"),
        (_set("metadata", "up_axis", "up"), r"metadata\.up_axis: expected one of"),
        (_set("writer", 1), r"writer: expected a string"),
        # negative, non-integer and huge counts and shapes
        (_set("mesh", "n_vertices", -9), r"mesh\.n_vertices: expected an integer >= 1, got a number -9"),
        (_set("mesh", "n_vertices", 9.0), r"mesh\.n_vertices: expected an integer >= 1, got a number 9\.0"),
        (_set("mesh", "n_faces", "8"), r"mesh\.n_faces: expected an integer >= 0, got a string"),
        (_set("mesh", "n_polygons", 5), r"arrays\.polygon_offsets\.shape: declares \[5\] .*= \[6\]"),
        (_set("expressions", 0, "n_handles", -1), r"expressions\[0\]\.n_handles: expected an integer >= 0"),
        (_set("expressions", 0, "n_handles", 1.5), r"expressions\[0\]\.n_handles: expected an integer"),
        (_set("expressions", 0, "n_handles", 2), r"arrays\.expression_handle_(vertices|offsets)\.shape: declares \[1"),
        (_set("expressions", 0, "weights", "up"), r"expressions\[0\]\.weights: expected an object"),
        (_set("arrays", "deltas", "shape", [2, 9.0, 3]), r"arrays\.deltas\.shape\[1\]: expected an integer"),
        (_set("arrays", "deltas", "shape", [2, -9, 3]), r"arrays\.deltas\.shape\[1\]: expected an integer >= 0"),
        (_set("arrays", "deltas", "shape", [2, 10**30, 3]), r"arrays\.deltas\.shape\[1\]: expected an integer"),
        (_set("arrays", "deltas", "shape", [18, 3]), r"arrays\.deltas\.shape: declares \[18, 3\] but expected 3"),
        (_set("arrays", "deltas", "shape", "2,9,3"), r"arrays\.deltas\.shape: expected a list, got a string"),
        (_set("arrays", "deltas", "sha256", 5), r"arrays\.deltas\.sha256: expected a string"),
        (_set("arrays", "deltas", "sha256", "abc"), r"arrays\.deltas\.sha256: expected 64 lowercase hex"),
        (_set("arrays", "deltas", "file", None), r"arrays\.deltas\.file: expected a non-empty string"),
        (_set("arrays", "deltas", "file", "arrays/nope.npy"), r"arrays\.deltas\.file: member 'arrays/nope\.npy'"),
        (_set("arrays", "deltas", "file", "arrays/masks.npy"), r"arrays\.deltas\.shape: declares"),
        # missing and unknown fields and arrays
        (_delete("arrays", "neutral"), r"arrays\.neutral: missing"),
        (_delete("arrays", "handle_mirror"), r"arrays\.handle_mirror: missing"),
        (_delete("arrays", "regions_labels_1"), r"arrays\.regions_labels_1: missing"),
        (_delete("arrays", "paint_maps"), r"arrays\.paint_maps: missing"),
        (_set("arrays", "junk", ARRAY_ENTRY), r"arrays\.junk: unknown array \(schema 2 has no such array\)"),
        (_set("regions", None), r"arrays\.regions_\w+: unknown array \(schema 2 has no such array while regions is null"),
        (_delete("shapes", 0, "slider_min"), r"shapes\[0\]\.slider_min: missing"),
        (_delete("metadata", "units"), r"metadata\.units: missing"),
        (_delete("mesh"), r"mesh: missing"),
        (_delete("schema_version"), r"schema_version: missing"),
        (_delete("regions", "n_levels"), r"regions\.n_levels: missing"),
        # cross references
        (_set("paint", ["ghost"]), r"paint\[0\]: paints 'ghost', which is neither"),
        (_set("paint", {"lean": 1}), r"paint: expected a list, got an object"),
        (_set("expressions", 0, "name", "ghost"), r"paint\[0\]: paints 'lean', which is neither"),
        (_set("regions", "n_levels", 0), r"regions\.n_levels: expected an integer in 1\.\.1000, got a number 0"),
        (_set("regions", "n_levels", 2), r"regions\.names: expected 2 entries \(one per level"),
        (_set("regions", "level", 3), r"regions\.level: expected an integer in 0\.\.2, got a number 3"),
        (_set("regions", "names", 0, "abc"), r"regions\.names\[0\]: expected a list, got a string"),
        (_set("regions", "names", 0, 1, "region_R_2"), r"regions\.names\[0\]\[1\]: duplicate name"),
        (_set("regions", "kinds", 1, ["skin"]), r"regions\.kinds\[1\]: expected 2 entries"),
        (_set("regions", "drivers", 0, 0, "up"), r"regions\.drivers\[0\]\[0\]: expected a list"),
        (_set("regions", "weights", "level", -1), r"regions\.weights\.level: expected an integer in 0\.\.2"),
        (_set("regions", "weights", "region_names", ["a"]), r"regions\.weights\.region_names: expected 3"),
        (_set("regions", "threshold", None), r"regions\.threshold: expected a number, got null"),
        (_set("tracks", "fps", "30"), r"tracks\.fps: expected a number, got a string"),
        (_set("tracks", "fps", -1), r"tracks: timeline fps must be a positive number"),
        (_set("tracks", "tracks", "weights/up", 0, "time", "0"), r"\[\"weights/up\"\]\[0\]\.time: expected a number"),
        (_set("tracks", "tracks", "weights/up", 0, "value", {}), r"\[0\]\.value: expected a number or a list"),
        (_set("tracks", "tracks", "weights/up", 0, "interpolation", 1), r"\[0\]\.interpolation: expected one of"),
        (_set("tracks", "tracks", "handles", 0, "value", [[0, 0]]), r"tracks: "),
    ],
)
def test_malformed_rich_manifest(rich: Path, tmp_path: Path, change, match: str) -> None:
    bad = tmp_path / "bad.fwb"
    _edit_manifest(rich, bad, change)
    with pytest.raises(WorkbenchFileError, match=match) as info:
        workbench.load(bad)
    assert str(info.value).startswith(f"{bad}: ")


def test_read_manifest_checks_fields_too(rich: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.fwb"
    _edit_manifest(rich, bad, _set("mesh", "n_vertices", "nine"))
    with pytest.raises(WorkbenchFileError, match=r"mesh\.n_vertices: expected an integer"):
        read_manifest(bad)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (b"[1, 2]", r"manifest\.json: expected a JSON object, got a list"),
        (b"\"face-workbench\"", r"manifest\.json: expected a JSON object, got a string"),
        (b"[" * 100_000 + b"]" * 100_000, r"manifest\.json: not valid JSON"),
        (b"\xff\xfe", r"manifest\.json: not valid JSON"),
    ],
)
def test_manifest_that_is_not_an_object(rich: Path, tmp_path: Path, text: bytes, match: str) -> None:
    bad = tmp_path / "bad.fwb"
    _rewrite(rich, bad, lambda name, data: text if name == "manifest.json" else data)
    with pytest.raises(WorkbenchFileError, match=match):
        workbench.load(bad)


def _npy(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def _replace_array(src: Path, dst: Path, name: str, a: np.ndarray, declare: bool = False) -> None:
    """Store ``a`` as array ``name`` with a correct checksum (and, if ``declare``, its shape and dtype)."""
    data = _npy(a)

    def edit(member: str, raw: bytes) -> bytes:
        if member == f"arrays/{name}.npy":
            return data
        if member != "manifest.json":
            return raw
        m = json.loads(raw)
        m["arrays"][name]["sha256"] = hashlib.sha256(data).hexdigest()
        if declare:
            m["arrays"][name].update(shape=list(a.shape), dtype=a.dtype.str)
        return json.dumps(m).encode()

    _rewrite(src, dst, edit)


@pytest.mark.parametrize(
    ("name", "array", "match"),
    [
        ("faces", np.array([[0, 1, 99]] * 8, "<i4"), r"arrays\.faces: vertex ids must be in 0\.\.8, got 99"),
        ("faces", np.full((8, 3), -1, "<i4"), r"arrays\.faces: vertex ids must be in 0\.\.8, got -1"),
        ("neutral", np.full((9, 3), np.nan), r"arrays\.neutral: NaN or infinity at flat index 0"),
        ("polygon_offsets", np.array([0, 4, 8, 12, 15], "<i8"), r"arrays\.polygon_offsets: offsets must"),
        ("component_labels", np.ones(9, "<i4"), r"arrays\.component_labels: labels .* must be in 0\.\.0"),
        ("masks", np.full((1, 9), 2.0, "<f4"), r"arrays\.masks: values must be in \[0, 1\]"),
        ("paint_maps", np.full((1, 9), -0.5, "<f4"), r"arrays\.paint_maps: values must be in \[0, 1\]"),
        ("handle_mirror", np.array([3], "<i4"), r"arrays\.handle_mirror: mirror handle indices"),
        ("expression_handle_vertices", np.array([9], "<i4"), r"arrays\.expression_handle_vertices: vertex ids"),
        ("regions_labels_0", np.full(9, 7, "<i4"), r"arrays\.regions_labels_0: labels \(-1 or regions"),
        ("regions_weight_cols_2", np.full(8, 1, "<i4"), r"arrays\.regions_weight_cols_2: regions of level 2"),
        ("regions_parents_0", np.full(3, 2, "<i4"), r"arrays\.regions_parents_0: regions of level 1"),
        # the .npy header disagrees with the manifest (checked before np.load allocates)
        ("deltas", np.zeros((2, 3, 9), "<f4"), r"arrays\.deltas: holds <f4\(2, 3, 9\), manifest says <f4\(2, 9, 3\)"),
        ("deltas", np.zeros((2, 9, 3), "<i4"), r"arrays\.deltas: holds <i4\(2, 9, 3\)"),
    ],
)
def test_bad_array_content_with_valid_checksum(
    rich: Path, tmp_path: Path, name: str, array: np.ndarray, match: str
) -> None:
    bad = tmp_path / "bad.fwb"
    _replace_array(rich, bad, name, array)
    with pytest.raises(WorkbenchFileError, match=match):
        workbench.load(bad)


def test_npy_header_declaring_a_huge_array_is_refused_before_allocating(rich: Path, tmp_path: Path) -> None:
    """A checksummed .npy whose header claims 3e12 floats is refused before np.load allocates them."""
    bad = tmp_path / "bad.fwb"
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "<f4", "fortran_order": False, "shape": (10000, 100000000, 3)}
    )
    data = buf.getvalue() + np.zeros((2, 9, 3), "<f4").tobytes()

    def edit(member: str, raw: bytes) -> bytes:
        if member == "arrays/deltas.npy":
            return data
        if member == "manifest.json":
            m = json.loads(raw)
            m["arrays"]["deltas"]["sha256"] = hashlib.sha256(data).hexdigest()
            return json.dumps(m).encode()
        return raw

    _rewrite(rich, bad, edit)
    with pytest.raises(WorkbenchFileError, match=r"arrays\.deltas: holds <f4\(10000, 100000000, 3\), manifest says"):
        workbench.load(bad)


# --------------------------------------------------- property: mutate any field
_KINDS = ("null", "bool", "int", "float", "str", "list", "object")


def _kind(v) -> str:
    if v is None:
        return "null"
    return {bool: "bool", int: "int", float: "float", str: "str", list: "list", dict: "object"}[type(v)]


_names = st.sampled_from(["up", "left", "lean", "centre", "mesh", "region", "weights/up", "handles", "name"])
_scalars = {
    "null": st.none(),
    "bool": st.booleans(),
    "int": st.integers(-3, 12) | st.integers(-(2**70), 2**70),
    "float": st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([0.0, 0.5, -1.0, 9.0]),
    "str": _names | st.sampled_from(["", " ", "<f4", "<f8", "<i4", "|O", "garbage", "+y", "m"]) | st.text(max_size=6),
}
_json = st.recursive(
    st.one_of(*_scalars.values()),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(_names | st.text(max_size=4), inner, max_size=3),
    max_leaves=6,
)
_by_kind = {
    **_scalars,
    "list": st.lists(_json, max_size=3),
    "object": st.dictionaries(_names | st.text(max_size=4), _json, max_size=3),
}


def _locations(v, prefix=()):
    """Every (container path, key) in a JSON tree."""
    items = v.items() if isinstance(v, dict) else enumerate(v) if isinstance(v, list) else ()
    for k, x in items:
        yield prefix, k
        yield from _locations(x, (*prefix, k))


def _mutate(data, manifest: dict) -> dict:
    """Replace a random field's value (usually by one of another JSON type) or delete it, once or twice."""
    m = copy.deepcopy(manifest)
    for _ in range(data.draw(st.integers(1, 2), label="mutations")):
        container_path, key = data.draw(st.sampled_from(list(_locations(m))), label="where")
        parent = m
        for k in container_path:
            parent = parent[k]
        old = _kind(parent[key])
        op = data.draw(st.sampled_from(["other_type", "other_type", "same_type", "delete"]), label="how")
        if op == "delete":
            del parent[key]
        else:
            kind = old if op == "same_type" else data.draw(st.sampled_from([k for k in _KINDS if k != old]))
            parent[key] = data.draw(_by_kind[kind], label="value")
    return m


def _rezip(src: Path, dst: Path, original: dict, mutated: dict) -> None:
    """Write ``mutated`` as the manifest; where an array's declared shape/dtype changed to a
    sensible one, store a matching array with a matching checksum so deeper checks run too."""
    members = {}
    entries = mutated.get("arrays") if isinstance(mutated, dict) else None
    for name, e in (entries.items() if isinstance(entries, dict) else ()):
        old = original["arrays"].get(name)
        if not (isinstance(e, dict) and old and e.get("file") == old["file"]):
            continue
        shape, dtype = e.get("shape"), e.get("dtype")
        if (shape, dtype) == (old["shape"], old["dtype"]):
            continue
        ok_shape = isinstance(shape, list) and all(type(d) is int and 0 <= d <= 64 for d in shape)
        if ok_shape and len(shape) <= 3 and dtype in ("<f4", "<f8", "<i4", "<i8"):
            members[e["file"]] = data = _npy(np.zeros(shape, dtype))
            if e.get("sha256") == old["sha256"]:
                e["sha256"] = hashlib.sha256(data).hexdigest()

    def edit(name: str, raw: bytes) -> bytes:
        if name == "manifest.json":
            return json.dumps(mutated).encode()
        return members.get(name, raw)

    _rewrite(src, dst, edit)


@pytest.fixture(scope="module")
def rich_manifest(rich: Path) -> dict:
    with zipfile.ZipFile(rich) as zf:
        return json.loads(zf.read("manifest.json"))


@settings(max_examples=int(os.environ.get("FWB_EXAMPLES", "200")), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_manifest_mutation_loads_or_raises_a_file_error(
    rich: Path, rich_manifest: dict, tmp_path_factory: pytest.TempPathFactory, data
) -> None:
    mutated = _mutate(data, rich_manifest)
    bad = tmp_path_factory.mktemp("mut") / "mutated.fwb"
    _rezip(rich, bad, rich_manifest, mutated)
    try:
        model = workbench.load(bad)
    except WorkbenchFileError as exc:
        assert exc.path == str(bad)
        assert str(exc).startswith(f"{bad}: ")
        assert exc.field not in ("", "manifest", "content"), str(exc)  # a specific field is named
        return
    # whatever loads is a whole, usable model
    model.evaluate()
    model.evaluate_at(0.5)
