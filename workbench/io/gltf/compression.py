"""Compressed geometry: meshopt bufferViews, Draco primitives, and which extensions matter.

* ``EXT_meshopt_compression`` / ``KHR_meshopt_compression`` (gltfpack,
  glTF-Transform ``meshopt``) compress a bufferView; the PyPI ``meshopt``
  binding (meshoptimizer's own decoder, shaped like its JavaScript module)
  decodes it, filters (octahedral, quaternion, exponential, colour) included.
  meshoptimizer cannot compress data more than about 128:1, so a declared
  size beyond 256 times the compressed bytes is rejected before anything is
  allocated.
* ``KHR_draco_mesh_compression`` (glTF-Transform ``draco``, Blender) replaces
  a primitive's attributes and indices; PyPI ``DracoPy`` (Google's decoder)
  decodes it and gives each attribute by its Draco unique id. Morph targets
  are never Draco-compressed: they stay plain accessors, in the decoded
  vertex order (the writers reorder them along).
* ``KHR_mesh_quantization`` only widens the allowed component types, which the
  accessor reader handles anyway.

Required extensions that only concern textures, materials, lights or
metadata cannot change positions, triangles or morph targets: they are
skipped with a logged note. Any other unknown required extension is an error.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DRACO",
    "GEOMETRY_EXTENSIONS",
    "MESHOPT_EXTENSIONS",
    "DracoPrimitive",
    "MeshoptView",
    "decode_draco",
    "decode_meshopt",
    "is_skippable",
]

MESHOPT_EXTENSIONS = ("EXT_meshopt_compression", "KHR_meshopt_compression")
DRACO = "KHR_draco_mesh_compression"
#: required extensions this reader implements
GEOMETRY_EXTENSIONS = frozenset({"KHR_mesh_quantization", DRACO, *MESHOPT_EXTENSIONS})
#: extensions that cannot change positions, triangles or morph targets
_SKIPPABLE = frozenset(
    {
        "KHR_texture_basisu",
        "KHR_texture_transform",
        "EXT_texture_webp",
        "EXT_texture_avif",
        "MSFT_texture_dds",
        "KHR_lights_punctual",
        "EXT_lights_image_based",
        "KHR_xmp_json_ld",
        "KHR_animation_pointer",
        "KHR_node_visibility",
    }
)
_SKIPPABLE_PREFIXES = ("KHR_materials_", "EXT_materials_", "KHR_techniques_")

_MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
_FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL", "COLOR")
_MAX_RATIO = 256  # decoded bytes per compressed byte, well above meshoptimizer's limit
#: a face mesh never comes near this; a Draco header claiming more is rejected unread
MAX_DRACO_ELEMENTS = 50_000_000


def is_skippable(name: str) -> bool:
    """True for an extension about textures/materials/lights/metadata only."""
    return name in _SKIPPABLE or name.startswith(_SKIPPABLE_PREFIXES)


@dataclass(frozen=True)
class MeshoptView:
    """The extension object of a meshopt-compressed bufferView (fields as in the spec)."""

    extension: str
    buffer: int
    start: int
    length: int
    stride: int
    count: int
    mode: Any
    filter: Any

    def problem(self) -> tuple[str, str] | None:
        """``(field key, message)`` of the first field the spec does not allow, else None."""
        if self.mode not in _MODES:
            return "mode", f"expected one of {list(_MODES)}, got {self.mode!r:.40}"
        if self.filter not in _FILTERS or (
            self.filter == "COLOR" and self.extension != "KHR_meshopt_compression"
        ):
            return "filter", f"unknown filter {self.filter!r:.40}"
        if self.mode == "ATTRIBUTES":
            if self.stride % 4 or not 4 <= self.stride <= 256:
                return "byteStride", f"{self.stride} is not a multiple of 4 from 4 to 256"
        elif self.stride not in (2, 4):
            return "byteStride", f"{self.stride}: {self.mode} data has a byteStride of 2 or 4"
        if self.filter != "NONE" and self.mode != "ATTRIBUTES":
            return "filter", f"{self.filter} applies to ATTRIBUTES data only"
        if self.filter in ("OCTAHEDRAL", "COLOR") and self.stride not in (4, 8):
            return "byteStride", f"{self.stride}: the {self.filter} filter needs 4 or 8"
        if self.filter == "QUATERNION" and self.stride != 8:
            return "byteStride", f"{self.stride}: the QUATERNION filter needs 8"
        if self.mode == "TRIANGLES" and self.count % 3:
            return "count", f"{self.count} indices is not a multiple of 3 (TRIANGLES)"
        if self.count * self.stride > _MAX_RATIO * self.length + 4096:
            return (
                "count",
                f"{self.count} x {self.stride} bytes cannot come from {self.length} "
                f"compressed bytes (meshopt compresses at most about 128:1)",
            )
        return None


def decode_meshopt(mv: MeshoptView, data: bytes) -> bytes:
    """The bufferView's plain bytes; raises ValueError on malformed data."""
    import meshopt

    if len(data) != mv.length:
        raise ValueError(f"{len(data)} compressed bytes, expected {mv.length}")
    out = meshopt.decode_gltf_buffer(
        data, mv.count, mv.stride, mv.mode, None if mv.filter == "NONE" else mv.filter
    )
    raw = np.ascontiguousarray(out)
    if raw.dtype.byteorder == ">":  # pragma: no cover - big-endian hosts
        raw = raw.byteswap()
    result = raw.tobytes()
    if len(result) != mv.count * mv.stride:
        raise ValueError(f"decoder gave {len(result)} bytes, expected {mv.count * mv.stride}")
    return result


@dataclass(frozen=True)
class DracoPrimitive:
    """A decoded Draco primitive: ``(k, 3)`` triangles and attributes by unique id."""

    triangles: NDArray[np.int64]
    n_points: int
    attributes: dict[int, NDArray[Any]]


def decode_draco(data: bytes) -> DracoPrimitive:
    """Decode a Draco mesh; raises ValueError on malformed data or a point cloud."""
    import DracoPy

    try:
        mesh = DracoPy.decode(bytes(data))
    except Exception as exc:  # the C++ decoder reports any defect as some exception
        raise ValueError(str(exc) or type(exc).__name__) from None
    faces = getattr(mesh, "faces", None)
    if faces is None:
        raise ValueError("the Draco data is a point cloud, not a triangle mesh")
    tris = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    n_points = int(np.asarray(mesh.points).shape[0])
    attrs: dict[int, NDArray[Any]] = {}
    for a in mesh.attributes:
        data_a = np.asarray(a["data"])
        attrs[int(a["unique_id"])] = data_a.reshape(data_a.shape[0], -1)
    return DracoPrimitive(tris, n_points, attrs)
