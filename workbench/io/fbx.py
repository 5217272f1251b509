"""FBX reader: meshes with shape keys (blend shapes) and their animation, through Blender's importer.

The registry's module for ``.fbx`` (``detect``, ``read``, ``DESCRIPTION``).
FBX has no open specification and no maintained Python reader (the FBX SDK is
proprietary), so the file is imported by Blender's own FBX importer, run in the
bpy venv as a subprocess (:mod:`.blender_bridge`), which dumps the meshes,
their shape keys and the keyframes of the shape-key values. Blender applies
the file's object transforms, axis system and unit scale; the reader turns
Blender's z-up metres back into the file's unit, y up, front +z:

* **geometry**: every mesh object (sorted by name), its vertices under the
  object's world transform, faces as in the file (n-gons kept); several meshes
  become face groups named after the objects;
* **shapes**: one per shape key (FBX ``BlendShapeChannel``), delta from its
  relative key; a name on several meshes is one shape;
* **units**: ``GlobalSettings.UnitScaleFactor`` is centimetres per unit
  (1 = cm, 100 = m, 0.1 = mm, 2.54 = in, 10 = dm): coordinates are given in that
  unit, which ``ImportedFace.units`` states (metres-per-unit in
  ``FaceModel.metadata``); another factor gives metres;
* **animation** (:func:`read_fbx_animation`): the F-curves of the shape-key
  values (FBX ``DeformPercent`` / 100) on the timeline, key frame ``f`` at
  ``f / fps`` seconds with the file's frame rate (``GlobalSettings``
  ``TimeMode``/``CustomFrameRate``), imported with ``anim_offset=0`` (Blender's
  default shifts keys one frame late). Blender's importer makes every key
  LINEAR, so these are linear keys at the file's key times and values.

Before Blender runs, the binary file is walked by a small checked parser
(:func:`parse_fbx`): every node's end offset, property and array (zlib
included) is checked against the bytes present, and the mesh, shape, curve and
unit fields Blender will read are checked for counts, ranges and finite numbers,
so a malformed file fails in milliseconds with a :class:`MeshFormatError`
naming the file, the node path and the field, never half-loaded or as a
traceback from inside Blender. ASCII FBX is refused with a note (Blender's
importer reads binary FBX 7.1 and later only).
"""

from __future__ import annotations

import logging
import math
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.base import ImportedFace
from workbench.io.blender_bridge import BlenderDump, run_dump
from workbench.io.parts import Part, merge_parts, polygons_from_counts, reverse_winding, to_y_up

__all__ = [
    "DESCRIPTION",
    "FbxFile",
    "FbxNode",
    "detect",
    "parse_fbx",
    "read",
    "read_fbx",
    "read_fbx_animation",
]

log = logging.getLogger("workbench.io")

DESCRIPTION = (
    "a binary .fbx file (meshes with shape keys and their animation; read by Blender's "
    "FBX importer in the bpy venv, WORKBENCH_BPY_PYTHON)"
)

MAGIC = b"Kaydara FBX Binary  \x00"
#: oldest FBX version Blender's importer reads
MIN_VERSION = 7100
_MAX_DEPTH = 64
#: FBX UnitScaleFactor (centimetres per unit) -> unit name
_UNIT_OF_SCALE = {0.1: "mm", 1.0: "cm", 2.54: "in", 10.0: "dm", 100.0: "m"}
_SCALAR = {"Y": ("<h", 2), "C": ("<B", 1), "I": ("<i", 4), "F": ("<f", 4), "D": ("<d", 8), "L": ("<q", 8)}
_ARRAY: dict[str, np.dtype[Any]] = {"f": np.dtype("<f4"), "d": np.dtype("<f8"), "l": np.dtype("<i8"), "i": np.dtype("<i4"), "b": np.dtype("u1")}


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() == ".fbx"


def read(path: Path) -> ImportedFace:
    return read_fbx(path)


