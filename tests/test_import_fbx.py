"""FBX import (workbench.io.fbx) on a file written by Blender's FBX exporter, and a malformed corpus.

The source (``tests/tools/format_writers.py``) is the sample head as two meshes
with six shape keys and LINEAR keys; Blender builds it and writes ``face.fbx``
(bpy in ``$WORKBENCH_BPY_PYTHON``; cached). The reader imports it with
Blender's FBX importer and must give back the source geometry (centimetres:
Blender writes UnitScaleFactor 1 with a x100 model scale), shape names and
deltas, and the keyed values at every frame. The corpus (>= 50 variants:
truncations, damaged records and arrays, NaN, wrong counts, out-of-range
indices, bad units) is rejected by the checked parser before Blender runs,
each with the file and the field named.
"""

from __future__ import annotations

import copy
import struct
import sys
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ci_env import in_ci

import workbench.io.fbx as fbx_mod
from workbench.cli import main
from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io import blender_bridge, load
from workbench.io.fbx import FbxFile, FbxNode, parse_fbx, read_fbx, read_fbx_animation

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))
import format_writers as fw

CM = 10.0  # source decimetres -> the file's centimetres


@pytest.fixture(scope="session")
def fbx_file() -> Path:
    try:
        return fw.blender_files()["fbx"]
    except fw.ToolMissing as exc:
        if in_ci():
            pytest.fail(f"{exc} is missing under CI=true", pytrace=False)
        pytest.skip(str(exc))


@pytest.fixture(scope="session")
def face(fbx_file: Path):
    return read_fbx(fbx_file)


def test_geometry_and_shapes_match_the_source(face) -> None:
    src = fw.face_source()
    assert face.units == "cm" and face.up_axis == "+y"
    assert face.group_names == ["Head", "Mouth"]
    assert face.n_vertices == src.vertices().shape[0]
    np.testing.assert_allclose(face.vertices, src.vertices() * CM, atol=2e-5, rtol=0)
    assert face.shape_names == list(fw.SHAPES)
    for name, D in face.shapes:
        np.testing.assert_allclose(D, src.delta(name) * CM, atol=2e-5, rtol=0)
    # faces as written: the same polygons (quads kept), objects concatenated in name order
    counts = np.concatenate([o.counts for o in src.objects])
    np.testing.assert_array_equal(face.polygons.sizes, counts)


def test_keyed_values_at_key_times_and_between(fbx_file: Path, face) -> None:
    tl = read_fbx_animation(fbx_file, face.shape_names)
    src = fw.face_source()
    assert tl.fps == fw.FPS
    assert tl.start == 0.0 and tl.end == pytest.approx(fw.LAST_FRAME / fw.FPS)
    for s in fw.SHAPES:
        tr = tl.tracks[f"weights/{s}"]
        assert set(tr.interpolations) == {"linear"}
        for f, v in fw.KEYS[s]:
            assert float(tr.evaluate(f / fw.FPS)) == pytest.approx(v, abs=1e-6), (s, f)
        for f in range(fw.LAST_FRAME + 1):  # baked per frame: the LINEAR source curve everywhere
            assert float(tr.evaluate(f / fw.FPS)) == pytest.approx(src.weight(s, f), abs=1e-6)


