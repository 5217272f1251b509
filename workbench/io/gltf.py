"""glTF 2.0 (.gltf / .glb) reader for a mesh with morph targets.

Reads one mesh: every TRIANGLES primitive's POSITION and indices (primitives
are concatenated with an index offset and become face groups named by their
material), and each morph target's POSITION as a delta. Target names come from
``mesh.extras.targetNames`` (the convention of Blender and three.js), else
``target_<i>``. Node transforms are not applied: positions are the mesh's own
coordinates. glTF units are metres, +y up.

Why the decoding is hand-written: pygltflib (kept for writing files and its
constants) turns the JSON into dataclasses without checking field types (a
string ``count`` stays a string), leaves morph targets as raw dicts, and has
no accessor decoding at all (byteStride, sparse accessors, normalized
integers); its GLB loader does not report truncated chunks. trimesh's loader
drops morph targets. The file is untrusted input, so every count and offset is
checked against the bytes actually present *before* anything is allocated, and
every problem becomes a :class:`MeshFormatError` naming the JSON field.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct
from pathlib import Path
from typing import Any, NoReturn
from urllib.parse import unquote

import numpy as np
from numpy.typing import NDArray
from pygltflib import (
    BYTE,
    FLOAT,
    SHORT,
    TRIANGLES,
    UNSIGNED_BYTE,
    UNSIGNED_INT,
    UNSIGNED_SHORT,
)

from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, check_faces, check_vertices
from workbench.io.base import ImportedFace, check_shape_names

__all__ = ["DESCRIPTION", "detect", "read", "read_gltf"]

DESCRIPTION = "a .glb or .gltf file (one mesh; morph targets become shapes)"

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942

_DTYPES: dict[int, str] = {
    BYTE: "i1",
    UNSIGNED_BYTE: "u1",
    SHORT: "<i2",
    UNSIGNED_SHORT: "<u2",
    UNSIGNED_INT: "<u4",
    FLOAT: "<f4",
}
# divisor and lower clamp for normalized integers (glTF 2.0 spec, "Animations"/"Meshes")
_NORMALIZE: dict[int, tuple[float, float]] = {
    BYTE: (127.0, -1.0),
    UNSIGNED_BYTE: (255.0, 0.0),
    SHORT: (32767.0, -1.0),
    UNSIGNED_SHORT: (65535.0, 0.0),
}
_N_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_MODES = {
    0: "POINTS",
    1: "LINES",
    2: "LINE_LOOP",
    3: "LINE_STRIP",
    4: "TRIANGLES",
    5: "TRIANGLE_STRIP",
    6: "TRIANGLE_FAN",
}
# required extensions we can read (quantization only widens the allowed component types)
_SUPPORTED_REQUIRED = {"KHR_mesh_quantization"}


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in (".glb", ".gltf")


def read(path: Path) -> ImportedFace:
    return read_gltf(path)


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


class _Gltf:
    """Validated access to the JSON document and its buffers."""

    def __init__(self, doc: Any, src: str, bin_chunk: bytes | None, base_dir: Path) -> None:
        self.src = src
        self.bin_chunk = bin_chunk
        self.base_dir = base_dir
        if not isinstance(doc, dict):
            self.fail("JSON", "top level is not a JSON object")
        self.doc: dict[str, Any] = doc
        self._buffers: dict[int, bytes] = {}

    def fail(self, field: str, msg: str) -> NoReturn:
        raise MeshFormatError(self.src, field, f"{field}: {msg}")

    # ---- typed field access -------------------------------------------------
    def array(self, key: str) -> list[Any]:
        v = self.doc.get(key, [])
        if not isinstance(v, list):
            self.fail(key, "expected a JSON array")
        return v

    def item(self, key: str, i: Any, field: str) -> dict[str, Any]:
        arr = self.array(key)
        if not _is_int(i) or not 0 <= i < len(arr):
            self.fail(field, f"refers to {key}[{i!r}] but the file has {len(arr)} {key}")
        obj = arr[i]
        if not isinstance(obj, dict):
            self.fail(f"{key}[{i}]", "expected a JSON object")
        return obj

    def get_int(
        self,
        obj: dict[str, Any],
        key: str,
        field: str,
        default: int | None = None,
        minimum: int = 0,
    ) -> int:
        if key not in obj:
            if default is None:
                self.fail(f"{field}.{key}", "required integer is missing")
            return default
        v = obj[key]
        if not _is_int(v) or v < minimum:
            self.fail(f"{field}.{key}", f"expected an integer >= {minimum}, got {v!r:.40}")
        return int(v)

    # ---- buffers ---------------------------------------------------------------
    def buffer(self, i: int, field: str) -> bytes:
        if i in self._buffers:
            return self._buffers[i]
        b = self.item("buffers", i, field)
        bfield = f"buffers[{i}]"
        length = self.get_int(b, "byteLength", bfield, minimum=1)
        uri = b.get("uri")
        if uri is None:
            if i != 0 or self.bin_chunk is None:
                self.fail(bfield, "has no uri and the file has no GLB binary chunk")
            data = self.bin_chunk
        elif not isinstance(uri, str):
            self.fail(f"{bfield}.uri", "expected a string")
        elif uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if not head.endswith(";base64"):
                self.fail(f"{bfield}.uri", "data URI is not base64")
            try:
                data = base64.b64decode(payload, validate=True)
            except (binascii.Error, ValueError):
                self.fail(f"{bfield}.uri", "data URI is not valid base64")
        else:
            p = self.base_dir / unquote(uri)
            try:
                data = p.read_bytes()
            except OSError as exc:
                self.fail(f"{bfield}.uri", f"cannot read {uri!r:.80}: {exc.strerror}")
        assert data is not None
        if len(data) < length:
            self.fail(
                bfield,
                f"byteLength is {length} but only {len(data)} bytes are present (truncated?)",
            )
        self._buffers[i] = data
        return data

    def view(self, bvi: Any, field: str) -> tuple[bytes, int, int, int | None]:
        """(buffer bytes, start, byteLength, byteStride) of a bufferView, range-checked."""
        bv = self.item("bufferViews", bvi, field)
        bfield = f"bufferViews[{bvi}]"
        bi = self.get_int(bv, "buffer", bfield)
        start = self.get_int(bv, "byteOffset", bfield, default=0)
        length = self.get_int(bv, "byteLength", bfield, minimum=1)
        stride = self.get_int(bv, "byteStride", bfield, minimum=4) if "byteStride" in bv else None
        if stride is not None and stride > 252:
            self.fail(f"{bfield}.byteStride", f"{stride} is above the maximum 252")
        data = self.buffer(bi, f"{bfield}.buffer")
        if start + length > len(data):
            self.fail(
                bfield,
                f"bytes {start}..{start + length} lie past the end of buffers[{bi}] ({len(data)} bytes)",
            )
        return data, start, length, stride

    # ---- accessors -------------------------------------------------------------
    def accessor(
        self,
        ai: Any,
        field: str,
        *,
        types: tuple[str, ...],
        expect_count: int | None = None,
        as_index: bool = False,
    ) -> NDArray[Any]:
        """Decode accessor ``ai`` to (count, ncomp) float64, or (count,) int64 if ``as_index``."""
        acc = self.item("accessors", ai, field)
        afield = f"accessors[{ai}] ({field})"
        ctype = self.get_int(acc, "componentType", afield)
        if ctype not in _DTYPES:
            self.fail(f"{afield}.componentType", f"unknown component type {ctype}")
        atype = acc.get("type")
        if atype not in types:
            self.fail(f"{afield}.type", f"expected {' or '.join(types)}, got {atype!r:.40}")
        ncomp = _N_COMPONENTS[atype]
        count = self.get_int(acc, "count", afield, minimum=1)
        if expect_count is not None and count != expect_count:
            self.fail(
                f"{afield}.count", f"is {count}, expected {expect_count} (the POSITION count)"
            )
        normalized = acc.get("normalized", False)
        if not isinstance(normalized, bool):
            self.fail(f"{afield}.normalized", "expected true or false")
        if as_index and (ctype not in (UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT) or normalized):
            self.fail(afield, "indices must be unsigned byte/short/int, not normalized")
        if normalized and ctype not in _NORMALIZE:
            self.fail(f"{afield}.normalized", "only byte/short component types can be normalized")
        dtype = np.dtype(_DTYPES[ctype])
        elem = dtype.itemsize * ncomp

        if "bufferView" in acc:
            data, start, length, stride = self.view(acc["bufferView"], f"{afield}.bufferView")
            if as_index and stride is not None:
                self.fail(afield, "the bufferView of indices must not have a byteStride")
            offset = self.get_int(acc, "byteOffset", afield, default=0)
            step = stride if stride is not None else elem
            if step < elem:
                self.fail(afield, f"byteStride {step} is smaller than one element ({elem} bytes)")
            # checked with Python ints before allocating anything
            need = offset + step * (count - 1) + elem
            if need > length:
                self.fail(
                    afield,
                    f"declares {count} elements ({need} bytes from offset {offset}) but its "
                    f"bufferView holds only {length} bytes",
                )
            raw = np.ndarray(
                (count, ncomp),
                dtype=dtype,
                buffer=data,
                offset=start + offset,
                strides=(step, dtype.itemsize),
            ).copy()
        else:
            if expect_count is None:
                self.fail(afield, "has no bufferView (all zeros); not supported here")
            raw = np.zeros((count, ncomp), dtype=dtype)

        if "sparse" in acc:
            self._apply_sparse(acc["sparse"], raw, afield, dtype, ncomp)

        if as_index:
            return raw.reshape(-1).astype(np.int64)
        out = raw.astype(np.float64)
        if normalized:
            div, lo = _NORMALIZE[ctype]
            out = np.maximum(out / div, lo)
        return out

    def _apply_sparse(
        self, sparse: Any, raw: NDArray[Any], afield: str, dtype: np.dtype[Any], ncomp: int
    ) -> None:
        sfield = f"{afield}.sparse"
        if not isinstance(sparse, dict):
            self.fail(sfield, "expected a JSON object")
        count = raw.shape[0]
        scount = self.get_int(sparse, "count", sfield, minimum=1)
        if scount > count:
            self.fail(f"{sfield}.count", f"{scount} exceeds the accessor count {count}")
        ind, val = sparse.get("indices"), sparse.get("values")
        if not isinstance(ind, dict) or not isinstance(val, dict):
            self.fail(sfield, "needs 'indices' and 'values' objects")
        ifield, vfield = f"{sfield}.indices", f"{sfield}.values"
        ictype = self.get_int(ind, "componentType", ifield)
        if ictype not in (UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT):
            self.fail(f"{ifield}.componentType", f"{ictype} is not an unsigned byte/short/int type")
        idtype = np.dtype(_DTYPES[ictype])
        idx = self._packed(ind, ifield, idtype, scount, 1).reshape(-1).astype(np.int64)
        vals = self._packed(val, vfield, dtype, scount, ncomp)
        if idx.size > 1 and np.any(np.diff(idx) <= 0):
            self.fail(ifield, "sparse indices must be strictly increasing")
        if idx.max() >= count:
            self.fail(
                ifield, f"sparse index {int(idx.max())} out of range (accessor count {count})"
            )
        raw[idx] = vals

    def _packed(
        self, obj: dict[str, Any], field: str, dtype: np.dtype[Any], count: int, ncomp: int
    ) -> NDArray[Any]:
        """Tightly packed array from a sparse indices/values object."""
        data, start, length, _ = self.view(obj.get("bufferView"), f"{field}.bufferView")
        offset = self.get_int(obj, "byteOffset", field, default=0)
        need = offset + count * ncomp * dtype.itemsize
        if need > length:
            self.fail(
                field, f"needs {need} bytes for {count} elements but its bufferView holds {length}"
            )
        return (
            np.frombuffer(data, dtype=dtype, count=count * ncomp, offset=start + offset)
            .reshape(count, ncomp)
            .copy()
        )


def _split_glb(data: bytes, src: str) -> tuple[bytes, bytes | None]:
    """JSON and BIN chunks of a GLB container, with length checks."""
    if len(data) < 12:
        raise MeshFormatError(
            src, "header", f"truncated GLB: {len(data)} bytes, the header alone is 12"
        )
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if magic != _GLB_MAGIC:
        raise MeshFormatError(src, "header", f"not a GLB file (magic {magic!r})")
    if version != 2:
        raise MeshFormatError(src, "header", f"GLB version {version}, only 2 is supported")
    if length != len(data):
        what = "truncated GLB" if length > len(data) else "GLB has trailing bytes"
        raise MeshFormatError(
            src, "header", f"{what}: header says {length} bytes, file has {len(data)}"
        )
    json_chunk: bytes | None = None
    bin_chunk: bytes | None = None
    off, k = 12, 0
    while off < length:
        if off + 8 > length:
            raise MeshFormatError(
                src, f"chunk {k}", f"truncated GLB: chunk {k} header cut off at byte {off}"
            )
        clen, ctype = struct.unpack_from("<II", data, off)
        if off + 8 + clen > length:
            raise MeshFormatError(
                src,
                f"chunk {k}",
                f"truncated GLB: chunk {k} declares {clen} bytes, only {length - off - 8} remain",
            )
        body = data[off + 8 : off + 8 + clen]
        if k == 0:
            if ctype != _CHUNK_JSON:
                raise MeshFormatError(src, "chunk 0", "first GLB chunk is not JSON")
            json_chunk = body
        elif ctype == _CHUNK_BIN and bin_chunk is None and k == 1:
            bin_chunk = body
        elif ctype in (_CHUNK_JSON, _CHUNK_BIN):
            raise MeshFormatError(src, f"chunk {k}", "unexpected extra JSON/BIN chunk")
        # other chunk types are ignored, as the spec requires
        off += 8 + clen
        k += 1
    if json_chunk is None:
        raise MeshFormatError(src, "chunk 0", "GLB has no JSON chunk")
    return json_chunk, bin_chunk


def _parse_json(raw: bytes, src: str) -> Any:
    try:
        text = raw.decode("utf-8")
        return json.loads(text)
    except UnicodeDecodeError as exc:
        raise MeshFormatError(src, "JSON", f"JSON is not UTF-8 (byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise MeshFormatError(
            src, "JSON", f"garbled JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from None
    except (ValueError, RecursionError) as exc:  # e.g. a 5000-digit integer, absurd nesting
        raise MeshFormatError(src, "JSON", f"unreadable JSON: {type(exc).__name__}") from None


def _pick_mesh(g: _Gltf, mesh: int | str | None) -> int:
    meshes = g.array("meshes")
    if not meshes:
        g.fail("meshes", "the file has no meshes")
    if mesh is None:
        for i, m in enumerate(meshes):
            prims = m.get("primitives") if isinstance(m, dict) else None
            if isinstance(prims, list) and any(
                isinstance(p, dict) and p.get("targets") for p in prims
            ):
                return i
        return 0
    if isinstance(mesh, str):
        names = [m.get("name") if isinstance(m, dict) else None for m in meshes]
        if mesh not in names:
            g.fail("meshes", f"no mesh named {mesh!r}; names: {names}")
        return names.index(mesh)
    if not 0 <= mesh < len(meshes):
        g.fail("meshes", f"mesh index {mesh} out of range ({len(meshes)} meshes)")
    return mesh


def read_gltf(path: str | Path, mesh: int | str | None = None) -> ImportedFace:
    """Read one mesh and its morph targets from a .glb or .gltf file.

    Parameters
    ----------
    path : str or Path
        .glb (binary) or .gltf (JSON with external or data-URI buffers).
    mesh : int or str, optional
        Mesh index or name; default the first mesh that has morph targets,
        else the first mesh.

    Returns
    -------
    ImportedFace
        Positions (n, 3) float64, triangles as polygons, one face group per
        primitive when there are several, shapes from the targets' POSITION
        (float32 deltas), units "m", up axis "+y".

    Raises
    ------
    MeshFormatError
        Truncated or garbled container/JSON, counts larger than the data, index
        out of range, non-TRIANGLES primitives, NaN/inf, mismatched targets,
        degenerate or duplicate triangles, duplicate target names.
    """
    p = Path(path)
    src = str(p)
    data = p.read_bytes()
    if not data:
        raise MeshFormatError(src, "file", "empty file")
    if p.suffix.lower() == ".glb" or data[:4] == _GLB_MAGIC:
        json_raw, bin_chunk = _split_glb(data, src)
    else:
        json_raw, bin_chunk = data, None
    g = _Gltf(_parse_json(json_raw, src), src, bin_chunk, p.parent)

    asset = g.doc.get("asset")
    if not isinstance(asset, dict) or not str(asset.get("version", "")).startswith("2"):
        g.fail("asset.version", "missing or not glTF 2.x")
    required = g.doc.get("extensionsRequired", [])
    if not isinstance(required, list) or not all(isinstance(e, str) for e in required):
        g.fail("extensionsRequired", "expected an array of strings")
    unsupported = [e for e in required if e not in _SUPPORTED_REQUIRED]
    if unsupported:
        g.fail(
            "extensionsRequired",
            f"unsupported extensions {unsupported} (e.g. Draco/meshopt compression)",
        )

    mi = _pick_mesh(g, mesh)
    m = g.item("meshes", mi, "meshes")
    mfield = f"meshes[{mi}]"
    prims = m.get("primitives")
    if not isinstance(prims, list) or not prims:
        g.fail(f"{mfield}.primitives", "expected a non-empty array")

    positions: list[NDArray[np.float64]] = []
    tris: list[NDArray[np.int64]] = []
    target_deltas: list[list[NDArray[np.float64]]] = []
    n_targets: int | None = None
    group_names: list[str] = []
    offset = 0
    for k, prim in enumerate(prims):
        pfield = f"{mfield}.primitives[{k}]"
        if not isinstance(prim, dict):
            g.fail(pfield, "expected a JSON object")
        mode = g.get_int(prim, "mode", pfield, default=TRIANGLES)
        if mode != TRIANGLES:
            g.fail(
                f"{pfield}.mode",
                f"{mode} ({_MODES.get(mode, '?')}) is not supported; only TRIANGLES (4)",
            )
        attrs = prim.get("attributes")
        if not isinstance(attrs, dict) or "POSITION" not in attrs:
            g.fail(f"{pfield}.attributes", "POSITION is missing")
        V = g.accessor(attrs["POSITION"], f"{pfield}.attributes.POSITION", types=("VEC3",))
        V = check_vertices(V, src, f"{pfield}.attributes.POSITION")
        n = V.shape[0]
        if "indices" in prim:
            idx = g.accessor(prim["indices"], f"{pfield}.indices", types=("SCALAR",), as_index=True)
            ifield = f"{pfield}.indices"
        else:
            idx = np.arange(n, dtype=np.int64)
            ifield = f"{pfield} (non-indexed)"
        if idx.size % 3:
            g.fail(ifield, f"{idx.size} indices is not a multiple of 3")
        if idx.size and idx.max() >= n:
            g.fail(ifield, f"index {int(idx.max())} out of range (POSITION has {n} vertices)")

        targets = prim.get("targets", [])
        if not isinstance(targets, list):
            g.fail(f"{pfield}.targets", "expected an array")
        if n_targets is None:
            n_targets = len(targets)
            target_deltas = [[] for _ in range(n_targets)]
        elif len(targets) != n_targets:
            g.fail(f"{pfield}.targets", f"has {len(targets)} targets, primitive 0 has {n_targets}")
        for t, target in enumerate(targets):
            tfield = f"{pfield}.targets[{t}]"
            if not isinstance(target, dict):
                g.fail(tfield, "expected a JSON object")
            if "POSITION" in target:
                D = g.accessor(
                    target["POSITION"], f"{tfield}.POSITION", types=("VEC3",), expect_count=n
                )
                D = check_vertices(D, src, f"{tfield}.POSITION")
            else:  # a target may move only normals
                D = np.zeros((n, 3))
            target_deltas[t].append(D)

        positions.append(V)
        tris.append(idx.reshape(-1, 3) + offset)
        offset += n
        mat = prim.get("material")
        name = None
        if mat is not None:
            material = g.item("materials", mat, f"{pfield}.material")
            name = material.get("name") if isinstance(material.get("name"), str) else None
        group_names.append(name or f"primitive_{k}")

    V_all = np.concatenate(positions)
    F = np.concatenate(tris)
    if F.shape[0] == 0:
        g.fail(mfield, "has no triangles")
    polygons = Polygons.from_triangles(F)
    check_faces(polygons, V_all.shape[0], src, vertices=V_all, field=f"{mfield} triangles")

    n_t = n_targets or 0
    names = _target_names(g, m, mfield, n_t)
    check_shape_names(names, [src] * n_t, src)
    shapes = [(names[t], np.concatenate(target_deltas[t]).astype(np.float32)) for t in range(n_t)]

    face_groups = None
    if len(prims) > 1:
        face_groups = np.repeat(np.arange(len(prims), dtype=np.int32), [len(t) for t in tris])
    return ImportedFace(
        vertices=V_all,
        polygons=polygons,
        face_groups=face_groups,
        group_names=group_names if face_groups is not None else [],
        shapes=shapes,
        source_files=[src],
        units="m",
        up_axis="+y",
    )


def _target_names(g: _Gltf, m: dict[str, Any], mfield: str, n_t: int) -> list[str]:
    extras = m.get("extras")
    names = extras.get("targetNames") if isinstance(extras, dict) else None
    if names is None:
        return [f"target_{t}" for t in range(n_t)]
    if not isinstance(names, list) or not all(isinstance(s, str) for s in names):
        g.fail(f"{mfield}.extras.targetNames", "expected an array of strings")
    if len(names) != n_t:
        g.fail(f"{mfield}.extras.targetNames", f"has {len(names)} names for {n_t} targets")
    return list(names)
