"""Checked access to a glTF document: typed fields, buffers, bufferViews and accessors.

Every count, offset and stride is checked with Python integers against the
bytes actually present *before* an array is allocated, and every problem
raises :class:`MeshFormatError` naming the JSON path of the field
(``accessors[3] (meshes[0].primitives[0].targets[2].POSITION).count``).

Accessors are decoded as the spec says: any component type, ``normalized``
integers (``KHR_mesh_quantization``), interleaved ``byteStride``, sparse
substitution, no bufferView (zeros). A bufferView compressed with
``EXT_meshopt_compression`` / ``KHR_meshopt_compression`` is decoded once,
when an accessor first reads it (:func:`.compression.decode_meshopt`).
"""

from __future__ import annotations

import base64
import binascii
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn
from urllib.parse import unquote

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.gltf.compression import MESHOPT_EXTENSIONS, MeshoptView, decode_meshopt

__all__ = ["Gltf", "View"]

BYTE, UNSIGNED_BYTE, SHORT, UNSIGNED_SHORT, UNSIGNED_INT, FLOAT = (
    5120,
    5121,
    5122,
    5123,
    5125,
    5126,
)
DTYPES: dict[int, str] = {
    BYTE: "i1",
    UNSIGNED_BYTE: "u1",
    SHORT: "<i2",
    UNSIGNED_SHORT: "<u2",
    UNSIGNED_INT: "<u4",
    FLOAT: "<f4",
}
INDEX_TYPES = (UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT)
# divisor and lower clamp of normalized integers (glTF 2.0 spec, 3.11 "Animations" / 3.7.2)
NORMALIZE: dict[int, tuple[float, float]] = {
    BYTE: (127.0, -1.0),
    UNSIGNED_BYTE: (255.0, 0.0),
    SHORT: (32767.0, -1.0),
    UNSIGNED_SHORT: (65535.0, 0.0),
}
N_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


@dataclass(frozen=True)
class View:
    """A bufferView after its JSON was checked (its bytes are fetched on demand)."""

    index: int
    field: str
    buffer: int
    start: int
    length: int
    stride: int | None
    meshopt: MeshoptView | None


