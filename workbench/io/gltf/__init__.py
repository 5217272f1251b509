"""glTF 2.0 (.gltf / .glb) reader: a scene's meshes with morph targets, plain or compressed.

The registry's module for glTF (:data:`workbench.io.registry.BUILTIN_READERS`
names ``workbench.io.gltf``); it defines ``detect``, ``read`` and
``DESCRIPTION``. The work is split by concept:

* :mod:`.container` — the GLB container and the JSON text;
* :mod:`.document` — checked fields, buffers, bufferViews and accessors
  (strides, normalized/quantized integers, sparse, meshopt-decoded views);
* :mod:`.compression` — meshopt and Draco decoding, which extensions matter;
* :mod:`.scene` — nodes, world transforms, which meshes are drawn;
* :mod:`.reader` — meshes, primitives and morph targets → :class:`ImportedFace`.

Why the decoding is hand-written: pygltflib (kept for writing files)
turns the JSON into dataclasses without checking field types, leaves morph
targets as raw dicts and has no accessor decoding (byteStride, sparse,
normalized integers, meshopt, Draco); trimesh's loader drops morph targets.
The file is untrusted input, so every count and offset is checked against the
bytes actually present before anything is allocated, and every problem is a
:class:`MeshFormatError` naming the file and the JSON field. Decoding uses
meshoptimizer's decoder (PyPI ``meshopt``) and Google's Draco decoder (PyPI
``DracoPy``).

The weights animation of such a file is read by
:func:`workbench.animation.importers.read_gltf_animation`, which uses the same
checked accessors (:class:`.document.Gltf`), so compressed keyframes decode the same way.
"""

from __future__ import annotations

from pathlib import Path

from workbench.io.base import ImportedFace
from workbench.io.gltf.reader import read_gltf

__all__ = ["DESCRIPTION", "detect", "read", "read_gltf"]

DESCRIPTION = (
    "a .glb or .gltf file (every mesh of the scene under its node transform; morph targets "
    "become shapes; meshopt, Draco and quantized data are decoded)"
)


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in (".glb", ".gltf")


def read(path: Path) -> ImportedFace:
    return read_gltf(path)
