"""FBX and Alembic through Blender (optional: needs Blender as a Python module in its own venv).

Neither format has a maintained Python writer we could depend on (the FBX SDK
is proprietary, the ``alembic`` Python bindings are not on PyPI for this
Python), while Blender reads our glTF exactly and writes both. So the writer:

1. writes the animation as a temporary ``.glb`` with weights resampled at every
   frame (``bake=True`` of :mod:`.gltf`: LINEAR keys, so Blender's importer
   plays every frame exactly; editing layers encoded as in :mod:`.gltf`);
2. runs Blender's Python (``WORKBENCH_BPY_PYTHON``, else ``<repo>/.venv/blender``,
   which ``bash .ci/workbench test`` installs; bpy needs ``numpy<2``, hence its own
   venv) on a short script that sets the scene rate to the timeline's fps, imports
   the ``.glb`` and exports
   * **FBX** (``bpy.ops.export_scene.fbx``): the mesh with one shape key per
     morph target and their animated values (baked per frame);
   * **Alembic** (``bpy.ops.wm.alembic_export``): the deformed mesh at every
     frame of the timeline (a point cache, like PC2/MDD, but in Alembic; no
     normals: per-corner normals would multiply the size by seven, viewers compute them);
3. renames the file into place (:func:`workbench.export.atomic_path`).

Axes: Blender converts glTF's +y up to +z up on import and back on export
(FBX: +y up, -z forward; Alembic: +y up), metres throughout. FBX keys are
written at every frame (no curve simplification). Note for Blender users:
Blender's FBX *importer* shifts animation one frame late by default
(``anim_offset=1``); import with an offset of 0 to get the frames as written
(``tests/consumers/test_blender_consumer.py`` reads both formats back with
Blender and compares every sampled frame with ``evaluate_at``).
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from workbench.export.base import ExportError, ExportResult, atomic_path

if TYPE_CHECKING:
    from workbench.animation.tracks import Timeline
    from workbench.model import FaceModel

_SCRIPT = r"""
import json, sys
import bpy
args = json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
fps = args["fps"]
scene.render.fps = max(1, round(fps))
scene.render.fps_base = scene.render.fps / fps
bpy.ops.import_scene.gltf(filepath=args["glb"])
scene.frame_start, scene.frame_end = args["frame_start"], args["frame_end"]
if args["kind"] == "fbx":
    bpy.ops.export_scene.fbx(
        filepath=args["out"], object_types={"MESH"}, use_mesh_modifiers=False,
        bake_anim=True, bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
        bake_anim_force_startend_keying=True, bake_anim_step=1.0, bake_anim_simplify_factor=0.0,
        add_leaf_bones=False, apply_unit_scale=True,
    )
else:
    bpy.ops.wm.alembic_export(
        filepath=args["out"], start=args["frame_start"], end=args["frame_end"],
        selected=False, flatten=False, uvs=False, normals=False, face_sets=False,
        export_hair=False, export_particles=False,
    )
print("BLENDER_OK " + bpy.app.version_string)
"""

#: timeout for one Blender run (import + export), seconds
TIMEOUT_S = 1800


def blender_python() -> Path | None:
    """Python of a venv with ``bpy``: ``$WORKBENCH_BPY_PYTHON`` or ``<repo>/.venv/blender``."""
    env = os.environ.get("WORKBENCH_BPY_PYTHON")
    if env:
        return Path(env) if Path(env).is_file() else None
    p = Path(__file__).resolve().parents[2] / ".venv" / "blender" / "bin" / "python"
    return p if p.is_file() else None


def write(
    model: FaceModel, timeline: Timeline, path: Path, *, bake: bool = False, kind: str | None = None
) -> ExportResult:
    """Registry entry for ``fbx`` and ``abc`` (``kind`` or the suffix picks the format)."""
    from workbench.export import gltf

    k = (kind or path.suffix.lower().lstrip(".")).replace("alembic", "abc")
    if k not in ("fbx", "abc"):
        raise ExportError(f"{path.name}: unknown Blender format {k!r} (fbx, abc)")
    py = blender_python()
    if py is None:
        raise ExportError(
            f"{path.name}: FBX and Alembic are written by Blender, and no Python with bpy was found; "
            "set WORKBENCH_BPY_PYTHON to one (bash .ci/workbench test installs bpy into .venv/blender)"
        )
    frames = timeline.frame_times()
    f0 = round(float(frames[0]) * timeline.fps)
    with tempfile.TemporaryDirectory(prefix="fwb-blender-") as tmp:
        glb = Path(tmp) / "animation.glb"
        written = gltf.write(model, timeline, glb, bake=True)
        script = Path(tmp) / "export.py"
        script.write_text(_SCRIPT)
        with atomic_path(path) as out:
            args = {
                "glb": str(glb), "out": str(out), "kind": k, "fps": float(timeline.fps),
                "frame_start": f0, "frame_end": f0 + int(frames.size) - 1,
            }
            proc = subprocess.run(
                [str(py), str(script), json.dumps(args)], capture_output=True, text=True, timeout=TIMEOUT_S
            )
            if proc.returncode != 0 or "BLENDER_OK" not in proc.stdout or not out.is_file() or out.stat().st_size == 0:
                tail = (proc.stderr or proc.stdout)[-1500:]
                raise ExportError(f"{path.name}: Blender could not write the {k.upper()} file:\n{tail}")
    return ExportResult([path], written.layers)
