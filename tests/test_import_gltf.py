"""glTF/GLB reader: fixtures built with pygltflib in the test, then damaged on purpose."""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pygltflib
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.gltf import read_gltf
from workbench.io.registry import read_any

# a 2x1 quad strip as 4 triangles
V0 = (
    np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], dtype=np.float32)
    * 0.1
)
F0 = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]], dtype=np.uint16)
DENSE = (np.arange(18, dtype=np.float32).reshape(6, 3) - 9) / 64  # exact in float32
SPARSE_IDX = np.array([1, 4], dtype=np.uint16)
SPARSE_VAL = np.array([[0.5, 0, 0], [0, -0.25, 0.125]], dtype=np.float32)
QUANT = np.array(
    [[0, 0, 0], [32767, 0, 0], [0, -32767, 0], [0, 0, -32768], [100, 200, 300], [0, 0, 1]],
    dtype=np.int16,
)
NAMES = ["jawOpen", "eyeBlink_L", "mouthSmileLeft"]


class Blob:
    """Accumulates a binary buffer with 4-byte aligned bufferViews."""

    def __init__(self, gltf: pygltflib.GLTF2) -> None:
        self.gltf = gltf
        self.data = bytearray()

    def view(self, arr: np.ndarray, stride: int | None = None) -> int:
        while len(self.data) % 4:
            self.data.append(0)
        raw = np.ascontiguousarray(arr)
        if stride is not None:  # interleave: pad each element to `stride` bytes with 0xEE
            elem = raw.itemsize * raw.shape[1]
            rows = np.full((raw.shape[0], stride), 0xEE, dtype=np.uint8)
            rows[:, :elem] = raw.view(np.uint8).reshape(raw.shape[0], elem)
            raw = rows
        self.gltf.bufferViews.append(
            pygltflib.BufferView(
                buffer=0, byteOffset=len(self.data), byteLength=raw.nbytes, byteStride=stride
            )
        )
        self.data += raw.tobytes()
        return len(self.gltf.bufferViews) - 1

    def accessor(self, **kw: Any) -> int:
        self.gltf.accessors.append(pygltflib.Accessor(**kw))
        return len(self.gltf.accessors) - 1


def build_gltf(
    V: np.ndarray = V0, F: np.ndarray = F0, names: list[str] | None = NAMES, stride: int | None = 16
) -> pygltflib.GLTF2:
    """Mesh with three targets: dense float, sparse float (no bufferView), normalized short."""
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
    g.extensionsUsed = ["KHR_mesh_quantization"]
    g.extensionsRequired = ["KHR_mesh_quantization"]
    b = Blob(g)
    n = len(V)
    pos = b.accessor(
        bufferView=b.view(V, stride=stride),
        componentType=pygltflib.FLOAT,
        count=n,
        type="VEC3",
        min=np.nanmin(V, 0).tolist(),
        max=np.nanmax(V, 0).tolist(),
    )
    ind = b.accessor(
        bufferView=b.view(F.reshape(-1, 1)),
        componentType=pygltflib.UNSIGNED_SHORT,
        count=F.size,
        type="SCALAR",
    )
    t0 = b.accessor(
        bufferView=b.view(DENSE[:n]), componentType=pygltflib.FLOAT, count=n, type="VEC3"
    )
    sparse = pygltflib.Sparse(
        count=len(SPARSE_IDX),
        indices=pygltflib.AccessorSparseIndices(
            bufferView=b.view(SPARSE_IDX.reshape(-1, 1)), componentType=pygltflib.UNSIGNED_SHORT
        ),
        values=pygltflib.AccessorSparseValues(bufferView=b.view(SPARSE_VAL)),
    )
    t1 = b.accessor(
        byteOffset=None, componentType=pygltflib.FLOAT, count=n, type="VEC3", sparse=sparse
    )
    t2 = b.accessor(
        bufferView=b.view(QUANT[:n], stride=8),
        componentType=pygltflib.SHORT,
        normalized=True,
        count=n,
        type="VEC3",
    )
    prim = pygltflib.Primitive(
        attributes=pygltflib.Attributes(POSITION=pos),
        indices=ind,
        targets=[{"POSITION": t} for t in (t0, t1, t2)],
    )
    mesh = pygltflib.Mesh(primitives=[prim], weights=[0.0, 0.0, 0.0], name="face")
    if names is not None:
        mesh.extras = {"targetNames": names}
    g.meshes.append(mesh)
    g.nodes.append(pygltflib.Node(mesh=0))
    g.scenes.append(pygltflib.Scene(nodes=[0]))
    g.buffers.append(pygltflib.Buffer(byteLength=len(b.data)))
    g.set_binary_blob(bytes(b.data))
    return g


