"""The source .glb re-written by real third-party writers, made once and cached.

``written(kind)`` returns the path of :func:`face_gltf.build_source_glb`'s file
as written by one of :data:`WRITERS`: gltfpack 1.3 and glTF-Transform 4.5.1
(npm, pinned in ``tests/tools/package.json`` + ``package-lock.json``,
installed by ``bash .ci/workbench test`` or here with ``npm ci``) and
Blender 5.0's exporter (bpy in ``$WORKBENCH_BPY_PYTHON``, default
``.venv/blender/bin/python``). Files are cached in
``.venv/cache/gltf-writers/<key>/`` (else the temp folder), where ``key``
hashes everything that shapes them (this file, the source builder, the
Blender script, the npm lock file, the sample head's manifest): a change to
any of them writes them anew. A missing tool raises :class:`ToolMissing`.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import struct
import subprocess
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

#: writer id -> (tool, arguments after input and output)
WRITERS: dict[str, tuple[str, list[str]]] = {
    "gltfpack": ("gltfpack", ["-cc", "-kn", "-km"]),  # + a KHR_texture_basisu texture, see below
    "gltfpack-khr": ("gltfpack", ["-cc", "-ce", "khr", "-kn"]),
    "gltfpack-normalized": ("gltfpack", ["-c", "-vpn", "-kn"]),
    "gltfpack-float": ("gltfpack", ["-cc", "-vpf", "-kn"]),
    "gltfpack-13bit": ("gltfpack", ["-c", "-vp", "13", "-kn"]),  # coarse: a few triangles go flat
    "draco": ("gltf-transform", ["draco"]),
    "sparse": ("gltf-transform", ["sparse"]),
    "quantize": ("gltf-transform", ["quantize"]),
    "blender": ("blender", []),
    "blender-draco": ("blender", ["draco"]),
}


class ToolMissing(RuntimeError):
    """A writer (node/npm tools or Blender) is not installed."""


def bpy_python() -> Path | None:
    p = os.environ.get("WORKBENCH_BPY_PYTHON") or str(ROOT / ".venv" / "blender" / "bin" / "python")
    return Path(p) if Path(p).is_file() else None


def node_bin() -> Path:
    """``tests/tools/node_modules/.bin`` with gltfpack and gltf-transform (``npm ci`` if missing)."""
    npm = shutil.which("npm")
    if shutil.which("node") is None or npm is None:
        raise ToolMissing("node and npm")
    binp = HERE / "node_modules" / ".bin"
    if not (binp / "gltfpack").exists() or not (binp / "gltf-transform").exists():
        proc = subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund", "--prefix", str(HERE)],
            capture_output=True,
            text=True,
            timeout=600,
        )
        if proc.returncode != 0:
            raise RuntimeError(f"npm ci --prefix tests/tools failed:\n{proc.stderr[-2000:]}")
    return binp


def _key() -> str:
    h = hashlib.sha256()
    for f in (
        HERE / "gltf_writers.py",
        HERE / "face_gltf.py",
        HERE / "blender_gltf_export.py",
        HERE / "package-lock.json",
        ROOT / "sample_models" / "head" / "manifest.json",
    ):
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    base = ROOT / ".venv" / "cache" if (ROOT / ".venv").is_dir() else Path(tempfile.gettempdir())
    d = base / "gltf-writers" / _key()
    d.mkdir(parents=True, exist_ok=True)
    return d


def run(cmd: list[str], timeout: float = 300) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(
            f"{' '.join(map(str, cmd))} failed:\n{proc.stdout[-1500:]}\n{proc.stderr[-1500:]}"
        )


def source_glb() -> Path:
    """The uncompressed source file (built from the sample head)."""
    from face_gltf import build_source_glb, face_source

    out = cache_dir() / "source.glb"
    if not out.is_file():
        tmp = out.with_suffix(f".{os.getpid()}.tmp")
        build_source_glb(face_source(), tmp)
        tmp.replace(out)
    return out


def written(kind: str) -> Path:
    """The source as written by writer ``kind`` (cached)."""
    tool, args = WRITERS[kind]
    out = cache_dir() / f"{kind}.glb"
    if out.is_file():
        return out
    src = source_glb()
    tmp = out.with_name(f"{kind}.{os.getpid()}.tmp.glb")
    if tool == "gltfpack":
        run([str(node_bin() / "gltfpack"), "-i", str(src), "-o", str(tmp), *args])
        if kind == "gltfpack":
            add_basisu_texture(tmp)
    elif tool == "gltf-transform":
        run([str(node_bin() / "gltf-transform"), args[0], str(src), str(tmp), *args[1:]])
    else:
        py = bpy_python()
        if py is None:
            raise ToolMissing("Blender as a Python module (WORKBENCH_BPY_PYTHON)")
        run([str(py), str(HERE / "blender_gltf_export.py"), str(src), str(tmp), *args])
    tmp.replace(out)
    return out


# ---- GLB editing (for the texture stub and the malformed corpus) -------------------------


def split_glb(data: bytes) -> tuple[dict[str, Any], bytes]:
    """(JSON document, BIN chunk) of a well-formed GLB."""
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + jlen])
    if len(data) <= 20 + jlen:
        return doc, b""
    (blen,) = struct.unpack_from("<I", data, 20 + jlen)
    return doc, data[28 + jlen : 28 + jlen + blen]


def pack_glb(doc: dict[str, Any], bin_chunk: bytes) -> bytes:
    """A GLB container around ``doc`` and ``bin_chunk`` (padded to 4 bytes)."""
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    b = bin_chunk + b"\0" * (-len(bin_chunk) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j
    if b:
        body += struct.pack("<II", len(b), 0x004E4942) + b
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def glb_json(path: Path) -> dict[str, Any]:
    return split_glb(path.read_bytes())[0]


KTX2_IDENTIFIER = b"\xabKTX 20\xbb\r\n\x1a\n"


def add_basisu_texture(path: Path) -> None:
    """Give the head's material a required ``KHR_texture_basisu`` texture, as three.js-style files have.

    gltfpack's npm build cannot encode BasisU (its ``-tc`` says so), so the
    KTX2 image is a stub (the 12-byte KTX2 identifier and zeros): a reader
    that needed the texture would fail on it; one that skips texture
    extensions never looks at it.
    """
    doc, bin_chunk = split_glb(path.read_bytes())
    data = bytearray(bin_chunk)
    image = KTX2_IDENTIFIER + b"\0" * 68
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": len(image)})
    data += image
    doc["buffers"][0]["byteLength"] = len(data)
    doc["images"].append({"bufferView": len(doc["bufferViews"]) - 1, "mimeType": "image/ktx2"})
    doc["textures"].append({"extensions": {"KHR_texture_basisu": {"source": len(doc["images"]) - 1}}})
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"] = len(doc["textures"]) - 1
    for key in ("extensionsUsed", "extensionsRequired"):
        doc.setdefault(key, []).append("KHR_texture_basisu")
    path.write_bytes(pack_glb(doc, bytes(data)))
