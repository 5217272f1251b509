"""Run Blender's own importers (FBX, Alembic) in the bpy venv and read back what they built.

Neither FBX nor Alembic has a maintained Python reader we could depend on (the
FBX SDK is proprietary; the ``alembic`` bindings are not on PyPI for this
Python), while Blender's importers are what users trust for both. Blender as a
Python module (``bpy``) needs ``numpy<2``, so it lives in its own venv and runs
as a subprocess: ``$WORKBENCH_BPY_PYTHON``, else ``<repo>/.venv/blender/bin/python``
(``bash .ci/workbench test`` installs it; by hand:
``python -m venv .venv/blender && .venv/blender/bin/python -m pip install bpy==5.0.1 'numpy<2'``).

The script :data:`DUMP_SCRIPT` imports the file into an empty scene and dumps,
for every mesh object (sorted by name): its local vertex positions, world
matrix, faces, shape keys (delta from each key's relative key) and the
F-curves of the shape-key values; for a point cache, the evaluated vertices
at the requested frames. The interchange is a plain ``.npz`` (read with
``allow_pickle=False``) plus a JSON file, never pickles: nothing the
subprocess writes can run code here. The readers (:mod:`.fbx`,
:mod:`.alembic`) check every array before they use it.

The last two dumps are kept in memory (keyed by path, size and mtime), so
reading a face and then its animation runs Blender once.
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import zipfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError

__all__ = [
    "INSTALL_HINT",
    "BlenderDump",
    "BlenderMissingError",
    "blender_python",
    "run_dump",
]

#: how to get bpy, shown when it is missing
INSTALL_HINT = (
    "set WORKBENCH_BPY_PYTHON to a Python that has bpy, or install it into .venv/blender: "
    "`python -m venv .venv/blender && .venv/blender/bin/python -m pip install bpy==5.0.1 'numpy<2'` "
    "(`bash .ci/workbench test` does this)"
)
#: timeout for one Blender run, seconds
TIMEOUT_S = 1800

DUMP_SCRIPT = r"""
import json, sys
import numpy as np
import bpy

args = json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
notes = []
if args["kind"] == "fbx":
    bpy.ops.import_scene.fbx(
        filepath=args["path"], anim_offset=0.0, use_anim=True, use_custom_normals=False,
        use_image_search=False, use_subsurf=False,
    )
else:
    fps = float(args["fps"])
    scene.render.fps = max(1, round(fps))
    scene.render.fps_base = scene.render.fps / fps
    bpy.ops.wm.alembic_import(
        filepath=args["path"], set_frame_range=False, as_background_job=False,
        validate_meshes=False, always_add_cache_reader=True,
    )
fps = scene.render.fps / scene.render.fps_base
arrays = {}
objects = []
meshes = sorted((o for o in scene.objects if o.type == "MESH"), key=lambda o: o.name)
for i, ob in enumerate(meshes):
    me = ob.data
    n = len(me.vertices)
    co = np.empty(n * 3, np.float32)
    me.vertices.foreach_get("co", co)
    counts = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_total", counts)
    corners = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", corners)
    arrays[f"o{i}_co"] = co.reshape(n, 3)
    arrays[f"o{i}_counts"] = counts
    arrays[f"o{i}_corners"] = corners
    arrays[f"o{i}_matrix"] = np.array(ob.matrix_world, np.float64)
    info = {"name": ob.name, "data": me.name, "n": n, "keys": [], "curves": {}}
    oad = ob.animation_data
    if oad is not None and oad.action is not None:
        from bpy_extras import anim_utils
        obag = anim_utils.action_get_channelbag_for_slot(oad.action, oad.action_slot)
        for fc in (obag.fcurves if obag is not None else ()):
            vals = {round(kp.co[1], 9) for kp in fc.keyframe_points}
            if len(vals) > 1:
                info["object_animation"] = oad.action.name
                break
    mods = [m.type for m in ob.modifiers if m.type not in ("MESH_SEQUENCE_CACHE",)]
    if mods:
        info["modifiers"] = mods
    keys = me.shape_keys
    if keys is not None:
        info["use_relative"] = bool(keys.use_relative)
        ref = keys.reference_key
        buf = {}
        for kb in keys.key_blocks:
            a = np.empty(n * 3, np.float32)
            kb.data.foreach_get("co", a)
            buf[kb.name] = a.reshape(n, 3)
        for j, kb in enumerate(keys.key_blocks):
            if kb == ref:
                continue
            rel = kb.relative_key.name if kb.relative_key is not None else ref.name
            arrays[f"o{i}_d{len(info['keys'])}"] = buf[kb.name] - buf[rel]
            info["keys"].append({
                "name": kb.name, "relative": rel, "value": kb.value, "min": kb.slider_min,
                "max": kb.slider_max, "mute": bool(kb.mute), "vertex_group": kb.vertex_group,
            })
        ad = keys.animation_data
        if ad is not None and ad.action is not None:
            from bpy_extras import anim_utils
            bag = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot)
            info["action"] = ad.action.name
            for fc in (bag.fcurves if bag is not None else ()):
                path = fc.data_path
                if not (path.startswith('key_blocks["') and path.endswith('"].value')):
                    continue
                name = path[len('key_blocks["'):-len('"].value')]
                info["curves"][name] = {
                    "extrapolation": fc.extrapolation,
                    "keys": [
                        [kp.co[0], kp.co[1], kp.interpolation, kp.handle_left[0], kp.handle_left[1],
                         kp.handle_right[0], kp.handle_right[1], kp.easing]
                        for kp in fc.keyframe_points
                    ],
                }
    objects.append(info)
