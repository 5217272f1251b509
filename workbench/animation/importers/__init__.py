"""Import animation: per-frame ARKit weight CSVs and glTF weight animations → a Timeline.

Supported inputs, each read by its own module:

* **Live Link Face CSV** (Epic's iPhone app), **plain weight CSV** ("time +
  one column per shape", what :mod:`workbench.export.csv` writes) and **Face
  Cap text** — :mod:`~workbench.animation.importers.weights_csv`, with the
  Live Link Face header, timecodes, frame rate and head angles in
  :mod:`~workbench.animation.importers.livelink`;
* **glTF/GLB weight animations** — :mod:`~workbench.animation.importers.gltf`.

The stages they share: column names are matched to the model's shapes
(exactly, else by ARKit meaning, on any rig) in
:mod:`~workbench.animation.importers.names`; sampled rows become linear keys,
optionally reduced within a tolerance, in
:mod:`~workbench.animation.importers.keys`. Every problem raises
:class:`AnimationImportError` naming the file, the row/line and the column.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from workbench.animation.importers.errors import AnimationImportError
from workbench.animation.importers.gltf import read_gltf_animation
from workbench.animation.importers.keys import (
    reduce_keys,
    reduce_keys_jointly,
    timeline_from_samples,
)
from workbench.animation.importers.livelink import (
    LIVELINK_ANGLE_UNIT,
    LIVELINK_EYE_COLUMNS,
    LIVELINK_HEAD_COLUMNS,
    LIVELINK_HEADER,
    LIVELINK_SHAPE_COLUMNS,
    livelink_fps,
    livelink_head_angles,
    livelink_head_rotation,
)
from workbench.animation.importers.names import map_columns_to_rig, map_shape_names
from workbench.animation.importers.weights_csv import read_weights_csv
from workbench.animation.tracks import Timeline

__all__ = [
    "LIVELINK_ANGLE_UNIT",
    "LIVELINK_EYE_COLUMNS",
    "LIVELINK_HEADER",
    "LIVELINK_HEAD_COLUMNS",
    "LIVELINK_SHAPE_COLUMNS",
    "AnimationImportError",
    "livelink_fps",
    "livelink_head_angles",
    "livelink_head_rotation",
    "map_columns_to_rig",
    "map_shape_names",
    "read_animation",
    "read_gltf_animation",
    "read_weights_csv",
    "reduce_keys",
    "reduce_keys_jointly",
    "timeline_from_samples",
]


def read_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    up_axis: str = "+y",
    front_axis: str = "+z",
    **kw: Any,
) -> Timeline:
    """Dispatch by suffix: .glb/.gltf → :func:`read_gltf_animation`, else :func:`read_weights_csv`.

    ``up_axis``/``front_axis`` (the model's, for Live Link Face head columns)
    only matter to CSVs.
    """
    p = Path(path)
    if p.suffix.lower() in (".glb", ".gltf"):
        return read_gltf_animation(p, shape_names, **kw)
    return read_weights_csv(p, shape_names, up_axis=up_axis, front_axis=front_axis, **kw)
