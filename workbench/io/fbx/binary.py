"""The binary FBX node tree: a small checked parser (:func:`parse_fbx`) and its records.

Every node's end offset, property and array (zlib included) is checked against
the bytes present, so a truncated or damaged file fails in milliseconds with a
:class:`MeshFormatError` naming the file, the node path and the byte. ASCII FBX
is refused with a note (Blender's importer reads binary FBX 7.1 and later only).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from workbench.geometry.mesh_checks import MeshFormatError

MAGIC = b"Kaydara FBX Binary  \x00"
#: oldest FBX version Blender's importer reads
MIN_VERSION = 7100
_MAX_DEPTH = 64

_SCALAR = {"Y": ("<h", 2), "C": ("<B", 1), "I": ("<i", 4), "F": ("<f", 4), "D": ("<d", 8), "L": ("<q", 8)}
_ARRAY: dict[str, np.dtype[Any]] = {"f": np.dtype("<f4"), "d": np.dtype("<f8"), "l": np.dtype("<i8"), "i": np.dtype("<i4"), "b": np.dtype("u1")}


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
