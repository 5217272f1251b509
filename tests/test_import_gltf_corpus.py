"""A corpus of malformed glTF files, each made from a real writer's output by one defect.

The bases are the files of ``tests/tools/gltf_writers.py``: gltfpack
(meshopt + quantization), glTF-Transform ``draco``/``sparse``/``quantize``
and the plain source. Every variant must raise :class:`MeshFormatError` from
both the reader and ``workbench.load`` whose source is the file, whose field
is the JSON path of the defect (``meshes[0].primitives[0].attributes.POSITION``,
``bufferViews[1].extensions.EXT_meshopt_compression.count``, ...) and whose
message starts with the file name: nothing is half-loaded, since a reader
returns only after every check has passed.
"""

from __future__ import annotations

import re
import struct
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ci_env import in_ci
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import workbench
from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.gltf import read_gltf

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))
from gltf_writers import ToolMissing, pack_glb, source_glb, split_glb, written

MO = "EXT_meshopt_compression"
DR = "KHR_draco_mesh_compression"
POS = "meshes[0].primitives[0].attributes.POSITION"
IND = "meshes[0].primitives[0].indices"
T0 = "meshes[0].primitives[0].targets[0].POSITION"


class Glb:
    """A writer's file opened for editing: ``doc`` (JSON) and ``bin`` (BIN chunk)."""

    def __init__(self, base: str) -> None:
        path = source_glb() if base == "source" else written(base)
        doc, b = split_glb(path.read_bytes())
        self.doc: dict[str, Any] = doc
        self.bin = bytearray(b)
        self.raw: bytes | None = None  # set to write these bytes instead of doc + bin

    @property
    def prim(self) -> dict[str, Any]:
        return self.doc["meshes"][0]["primitives"][0]

    def acc(self, i: int) -> dict[str, Any]:
        return self.doc["accessors"][i]

    @property
    def pos(self) -> int:
        return self.prim["attributes"]["POSITION"]

    @property
    def target0(self) -> int:
        return self.prim["targets"][0]["POSITION"]

    def view_index(self, ai: int) -> int:
        return self.acc(ai)["bufferView"]

    def view(self, ai: int) -> dict[str, Any]:
        return self.doc["bufferViews"][self.view_index(ai)]

    def meshopt(self, ai: int) -> dict[str, Any]:
        return self.view(ai)["extensions"][MO]

    def draco(self) -> dict[str, Any]:
        return self.prim["extensions"][DR]

    def element_offset(self, ai: int, row: int) -> int:
        a, v = self.acc(ai), self.view(ai)
        size = {5126: 12, 5123: 6, 5122: 6}[a["componentType"]] if a["type"] == "VEC3" else 4
        stride = v.get("byteStride", size)
        return v.get("byteOffset", 0) + a.get("byteOffset", 0) + row * stride

    def put(self, offset: int, fmt: str, *values: Any) -> None:
        struct.pack_into(fmt, self.bin, offset, *values)

    def bytes(self) -> bytes:
        return self.raw if self.raw is not None else pack_glb(self.doc, bytes(self.bin))


@dataclass(frozen=True)
class Variant:
    name: str
    base: str
    edit: Callable[[Glb], tuple[str, str]]  # returns (field, message regex)


VARIANTS: list[Variant] = []


def variant(base: str) -> Callable[[Callable[[Glb], tuple[str, str]]], Callable[[Glb], tuple[str, str]]]:
    def register(fn: Callable[[Glb], tuple[str, str]]) -> Callable[[Glb], tuple[str, str]]:
        VARIANTS.append(Variant(fn.__name__, base, fn))
        return fn

    return register


def acc_field(g: Glb, ai: int, path: str, key: str = "") -> str:
    return f"accessors[{ai}] ({path})" + (f".{key}" if key else "")


