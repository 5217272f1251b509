"""The GLB container and the JSON document: split, length-check, parse.

A GLB file is a 12-byte header (magic ``glTF``, version 2, total length) and
chunks of ``(length, type, body)``: the JSON chunk first, then at most one BIN
chunk; other chunk types are skipped, as the spec requires. Every length is
checked against the bytes actually present.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

from workbench.geometry.mesh_checks import MeshFormatError

__all__ = ["GLB_MAGIC", "parse_json", "read_container", "split_glb"]

GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942


def split_glb(data: bytes, src: str) -> tuple[bytes, bytes | None]:
    """JSON and BIN chunks of a GLB container, with length checks."""
    if len(data) < 12:
        raise MeshFormatError(
            src, "header", f"truncated GLB: {len(data)} bytes, the header alone is 12"
        )
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if magic != GLB_MAGIC:
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


def parse_json(raw: bytes, src: str) -> Any:
    """The JSON document; garbled text becomes a MeshFormatError with line and column."""
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


def read_container(path: Path) -> tuple[Any, bytes | None]:
    """``(JSON document, BIN chunk or None)`` of a .glb or .gltf file."""
    src = str(path)
    data = path.read_bytes()
    if not data:
        raise MeshFormatError(src, "file", "empty file")
    if path.suffix.lower() == ".glb" or data[:4] == GLB_MAGIC:
        json_raw, bin_chunk = split_glb(data, src)
    else:
        json_raw, bin_chunk = data, None
    return parse_json(json_raw, src), bin_chunk
