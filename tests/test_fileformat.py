"""Saved workbench files: round trip, atomicity, checksums, schema versions, bad input."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

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
    tiny_model.set_handles(HandleSet([4], [[0.0, 0.0, 0.1]], ("centre",), [-1]))
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
        (lambda m: m.pop("shapes"), "manifest: missing or malformed field 'shapes'"),
        (lambda m: m.update(format="other"), "manifest.format"),
        (lambda m: m["arrays"]["neutral"].update(dtype="|O"), "object arrays"),
        (lambda m: m["shapes"].append(dict(m["shapes"][0])), "expected 3 shapes"),
        (lambda m: m["shapes"][1].update(name="up"), "duplicate blendshape name"),
        (lambda m: m["metadata"].update(units="furlong"), "metadata.units"),
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
    from workbench.paint import Brush

    m = tiny_model
    m.set_handles(HandleSet([4], [[0.0, 0.0, 0.2]], ("centre",), [-1]))
    m.set_weight("left", 0.5)
    m.save_expression("lean")
    m.reset_weights()
    m.reset_handle_offsets()
    m.paint_dab("lean", 3, Brush(radius=1.5, opacity=0.6))
    m.set_weight("up", 0.2)
    m.key_weights(0.0)
    m.key_expression(1.0, "lean", interpolation="linear")
    m.save(tmp_path / "full.fwb")
    g = workbench.load(tmp_path / "full.fwb")
    assert list(g.expressions) == ["lean"]
    e, f = g.expressions["lean"], m.expressions["lean"]
    np.testing.assert_array_equal(e.displacement, f.displacement)
    np.testing.assert_array_equal(e.handle_offsets, f.handle_offsets)
    assert dict(e.weights) == dict(f.weights)
    assert list(g.paint_layers) == ["lean"]
    np.testing.assert_array_equal(g.paint_layers["lean"], m.paint_layers["lean"])
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
    from workbench.region_blend import RegionWeights

    m = workbench.load_sample("head")
    st = m.segment_regions(0.25)
    m.set_region_level(1)
    rw = RegionWeights.from_global(m, st.regions, 1).with_region(0, {"browInnerUp": 0.7})
    m.set_region_weights(rw)
    m.save(tmp_path / "regions.fwb")
    g = workbench.load(tmp_path / "regions.fwb")
    assert g.regions is not None and g.regions.level == 1
    for lv in range(st.regions.n_levels):
        np.testing.assert_array_equal(g.regions.regions.labels[lv], st.regions.labels[lv])
        assert g.regions.regions.names[lv] == st.regions.names[lv]
    np.testing.assert_array_equal(g.regions.weights.values, rw.values)
    np.testing.assert_allclose(g.evaluate(), m.evaluate(), atol=1e-6)
    assert np.abs(g.evaluate() - g.blended()).max() > 1e-3  # the region weights do act