# ---- truncated buffers and containers --------------------------------------------------
for _base in ("source", "gltfpack", "draco", "sparse"):

    def _cut(g: Glb) -> tuple[str, str]:
        n = len(g.bin)
        del g.bin[n // 2 :]
        return "buffers[0]", r"buffers\[0\]: byteLength is \d+ but only \d+ bytes are present \(truncated\?\)"

    VARIANTS.append(Variant(f"truncated_bin_chunk[{_base}]", _base, _cut))


@variant("gltfpack")
def truncated_file(g: Glb) -> tuple[str, str]:
    data = g.bytes()
    g.raw = data[: len(data) - 1000]
    return "header", r"truncated GLB: header says \d+ bytes, file has \d+"


@variant("draco")
def truncated_json_chunk(g: Glb) -> tuple[str, str]:
    data = bytearray(g.bytes())
    struct.pack_into("<I", data, 12, len(data))  # JSON chunk longer than the file
    g.raw = bytes(data)
    return "chunk 0", r"truncated GLB: chunk 0 declares"


@variant("gltfpack")
def meshopt_stream_cut(g: Glb) -> tuple[str, str]:
    ext = g.meshopt(g.pos)
    ext["byteLength"] //= 2
    return f"bufferViews[{g.view_index(g.pos)}].extensions.{MO}", r"meshopt data cannot be decoded"


@variant("draco")
def draco_stream_cut(g: Glb) -> tuple[str, str]:
    g.doc["bufferViews"][g.draco()["bufferView"]]["byteLength"] = 40
    return f"meshes[0].primitives[0].extensions.{DR}", r"Draco data cannot be decoded"


@variant("source")
def external_buffer_missing(g: Glb) -> tuple[str, str]:
    g.doc["buffers"][0]["uri"] = "missing.bin"
    return "buffers[0].uri", r"cannot read 'missing.bin'"


@variant("source")
def data_uri_not_base64(g: Glb) -> tuple[str, str]:
    g.doc["buffers"][0]["uri"] = "data:application/octet-stream;base64,@@@@"
    return "buffers[0].uri", r"data URI is not valid base64"


# ---- bad extension data ----------------------------------------------------------------
def _meshopt_field(key: str, value: Any, message: str) -> Callable[[Glb], tuple[str, str]]:
    def edit(g: Glb) -> tuple[str, str]:
        g.meshopt(g.pos)[key] = value
        field = f"bufferViews[{g.view_index(g.pos)}].extensions.{MO}"
        return (field if key == "byteOffset" else f"{field}.{key}"), message

    edit.__name__ = f"meshopt_{key}_{value!r}"
    return edit


for _key, _value, _msg in [
    ("mode", "QUADS", r"expected one of \['ATTRIBUTES', 'TRIANGLES', 'INDICES'\], got 'QUADS'"),
    ("filter", "WAVELET", r"unknown filter 'WAVELET'"),
    ("filter", "COLOR", r"unknown filter 'COLOR'"),  # KHR only
    ("byteStride", 6, r"6 is not a multiple of 4 from 4 to 256"),
    ("byteStride", "8", r"expected an integer >= 1, got '8'"),
    ("count", 9887, r"9887 elements x byteStride 8 = 79096 bytes, but the bufferView's byteLength is 79104"),
    ("buffer", 7, r"refers to buffers\[7\] but the file has 2 buffers"),
    ("byteOffset", 10**9, r"compressed bytes \d+\.\.\d+ lie past the end of buffers\[0\]"),
    ("mode", None, r"expected one of"),
]:
    VARIANTS.append(Variant(_meshopt_field(_key, _value, _msg).__name__, "gltfpack", _meshopt_field(_key, _value, _msg)))


@variant("gltfpack")
def meshopt_declared_size_beyond_any_ratio(g: Glb) -> tuple[str, str]:
    ext = g.meshopt(g.pos)
    ext["count"] = 10**9
    g.view(g.pos)["byteLength"] = 10**9 * ext["byteStride"]
    g.doc["buffers"][1]["byteLength"] = 2 * 10**10
    return f"bufferViews[{g.view_index(g.pos)}].extensions.{MO}.count", r"cannot come from \d+ compressed bytes"


@variant("gltfpack")
def meshopt_triangles_not_in_threes(g: Glb) -> tuple[str, str]:
    ai = g.prim["indices"]
    ext = g.meshopt(ai)
    ext["count"] -= 1
    g.view(ai)["byteLength"] = ext["count"] * ext["byteStride"]
    return f"bufferViews[{g.view_index(ai)}].extensions.{MO}.count", r"is not a multiple of 3 \(TRIANGLES\)"


@variant("gltfpack")
def meshopt_header_byte_garbled(g: Glb) -> tuple[str, str]:
    ext = g.meshopt(g.pos)
    g.bin[ext.get("byteOffset", 0)] = 0x00  # the vertex codec's header byte
    return f"bufferViews[{g.view_index(g.pos)}].extensions.{MO}", r"meshopt data cannot be decoded \(Malformed"


@variant("gltfpack")
def meshopt_extension_not_object(g: Glb) -> tuple[str, str]:
    g.view(g.pos)["extensions"][MO] = [1, 2]
    return f"bufferViews[{g.view_index(g.pos)}].extensions.{MO}", r"expected a JSON object"


@variant("gltfpack")
def meshopt_fallback_read_plain(g: Glb) -> tuple[str, str]:
    del g.view(g.pos)["extensions"]
    return "buffers[1]", r"is a meshopt fallback buffer without data"


@variant("draco")
def draco_unknown_attribute_id(g: Glb) -> tuple[str, str]:
    g.draco()["attributes"]["POSITION"] = 7
    return f"meshes[0].primitives[0].extensions.{DR}.attributes.POSITION", r"no attribute with unique id 7"


@variant("draco")
def draco_no_position_id(g: Glb) -> tuple[str, str]:
    del g.draco()["attributes"]["POSITION"]
    return f"meshes[0].primitives[0].extensions.{DR}.attributes", r"POSITION is missing"


@variant("draco")
def draco_missing_buffer_view(g: Glb) -> tuple[str, str]:
    del g.draco()["bufferView"]
    return f"meshes[0].primitives[0].extensions.{DR}.bufferView", r"refers to bufferViews\[None\]"


@variant("draco")
def draco_data_zeroed(g: Glb) -> tuple[str, str]:
    bv = g.doc["bufferViews"][g.draco()["bufferView"]]
    start = bv.get("byteOffset", 0)
    g.bin[start : start + bv["byteLength"]] = bytes(bv["byteLength"])
    return f"meshes[0].primitives[0].extensions.{DR}", r"Draco data cannot be decoded"


@variant("draco")
def draco_extension_not_object(g: Glb) -> tuple[str, str]:
    g.prim["extensions"][DR] = "draco"
    return f"meshes[0].primitives[0].extensions.{DR}", r"expected a JSON object"


@variant("draco")
def draco_vertex_count_differs(g: Glb) -> tuple[str, str]:
    g.acc(g.pos)["count"] += 1
    return acc_field(g, g.pos, POS, "count"), r"is 4805 but the Draco data decodes to 4804 vertices"


@variant("draco")
def draco_index_count_differs(g: Glb) -> tuple[str, str]:
    g.acc(g.prim["indices"])["count"] -= 3
    return acc_field(g, g.prim["indices"], IND, "count"), r"but the Draco data decodes to 28272 indices"


@variant("source")
def unknown_required_extension(g: Glb) -> tuple[str, str]:
    g.doc["extensionsRequired"] = ["KHR_texture_basisu", "EXT_mesh_gpu_instancing"]
    return "extensionsRequired", r"unsupported extensions \['EXT_mesh_gpu_instancing'\]"


@variant("source")
def required_extensions_not_strings(g: Glb) -> tuple[str, str]:
    g.doc["extensionsRequired"] = [1]
    return "extensionsRequired", r"expected an array of strings"


# ---- NaN and inf -----------------------------------------------------------------------
@variant("source")
def nan_position(g: Glb) -> tuple[str, str]:
    g.put(g.element_offset(g.pos, 17), "<f", float("nan"))
    return POS, r"row 17 is not finite"


@variant("source")
def inf_delta(g: Glb) -> tuple[str, str]:
    g.put(g.element_offset(g.target0, 3) + 4, "<f", float("inf"))
    return T0, r"row 3 is not finite"


@variant("sparse")
def nan_sparse_value(g: Glb) -> tuple[str, str]:
    for t, target in enumerate(g.prim["targets"]):
        a = g.acc(target["POSITION"])
        if "sparse" in a:
            vals = g.doc["bufferViews"][a["sparse"]["values"]["bufferView"]]
            g.put(vals.get("byteOffset", 0) + a["sparse"]["values"].get("byteOffset", 0), "<f", float("nan"))
            return f"meshes[0].primitives[0].targets[{t}].POSITION", r"is not finite"
    raise AssertionError("no sparse target")


@variant("gltfpack")
def nan_node_translation(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][0]["translation"][1] = float("nan")  # json writes NaN; Python's reader accepts it
    return "nodes[0].translation", r"is not finite"


@variant("quantize")
def inf_node_scale(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][1]["scale"] = [float("inf")] * 3
    return "nodes[1].scale", r"is not finite"


@variant("draco")
def nan_rotation(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][2]["rotation"] = [float("nan"), 0, 0, 1]
    return "nodes[2].rotation", r"is not finite"


# ---- out-of-range indices --------------------------------------------------------------
@variant("source")
def index_past_positions(g: Glb) -> tuple[str, str]:
    g.put(g.element_offset(g.prim["indices"], 5), "<I", 4804)
    return IND, r"index 4804 out of range \(POSITION has 4804 vertices\)"


@variant("gltfpack")
def fewer_positions_than_indexed(g: Glb) -> tuple[str, str]:
    g.acc(g.pos)["count"] = 4000
    return IND, r"out of range \(POSITION has 4000 vertices\)"


@variant("sparse")
def sparse_index_past_count(g: Glb) -> tuple[str, str]:
    for t, target in enumerate(g.prim["targets"]):
        a = g.acc(target["POSITION"])
        if "sparse" in a:
            ind = a["sparse"]["indices"]
            bv = g.doc["bufferViews"][ind["bufferView"]]
            n = a["sparse"]["count"]
            size = {5121: 1, 5123: 2, 5125: 4}[ind["componentType"]]
            fmt = {1: "<B", 2: "<H", 4: "<I"}[size]
            g.put(bv.get("byteOffset", 0) + ind.get("byteOffset", 0) + (n - 1) * size, fmt, 4804)
            return f"accessors[{target['POSITION']}] (meshes[0].primitives[0].targets[{t}].POSITION).sparse.indices", r"sparse index 4804 out of range"
    raise AssertionError("no sparse target")


@variant("sparse")
def sparse_indices_not_increasing(g: Glb) -> tuple[str, str]:
    for t, target in enumerate(g.prim["targets"]):
        a = g.acc(target["POSITION"])
        if "sparse" in a:
            ind = a["sparse"]["indices"]
            bv = g.doc["bufferViews"][ind["bufferView"]]
            off = bv.get("byteOffset", 0) + ind.get("byteOffset", 0)
            g.put(off, "<H", 4000)
            return f"accessors[{target['POSITION']}] (meshes[0].primitives[0].targets[{t}].POSITION).sparse.indices", r"strictly increasing"
    raise AssertionError("no sparse target")


@variant("draco")
def node_mesh_out_of_range(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][1]["mesh"] = 9
    return "nodes[1].mesh", r"refers to meshes\[9\] but the file has 3 meshes"


@variant("draco")
def scene_node_out_of_range(g: Glb) -> tuple[str, str]:
    g.doc["scenes"][0]["nodes"] = [0, 12]
    return "scenes[0].nodes[1]", r"refers to nodes\[12\] but the file has 4 nodes"


@variant("gltfpack")
def child_out_of_range(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][4]["children"] = [77]
    return "nodes[4].children[0]", r"refers to nodes\[77\]"


@variant("quantize")
def material_out_of_range(g: Glb) -> tuple[str, str]:
    g.prim["material"] = 40
    return "meshes[0].primitives[0].material", r"refers to materials\[40\]"


@variant("source")
def target_accessor_out_of_range(g: Glb) -> tuple[str, str]:
    g.prim["targets"][2]["POSITION"] = 999
    return "meshes[0].primitives[0].targets[2].POSITION", r"refers to accessors\[999\] but the file has 23 accessors"


@variant("source")
def default_scene_out_of_range(g: Glb) -> tuple[str, str]:
    g.doc["scene"] = 3
    return "scene", r"refers to scenes\[3\] but the file has 1 scenes"


# ---- wrong counts ----------------------------------------------------------------------
@variant("quantize")
def target_count_differs(g: Glb) -> tuple[str, str]:
    g.acc(g.target0)["count"] = 100
    return acc_field(g, g.target0, T0, "count"), r"is 100, expected 4804 \(the POSITION count\)"


@variant("gltfpack")
def target_names_count(g: Glb) -> tuple[str, str]:
    g.doc["meshes"][0]["extras"]["targetNames"].pop()
    return "meshes[0].extras.targetNames", r"has 8 names for 9 targets"


@variant("source")
def target_names_not_strings(g: Glb) -> tuple[str, str]:
    g.doc["meshes"][1]["extras"]["targetNames"] = [7]
    return "meshes[1].extras.targetNames", r"expected an array of strings"


@variant("source")
def primitives_with_different_target_counts(g: Glb) -> tuple[str, str]:
    second = dict(g.prim)
    second["targets"] = second["targets"][:4]
    g.doc["meshes"][0]["primitives"].append(second)
    return "meshes[0].primitives[1].targets", r"has 4 targets, primitive 0 has 9"


@variant("source")
def huge_count(g: Glb) -> tuple[str, str]:
    g.acc(g.pos)["count"] = 10**12
    return acc_field(g, g.pos, POS), r"declares 1000000000000 elements .* but its bufferView holds only 57648 bytes"


@variant("sparse")
def sparse_count_above_accessor(g: Glb) -> tuple[str, str]:
    for t, target in enumerate(g.prim["targets"]):
        a = g.acc(target["POSITION"])
        if "sparse" in a:
            a["sparse"]["count"] = 5000
            return f"accessors[{target['POSITION']}] (meshes[0].primitives[0].targets[{t}].POSITION).sparse.count", r"5000 exceeds the accessor count 4804"
    raise AssertionError("no sparse target")


@variant("source")
def indices_not_in_threes(g: Glb) -> tuple[str, str]:
    g.acc(g.prim["indices"])["count"] -= 1
    return IND, r"28271 indices is not a multiple of 3"


@variant("source")
def zero_count(g: Glb) -> tuple[str, str]:
    g.acc(g.pos)["count"] = 0
    return acc_field(g, g.pos, POS, "count"), r"expected an integer >= 1, got 0"


@variant("source")
def duplicate_names_in_one_mesh(g: Glb) -> tuple[str, str]:
    g.doc["meshes"][0]["extras"]["targetNames"][1] = "JawOpen"
    return "shape names", r"duplicate shape name: 'jawOpen' .* and 'JawOpen'"


# ---- bad byteStride --------------------------------------------------------------------
def _stride(value: Any, message: str, key: str = ".byteStride") -> Callable[[Glb], tuple[str, str]]:
    def edit(g: Glb) -> tuple[str, str]:
        g.view(g.pos)["byteStride"] = value
        return f"bufferViews[{g.view_index(g.pos)}]{key}", message

    edit.__name__ = f"byte_stride_{value!r}"
    return edit


for _value, _msg in [
    (2, r"expected an integer >= 4, got 2"),
    (256, r"256 is above the maximum 252"),
    (14, r"14 is not a multiple of 4"),
    (-4, r"expected an integer >= 4, got -4"),
    (12.0, r"expected an integer >= 4, got 12.0"),
]:
    VARIANTS.append(Variant(_stride(_value, _msg).__name__, "source", _stride(_value, _msg)))


@variant("source")
def byte_stride_smaller_than_element(g: Glb) -> tuple[str, str]:
    g.view(g.pos)["byteStride"] = 8
    return acc_field(g, g.pos, POS), r"byteStride 8 is smaller than one element \(12 bytes\)"


@variant("gltfpack")
def byte_stride_smaller_than_quantized_element(g: Glb) -> tuple[str, str]:
    g.view(g.pos)["byteStride"] = 4  # USHORT VEC3 is 6 bytes
    return acc_field(g, g.pos, POS), r"byteStride 4 is smaller than one element \(6 bytes\)"


@variant("source")
def byte_stride_on_indices(g: Glb) -> tuple[str, str]:
    g.view(g.prim["indices"])["byteStride"] = 4
    return acc_field(g, g.prim["indices"], IND), r"the bufferView of indices must not have a byteStride"


@variant("source")
def misaligned_byte_offset(g: Glb) -> tuple[str, str]:
    g.acc(g.pos)["byteOffset"] = 2
    return acc_field(g, g.pos, POS, "byteOffset"), r"2 is not a multiple of the component size 4"


# ---- missing or dangling bufferViews ---------------------------------------------------
@variant("source")
def position_without_buffer_view(g: Glb) -> tuple[str, str]:
    del g.acc(g.pos)["bufferView"]
    return acc_field(g, g.pos, POS), r"has no bufferView"


@variant("gltfpack")
def quantized_position_without_buffer_view(g: Glb) -> tuple[str, str]:
    del g.acc(g.pos)["bufferView"]
    return acc_field(g, g.pos, POS), r"has no bufferView"


@variant("sparse")
def sparse_indices_without_buffer_view(g: Glb) -> tuple[str, str]:
    for t, target in enumerate(g.prim["targets"]):
        a = g.acc(target["POSITION"])
        if "sparse" in a:
            del a["sparse"]["indices"]["bufferView"]
            return f"accessors[{target['POSITION']}] (meshes[0].primitives[0].targets[{t}].POSITION).sparse.indices.bufferView", r"refers to bufferViews\[None\]"
    raise AssertionError("no sparse target")


@variant("source")
def buffer_view_index_out_of_range(g: Glb) -> tuple[str, str]:
    g.acc(g.target0)["bufferView"] = 500
    return acc_field(g, g.target0, T0, "bufferView"), r"refers to bufferViews\[500\] but the file has 24 bufferViews"


@variant("draco")
def buffer_index_out_of_range(g: Glb) -> tuple[str, str]:
    g.view(g.target0)["buffer"] = 3
    return f"bufferViews[{g.view_index(g.target0)}].buffer", r"refers to buffers\[3\] but the file has 1 buffers"


@variant("quantize")
def buffer_view_past_buffer(g: Glb) -> tuple[str, str]:
    g.view(g.target0)["byteOffset"] = 10**8
    return f"bufferViews[{g.view_index(g.target0)}]", r"bytes \d+\.\.\d+ lie past the end of buffers\[0\]"


@variant("gltfpack")
def buffer_view_missing_length(g: Glb) -> tuple[str, str]:
    del g.view(g.target0)["byteLength"]
    return f"bufferViews[{g.view_index(g.target0)}].byteLength", r"required integer is missing"


# ---- nodes, modes, types ---------------------------------------------------------------
@variant("draco")
def node_cycle(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][3]["children"] = [0]
    return "nodes[3].children[0]", r"node 0 is reached twice"


@variant("source")
def node_with_two_parents(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][1]["children"] = [2]
    return "nodes[0].children[1]", r"node 2 is reached twice"


@variant("quantize")
def rotation_not_unit(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][2]["rotation"] = [0.5, 0, 0, 0.5]
    return "nodes[2].rotation", r"is not a unit quaternion"


@variant("source")
def matrix_not_affine(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][0] = {"children": [1, 2, 3], "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.5, 0, 0, 0, 1]}
    return "nodes[0].matrix", r"is not \[0, 0, 0, 1\] \(not affine\)"


@variant("source")
def matrix_and_trs(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][0]["matrix"] = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    return "nodes[0].matrix", r"either a matrix or translation/rotation/scale"


@variant("draco")
def zero_scale(g: Glb) -> tuple[str, str]:
    g.doc["nodes"][2]["scale"] = [0, 0, 0]
    return "nodes[2] (meshes[1])", r"singular \(a zero scale\)"


@variant("sparse")
def lines_mode(g: Glb) -> tuple[str, str]:
    g.prim["mode"] = 1
    return "meshes[0].primitives[0].mode", r"1 \(LINES\) is not supported"


@variant("source")
def zero_area_triangle(g: Glb) -> tuple[str, str]:
    off = g.element_offset(g.prim["indices"], 0)
    a, _, _ = struct.unpack_from("<III", g.bin, off)
    g.put(off, "<III", a, a, a)
    return "meshes[0] triangles", r"face 0 .*"


@variant("source")
def unsigned_int_position(g: Glb) -> tuple[str, str]:
    g.acc(g.pos)["componentType"] = 5125
    return acc_field(g, g.pos, POS, "componentType"), r"UNSIGNED_INT \(5125\) is only allowed for indices"


@variant("source")
def normalized_float(g: Glb) -> tuple[str, str]:
    g.acc(g.target0)["normalized"] = True
    return acc_field(g, g.target0, T0, "normalized"), r"only byte/short component types can be normalized"


@variant("quantize")
def matrix_typed_position(g: Glb) -> tuple[str, str]:
    g.acc(g.pos)["type"] = "MAT4"
    return acc_field(g, g.pos, POS, "type"), r"expected VEC3, got 'MAT4'"


@variant("source")
def missing_position(g: Glb) -> tuple[str, str]:
    del g.prim["attributes"]["POSITION"]
    return "meshes[0].primitives[0].attributes", r"POSITION is missing"


@variant("source")
def garbled_json(g: Glb) -> tuple[str, str]:
    data = bytearray(g.bytes())
    data[20 + 1] = ord("@")
    g.raw = bytes(data)
    return "JSON", r"garbled JSON at line 1"


def test_corpus_is_large_enough() -> None:
    assert len(VARIANTS) >= 50
    assert len({v.name for v in VARIANTS}) == len(VARIANTS)


@pytest.mark.parametrize("v", VARIANTS, ids=lambda v: v.name)
def test_malformed_variant_names_file_and_field(v: Variant, tmp_path: Path) -> None:
    try:
        g = Glb(v.base)
    except ToolMissing as exc:
        if in_ci():
            pytest.fail(f"{exc} is missing under CI=true", pytrace=False)
        pytest.skip(f"{exc} is not available")
    field, pattern = v.edit(g)
    path = tmp_path / f"{v.base}-{re.sub(r'[^A-Za-z0-9]+', '_', v.name)}.glb"
    path.write_bytes(g.bytes())
    with pytest.raises(MeshFormatError) as exc:
        read_gltf(path)
    e = exc.value
    assert e.source == str(path)
    assert e.field == field, (e.field, str(e))
    assert str(e).startswith(f"{path.name}: "), str(e)
    assert re.search(pattern, str(e)), str(e)
    # the public loader stops at the same place: no model, nothing half-loaded
    with pytest.raises(MeshFormatError) as again:
        workbench.load(path)
    assert again.value.field == field


def test_corrupted_compressed_bytes_never_crash(tmp_path: Path) -> None:
    """Random byte damage inside the meshopt and Draco streams: a result or a MeshFormatError, nothing else."""
    rng = np.random.default_rng(0)
    for base in ("gltfpack", "draco"):
        try:
            g0 = Glb(base)
        except ToolMissing:
            pytest.skip("writers not available")
        if base == "gltfpack":
            ext = g0.meshopt(g0.pos)
            start, length = ext.get("byteOffset", 0), ext["byteLength"]
        else:
            bv = g0.doc["bufferViews"][g0.draco()["bufferView"]]
            start, length = bv.get("byteOffset", 0), bv["byteLength"]
        for k in range(60):
            g = Glb(base)
            for pos in rng.integers(start, start + length, size=int(rng.integers(1, 6))):
                g.bin[pos] = int(rng.integers(0, 256))
            path = tmp_path / f"{base}{k}.glb"
            path.write_bytes(g.bytes())
            try:
                face = read_gltf(path)
            except MeshFormatError as exc:
                assert exc.source == str(path)
                continue
            assert np.isfinite(face.vertices).all()
            assert face.polygons.indices.max() < face.n_vertices


def _leaves(obj: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _leaves(v, (*path, k))] or [path]
    if isinstance(obj, list):
        return [p for i, v in enumerate(obj) for p in _leaves(v, (*path, i))] or [path]
    return [path]


JSON_VALUES = st.one_of(
    st.integers(-3, 70_000),
    st.sampled_from([0, 1, 2, 3, 4, 8, 2**31, 2**32 - 1, 10**30, -1]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["ATTRIBUTES", "TRIANGLES", "INDICES", "EXPONENTIAL", "OCTAHEDRAL", "NONE", ""]),
    st.none(),
    st.booleans(),
    st.lists(st.integers(-2, 10), max_size=4),
    st.dictionaries(st.sampled_from(["POSITION", "bufferView", "count"]), st.integers(-1, 30), max_size=2),
)


@pytest.mark.parametrize("base", ["gltfpack", "draco", "quantize"])
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_fuzz_json_of_real_files(base: str, tmp_path: Path, data: st.DataObject) -> None:
    """Any JSON field of a real writer's file set to a random value: a result or a MeshFormatError."""
    try:
        g = Glb(base)
    except ToolMissing:
        pytest.skip("writers not available")
    leaves = _leaves(g.doc)
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(leaves))
        if not path:
            break
        target: Any = g.doc
        for k in path[:-1]:
            target = target[k]
        if data.draw(st.booleans()):
            target[path[-1]] = data.draw(JSON_VALUES)
        else:
            del target[path[-1]]
            leaves = _leaves(g.doc)
    p = tmp_path / f"fuzz-{base}.glb"
    p.write_bytes(g.bytes())
    try:
        face = read_gltf(p)
    except MeshFormatError as exc:
        assert exc.source == str(p)
        return
    assert np.isfinite(face.vertices).all()
    assert face.polygons.indices.max() < face.n_vertices
    for _, d in face.shapes:
        assert d.shape == face.vertices.shape and np.isfinite(d).all()
