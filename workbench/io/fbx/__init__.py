"""FBX reader: meshes with shape keys (blend shapes) and their animation, through Blender's importer.

The registry's module for ``.fbx`` (``detect``, ``read``, ``DESCRIPTION``).
FBX has no open specification and no maintained Python reader (the FBX SDK is
proprietary), so the file is imported by Blender's own FBX importer, run in the
bpy venv as a subprocess (:mod:`.blender_bridge`), which dumps the meshes,
their shape keys and the keyframes of the shape-key values. Blender applies
the file's object transforms, axis system and unit scale; the reader turns
Blender's z-up metres back into the file's unit, y up, front +z:

* **geometry**: every mesh object (sorted by name), its vertices under the
  object's world transform, faces as in the file (n-gons kept); several meshes
  become face groups named after the objects;
* **shapes**: one per shape key (FBX ``BlendShapeChannel``), delta from its
  relative key; a name on several meshes is one shape;
* **units**: ``GlobalSettings.UnitScaleFactor`` is centimetres per unit
  (1 = cm, 100 = m, 0.1 = mm, 2.54 = in, 10 = dm): coordinates are given in that
  unit, which ``ImportedFace.units`` states (metres-per-unit in
  ``FaceModel.metadata``); another factor gives metres;
* **animation** (:func:`read_fbx_animation`): the F-curves of the shape-key
  values (FBX ``DeformPercent`` / 100) on the timeline, key frame ``f`` at
  ``f / fps`` seconds with the file's frame rate (``GlobalSettings``
  ``TimeMode``/``CustomFrameRate``), imported with ``anim_offset=0`` (Blender's
  default shifts keys one frame late). Blender's importer makes every key
  LINEAR, so these are linear keys at the file's key times and values.

Before Blender runs, the binary file is walked by a small checked parser
(:func:`parse_fbx`, :mod:`~workbench.io.fbx.binary`; the fields in
:mod:`~workbench.io.fbx.checks`): every node's end offset, property and array (zlib
included) is checked against the bytes present, and the mesh, shape, curve and
unit fields Blender will read are checked for counts, ranges and finite numbers,
so a malformed file fails in milliseconds with a :class:`MeshFormatError`
naming the file, the node path and the field, never half-loaded or as a
traceback from inside Blender. ASCII FBX is refused with a note (Blender's
importer reads binary FBX 7.1 and later only).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.base import ImportedFace
from workbench.io.blender_bridge import run_dump
from workbench.io.fbx.animation import _timeline
from workbench.io.fbx.binary import MAGIC as MAGIC
from workbench.io.fbx.binary import MIN_VERSION as MIN_VERSION
from workbench.io.fbx.binary import FbxFile, FbxNode, parse_fbx
from workbench.io.fbx.checks import _prepare
from workbench.io.fbx.geometry import _parts, _unit
from workbench.io.parts import merge_parts

__all__ = [
    "DESCRIPTION",
    "FbxFile",
    "FbxNode",
    "detect",
    "parse_fbx",
    "read",
    "read_fbx",
    "read_fbx_animation",
]


log = logging.getLogger("workbench.io")


DESCRIPTION = (
    "a binary .fbx file (meshes with shape keys and their animation; read by Blender's "
    "FBX importer in the bpy venv, WORKBENCH_BPY_PYTHON)"
)


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() == ".fbx"


def read(path: Path) -> ImportedFace:
    return read_fbx(path)


def read_fbx(path: str | Path) -> ImportedFace:
    """Read an FBX file's meshes and shape keys (see the module docstring).

    Raises
    ------
    FileNotFoundError
        No such file.
    MeshFormatError
        Malformed file (checked before Blender runs) or Blender's importer failed.
    workbench.io.blender_bridge.BlenderMissingError
        No Python with bpy (the message says how to install it).
    """
    p, s, notes = _prepare(path)
    src = str(p)
    unit, mpu = _unit(s.unit_scale)
    if unit == "m" and abs(s.unit_scale - 100.0) > 1e-4:
        notes.append(f"UnitScaleFactor {s.unit_scale:g} cm per unit is not mm/cm/in/dm/m: coordinates converted to metres")
    dump = run_dump(p, "fbx")
    parts = _parts(dump, src, mpu)
    if s.up_axis != 1 or s.up_sign != 1:
        notes.append(f"the file is {'-' if s.up_sign < 0 else '+'}{'xyz'[s.up_axis]} up; converted to +y up")
    for n in notes:
        log.info("%s: %s", p.name, n)
    return merge_parts(parts, src, units=unit, up_axis="+y")


def read_fbx_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    fps: float | None = None,
    on_unknown: str = "error",
) -> Any:
    """Read the shape-key animation of an FBX file as a :class:`~workbench.animation.tracks.Timeline`.

    Mirrors :func:`workbench.animation.importers.read_gltf_animation`: curves are
    matched to ``shape_names`` exactly, else by ARKit meaning.

    Parameters
    ----------
    path : str or Path
        The .fbx file.
    shape_names : sequence of str
        The model's shapes.
    fps : float, optional
        Frame rate of the timeline (default: the file's).
    on_unknown : {"error", "ignore"}
        What to do with animated shape keys that match no shape.

    Raises
    ------
    AnimationImportError
        Malformed file, no shape-key animation, unknown names, the same shape
        animated differently on two meshes, an unsupported interpolation.
    """
    from workbench.animation.importers import AnimationImportError

    p = Path(path)
    try:
        p, s, _ = _prepare(p)
        dump = run_dump(p, "fbx")
    except MeshFormatError as exc:
        raise AnimationImportError(str(p), exc.detail) from None
    file_fps = float(dump.meta.get("fps") or s.fps or 24.0)
    curves: dict[str, tuple[str, list[list[Any]]]] = {}
    for ob in dump.meta.get("objects", []):
        for name, c in ob.get("curves", {}).items():
            keys = c.get("keys", [])
            if name in curves and curves[name][1] != keys:
                raise AnimationImportError(
                    str(p), f"shape key '{name}' is animated differently on '{curves[name][0]}' and '{ob['name']}'"
                )
            curves[name] = (str(ob.get("name")), keys)
    if not curves:
        raise AnimationImportError(str(p), "the file has no shape-key animation (no keyed DeformPercent)")
    return _timeline(str(p), curves, shape_names, file_fps, fps or file_fps, on_unknown)