frames = args.get("frames") or []
if frames:
    stacks = {i: [] for i in range(len(meshes))}
    mats = {i: [] for i in range(len(meshes))}
    for f, sub in frames:
        scene.frame_set(int(f), subframe=float(sub))
        dg = bpy.context.evaluated_depsgraph_get()
        for i, ob in enumerate(meshes):
            ev = ob.evaluated_get(dg)
            me = ev.to_mesh()
            n = len(me.vertices)
            if n != objects[i]["n"]:
                objects[i]["frame_error"] = [int(f), float(sub), n]
                ev.to_mesh_clear()
                continue
            a = np.empty(n * 3, np.float32)
            me.vertices.foreach_get("co", a)
            stacks[i].append(a.reshape(n, 3))
            mats[i].append(np.array(ev.matrix_world, np.float64))
            ev.to_mesh_clear()
    for i in range(len(meshes)):
        if "frame_error" not in objects[i]:
            arrays[f"o{i}_frames"] = np.stack(stacks[i]) if stacks[i] else np.zeros((0, objects[i]["n"], 3), np.float32)
            arrays[f"o{i}_frame_matrices"] = np.stack(mats[i]) if mats[i] else np.zeros((0, 4, 4))
other_actions = [a.name for a in bpy.data.actions]
np.savez(args["npz"], **arrays)
with open(args["json"], "w") as fh:
    json.dump({"fps": fps, "objects": objects, "actions": other_actions,
               "blender": bpy.app.version_string}, fh)
print("BLENDER_DUMP_OK " + bpy.app.version_string)
"""


class BlenderMissingError(OSError):
    """No Python with bpy was found: the message names ``WORKBENCH_BPY_PYTHON`` and how to install it."""


@dataclass
class BlenderDump:
    """What :data:`DUMP_SCRIPT` wrote: arrays by name and the JSON metadata."""

    arrays: dict[str, NDArray[Any]]
    meta: dict[str, Any]
    seconds: float

    def array(self, name: str, src: str, what: str) -> NDArray[Any]:
        try:
            return self.arrays[name]
        except KeyError:
            raise MeshFormatError(
                src, what, f"{what}: Blender's import gave no {name!r} array"
            ) from None


def blender_python() -> Path | None:
    """Python of a venv with ``bpy``: ``$WORKBENCH_BPY_PYTHON`` or ``<repo>/.venv/blender/bin/python``."""
    env = os.environ.get("WORKBENCH_BPY_PYTHON")
    if env:
        return Path(env) if Path(env).is_file() else None
    p = Path(__file__).resolve().parents[2] / ".venv" / "blender" / "bin" / "python"
    return p if p.is_file() else None


_CACHE: OrderedDict[tuple[Any, ...], BlenderDump] = OrderedDict()
_CACHE_SIZE = 2


def _blender_error(text: str) -> str:
    """The most telling lines of Blender's output (the Python error, or the tail)."""
    lines = [ln for ln in text.splitlines() if ln.strip()]
    errs = [ln for ln in lines if "Error" in ln or "error" in ln]
    pick = errs[-3:] if errs else lines[-5:]
    return "\n  ".join(pick)[-1500:]


def run_dump(path: Path, kind: str, fps: float = 0.0, frames: list[tuple[int, float]] | None = None) -> BlenderDump:
    """Import ``path`` with Blender (``kind`` "fbx" or "abc") and return the dump.

    Raises
    ------
    BlenderMissingError
        No Python with bpy.
    MeshFormatError
        Blender's importer failed (its error is quoted) or wrote nothing.
    """
    import time

    src = str(path)
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns, kind, fps, tuple(frames or ()))
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    py = blender_python()
    if py is None:
        where = os.environ.get("WORKBENCH_BPY_PYTHON")
        found = f"WORKBENCH_BPY_PYTHON={where} is not a file" if where else "no .venv/blender/bin/python"
        raise BlenderMissingError(
            f"{path.name}: {kind.upper().replace('ABC', 'Alembic')} files are read by Blender's own "
            f"importer, and no Python with bpy was found ({found}); {INSTALL_HINT}"
        )
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fwb-bpy-import-") as tmp:
        script = Path(tmp) / "dump.py"
        script.write_text(DUMP_SCRIPT)
        args: dict[str, Any] = {
            "path": str(path.resolve()),
            "kind": kind,
            "fps": fps,
            "frames": [list(f) for f in (frames or [])],
            "npz": str(Path(tmp) / "dump.npz"),
            "json": str(Path(tmp) / "dump.json"),
        }
        try:
            proc = subprocess.run(
                [str(py), str(script), json.dumps(args)],
                capture_output=True,
                text=True,
                timeout=TIMEOUT_S,
            )
        except subprocess.TimeoutExpired:
            raise MeshFormatError(src, "blender", f"Blender's importer took more than {TIMEOUT_S} s") from None
        if proc.returncode != 0 or "BLENDER_DUMP_OK" not in proc.stdout:
            raise MeshFormatError(
                src,
                "blender",
                f"Blender's {kind.upper().replace('ABC', 'Alembic')} importer could not read the file:\n  "
                + _blender_error(proc.stderr + "\n" + proc.stdout),
            )
        try:
            meta = json.loads(Path(args["json"]).read_text())
            with np.load(args["npz"], allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError, zipfile.BadZipFile) as exc:
            raise MeshFormatError(src, "blender", f"could not read Blender's dump: {exc}") from None
    dump = BlenderDump(arrays, meta, time.perf_counter() - t0)
    _CACHE[key] = dump
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return dump