def test_load_and_info(fbx_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = load(fbx_file)
    assert model.metadata.units == "cm" and model.metadata.metres_per_unit == pytest.approx(0.01)
    assert main(["info", str(fbx_file)]) == 0
    out = capsys.readouterr().out
    assert "units       cm (0.01 m per unit)" in out
    assert "jawOpen" in out and "Head" in out


def test_missing_blender_names_the_variable_and_install(fbx_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WORKBENCH_BPY_PYTHON", "/nonexistent/python")
    monkeypatch.setattr(blender_bridge, "_CACHE", type(blender_bridge._CACHE)())
    with pytest.raises(blender_bridge.BlenderMissingError) as ei:
        read_fbx(fbx_file)
    msg = str(ei.value)
    assert "WORKBENCH_BPY_PYTHON" in msg and "pip install bpy==5.0.1" in msg and fbx_file.name in msg
    assert main(["info", str(fbx_file)]) == 2


def test_unknown_shapes_in_animation_are_named(fbx_file: Path) -> None:
    from workbench.animation.importers import AnimationImportError

    with pytest.raises(AnimationImportError, match="unknown shape names"):
        read_fbx_animation(fbx_file, ["jawOpen"])
    tl = read_fbx_animation(fbx_file, ["jawOpen"], on_unknown="ignore")
    assert list(tl.tracks) == ["weights/jawOpen"]


# ---------------------------------------------------------------- binary FBX writer (tests only)
@dataclass
class Raw:
    """A property written verbatim: type code + payload bytes (for damaged arrays and codes)."""

    code: str
    payload: bytes


def _prop(code: str, v: Any) -> bytes:
    if isinstance(v, Raw):
        return v.code.encode() + v.payload
    scal = {"Y": "<h", "C": "<B", "I": "<i", "F": "<f", "D": "<d", "L": "<q"}
    if code in scal:
        return code.encode() + struct.pack(scal[code], v)
    if code in "fdlib":
        raw = np.ascontiguousarray(v).tobytes()
        return code.encode() + struct.pack("<III", len(v), 0, len(raw)) + raw
    return code.encode() + struct.pack("<I", len(v)) + v


def _node(n: FbxNode, pos: int, wide: bool) -> bytes:
    hdr = 25 if wide else 13
    name = n.name.encode()
    props = b"".join(_prop(c, v) for c, v in zip(n.codes, n.props, strict=True))
    q = pos + hdr + len(name) + len(props)
    kids = b""
    for c in n.children:
        b = _node(c, q, wide)
        kids += b
        q += len(b)
    if n.children or not n.props:
        kids += b"\0" * hdr
        q += hdr
    head = struct.pack("<QQQ" if wide else "<III", q, len(n.props), len(props)) + bytes([len(name)])
    return head + name + props + kids


def write_fbx(f: FbxFile, footer: bytes = b"") -> bytes:
    wide = f.version >= 7500
    out = bytearray(fbx_mod.MAGIC + b"\x1a\x00" + struct.pack("<I", f.version))
    for n in f.nodes:
        out += _node(n, len(out), wide)
    out += b"\0" * (25 if wide else 13)
    return bytes(out) + footer


def _find(f: FbxFile, pred: Callable[[FbxNode], bool]) -> FbxNode:
    stack = list(f.nodes)
    while stack:
        n = stack.pop(0)
        if pred(n):
            return n
        stack.extend(n.children)
    raise LookupError("no such node")


def _geom(kind: bytes) -> Callable[[FbxNode], bool]:
    return lambda n: n.name == "Geometry" and len(n.props) > 2 and n.props[2] == kind


def _child(f: FbxFile, pred: Callable[[FbxNode], bool], name: str) -> FbxNode:
    c = _find(f, pred).child(name)
    assert c is not None
    return c


def _setting(f: FbxFile, key: bytes) -> FbxNode:
    return _find(f, lambda n: n.name == "P" and n.props[:1] == [key] and "GlobalSettings" in n.path)


def test_unmodified_rewrite_reads_the_same(fbx_file: Path, face, tmp_path: Path) -> None:
    """The corpus writer is faithful: the re-written file reads through Blender as the original."""
    f = parse_fbx(fbx_file)
    p = tmp_path / "same.fbx"
    p.write_bytes(write_fbx(f))
    again = read_fbx(p)
    np.testing.assert_array_equal(again.vertices, face.vertices)
    assert again.shape_names == face.shape_names


# ---------------------------------------------------------------- the malformed corpus
def _edit(fn: Callable[[FbxFile], None]) -> Callable[[bytes, FbxFile], bytes]:
    def make(data: bytes, f: FbxFile) -> bytes:
        g = copy.deepcopy(f)
        fn(g)
        return write_fbx(g)

    return make


def _set_array(pred: Callable[[FbxNode], bool], name: str, fn: Callable[[np.ndarray], np.ndarray]):
    def edit(f: FbxFile) -> None:
        c = _child(f, pred, name)
        c.props[0] = fn(np.array(c.props[0]))

    return _edit(edit)


def _set_value(key: bytes, value: Any, code: str | None = None):
    def edit(f: FbxFile) -> None:
        p = _setting(f, key)
        p.props[4] = value
        if code:
            p.codes = p.codes[:4] + code + p.codes[5:]

    return _edit(edit)


def _patch(at: int, raw: bytes) -> Callable[[bytes, FbxFile], bytes]:
    return lambda d, f: d[:at] + raw + d[at + len(raw) :]


def _nan_at(i: int):
    def fn(a: np.ndarray) -> np.ndarray:
        a = a.copy()
        a[i] = np.nan
        return a

    return fn


def _drop(f: FbxFile, pred: Callable[[FbxNode], bool], name: str) -> None:
    n = _find(f, pred)
    n.children = [c for c in n.children if c.name != name]


def _curve(n: FbxNode) -> bool:
    return n.name == "AnimationCurve"


def _raw_array(code: str, count: int, enc: int, payload: bytes) -> Raw:
    return Raw(code, struct.pack("<III", count, enc, len(payload)) + payload)


def _replace_prop(pred, name: str, value: Any, code: str | None = None):
    def edit(f: FbxFile) -> None:
        c = _child(f, pred, name)
        c.props[0] = value
        if code:
            c.codes = code
    return _edit(edit)


def _bad_zlib(f: FbxFile) -> None:
    c = _child(f, _geom(b"Mesh"), "Vertices")
    raw = zlib.compress(np.asarray(c.props[0]).tobytes())
    raw = raw[:10] + bytes(b ^ 0x5A for b in raw[10:40]) + raw[40:]
    c.props[0] = _raw_array("d", len(c.props[0]), 1, raw)


def _short_zlib(f: FbxFile) -> None:
    c = _child(f, _geom(b"Mesh"), "Vertices")
    raw = zlib.compress(np.asarray(c.props[0]).tobytes()[:-8])
    c.props[0] = _raw_array("d", len(c.props[0]), 1, raw)


def _variants(size: int) -> dict[str, tuple[Callable[[bytes, FbxFile], bytes], str]]:
    """name -> (make bytes from (original bytes, parsed), expected text in the message)."""
    v: dict[str, tuple[Callable[[bytes, FbxFile], bytes], str]] = {}
    for k, frac in enumerate(np.linspace(0.01, 0.99, 22)):
        cut = int(size * frac)
        v[f"truncated_{k:02d}"] = ((lambda c: lambda d, f: d[:c])(cut), "truncated")
    v["truncated_in_header"] = (lambda d, f: d[:25], "header")
    v["empty"] = (lambda d, f: b"", "not a binary FBX")
    v["random_bytes"] = (lambda d, f: bytes(range(256)) * 4, "not a binary FBX")
    v["ascii_fbx"] = (lambda d, f: b"; FBX 7.4.0 project file\nFBXHeaderExtension:  {\n}\n", "ASCII FBX")
    v["damaged_magic"] = (_patch(19, b"\x01"), "magic is damaged")
    v["version_too_old"] = (_patch(23, struct.pack("<I", 6100)), "older than Blender")
    v["version_unknown"] = (_patch(23, struct.pack("<I", 99999)), "not a known version")
    v["first_node_end_beyond_file"] = (_patch(27, struct.pack("<I", size + 1000)), "beyond the end of the file")
    v["first_node_end_inside_props"] = (_patch(27, struct.pack("<I", 40)), "before its")
    v["first_node_more_props"] = (lambda d, f: d[:31] + struct.pack("<I", struct.unpack_from("<I", d, 31)[0] + 3) + d[35:], "properties")
    v["first_node_props_length"] = (lambda d, f: d[:35] + struct.pack("<I", struct.unpack_from("<I", d, 35)[0] + 1) + d[39:], "properties end at byte")
    v["node_name_not_ascii"] = (_patch(40, b"\xff"), "not ASCII")
    v["unknown_property_code"] = (_replace_prop(_geom(b"Mesh"), "Vertices", Raw("Z", b"\0" * 8), "Z"), "unknown property type code")
    v["array_encoding_2"] = (
        _replace_prop(_geom(b"Mesh"), "Vertices", _raw_array("d", 3, 2, b"\0" * 24)), "unknown array encoding"
    )
    v["array_count_exceeds_data"] = (
        _replace_prop(_geom(b"Mesh"), "Vertices", _raw_array("d", 4, 0, b"\0" * 24)), "should take"
    )
    v["array_zlib_damaged"] = (_edit(_bad_zlib), "compressed array data is damaged")
    v["array_zlib_short"] = (_edit(_short_zlib), "its data holds")
    mesh, shape = _geom(b"Mesh"), _geom(b"Shape")
    v["vertices_nan"] = (_set_array(mesh, "Vertices", _nan_at(7)), "Vertices: vertex 2 is not finite")
    v["vertices_inf"] = (_set_array(mesh, "Vertices", lambda a: np.where(np.arange(a.size) == 0, np.inf, a)), "not finite")
    v["vertices_not_xyz"] = (_set_array(mesh, "Vertices", lambda a: a[:-1]), "not a multiple of 3")
    v["vertices_missing"] = (_edit(lambda f: _drop(f, mesh, "Vertices")), "Vertices: missing")
    v["vertices_wrong_type"] = (_replace_prop(mesh, "Vertices", b"oops", "S"), "expected an array")
    v["polygon_index_out_of_range"] = (_set_array(mesh, "PolygonVertexIndex", lambda a: np.where(np.arange(a.size) == 5, 10**6, a).astype(a.dtype)), "out of range")
    v["polygon_index_negative_out_of_range"] = (_set_array(mesh, "PolygonVertexIndex", lambda a: np.where(np.arange(a.size) == 3, -(10**6), a).astype(a.dtype)), "out of range")
    v["polygon_not_closed"] = (_set_array(mesh, "PolygonVertexIndex", lambda a: np.abs(a[:-1]).astype(a.dtype)), "does not close a polygon")
    v["polygon_index_empty"] = (_set_array(mesh, "PolygonVertexIndex", lambda a: a[:0]), "empty")
    v["polygon_index_missing"] = (_edit(lambda f: _drop(f, mesh, "PolygonVertexIndex")), "PolygonVertexIndex: missing")
    v["polygon_index_as_floats"] = (_replace_prop(mesh, "PolygonVertexIndex", np.zeros(6), "d"), "expected an array of i")
    v["shape_index_out_of_range"] = (_set_array(shape, "Indexes", lambda a: (a + 10**6).astype(a.dtype)), "out of range")
    v["shape_index_negative"] = (_set_array(shape, "Indexes", lambda a: np.where(np.arange(a.size) == 1, -4, a).astype(a.dtype)), "negative")
    v["shape_offsets_count"] = (_set_array(shape, "Vertices", lambda a: a[:-3]), "3 per index expected")
    v["shape_offsets_nan"] = (_set_array(shape, "Vertices", _nan_at(4)), "is not finite")
    v["shape_indexes_missing"] = (_edit(lambda f: _drop(f, shape, "Indexes")), "Indexes: missing")
    v["curve_values_count"] = (_set_array(_curve, "KeyValueFloat", lambda a: a[:-1]), "one per key expected")
    v["curve_value_nan"] = (_set_array(_curve, "KeyValueFloat", _nan_at(2)), "not finite")
    v["curve_times_not_increasing"] = (_set_array(_curve, "KeyTime", lambda a: a[::-1].copy()), "times must increase")
    v["curve_times_missing"] = (_edit(lambda f: _drop(f, _curve, "KeyTime")), "KeyTime: missing")
    v["unit_scale_zero"] = (_set_value(b"UnitScaleFactor", 0.0), "UnitScaleFactor: must be > 0")
    v["unit_scale_negative"] = (_set_value(b"UnitScaleFactor", -1.0), "UnitScaleFactor: must be > 0")
    v["unit_scale_nan"] = (_set_value(b"UnitScaleFactor", float("nan")), "UnitScaleFactor: expected a finite")
    v["unit_scale_text"] = (_set_value(b"UnitScaleFactor", b"cm", "S"), "UnitScaleFactor: expected a number")
    v["up_axis_7"] = (_set_value(b"UpAxis", 7), "UpAxis: must be 0, 1 or 2")
    v["up_axis_sign_0"] = (_set_value(b"UpAxisSign", 0), "UpAxisSign: must be 1 or -1")
    v["custom_frame_rate_zero"] = (
        _edit(lambda f: (_setting(f, b"TimeMode").props.__setitem__(4, 14), _setting(f, b"CustomFrameRate").props.__setitem__(4, 0.0))),
        "CustomFrameRate: must be > 0",
    )
    v["no_objects"] = (_edit(lambda f: setattr(f, "nodes", [n for n in f.nodes if n.name != "Objects"])), "Objects: missing")
    v["no_mesh_geometry"] = (
        _edit(lambda f: [n.props.__setitem__(2, b"Nurbs") for n in _find(f, lambda n: n.name == "Objects").children if _geom(b"Mesh")(n)]),
        "no mesh geometry",
    )
    return v


@pytest.fixture(scope="session")
def corpus(fbx_file: Path) -> tuple[bytes, FbxFile]:
    return fbx_file.read_bytes(), parse_fbx(fbx_file)


VARIANTS = sorted(_variants(100_000))


def test_corpus_is_large_enough() -> None:
    assert len(VARIANTS) >= 50


@pytest.mark.parametrize("name", VARIANTS)
def test_malformed_variant_is_refused_before_blender(
    name: str, corpus: tuple[bytes, FbxFile], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    data, parsed = corpus
    make, expected = _variants(len(data))[name]
    p = tmp_path / f"{name}.fbx"
    p.write_bytes(make(data, parsed))

    def no_blender(*a: Any, **k: Any) -> Any:
        raise AssertionError("Blender ran on a malformed file")

    monkeypatch.setattr(fbx_mod, "run_dump", no_blender)
    with pytest.raises(MeshFormatError) as ei:
        read_fbx(p)
    msg = str(ei.value)
    assert msg.startswith(f"{p.name}: "), msg
    assert expected in msg, msg
    assert ei.value.field, msg