def to_glb(g: pygltflib.GLTF2) -> bytes:
    return b"".join(g.save_to_bytes())


def split_glb(data: bytes) -> tuple[dict[str, Any], bytes]:
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + jlen])
    (blen,) = struct.unpack_from("<I", data, 20 + jlen)
    return doc, data[28 + jlen : 28 + jlen + blen]


def pack_glb(doc: dict[str, Any], bin_chunk: bytes) -> bytes:
    """GLB container around an edited JSON document (the test's own tiny writer)."""
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    b = bin_chunk + b"\0" * (-len(bin_chunk) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + struct.pack("<II", len(b), 0x004E4942) + b
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


@pytest.fixture
def glb(tmp_path: Path) -> Path:
    p = tmp_path / "face.glb"
    p.write_bytes(to_glb(build_gltf()))
    return p


def expected_quant() -> np.ndarray:
    return np.maximum(QUANT.astype(np.float64) / 32767.0, -1.0)


def test_round_trip_exact_values(glb: Path) -> None:
    face = read_gltf(glb)
    np.testing.assert_array_equal(face.vertices, V0.astype(np.float64))
    assert face.vertices.dtype == np.float64
    tris, _ = face.polygons.triangulate()
    np.testing.assert_array_equal(tris, F0)
    assert face.shape_names == NAMES
    d = dict(face.shapes)
    assert all(x.dtype == np.float32 for x in d.values())
    np.testing.assert_array_equal(d["jawOpen"], DENSE)
    sparse = np.zeros((6, 3), np.float32)
    sparse[SPARSE_IDX] = SPARSE_VAL
    np.testing.assert_array_equal(d["eyeBlink_L"], sparse)
    np.testing.assert_array_equal(d["mouthSmileLeft"], expected_quant().astype(np.float32))
    assert d["mouthSmileLeft"][3, 2] == -1.0  # -32768 clamps to -1
    assert face.units == "m" and face.up_axis == "+y"
    assert face.face_groups is None and face.source_files == [str(glb)]
    assert read_any(glb).shape_names == NAMES


def test_names_fall_back_to_target_index(tmp_path: Path) -> None:
    p = tmp_path / "a.glb"
    p.write_bytes(to_glb(build_gltf(names=None, stride=None)))
    assert read_gltf(p).shape_names == ["target_0", "target_1", "target_2"]


def test_gltf_with_data_uri_buffer(tmp_path: Path) -> None:
    doc, bin_chunk = split_glb(to_glb(build_gltf()))
    doc["buffers"][0]["uri"] = (
        "data:application/octet-stream;base64," + base64.b64encode(bin_chunk).decode()
    )
    p = tmp_path / "face.gltf"
    p.write_text(json.dumps(doc))
    face = read_gltf(p)
    np.testing.assert_array_equal(face.vertices, V0)
    np.testing.assert_array_equal(dict(face.shapes)["jawOpen"], DENSE)


def test_gltf_with_external_bin(tmp_path: Path) -> None:
    doc, bin_chunk = split_glb(to_glb(build_gltf()))
    doc["buffers"][0]["uri"] = "face%20data.bin"
    (tmp_path / "face data.bin").write_bytes(bin_chunk)
    p = tmp_path / "face.gltf"
    p.write_text(json.dumps(doc))
    np.testing.assert_array_equal(read_gltf(p).vertices, V0)
    (tmp_path / "face data.bin").write_bytes(bin_chunk[:-10])
    with pytest.raises(
        MeshFormatError, match=r"face.gltf: buffers\[0\]: byteLength is \d+ but only \d+ bytes"
    ):
        read_gltf(p)


def test_two_primitives_are_merged_with_offset(tmp_path: Path) -> None:
    doc, bin_chunk = split_glb(to_glb(build_gltf()))
    doc["materials"] = [{"name": "skin"}, {"name": "teeth"}]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    p = tmp_path / "two.glb"
    # second primitive from a mesh of its own: positions shifted by +5 in x
    V1 = V0 + np.array([5, 0, 0], np.float32)
    g1 = build_gltf(V=V1)
    doc1, bin1 = split_glb(to_glb(g1))
    # append bin1 after bin_chunk and relocate doc1's views into the merged buffer
    base = len(bin_chunk) + (-len(bin_chunk) % 4)
    merged = bin_chunk + b"\0" * (-len(bin_chunk) % 4) + bin1
    nbv, nacc = len(doc["bufferViews"]), len(doc["accessors"])
    for bv in doc1["bufferViews"]:
        bv["byteOffset"] = bv.get("byteOffset", 0) + base
    doc["bufferViews"] += doc1["bufferViews"]
    for acc in doc1["accessors"]:
        if "bufferView" in acc:
            acc["bufferView"] += nbv
        if "sparse" in acc:
            acc["sparse"]["indices"]["bufferView"] += nbv
            acc["sparse"]["values"]["bufferView"] += nbv
    doc["accessors"] += doc1["accessors"]
    p2 = doc1["meshes"][0]["primitives"][0]
    p2["attributes"]["POSITION"] += nacc
    p2["indices"] += nacc
    p2["targets"] = [{"POSITION": t["POSITION"] + nacc} for t in p2["targets"]]
    p2["material"] = 1
    doc["meshes"][0]["primitives"].append(p2)
    doc["buffers"][0]["byteLength"] = len(merged)
    p.write_bytes(pack_glb(doc, merged))
    face = read_gltf(p)
    np.testing.assert_array_equal(face.vertices, np.concatenate([V0, V1]))
    tris, _ = face.polygons.triangulate()
    np.testing.assert_array_equal(tris, np.concatenate([F0, F0.astype(np.int32) + 6]))
    assert face.group_names == ["skin", "teeth"]
    assert face.face_groups is not None and face.face_groups.tolist() == [0] * 4 + [1] * 4
    np.testing.assert_array_equal(dict(face.shapes)["jawOpen"], np.concatenate([DENSE, DENSE]))
    labels, names = face.components()
    assert [names[i] for i in labels] == ["skin"] * 6 + ["teeth"] * 6


# ---- damaged files ----------------------------------------------------------------


def write_doc(tmp_path: Path, edit: Any, name: str = "bad.glb") -> Path:
    doc, bin_chunk = split_glb(to_glb(build_gltf()))
    out = edit(doc)
    if isinstance(out, bytes):
        bin_chunk = out
    p = tmp_path / name
    p.write_bytes(pack_glb(doc, bin_chunk))
    return p


def expect(path: Path, pattern: str, field: str | None = None) -> MeshFormatError:
    with pytest.raises(MeshFormatError, match=pattern) as exc:
        read_gltf(path)
    assert exc.value.source == str(path)
    if field is not None:
        assert exc.value.field == field
    return exc.value


def test_empty_file(tmp_path: Path) -> None:
    p = tmp_path / "bad.glb"
    p.write_bytes(b"")
    expect(p, r"^bad.glb: empty file$", "file")


@pytest.mark.parametrize("cut", [5, 12, 19, 100, -1, -37])
def test_truncated_glb(glb: Path, cut: int) -> None:
    data = glb.read_bytes()
    glb.write_bytes(data[:cut])
    expect(glb, r"^face.glb: truncated GLB", "header")


def test_chunk_longer_than_file(glb: Path) -> None:
    data = bytearray(glb.read_bytes())
    (jlen,) = struct.unpack_from("<I", data, 12)
    struct.pack_into("<I", data, 20 + jlen, 10_000_000)  # BIN chunk length
    glb.write_bytes(bytes(data))
    expect(glb, r"truncated GLB: chunk 1 declares 10000000 bytes, only \d+ remain", "chunk 1")


def test_trailing_bytes(glb: Path) -> None:
    glb.write_bytes(glb.read_bytes() + b"\0\0\0\0")
    expect(glb, r"GLB has trailing bytes: header says \d+ bytes, file has \d+", "header")


def test_not_a_glb(tmp_path: Path) -> None:
    p = tmp_path / "bad.glb"
    p.write_bytes(b"PK\x03\x04" + b"\0" * 40)
    expect(p, r"not a GLB file", "header")


def test_garbled_json(glb: Path) -> None:
    data = bytearray(glb.read_bytes())
    data[20 + 1] = ord("@")  # {"accessors"... -> {@accessors"...
    glb.write_bytes(bytes(data))
    expect(glb, r"^face.glb: garbled JSON at line 1 column \d+", "JSON")


def test_garbled_gltf_text(tmp_path: Path) -> None:
    p = tmp_path / "bad.gltf"
    p.write_text('{"asset": {"version": "2.0"}, "meshes": [')
    expect(p, r"garbled JSON", "JSON")


def test_huge_declared_count_little_data(tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["accessors"][0]["count"] = 10**12

    e = expect(
        write_doc(tmp_path, edit),
        r"accessors\[0\] \(meshes\[0\]\.primitives\[0\]\.attributes\.POSITION\): declares 1000000000000 elements "
        r"\(\d+ bytes from offset 0\) but its bufferView holds only 96 bytes",
    )
    assert e.field.startswith("accessors[0]")


def test_huge_sparse_count(tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["accessors"][3]["count"] = 10**12  # the sparse target: also differs from POSITION

    expect(
        write_doc(tmp_path, edit), r"targets\[1\]\.POSITION\)\.count: is 1000000000000, expected 6"
    )

    def edit2(doc: dict[str, Any]) -> None:
        doc["accessors"][3]["sparse"]["count"] = 5

    expect(
        write_doc(tmp_path, edit2),
        r"sparse.indices: needs 10 bytes for 5 elements but its bufferView holds 4",
    )


def test_buffer_view_past_end_of_buffer(tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["bufferViews"][1]["byteLength"] = 10**9

    expect(
        write_doc(tmp_path, edit),
        r"bufferViews\[1\]: bytes \d+\.\.\d+ lie past the end of buffers\[0\]",
    )


def test_nan_position_and_delta(tmp_path: Path) -> None:
    V = V0.copy()
    V[2, 1] = np.nan
    p = tmp_path / "nan.glb"
    p.write_bytes(to_glb(build_gltf(V=V)))
    expect(p, r"meshes\[0\]\.primitives\[0\]\.attributes\.POSITION: row 2 is not finite")

    def edit(doc: dict[str, Any]) -> bytes:
        # overwrite the first delta of the dense target with +inf
        off = doc["bufferViews"][2]["byteOffset"]
        _, b = split_glb(to_glb(build_gltf()))
        return b[:off] + struct.pack("<f", np.inf) + b[off + 4 :]

    expect(write_doc(tmp_path, edit), r"targets\[0\]\.POSITION: row 0 is not finite \(inf")


def test_index_out_of_range(tmp_path: Path) -> None:
    F = F0.copy()
    F[2, 1] = 6
    p = tmp_path / "idx.glb"
    p.write_bytes(to_glb(build_gltf(F=F)))
    expect(
        p,
        r"meshes\[0\]\.primitives\[0\]\.indices: index 6 out of range \(POSITION has 6 vertices\)",
    )


def test_zero_area_and_duplicate_triangles(tmp_path: Path) -> None:
    p = tmp_path / "deg.glb"
    p.write_bytes(to_glb(build_gltf(F=np.array([[0, 1, 4], [0, 1, 2]], np.uint16))))
    expect(p, r"meshes\[0\] triangles: face 1 \[0, 1, 2\] has zero area")
    p.write_bytes(to_glb(build_gltf(F=np.array([[0, 1, 4], [4, 0, 1]], np.uint16))))
    expect(p, r"meshes\[0\] triangles: face 1 \[4, 0, 1\] duplicates face 0")


def test_target_vertex_count_differs(tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["accessors"][2]["count"] = 5

    expect(
        write_doc(tmp_path, edit),
        r"targets\[0\]\.POSITION\)\.count: is 5, expected 6 \(the POSITION count\)",
    )


def test_duplicate_target_names(tmp_path: Path) -> None:
    p = tmp_path / "dup.glb"
    p.write_bytes(to_glb(build_gltf(names=["jawOpen", "eyeBlinkLeft", "EyeBlink_L"])))
    expect(
        p,
        r"duplicate shape name: 'eyeBlinkLeft' .* and 'EyeBlink_L' .*both are ARKit 'eyeBlinkLeft'",
        "shape names",
    )


def test_wrong_number_of_target_names(tmp_path: Path) -> None:
    p = tmp_path / "n.glb"
    p.write_bytes(to_glb(build_gltf(names=["a", "b"])))
    expect(p, r"meshes\[0\]\.extras\.targetNames: has 2 names for 3 targets")


def test_non_triangle_mode(tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> None:
        doc["meshes"][0]["primitives"][0]["mode"] = 5

    expect(
        write_doc(tmp_path, edit), r"primitives\[0\]\.mode: 5 \(TRIANGLE_STRIP\) is not supported"
    )


def test_sparse_indices_not_increasing(tmp_path: Path) -> None:
    def edit(doc: dict[str, Any]) -> bytes:
        off = doc["bufferViews"][3]["byteOffset"]
        _, b = split_glb(to_glb(build_gltf()))
        return b[:off] + np.array([4, 1], np.uint16).tobytes() + b[off + 4 :]

    expect(
        write_doc(tmp_path, edit), r"sparse\.indices: sparse indices must be strictly increasing"
    )


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (
            lambda d: d["accessors"][0].__setitem__("count", "6"),
            r"\.count: expected an integer >= 1, got '6'",
        ),
        (
            lambda d: d["accessors"][0].__setitem__("count", 6.0),
            r"\.count: expected an integer >= 1, got 6.0",
        ),
        (
            lambda d: d["accessors"][0].__setitem__("componentType", 5124),
            r"unknown component type 5124",
        ),
        (
            lambda d: d["accessors"][0].__setitem__("type", "MAT4"),
            r"\.type: expected VEC3, got 'MAT4'",
        ),
        (
            lambda d: d["meshes"][0]["primitives"][0].__setitem__("indices", 99),
            r"indices: refers to accessors\[99\]",
        ),
        (
            lambda d: d["bufferViews"][0].__setitem__("byteStride", 8),
            r"byteStride 8 is smaller than one element \(12 bytes\)",
        ),
        (lambda d: d.__setitem__("meshes", []), r"meshes: the file has no meshes"),
        (
            lambda d: d.__setitem__("extensionsRequired", ["EXT_mesh_gpu_instancing"]),
            r"unsupported extensions \['EXT_mesh_gpu_instancing'\]: they may change the geometry",
        ),
        (lambda d: d["asset"].__setitem__("version", "1.0"), r"asset.version"),
    ],
)
def test_bad_fields(tmp_path: Path, edit: Any, pattern: str) -> None:
    expect(write_doc(tmp_path, edit), pattern)


# ---- fuzzing: damaged files load or raise MeshFormatError, nothing else ---------------

VALID_GLB = to_glb(build_gltf())


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_fuzz_corrupted_glb_bytes(tmp_path: Path, data: st.DataObject) -> None:
    raw = bytearray(VALID_GLB)
    for _ in range(data.draw(st.integers(1, 6))):
        op = data.draw(st.sampled_from(["set", "set", "insert", "delete", "truncate"]))
        pos = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if op == "set" and raw:
            raw[pos] = data.draw(st.integers(0, 255))
        elif op == "insert":
            raw[pos:pos] = data.draw(st.binary(min_size=1, max_size=8))
        elif op == "delete" and raw:
            del raw[pos : pos + data.draw(st.integers(1, 8))]
        elif op == "truncate":
            del raw[pos:]
    check_loads_or_format_error(tmp_path / "fuzz.glb", bytes(raw))


def _leaves(obj: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _leaves(v, (*path, k))]
    if isinstance(obj, list):
        return [p for i, v in enumerate(obj) for p in _leaves(v, (*path, i))]
    return [path]


JSON_VALUES = st.one_of(
    st.integers(-(2**40), 2**40),
    st.integers(-3, 300),
    st.sampled_from([0, 1, 2**31, 2**32 - 1, 10**30, -1]),
    st.floats(allow_nan=False),
    st.text(max_size=5),
    st.none(),
    st.booleans(),
    st.lists(st.integers(-2, 10), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_fuzz_json_field_values(tmp_path: Path, data: st.DataObject) -> None:
    doc, bin_chunk = split_glb(VALID_GLB)
    leaves = _leaves(doc)
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(leaves))
        target = doc
        for k in path[:-1]:
            target = target[k]
        if data.draw(st.booleans()) or not path:
            target[path[-1]] = data.draw(JSON_VALUES)
        else:
            del target[path[-1]]
            leaves = _leaves(doc)
            if not leaves or leaves == [()]:
                break
    check_loads_or_format_error(tmp_path / "fuzz.glb", pack_glb(doc, bin_chunk))


def check_loads_or_format_error(path: Path, raw: bytes) -> None:
    path.write_bytes(raw)
    try:
        face = read_gltf(path)
    except MeshFormatError as exc:
        assert exc.source == str(path)
        return
    assert np.isfinite(face.vertices).all()
    assert face.polygons.indices.max() < face.n_vertices
    for _, d in face.shapes:
        assert d.shape == face.vertices.shape