# ------------------------------------------------------------------ binary structure
@dataclass
class FbxNode:
    """One node record of a binary FBX file.

    ``props`` holds Python scalars, ``bytes`` (S and R properties) and
    read-only numpy arrays (array properties); ``path`` is e.g.
    ``"Objects/Geometry"``; ``offset`` the byte where the record starts;
    ``codes`` the property type codes (``"LSS"``...), so a tree can be written back.
    """

    name: str
    props: list[Any]
    children: list[FbxNode] = field(default_factory=list)
    path: str = ""
    offset: int = 0
    codes: str = ""

    def child(self, name: str) -> FbxNode | None:
        return next((c for c in self.children if c.name == name), None)

    def label(self) -> str:
        """``Geometry 'jawOpen' (Shape)`` for objects, the path otherwise."""
        if len(self.props) >= 3 and isinstance(self.props[1], bytes) and isinstance(self.props[2], bytes):
            name, cls = object_name(self.props[1]), self.props[2].decode("utf-8", "replace")
            if name or cls:
                return f"{self.path} '{name}' ({cls})"
            return f"{self.path} {self.props[0]}"
        return self.path


@dataclass
class FbxFile:
    """A parsed binary FBX: its version and top-level nodes."""

    version: int
    nodes: list[FbxNode]

    def top(self, name: str) -> FbxNode | None:
        return next((n for n in self.nodes if n.name == name), None)


def object_name(raw: bytes) -> str:
    """``b"Head\\x00\\x01Model"`` → ``"Head"`` (FBX binary names carry their class after ``\\x00\\x01``)."""
    return raw.split(b"\x00\x01", 1)[0].decode("utf-8", "replace")


