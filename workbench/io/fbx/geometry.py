"""Blender's dump of the meshes and shape keys → parts in the file's unit, y up.

Every mesh object's vertices under its world transform, faces as in the file
(n-gons kept), one shape per shape key; Blender's z-up metres are turned back
into the file's unit (``GlobalSettings.UnitScaleFactor``, centimetres per unit).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.blender_bridge import BlenderDump
from workbench.io.parts import Part, polygons_from_counts, reverse_winding, to_y_up

log = logging.getLogger("workbench.io")


#: FBX UnitScaleFactor (centimetres per unit) -> unit name
_UNIT_OF_SCALE = {0.1: "mm", 1.0: "cm", 2.54: "in", 10.0: "dm", 100.0: "m"}


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
