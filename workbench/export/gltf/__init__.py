"""glTF 2.0 (.glb / .gltf) export: morph targets and a weights animation.

What is written (one mesh, a morph target per shape and per layer term, one
animation) is described in :mod:`~workbench.export.gltf.document`, which builds
the document; how the keys of every curve are merged onto glTF's one sampler
exactly, in :mod:`~workbench.export.gltf.sampler`; the binary buffer and its
accessors in :mod:`~workbench.export.gltf.buffers`. This module packs the
result as ``.glb`` or ``.gltf`` + ``.bin``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pygltflib

from workbench.animation.tracks import Timeline
from workbench.export.base import ExportResult, atomic_write_bytes
from workbench.export.gltf.document import _build, build_gltf
from workbench.export.gltf.sampler import Curve, SamplerData, merge_curves

if TYPE_CHECKING:
    from workbench.model import FaceModel


__all__ = ["Curve", "SamplerData", "build_gltf", "merge_curves", "write"]


def _glb_bytes(gltf: pygltflib.GLTF2, data: bytes) -> bytes:
    """Pack a GLB container (12-byte header, padded JSON chunk, BIN chunk)."""
    import struct

    js = gltf.to_json(separators=(",", ":")).encode("utf-8")
    js += b" " * ((-len(js)) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(data), 0x004E4942) + data
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def write(
    model: FaceModel,
    timeline: Timeline,
    path: Path,
    *,
    bake: bool = False,
    sparse: bool = True,
) -> ExportResult:
    """Write a .glb (one file) or .gltf (+ ``<stem>.bin``) atomically.

    Parameters
    ----------
    bake : bool
        Resample every curve at each frame (LINEAR) instead of writing keys.
    sparse : bool
        Store blendshape targets that move few vertices as sparse accessors.
    """
    gltf, data, layers = _build(model, timeline, bake=bake, sparse=sparse)
    if path.suffix.lower() == ".gltf":
        bin_path = path.with_suffix(".bin")
        gltf.buffers[0].uri = bin_path.name
        atomic_write_bytes(bin_path, data)
        atomic_write_bytes(path, gltf.to_json(indent=1).encode("utf-8"))
        return ExportResult([path, bin_path], layers)
    atomic_write_bytes(path, _glb_bytes(gltf, data))
    return ExportResult([path], layers)