class _Parser:
    def __init__(self, data: bytes, src: str) -> None:
        self.data = data
        self.src = src
        self.size = len(data)
        self.version = 0
        self.wide = False

    def fail(self, where: str, msg: str) -> NoReturn:
        raise MeshFormatError(self.src, where, f"{where}: {msg}")

    def parse(self) -> FbxFile:
        d = self.data
        if d[: len(MAGIC)] != MAGIC:
            head = d[:4096].lstrip(b"\xef\xbb\xbf \t\r\n")
            if head.startswith(b";") or b"FBXHeaderExtension:" in head or b"FBXVersion:" in head:
                self.fail(
                    "header",
                    "this is an ASCII FBX file; Blender's importer reads binary FBX only: "
                    "re-export it as binary (FBX 7.4 or later)",
                )
            if d[:18] == MAGIC[:18]:
                self.fail("header", f"the FBX magic is damaged ({d[:23]!r})")
            self.fail("header", f"not a binary FBX file (expected {MAGIC[:18]!r}, found {d[:18]!r})")
        if self.size < 27:
            self.fail("header", f"the file ends at byte {self.size}, inside the 27-byte header")
        self.version = struct.unpack_from("<I", d, 23)[0]
        if self.version < MIN_VERSION:
            self.fail(
                "header.version",
                f"FBX version {self.version} is older than Blender's importer reads "
                f"({MIN_VERSION} or later): re-export as FBX 2011 or newer",
            )
        if self.version >= 10000:
            self.fail("header.version", f"FBX version {self.version} is not a known version (7100-7700)")
        self.wide = self.version >= 7500
        nodes: list[FbxNode] = []
        pos = 27
        while True:
            node, pos = self._node(pos, self.size, 0, "")
            if node is None:
                break
            nodes.append(node)
        return FbxFile(self.version, nodes)

    def _node(self, pos: int, limit: int, depth: int, parent: str) -> tuple[FbxNode | None, int]:
        hdr = 25 if self.wide else 13
        where = f"{parent or 'top level'} (byte {pos})"
        if pos + hdr > limit:
            if limit == self.size:
                self.fail(where, f"the file is truncated: a node record starts at byte {pos} but the file ends at byte {self.size}")
            self.fail(where, f"a child record at byte {pos} runs past its parent's end (byte {limit})")
        if self.wide:
            end, nprops, plen = struct.unpack_from("<QQQ", self.data, pos)
        else:
            end, nprops, plen = struct.unpack_from("<III", self.data, pos)
        nlen = self.data[pos + hdr - 1]
        if end == 0 and nprops == 0 and plen == 0 and nlen == 0:
            return None, pos + hdr
        raw_name = self.data[pos + hdr : pos + hdr + nlen]
        try:
            name = raw_name.decode("ascii")
        except UnicodeDecodeError:
            self.fail(where, f"node name {raw_name!r} is not ASCII (a damaged record)")
        if not name.isidentifier():
            self.fail(where, f"node name {name!r} is not a valid FBX node name (a damaged record)")
        path = f"{parent}/{name}" if parent else name
        p0 = pos + hdr + nlen
        if end > limit or end < p0 + plen:
            beyond = "the end of the file" if limit == self.size else "its parent's end"
            self.fail(
                f"{path} (byte {pos})",
                f"the record says it ends at byte {end}, "
                + (f"beyond {beyond} (byte {limit}): the file is truncated or damaged" if end > limit
                   else f"before its {plen} bytes of properties (from byte {p0})"),
            )
        if depth > _MAX_DEPTH:
            self.fail(path, f"nodes nested more than {_MAX_DEPTH} deep")
        props, codes = self._props(p0, p0 + plen, int(nprops), path)
        node = FbxNode(name, props, [], path, pos, codes)
        q = p0 + plen
        while q < end:
            child, q = self._node(q, end, depth + 1, path)
            if child is None:
                break
            node.children.append(child)
        if q != end:
            self.fail(f"{path} (byte {pos})", f"its children end at byte {q}, the record says {end}")
        return node, end

    def _props(self, q: int, pend: int, n: int, path: str) -> tuple[list[Any], str]:
        d = self.data
        out: list[Any] = []
        codes = ""
        for k in range(n):
            where = f"{path} property {k}"
            if q >= pend:
                self.fail(where, f"the node has {n} properties but its property bytes end after {k}")
            code = chr(d[q])
            codes += code
            q += 1
            if code in _SCALAR:
                fmt, size = _SCALAR[code]
                if q + size > pend:
                    self.fail(where, f"a {code} value at byte {q} runs past the property list")
                v = struct.unpack_from(fmt, d, q)[0]
                out.append(bool(v) if code == "C" else v)
                q += size
            elif code in _ARRAY:
                if q + 12 > pend:
                    self.fail(where, f"an array header at byte {q} runs past the property list")
                count, enc, clen = struct.unpack_from("<III", d, q)
                q += 12
                if q + clen > pend:
                    self.fail(where, f"array data of {clen} bytes at byte {q} runs past the property list (ends at byte {pend})")
                dt = _ARRAY[code]
                want = count * dt.itemsize
                raw = d[q : q + clen]
                if enc == 0:
                    if clen != want:
                        self.fail(where, f"array of {count} '{code}' values should take {want} bytes, has {clen}")
                elif enc == 1:
                    try:
                        z = zlib.decompressobj()
                        raw = z.decompress(raw, want + 1)
                    except zlib.error as exc:
                        self.fail(where, f"compressed array data is damaged (zlib: {exc})")
                    if len(raw) != want:
                        self.fail(where, f"array says {count} '{code}' values ({want} bytes), its data holds {len(raw)} bytes")
                else:
                    self.fail(where, f"unknown array encoding {enc} (0 raw, 1 zlib)")
                arr = np.frombuffer(raw, dt)
                out.append(arr)
                q += clen
            elif code in ("S", "R"):
                if q + 4 > pend:
                    self.fail(where, f"a string length at byte {q} runs past the property list")
                ln = struct.unpack_from("<I", d, q)[0]
                q += 4
                if q + ln > pend:
                    self.fail(where, f"a {ln}-byte string at byte {q} runs past the property list (ends at byte {pend})")
                out.append(bytes(d[q : q + ln]))
                q += ln
            else:
                self.fail(where, f"unknown property type code {code!r} at byte {q - 1}")
        if q != pend:
            self.fail(path, f"its {n} properties end at byte {q}, the record says {pend}")
        return out, codes


