"""Loading faces from files: one module per format behind a registry (see ``registry``).

:func:`load` accepts a saved workbench file (``.fwb``), a ``.glb``/``.gltf`` with
morph targets, a folder of same-topology OBJ files, or an ``.obj`` with
MakeHuman ``.target`` files beside it, and returns a :class:`~workbench.FaceModel`.
Every reader verifies its input completely before a model is built, so a bad
file raises a clear error and nothing is half-loaded.
"""

from __future__ import annotations

import logging
import os
import zipfile
from pathlib import Path

import numpy as np

from workbench.fileformat import SUFFIX, load_model
from workbench.geometry.mesh_checks import label_components
from workbench.io.animation import animation_of
from workbench.io.base import ImportedFace
from workbench.io.registry import read_any
from workbench.io.units import decide_units
from workbench.model import BlendShape, FaceModel, ModelMetadata

__all__ = ["ImportedFace", "load", "model_from_imported"]

logger = logging.getLogger("workbench.io")


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

    ``units`` overrides the file's unit; for files without one (OBJ) the unit is
    inferred from the head's size (:func:`workbench.io.units.decide_units`, logged
    and recorded in ``metadata.provenance``).
    """
    faces, tri_poly = imported.polygons.triangulate()
    group_of_face = (
        None if imported.face_groups is None else np.asarray(imported.face_groups)[tri_poly]
    )
    labels, names = label_components(
        faces, len(imported.vertices), group_of_face, list(imported.group_names or [])
    )
    decision = decide_units(
        imported.vertices,
        stated=imported.units,
        given=units or None,
        source=str(imported.source_files[0]) if imported.source_files else name,
    )
    metadata = ModelMetadata(
        name=name,
        units=decision.unit,
        up_axis=imported.up_axis or "+y",
        front_axis="+z",
        provenance=(
            *({"source": str(f)} for f in imported.source_files),
            decision.provenance(),
        ),
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
        files in a ``targets/`` folder beside it (pass the folder); ``.fbx``,
        ``.usd*`` or ``.abc`` (:mod:`workbench.io.registry`). A file's own weights
        animation is put on the model's timeline (not an undo step).
    units : {"m", "dm", "cm", "mm", "in"}, optional
        Length unit of an imported mesh. Default: the one the format states (glTF:
        metres), else (OBJ) inferred from the head's size, see
        :mod:`workbench.io.units`. Ignored for workbench files, which store their unit.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if p.is_file() and _is_workbench_file(p):
        return load_model(p)
    model = model_from_imported(read_any(p), name=p.stem, units=units)
    # the file's own weights animation (glTF, FBX, USD, Alembic) starts on the timeline
    timeline = animation_of(p, model.shape_names)
    if timeline is not None:
        model.restore_slots({"tracks": timeline})
        logger.info("%s: its animation is on the timeline (%d tracks, %.3g-%.3g s)",
                    p.name, len(timeline.tracks), timeline.start, timeline.end)
    return model