class Gltf:
    """Validated access to the JSON document and its buffers.

    Parameters
    ----------
    doc : Any
        The parsed JSON.
    src : str
        File path, for messages.
    bin_chunk : bytes or None
        The GLB BIN chunk (buffer 0 without uri).
    base_dir : Path
        Folder that relative buffer URIs are resolved against.
    """

    def __init__(self, doc: Any, src: str, bin_chunk: bytes | None, base_dir: Path) -> None:
        self.src = src
        self.bin_chunk = bin_chunk
        self.base_dir = base_dir
        if not isinstance(doc, dict):
            self.fail("JSON", "top level is not a JSON object")
        self.doc: dict[str, Any] = doc
        self._buffers: dict[int, bytes] = {}
        self._decoded: dict[int, bytes] = {}

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
        if not is_int(i) or not 0 <= i < len(arr):
            self.fail(field, f"refers to {key}[{i!r:.40}] but the file has {len(arr)} {key}")
        obj = arr[i]
        if not isinstance(obj, dict):
            self.fail(f"{key}[{i}]", "expected a JSON object")
        return obj

    def obj(self, parent: dict[str, Any], key: str, field: str) -> dict[str, Any]:
        """``parent[key]`` as a JSON object ({} when absent)."""
        v = parent.get(key, {})
        if not isinstance(v, dict):
            self.fail(f"{field}.{key}", "expected a JSON object")
        return v

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
        if not is_int(v) or v < minimum:
            self.fail(f"{field}.{key}", f"expected an integer >= {minimum}, got {v!r:.40}")
        return int(v)

    def get_numbers(
        self, obj: dict[str, Any], key: str, field: str, n: int, default: list[float]
    ) -> NDArray[np.float64]:
        """``obj[key]`` as ``n`` finite numbers (``default`` when absent)."""
        if key not in obj:
            return np.array(default, np.float64)
        v = obj[key]
        if (
            not isinstance(v, list)
            or len(v) != n
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        ):
            self.fail(f"{field}.{key}", f"expected an array of {n} numbers, got {v!r:.60}")
        if not all(math.isfinite(x) for x in v):
            self.fail(f"{field}.{key}", f"is not finite: {v!r:.60}")
        return np.array(v, np.float64)

    # ---- buffers ---------------------------------------------------------------
    def buffer_length(self, i: Any, field: str) -> int:
        """Declared byteLength of buffers[i] (its bytes are not read)."""
        b = self.item("buffers", i, field)
        return self.get_int(b, "byteLength", f"buffers[{i}]", minimum=1)

    def buffer(self, i: int, field: str) -> bytes:
        if i in self._buffers:
            return self._buffers[i]
        b = self.item("buffers", i, field)
        bfield = f"buffers[{i}]"
        length = self.get_int(b, "byteLength", bfield, minimum=1)
        uri = b.get("uri")
        if uri is None:
            if i != 0 or self.bin_chunk is None:
                ext = b.get("extensions")
                if isinstance(ext, dict) and any(e in ext for e in MESHOPT_EXTENSIONS):
                    self.fail(
                        bfield,
                        "is a meshopt fallback buffer without data, but a bufferView that is "
                        "not meshopt-compressed reads it",
                    )
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

    # ---- bufferViews -------------------------------------------------------------
    def view(self, bvi: Any, field: str) -> View:
        """The checked JSON of a bufferView; no bytes are read or decoded yet."""
        bv = self.item("bufferViews", bvi, field)
        bfield = f"bufferViews[{bvi}]"
        bi = self.get_int(bv, "buffer", bfield)
        start = self.get_int(bv, "byteOffset", bfield, default=0)
        length = self.get_int(bv, "byteLength", bfield, minimum=1)
        stride = self.get_int(bv, "byteStride", bfield, minimum=4) if "byteStride" in bv else None
        if stride is not None and stride > 252:
            self.fail(f"{bfield}.byteStride", f"{stride} is above the maximum 252")
        if stride is not None and stride % 4:
            self.fail(f"{bfield}.byteStride", f"{stride} is not a multiple of 4")
        blen = self.buffer_length(bi, f"{bfield}.buffer")
        if start + length > blen:
            self.fail(
                bfield,
                f"bytes {start}..{start + length} lie past the end of buffers[{bi}] ({blen} bytes)",
            )
        exts = self.obj(bv, "extensions", bfield)
        mo: MeshoptView | None = None
        for name in MESHOPT_EXTENSIONS:
            if name in exts:
                mo = self._meshopt(exts[name], f"{bfield}.extensions.{name}", length, name)
        return View(int(bvi), bfield, bi, start, length, stride, mo)

    def _meshopt(self, ext: Any, field: str, length: int, name: str) -> MeshoptView:
        if not isinstance(ext, dict):
            self.fail(field, "expected a JSON object")
        bi = self.get_int(ext, "buffer", field)
        start = self.get_int(ext, "byteOffset", field, default=0)
        clen = self.get_int(ext, "byteLength", field, minimum=1)
        stride = self.get_int(ext, "byteStride", field, minimum=1)
        count = self.get_int(ext, "count", field, minimum=1)
        mode = ext.get("mode")
        filt = ext.get("filter", "NONE")
        mv = MeshoptView(name, bi, start, clen, stride, count, mode, filt)
        problem = mv.problem()
        if problem is not None:
            key, msg = problem
            self.fail(f"{field}.{key}" if key else field, msg)
        if count * stride != length:
            self.fail(
                f"{field}.count",
                f"{count} elements x byteStride {stride} = {count * stride} bytes, but the "
                f"bufferView's byteLength is {length}",
            )
        blen = self.buffer_length(bi, f"{field}.buffer")
        if start + clen > blen:
            self.fail(
                field,
                f"compressed bytes {start}..{start + clen} lie past the end of buffers[{bi}] "
                f"({blen} bytes)",
            )
        return mv

    def view_bytes(self, v: View) -> tuple[bytes, int]:
        """``(bytes, offset of the view's first byte in them)``, decoding meshopt once."""
        if v.meshopt is None:
            return self.buffer(v.buffer, f"{v.field}.buffer"), v.start
        if v.index not in self._decoded:
            mo = v.meshopt
            field = f"{v.field}.extensions.{mo.extension}"
            data = self.buffer(mo.buffer, f"{field}.buffer")
            try:
                self._decoded[v.index] = decode_meshopt(mo, data[mo.start : mo.start + mo.length])
            except ValueError as exc:
                self.fail(field, f"meshopt data cannot be decoded ({exc})")
        return self._decoded[v.index], 0

    # ---- accessors -------------------------------------------------------------
    def accessor_header(
        self, ai: Any, field: str, *, types: tuple[str, ...], as_index: bool = False
    ) -> tuple[dict[str, Any], str, int, int, int, bool]:
        """``(json, field, componentType, ncomp, count, normalized)`` of a checked accessor."""
        acc = self.item("accessors", ai, field)
        afield = f"accessors[{ai}] ({field})"
        ctype = self.get_int(acc, "componentType", afield)
        if ctype not in DTYPES:
            self.fail(f"{afield}.componentType", f"unknown component type {ctype}")
        atype = acc.get("type")
        if atype not in types:
            self.fail(f"{afield}.type", f"expected {' or '.join(types)}, got {atype!r:.40}")
        count = self.get_int(acc, "count", afield, minimum=1)
        normalized = acc.get("normalized", False)
        if not isinstance(normalized, bool):
            self.fail(f"{afield}.normalized", "expected true or false")
        if as_index and (ctype not in INDEX_TYPES or normalized):
            self.fail(afield, "indices must be unsigned byte/short/int, not normalized")
        if not as_index and ctype == UNSIGNED_INT:
            self.fail(f"{afield}.componentType", "UNSIGNED_INT (5125) is only allowed for indices")
        if normalized and ctype not in NORMALIZE:
            self.fail(f"{afield}.normalized", "only byte/short component types can be normalized")
        return acc, afield, ctype, N_COMPONENTS[atype], count, normalized

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
        acc, afield, ctype, ncomp, count, normalized = self.accessor_header(
            ai, field, types=types, as_index=as_index
        )
        if expect_count is not None and count != expect_count:
            self.fail(
                f"{afield}.count", f"is {count}, expected {expect_count} (the POSITION count)"
            )
        dtype = np.dtype(DTYPES[ctype])
        elem = dtype.itemsize * ncomp

        if "bufferView" in acc:
            v = self.view(acc["bufferView"], f"{afield}.bufferView")
            if as_index and v.stride is not None:
                self.fail(afield, "the bufferView of indices must not have a byteStride")
            offset = self.get_int(acc, "byteOffset", afield, default=0)
            if offset % dtype.itemsize:
                self.fail(
                    f"{afield}.byteOffset",
                    f"{offset} is not a multiple of the component size {dtype.itemsize}",
                )
            step = v.stride if v.stride is not None else elem
            if step < elem:
                self.fail(afield, f"byteStride {step} is smaller than one element ({elem} bytes)")
            # checked with Python ints before anything is read, decoded or allocated
            need = offset + step * (count - 1) + elem
            if need > v.length:
                self.fail(
                    afield,
                    f"declares {count} elements ({need} bytes from offset {offset}) but its "
                    f"bufferView holds only {v.length} bytes",
                )
            data, start = self.view_bytes(v)
            raw = np.ndarray(
                (count, ncomp),
                dtype=dtype,
                buffer=data,
                offset=start + offset,
                strides=(step, dtype.itemsize),
            ).copy()
        else:
            if expect_count is None and "sparse" not in acc:
                self.fail(afield, "has no bufferView (all zeros); not supported here")
            raw = np.zeros((count, ncomp), dtype=dtype)

        if "sparse" in acc:
            self._apply_sparse(acc["sparse"], raw, afield, dtype, ncomp)

        if as_index:
            return raw.reshape(-1).astype(np.int64)
        with np.errstate(invalid="ignore"):  # a signalling NaN in the file; check_vertices reports it
            out = raw.astype(np.float64)
        if normalized:
            div, lo = NORMALIZE[ctype]
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
        if ictype not in INDEX_TYPES:
            self.fail(f"{ifield}.componentType", f"{ictype} is not an unsigned byte/short/int type")
        idtype = np.dtype(DTYPES[ictype])
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
        v = self.view(obj.get("bufferView"), f"{field}.bufferView")
        offset = self.get_int(obj, "byteOffset", field, default=0)
        need = offset + count * ncomp * dtype.itemsize
        if need > v.length:
            self.fail(
                field,
                f"needs {need} bytes for {count} elements but its bufferView holds {v.length}",
            )
        data, start = self.view_bytes(v)
        return (
            np.frombuffer(data, dtype=dtype, count=count * ncomp, offset=start + offset)
            .reshape(count, ncomp)
            .copy()
        )