def parse_fbx(path: str | Path) -> FbxFile:
    """Parse the node tree of a binary FBX file, checking every offset and array.

    Raises
    ------
    MeshFormatError
        Not binary FBX (ASCII is named as such), a version Blender cannot read,
        a truncated file or a damaged record; names the node path and byte.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise MeshFormatError(p, "file", f"cannot read: {exc}") from None
    return _Parser(data, str(p)).parse()


# ------------------------------------------------------------------ semantic checks
@dataclass
class _Settings:
    unit_scale: float = 1.0
    up_axis: int = 1
    up_sign: int = 1
    fps: float | None = None
    notes: list[str] = field(default_factory=list)


def _p70(node: FbxNode | None) -> dict[str, list[Any]]:
    """Properties70 ``P`` records of a node: name -> values."""
    out: dict[str, list[Any]] = {}
    if node is None:
        return out
    p70 = node.child("Properties70")
    for p in p70.children if p70 is not None else ():
        if p.name == "P" and p.props and isinstance(p.props[0], bytes):
            out[p.props[0].decode("utf-8", "replace")] = p.props[4:]
    return out


def _number(v: list[Any], src: str, where: str, *, integer: bool = False) -> float:
    if not v or isinstance(v[0], bytes | np.ndarray) or isinstance(v[0], bool):
        raise MeshFormatError(src, where, f"{where}: expected a number, got {v[:1]!r}")
    x = float(v[0])
    if not math.isfinite(x) or (integer and x != int(x)):
        raise MeshFormatError(src, where, f"{where}: expected a finite {'integer' if integer else 'number'}, got {v[0]!r}")
    return x


#: FBX TimeMode enum -> frames per second (14 = custom: CustomFrameRate)
_TIME_MODES = {1: 120.0, 2: 100.0, 3: 60.0, 4: 50.0, 5: 48.0, 6: 30.0, 7: 30.0, 8: 30.0,
               9: 29.97, 10: 25.0, 11: 24.0, 12: 1000.0, 13: 23.976, 15: 96.0, 16: 72.0,
               17: 59.94, 18: 119.88}


def _settings(f: FbxFile, src: str) -> _Settings:
    s = _Settings()
    gs = f.top("GlobalSettings")
    if gs is None:
        s.notes.append("no GlobalSettings: centimetres and y up assumed (the FBX defaults)")
        return s
    p = _p70(gs)
    if "UnitScaleFactor" in p:
        s.unit_scale = _number(p["UnitScaleFactor"], src, "GlobalSettings.UnitScaleFactor")
        if not s.unit_scale > 0:
            raise MeshFormatError(
                src, "GlobalSettings.UnitScaleFactor",
                f"GlobalSettings.UnitScaleFactor: must be > 0 (centimetres per unit), got {s.unit_scale:g}",
            )
    for key, lo, hi in (("UpAxis", 0, 2), ("FrontAxis", 0, 2), ("CoordAxis", 0, 2)):
        if key in p:
            v = _number(p[key], src, f"GlobalSettings.{key}", integer=True)
            if not lo <= v <= hi:
                raise MeshFormatError(src, f"GlobalSettings.{key}", f"GlobalSettings.{key}: must be 0, 1 or 2 (x, y, z), got {v:g}")
            if key == "UpAxis":
                s.up_axis = int(v)
    for key in ("UpAxisSign", "FrontAxisSign", "CoordAxisSign"):
        if key in p:
            v = _number(p[key], src, f"GlobalSettings.{key}", integer=True)
            if v not in (1, -1):
                raise MeshFormatError(src, f"GlobalSettings.{key}", f"GlobalSettings.{key}: must be 1 or -1, got {v:g}")
            if key == "UpAxisSign":
                s.up_sign = int(v)
    mode = int(_number(p["TimeMode"], src, "GlobalSettings.TimeMode", integer=True)) if "TimeMode" in p else 0
    if mode in _TIME_MODES:
        s.fps = _TIME_MODES[mode]
    if "CustomFrameRate" in p:
        rate = _number(p["CustomFrameRate"], src, "GlobalSettings.CustomFrameRate")
        if mode == 14 or mode not in _TIME_MODES:
            if not rate > 0 and mode == 14:
                raise MeshFormatError(src, "GlobalSettings.CustomFrameRate", f"GlobalSettings.CustomFrameRate: must be > 0 with TimeMode 14 (custom), got {rate:g}")
            if rate > 0:
                s.fps = rate
    return s


def _array(node: FbxNode, name: str, src: str, kinds: str, *, required: bool = True) -> NDArray[Any] | None:
    c = node.child(name)
    where = f"{node.label()}.{name}"
    if c is None or not c.props:
        if required:
            raise MeshFormatError(src, where, f"{where}: missing (an array is required here)")
        return None
    a = c.props[0]
    if not isinstance(a, np.ndarray) or a.dtype not in [_ARRAY[k] for k in kinds]:
        raise MeshFormatError(src, where, f"{where}: expected an array of {'/'.join(kinds)} values, got {type(a).__name__}")
    return a


def _check_objects(f: FbxFile, src: str) -> list[str]:
    """Check what Blender's importer reads from ``Objects``; return notes."""
    notes: list[str] = []
    objs = f.top("Objects")
    if objs is None:
        raise MeshFormatError(src, "Objects", "Objects: missing (the file has no objects)")
    by_id: dict[int, FbxNode] = {}
    for o in objs.children:
        if o.props and isinstance(o.props[0], int):
            by_id[o.props[0]] = o
    mesh_vertices: dict[int, int] = {}
    n_meshes = 0
    for o in objs.children:
        if o.name != "Geometry" or len(o.props) < 3 or o.props[2] != b"Mesh":
            continue
        n_meshes += 1
        V = _array(o, "Vertices", src, "df")
        assert V is not None
        where = f"{o.label()}.Vertices"
        if V.size % 3:
            raise MeshFormatError(src, where, f"{where}: {V.size} values, not a multiple of 3 (x, y, z)")
        bad = ~np.isfinite(V)
        if bad.any():
            i = int(np.argmax(bad))
            raise MeshFormatError(src, where, f"{where}: vertex {i // 3} is not finite ({V[i - i % 3 : i - i % 3 + 3].tolist()})")
        n = V.size // 3
        mesh_vertices[o.props[0]] = n
        P = _array(o, "PolygonVertexIndex", src, "i")
        assert P is not None
        where = f"{o.label()}.PolygonVertexIndex"
        if P.size == 0:
            raise MeshFormatError(src, where, f"{where}: empty (the mesh has no faces)")
        if P[-1] >= 0:
            raise MeshFormatError(src, where, f"{where}: the last index {int(P[-1])} does not close a polygon (the last corner of each polygon is stored as -(index+1))")
        idx = np.where(P < 0, -P.astype(np.int64) - 1, P)
        out = idx >= n
        if out.any():
            k = int(np.argmax(out))
            raise MeshFormatError(src, where, f"{where}: corner {k} refers to vertex {int(idx[k])}, out of range (the mesh has {n} vertices)")
    if n_meshes == 0:
        raise MeshFormatError(src, "Objects/Geometry", "Objects: the file has no mesh geometry (Geometry of class Mesh)")
    # connections: child id -> parent ids
    parents: dict[int, list[int]] = {}
    conns = f.top("Connections")
    for c in conns.children if conns is not None else ():
        if c.name == "C" and len(c.props) >= 3 and isinstance(c.props[1], int) and isinstance(c.props[2], int):
            parents.setdefault(c.props[1], []).append(c.props[2])

    def mesh_of_shape(shape_id: int) -> int | None:
        for ch in parents.get(shape_id, []):  # BlendShapeChannel
            for bs in parents.get(ch, []):  # BlendShape deformer
                for g in parents.get(bs, []):
                    if g in mesh_vertices:
                        return g
        return None

    for o in objs.children:
        if o.name == "Geometry" and len(o.props) >= 3 and o.props[2] == b"Shape":
            ix = _array(o, "Indexes", src, "i")
            V = _array(o, "Vertices", src, "df")
            assert ix is not None and V is not None
            where = f"{o.label()}.Vertices"
            if V.size != 3 * ix.size:
                raise MeshFormatError(src, where, f"{where}: {V.size} values for {ix.size} Indexes (3 per index expected)")
            bad = ~np.isfinite(V)
            if bad.any():
                i = int(np.argmax(bad))
                raise MeshFormatError(src, where, f"{where}: offset {i // 3} (vertex {int(ix[i // 3])}) is not finite")
            where = f"{o.label()}.Indexes"
            if (ix < 0).any():
                k = int(np.argmax(ix < 0))
                raise MeshFormatError(src, where, f"{where}: index {k} is negative ({int(ix[k])})")
            g = mesh_of_shape(o.props[0]) if isinstance(o.props[0], int) else None
            if g is not None and ix.size and int(ix.max()) >= mesh_vertices[g]:
                k = int(np.argmax(ix >= mesh_vertices[g]))
                raise MeshFormatError(
                    src, where,
                    f"{where}: index {k} refers to vertex {int(ix[k])}, out of range "
                    f"(its mesh {by_id[g].label()} has {mesh_vertices[g]} vertices)",
                )
        elif o.name == "Deformer" and len(o.props) >= 3 and o.props[2] == b"BlendShapeChannel":
            fw = _array(o, "FullWeights", src, "d", required=False)
            shapes = [
                c for c, ps in parents.items()
                if o.props[0] in ps and c in by_id and by_id[c].name == "Geometry"
            ]
            if fw is not None and len(shapes) > 1:
                notes.append(f"{o.label()} has {len(shapes)} in-between shapes; Blender's importer reads them as separate shape keys")
        elif o.name == "AnimationCurve":
            T = _array(o, "KeyTime", src, "l")
            Vv = _array(o, "KeyValueFloat", src, "fd")
            assert T is not None and Vv is not None
            where = f"{o.label()}.KeyValueFloat"
            if T.size != Vv.size:
                raise MeshFormatError(src, where, f"{where}: {Vv.size} values for {T.size} KeyTime entries (one per key expected)")
            if not np.isfinite(Vv).all():
                k = int(np.argmax(~np.isfinite(Vv)))
                raise MeshFormatError(src, where, f"{where}: key {k} value is not finite")
            if T.size > 1 and (np.diff(T) <= 0).any():
                k = int(np.argmax(np.diff(T) <= 0))
                raise MeshFormatError(
                    src, f"{o.label()}.KeyTime",
                    f"{o.label()}.KeyTime: key {k + 1} time {int(T[k + 1])} does not come after key {k} ({int(T[k])}); times must increase",
                )
    return notes


