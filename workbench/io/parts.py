"""Several meshes of one scene file → one :class:`ImportedFace` (used by the FBX, USD and Alembic readers).

A face exported from a DCC tool is often several meshes (head, teeth, eyes,
lashes), each with its own blend shapes. :func:`merge_parts` concatenates
them (one face group per mesh, named after it) and merges their shapes by
name: a shape that only some meshes have is zero on the others. Every array
goes through :func:`workbench.geometry.mesh_checks.check_vertices` /
``check_faces`` with the file and field named, so nothing half-loaded leaves.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, check_faces, check_vertices
from workbench.io.base import FrameSequence, ImportedFace, check_shape_names

__all__ = ["Part", "merge_parts", "polygons_from_counts", "reverse_winding", "to_y_up"]


@dataclass
class Part:
    """One mesh of a scene, already in the face's coordinates (world, y up, file unit).

    Attributes
    ----------
    name : str
        Mesh (object/prim) name, used as the face group name.
    vertices : (n, 3) float64
    polygons : Polygons
    shapes : list of (name, (n, 3) float32 delta)
    field : str
        Where the mesh is in the file, for messages (``"Objects/Geometry 'Head'"``).
    """

    name: str
    vertices: NDArray[np.float64]
    polygons: Polygons
    shapes: list[tuple[str, NDArray[np.float32]]] = field(default_factory=list)
    field: str = ""


def to_y_up(points: NDArray[np.float64], up: str) -> NDArray[np.float64]:
    """Rotate ``(..., 3)`` points from a z-up frame to y up (``(x, z, -y)``); y up is returned as is."""
    if up == "+y":
        return points
    if up != "+z":
        raise ValueError(f"to_y_up: unsupported up axis {up!r}")
    return np.stack([points[..., 0], points[..., 2], -points[..., 1]], axis=-1)


def polygons_from_counts(
    counts: NDArray[np.integer], indices: NDArray[np.integer], n_vertices: int, src: str, field: str
) -> Polygons:
    """Polygons from per-face corner counts + concatenated corner indices (USD, Blender), checked."""
    counts = np.asarray(counts, np.int64).reshape(-1)
    indices = np.asarray(indices, np.int64).reshape(-1)
    if counts.size == 0:
        raise MeshFormatError(src, field, f"{field}: the mesh has no faces")
    if (counts < 3).any():
        i = int(np.argmax(counts < 3))
        raise MeshFormatError(
            src, field, f"{field}: face {i} has {int(counts[i])} corners (at least 3 expected)"
        )
    total = int(counts.sum())
    if total != indices.size:
        raise MeshFormatError(
            src,
            field,
            f"{field}: the face corner counts add up to {total} but there are {indices.size} "
            "corner indices",
        )
    bad = (indices < 0) | (indices >= n_vertices)
    if bad.any():
        k = int(np.argmax(bad))
        raise MeshFormatError(
            src,
            field,
            f"{field}: corner {k} refers to vertex {int(indices[k])}, out of range "
            f"(the mesh has {n_vertices} vertices)",
        )
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return Polygons(indices.astype(np.int32), offsets)


def reverse_winding(P: Polygons) -> Polygons:
    """Each polygon's corners in reverse order (a mirroring transform or left-handed file flips the winding)."""
    sizes = P.sizes
    start = np.repeat(P.offsets[:-1], sizes)
    end = np.repeat(P.offsets[1:], sizes)
    k = np.arange(P.indices.size)
    return Polygons(P.indices[start + end - 1 - k], P.offsets)


def merge_parts(
    parts: list[Part],
    src: str,
    *,
    units: str | None,
    up_axis: str | None,
    frames: FrameSequence | None = None,
) -> ImportedFace:
    """Concatenate checked parts into one face; shapes merged by exact name.

    Raises
    ------
    MeshFormatError
        No part, a non-finite position or delta, a bad face, a shape whose
        delta does not have one row per vertex, or clashing shape names.
    """
    if not parts:
        raise MeshFormatError(src, "meshes", "the file has no mesh with faces")
    sizes = [p.vertices.shape[0] for p in parts]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    n = int(starts[-1])
    verts: list[NDArray[np.float64]] = []
    idx: list[NDArray[np.int32]] = []
    offs: list[NDArray[np.int64]] = []
    base_off = 0
    for k, p in enumerate(parts):
        V = check_vertices(p.vertices, src, f"{p.field}: points")
        P = check_faces(p.polygons, V.shape[0], src, vertices=V, field=f"{p.field}: faces")
        verts.append(V)
        idx.append(P.indices + np.int32(starts[k]))
        offs.append(P.offsets[:-1] + base_off)
        base_off += P.indices.size
    polygons = Polygons(np.concatenate(idx), np.concatenate([*offs, [base_off]]).astype(np.int64))

    order: list[str] = []
    merged: dict[str, NDArray[np.float32]] = {}
    for k, p in enumerate(parts):
        for name, D in p.shapes:
            what = f"{p.field}: shape '{name}'"
            D = np.asarray(D)
            if D.shape != (sizes[k], 3):
                raise MeshFormatError(
                    src, what, f"{what}: has {D.shape[0]} rows, the mesh has {sizes[k]} vertices"
                )
            check_vertices(D, src, what)
            if name not in merged:
                merged[name] = np.zeros((n, 3), np.float32)
                order.append(name)
            merged[name][starts[k] : starts[k + 1]] = D
    check_shape_names(order, [src] * len(order), src)

    face_groups: NDArray[np.int32] | None = None
    group_names: list[str] = []
    if len(parts) > 1:
        group_names = [p.name for p in parts]
        face_groups = np.repeat(
            np.arange(len(parts), dtype=np.int32), [len(o) for o in offs]
        ).astype(np.int32)
    return ImportedFace(
        vertices=np.concatenate(verts),
        polygons=polygons,
        face_groups=face_groups,
        group_names=group_names,
        shapes=[(s, merged[s]) for s in order],
        source_files=[src],
        units=units,
        up_axis=up_axis,
        frames=frames,
    )
