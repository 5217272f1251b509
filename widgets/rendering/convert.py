"""A :class:`workbench.FaceModel` as a :class:`pyvista.PolyData` and back.

Component labels travel as point data (``"component"``), component names as
field data (``"component_names"``); polygons (quads, n-gons) as VTK cells.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyvista as pv
from numpy.typing import ArrayLike, NDArray

from workbench import FaceModel, ModelMetadata
from workbench.core.polygons import Polygons

__all__ = ["from_pyvista", "polygon_cell_array", "to_pyvista"]

_LABEL_ARRAY = "component"
_NAMES_FIELD = "component_names"


def polygon_cell_array(indices: NDArray[np.int32], offsets: NDArray[np.int64]) -> NDArray:
    """Legacy VTK cell array ``[n0, i.., n1, i.., ...]`` from CSR polygons."""
    sizes = np.diff(offsets)
    out = np.empty(indices.size + sizes.size, dtype=np.int64)
    # polygon k's size sits at offsets[k] + k; its corners follow it
    size_pos = offsets[:-1] + np.arange(sizes.size)
    out[size_pos] = sizes
    mask = np.ones(out.size, dtype=bool)
    mask[size_pos] = False
    out[mask] = indices
    return out


def to_pyvista(
    model: FaceModel,
    points: ArrayLike | None = None,
    *,
    polygons: bool = False,
    scalars: ArrayLike | None = None,
    scalars_name: str = "scalars",
) -> pv.PolyData:
    """Convert a face model to a :class:`pyvista.PolyData`.

    Parameters
    ----------
    model : FaceModel
    points : (n, 3) float, optional
        Vertex positions to use instead of the neutral ``model.vertices``
        (e.g. ``model.evaluate()``).
    polygons : bool
        Write the original polygons (quads, n-gons) instead of the triangles.
    scalars : (n,) or (n, c) array, optional
        Extra point data, stored under ``scalars_name`` and made active.

    Returns
    -------
    pyvista.PolyData
        Point data ``"component"`` (n,) int32 holds ``model.component_labels``;
        field data ``"component_names"`` holds the names.
    """
    n = model.n_vertices
    pts = np.asarray(model.vertices if points is None else points, dtype=np.float64)
    if pts.shape != (n, 3):
        raise ValueError(f"to_pyvista: points must have shape ({n}, 3), got {pts.shape}")
    if polygons:
        poly = model.polygons
        mesh = pv.PolyData(pts.copy(), faces=polygon_cell_array(poly.indices, poly.offsets))
    else:
        faces: Any = np.asarray(model.faces, dtype=np.int64)  # pyvista's stubs want int, not int64
        mesh = pv.PolyData.from_regular_faces(pts.copy(), faces)
    mesh.point_data[_LABEL_ARRAY] = np.asarray(model.component_labels, dtype=np.int32)
    mesh.field_data[_NAMES_FIELD] = np.asarray(list(model.component_names), dtype=str)
    if scalars is not None:
        s = np.asarray(scalars)
        if s.shape[:1] != (n,):
            raise ValueError(f"to_pyvista: scalars must have {n} rows, got shape {s.shape}")
        mesh.point_data[scalars_name] = s
        mesh.point_data.active_scalars_name = scalars_name
    return mesh


def from_pyvista(
    mesh: pv.DataSet,
    name: str | None = None,
    *,
    units: str = "m",
    up_axis: str = "+y",
    front_axis: str = "+z",
) -> FaceModel:
    """Build a :class:`workbench.FaceModel` (no blendshapes) from a pyvista mesh.

    Parameters
    ----------
    mesh : pyvista.DataSet
        Any surface-like dataset; non-PolyData is passed through
        ``extract_surface``. Polygons are kept as ``model.polygons`` and
        fan-triangulated for ``model.faces``; lines, vertices and strips are
        ignored.
    name : str, optional
        Model name (``metadata.name``), also recorded in the provenance entry
        ``{"source": "pyvista", "name": ...}``.
    units, up_axis, front_axis : str
        Metadata; a pyvista mesh carries no units or orientation of its own.

    Returns
    -------
    FaceModel
        ``"component"`` point data (if present) become component labels, with
        names from the ``"component_names"`` field data.
    """
    if not isinstance(mesh, pv.PolyData):
        mesh = mesh.extract_surface()
    if mesh.GetNumberOfPolys() == 0:
        raise ValueError("from_pyvista: mesh has no polygon faces (only points/lines?)")
    cells = mesh.GetPolys()
    offsets = pv.convert_array(cells.GetOffsetsArray()).astype(np.int64)
    indices = pv.convert_array(cells.GetConnectivityArray()).astype(np.int32)
    polygons = Polygons(indices, offsets)
    faces, _ = polygons.triangulate()
    labels = names = None
    if _LABEL_ARRAY in mesh.point_data:
        labels = np.asarray(mesh.point_data[_LABEL_ARRAY], dtype=np.int32)
        if _NAMES_FIELD in mesh.field_data:
            names = [str(s) for s in mesh.field_data[_NAMES_FIELD]]
    provenance: dict[str, Any] = {"source": "pyvista"}
    if name is not None:
        provenance["name"] = name
    metadata = ModelMetadata(
        name=name or "",
        units=units,
        up_axis=up_axis,
        front_axis=front_axis,
        provenance=(provenance,),
    )
    return FaceModel(
        np.asarray(mesh.points, dtype=np.float64),
        faces,
        polygons=polygons,
        component_labels=labels,
        component_names=names,
        metadata=metadata,
    )