# ------------------------------------------------------------------ reading
def _prepare(path: str | Path) -> tuple[Path, _Settings, list[str]]:
    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    f = parse_fbx(p)
    s = _settings(f, src)
    notes = s.notes + _check_objects(f, src)
    return p, s, notes


def _unit(scale: float) -> tuple[str, float]:
    """(unit name, metres per unit) for a FBX UnitScaleFactor; metres for an unusual factor."""
    for k, u in _UNIT_OF_SCALE.items():
        if abs(scale - k) <= 1e-6 * k:
            return u, k / 100.0
    return "m", 1.0


def _parts(dump: BlenderDump, src: str, metres_per_unit: float) -> list[Part]:
    parts: list[Part] = []
    for i, ob in enumerate(dump.meta.get("objects", [])):
        what = f"object '{ob.get('name', i)}'"
        co = np.asarray(dump.array(f"o{i}_co", src, what), np.float64)
        M = np.asarray(dump.array(f"o{i}_matrix", src, what), np.float64)
        counts = dump.array(f"o{i}_counts", src, what)
        corners = dump.array(f"o{i}_corners", src, what)
        if co.ndim != 2 or co.shape[1] != 3 or M.shape != (4, 4):
            raise MeshFormatError(src, what, f"{what}: Blender gave points {co.shape} and matrix {M.shape}")
        if co.shape[0] == 0 or counts.size == 0:
            log.info("%s: %s has no faces; skipped", Path(src).name, what)
            continue
        L = M[:3, :3]
        V = to_y_up(co @ L.T + M[:3, 3], "+z") / metres_per_unit
        polys = polygons_from_counts(counts, corners, co.shape[0], src, f"{what}: faces")
        if np.linalg.det(L) < 0:
            polys = reverse_winding(polys)
        shapes: list[tuple[str, NDArray[np.float32]]] = []
        for j, k in enumerate(ob.get("keys", [])):
            D = np.asarray(dump.array(f"o{i}_d{j}", src, what), np.float64)
            if D.shape != co.shape:
                raise MeshFormatError(src, what, f"{what}: shape key '{k['name']}' has {D.shape[0]} points, the mesh {co.shape[0]}")
            shapes.append((str(k["name"]), (to_y_up(D @ L.T, "+z") / metres_per_unit).astype(np.float32)))
            if k.get("vertex_group"):
                log.info("%s: shape key '%s' is limited to vertex group '%s' in the file; read without it", Path(src).name, k["name"], k["vertex_group"])
        if ob.get("object_animation"):
            log.info("%s: %s has an animated transform; its first-frame transform is used", Path(src).name, what)
        parts.append(Part(str(ob.get("name", i)), V, polys, shapes, what))
    return parts


