"""What both OBJ parsers hand over (:class:`_Tokens`), checked and built into an ImportedFace."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, check_faces, check_vertices
from workbench.io.base import ImportedFace


@dataclass
class _Tokens:
    """What both parsers hand to :func:`_assemble`."""

    V: NDArray[np.float64]
    v_lines: NDArray[np.int64]
    ids: NDArray[np.int64]  # vertex index of every corner, as written (1-based or negative)
    sizes: NDArray[np.int64]
    f_lines: NDArray[np.int64]
    f_nv: NDArray[np.int64]  # vertices defined before each face
    f_group: NDArray[np.int32]
    group_names: list[str]
    any_group: bool


def _assemble(t: _Tokens, src: str) -> ImportedFace:
    """Check the parsed numbers and build the face (shared by both parsers)."""
    V = check_vertices(t.V, src, "v", line_numbers=t.v_lines)
    n = V.shape[0]
    sizes, ids = t.sizes, t.ids
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    def fail(c: int, msg: str) -> MeshFormatError:
        line = int(t.f_lines[int(np.searchsorted(offsets, c, side="right") - 1)])
        return MeshFormatError(src, "f", f"line {line}: {msg}")

    zero = ids == 0
    if zero.any():
        raise fail(int(np.argmax(zero)), "face index 0 (OBJ indices start at 1)")
    # negative indices count back from the last vertex defined before the face line
    nv = np.repeat(t.f_nv, sizes)
    corners = np.where(ids > 0, ids - 1, nv + ids)
    bad = (corners < 0) | (corners >= n)
    if bad.any():
        c = int(np.argmax(bad))
        raise fail(
            c,
            f"face index {int(ids[c])} out of range (file has {n} vertices"
            + (f", {int(nv[c])} before this line)" if ids[c] < 0 else ")"),
        )
    polygons = Polygons(corners.astype(np.int32), offsets)
    check_faces(polygons, n, src, vertices=V, line_numbers=t.f_lines)

    return ImportedFace(
        vertices=V,
        polygons=polygons,
        face_groups=t.f_group if t.any_group else None,
        group_names=t.group_names if t.any_group else [],
        shapes=[],
        source_files=[src],
        units=None,
        up_axis=None,
    )
