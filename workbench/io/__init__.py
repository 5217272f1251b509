"""Loading faces from files: one module per format behind a registry (see ``registry``).

:func:`load` accepts a saved workbench file (``.fwb``), a ``.glb``/``.gltf`` with
morph targets, a folder of same-topology OBJ files, or an ``.obj`` with
MakeHuman ``.target`` files beside it, and returns a :class:`~workbench.FaceModel`.
Every reader verifies its input completely before a model is built, so a bad
file raises a clear error and nothing is half-loaded.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from workbench.fileformat import SUFFIX, load_model
from workbench.geometry.mesh_checks import label_components
from workbench.io.base import ImportedFace
from workbench.io.registry import read_any
from workbench.model import BlendShape, FaceModel, ModelMetadata

__all__ = ["ImportedFace", "load", "model_from_imported"]

_UNIT_NAMES = {
    "m": "m",
    "meter": "m",
    "metre": "m",
    "meters": "m",
    "metres": "m",
    "dm": "dm",
    "decimeter": "dm",
    "decimetre": "dm",
    "cm": "cm",
    "centimeter": "cm",
    "centimetre": "cm",
    "mm": "mm",
    "millimeter": "mm",
    "millimetre": "mm",
}


def _is_workbench_file(path: Path) -> bool:
    if path.suffix.lower() == SUFFIX:
        return True
    if path.is_file() and zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as zf:
            return "manifest.json" in zf.namelist()
    return False


def model_from_imported(
    imported: ImportedFace, name: str = "", units: str | None = None
) -> FaceModel:
    """Build a :class:`FaceModel` from a reader's output (triangulate, label components).

    ``units`` overrides the file's unit; files without one (OBJ) default to metres.
    """
    faces, tri_poly = imported.polygons.triangulate()
    group_of_face = (
        None if imported.face_groups is None else np.asarray(imported.face_groups)[tri_poly]
    )
    labels, names = label_components(
        faces, len(imported.vertices), group_of_face, list(imported.group_names or [])
    )
    given = units or imported.units or "m"
    if given.lower() not in _UNIT_NAMES:
        raise ValueError(f"units: expected one of {sorted(set(_UNIT_NAMES.values()))}, got {given!r}")
    units = _UNIT_NAMES[given.lower()]
    metadata = ModelMetadata(
        name=name,
        units=units,
        up_axis=imported.up_axis or "+y",
        front_axis="+z",
        provenance=tuple({"source": str(f)} for f in imported.source_files),
    )
    shapes = [BlendShape(n, d) for n, d in imported.shapes]
    return FaceModel(
        imported.vertices,
        faces,
        shapes,
        polygons=imported.polygons,
        component_labels=labels,
        component_names=names,
        metadata=metadata,
    )


def load(path: str | os.PathLike[str], *, units: str | None = None) -> FaceModel:
    """Load a face from a workbench file or an importable mesh set.

    Parameters
    ----------
    path : path-like
        ``.fwb`` workbench file; ``.glb``/``.gltf`` with morph targets (names from
        ``mesh.extras.targetNames``); a folder of same-topology ``.obj`` files (a
        neutral plus one per expression); or an ``.obj`` with MakeHuman ``.target``
        files in a ``targets/`` folder beside it (pass the folder).
    units : {"m", "dm", "cm", "mm"}, optional
        Length unit of an imported mesh that does not state one (OBJ); default metres.
        Ignored for workbench files, which store their unit.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if p.is_file() and _is_workbench_file(p):
        return load_model(p)
    return model_from_imported(read_any(p), name=p.stem, units=units)