def read_fbx(path: str | Path) -> ImportedFace:
    """Read an FBX file's meshes and shape keys (see the module docstring).

    Raises
    ------
    FileNotFoundError
        No such file.
    MeshFormatError
        Malformed file (checked before Blender runs) or Blender's importer failed.
    workbench.io.blender_bridge.BlenderMissingError
        No Python with bpy (the message says how to install it).
    """
    p, s, notes = _prepare(path)
    src = str(p)
    unit, mpu = _unit(s.unit_scale)
    if unit == "m" and abs(s.unit_scale - 100.0) > 1e-4:
        notes.append(f"UnitScaleFactor {s.unit_scale:g} cm per unit is not mm/cm/in/dm/m: coordinates converted to metres")
    dump = run_dump(p, "fbx")
    parts = _parts(dump, src, mpu)
    if s.up_axis != 1 or s.up_sign != 1:
        notes.append(f"the file is {'-' if s.up_sign < 0 else '+'}{'xyz'[s.up_axis]} up; converted to +y up")
    for n in notes:
        log.info("%s: %s", p.name, n)
    return merge_parts(parts, src, units=unit, up_axis="+y")


def read_fbx_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    fps: float | None = None,
    on_unknown: str = "error",
) -> Any:
    """Read the shape-key animation of an FBX file as a :class:`~workbench.animation.tracks.Timeline`.

    Mirrors :func:`workbench.animation.importers.read_gltf_animation`: curves are
    matched to ``shape_names`` exactly, else by ARKit meaning.

    Parameters
    ----------
    path : str or Path
        The .fbx file.
    shape_names : sequence of str
        The model's shapes.
    fps : float, optional
        Frame rate of the timeline (default: the file's).
    on_unknown : {"error", "ignore"}
        What to do with animated shape keys that match no shape.

    Raises
    ------
    AnimationImportError
        Malformed file, no shape-key animation, unknown names, the same shape
        animated differently on two meshes, an unsupported interpolation.
    """
    from workbench.animation.importers import AnimationImportError

    p = Path(path)
    try:
        p, s, _ = _prepare(p)
        dump = run_dump(p, "fbx")
    except MeshFormatError as exc:
        raise AnimationImportError(str(p), exc.detail) from None
    file_fps = float(dump.meta.get("fps") or s.fps or 24.0)
    curves: dict[str, tuple[str, list[list[Any]]]] = {}
    for ob in dump.meta.get("objects", []):
        for name, c in ob.get("curves", {}).items():
            keys = c.get("keys", [])
            if name in curves and curves[name][1] != keys:
                raise AnimationImportError(
                    str(p), f"shape key '{name}' is animated differently on '{curves[name][0]}' and '{ob['name']}'"
                )
            curves[name] = (str(ob.get("name")), keys)
    if not curves:
        raise AnimationImportError(str(p), "the file has no shape-key animation (no keyed DeformPercent)")
    return _timeline(str(p), curves, shape_names, file_fps, fps or file_fps, on_unknown)


def _timeline(
    src: str,
    curves: dict[str, tuple[str, list[list[Any]]]],
    shape_names: Sequence[str],
    file_fps: float,
    fps: float,
    on_unknown: str,
) -> Any:
    from workbench.animation.curves import Key, Track, TrackError, weight_track_name
    from workbench.animation.importers import AnimationImportError, map_shape_names
    from workbench.animation.tracks import Timeline

    names = list(curves)
    mapping = map_shape_names(names, shape_names, src)
    unknown = [n for n in names if mapping[n] is None]
    if unknown and on_unknown != "ignore":
        raise AnimationImportError(
            src,
            f"unknown shape names {unknown[:10]}{'...' if len(unknown) > 10 else ''} (the model has no "
            "shape of that name or ARKit meaning; pass on_unknown='ignore' to skip them)",
        )
    tracks = {}
    for name in names:
        shape = mapping[name]
        if shape is None:
            continue
        keys = []
        for k, kp in enumerate(curves[name][1]):
            frame, value, interp = float(kp[0]), float(kp[1]), str(kp[2])
            t = frame / file_fps
            where = f"shape key '{name}' key {k} (frame {frame:g})"
            if not (math.isfinite(t) and math.isfinite(value)):
                raise AnimationImportError(src, f"{where}: time or value is not finite")
            if interp == "CONSTANT":
                keys.append(Key(t, value, "step"))
            elif interp == "LINEAR":
                keys.append(Key(t, value, "linear"))
            elif interp == "BEZIER":
                hlx, hly, hrx, hry = (float(x) for x in kp[3:7])
                s_in = (value - hly) / (frame - hlx) * file_fps if frame > hlx else 0.0
                s_out = (hry - value) / (hrx - frame) * file_fps if hrx > frame else 0.0
                keys.append(Key(t, value, "bezier", s_in, s_out, "user"))
            else:
                raise AnimationImportError(src, f"{where}: interpolation {interp} is not supported (constant, linear, Bézier)")
        if not keys:
            continue
        try:
            tn = weight_track_name(shape)
            tracks[tn] = Track(tn, tuple(keys))
        except TrackError as exc:
            raise AnimationImportError(src, f"shape key '{name}': {exc}") from None
    if not tracks:
        raise AnimationImportError(src, "no animated shape key matches a shape of the model")
    return Timeline(fps=fps, tracks=tracks).fit_range()
