"""Optional: Blender (bpy in its own venv) imports our .glb: shape-key names, LINEAR key values,
and the evaluated mesh of an edited head (handles, paint, regions) equal to ``model.evaluate_at``.

Runs with the Python given by ``WORKBENCH_BPY_PYTHON`` (``bash .ci/workbench test``
installs bpy into ``.venv/blender`` and sets it); bpy needs numpy<2, hence its own
venv. Outside CI it is skipped when no such Python exists; under ``CI=true`` a
missing Blender is a failure.
Blender maps glTF time t to frame t * 24, clamps shape-key values to [0, 1] (the
exporter keeps layer-target weights in [0, 1] for that) and turns glTF's +y up
into +z up: Blender (x, y, z) = glTF (x, -z, y).
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from ci_env import in_ci
from consumer_timelines import expected_points, expression_timeline
from edited_models import painted_head, regions_head

from workbench.export import export

SCRIPT = r"""
import json, sys
import bpy
from bpy_extras import anim_utils
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[-1])
obj = next(o for o in bpy.data.objects if o.type == "MESH")
keys = obj.data.shape_keys
names = [kb.name for kb in keys.key_blocks][1:]
ad = keys.animation_data
bag = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot)
curves = {}
for fc in bag.fcurves:
    name = fc.data_path.split('"')[1]
    curves[name] = [[kp.co[0], kp.co[1], kp.interpolation] for kp in fc.keyframe_points]
print("JSON" + json.dumps({"names": names, "curves": curves}))
"""


POINTS_SCRIPT = r"""
import json, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[-2])
obj = next(o for o in bpy.data.objects if o.type == "MESH")
scene = bpy.context.scene
out = []
for f in json.loads(sys.argv[-1]):
    scene.frame_set(f)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    out.append([list(ev.matrix_world @ v.co) for v in me.vertices])
    ev.to_mesh_clear()
names = [kb.name for kb in obj.data.shape_keys.key_blocks][1:]
print("JSON" + json.dumps({"names": names, "points": out}))
"""


def _bpy_python() -> Path | None:
    default = Path(__file__).resolve().parents[2] / ".venv" / "blender" / "bin" / "python"
    p = os.environ.get("WORKBENCH_BPY_PYTHON") or str(default)
    return Path(p) if Path(p).is_file() else None


@pytest.mark.skipif(
    _bpy_python() is None and not in_ci(),
    reason="no Python with bpy (set WORKBENCH_BPY_PYTHON)",
)
def test_blender_reads_names_and_linear_keys(head, tmp_path):
    assert _bpy_python() is not None, "CI must provide Blender (bpy) via WORKBENCH_BPY_PYTHON"
    tl = expression_timeline("linear")
    (p,) = export(head, tl, tmp_path / "a.glb")
    script = tmp_path / "check.py"
    script.write_text(SCRIPT)
    proc = subprocess.run(
        [str(_bpy_python()), str(script), str(p)], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(next(line[4:] for line in proc.stdout.splitlines() if line.startswith("JSON")))
    assert out["names"] == head.shape_names
    jaw = out["curves"]["jawOpen"]
    track = tl.tracks["weights/jawOpen"]
    for t, v in zip(track.times, track.values[:, 0], strict=True):
        hit = [c for c in jaw if abs(c[0] - t * 24) < 1e-3]
        assert hit and hit[0][1] == pytest.approx(v, abs=1e-6)
        assert hit[0][2] == "LINEAR"


@pytest.mark.skipif(
    _bpy_python() is None and not in_ci(),
    reason="no Python with bpy (set WORKBENCH_BPY_PYTHON)",
)
@pytest.mark.parametrize("build", [painted_head, regions_head], ids=["painted", "regions"])
def test_blender_plays_the_edited_head(build, tmp_path):
    # LINEAR keys: Blender's importer keeps LINEAR F-curves, so every frame is exact
    # (CUBICSPLINE becomes Bezier with auto handles in Blender: exact at keys only)
    assert _bpy_python() is not None, "CI must provide Blender (bpy) via WORKBENCH_BPY_PYTHON"
    m = build("linear")
    (p,) = export(m, m.tracks, tmp_path / "edited.glb")
    frames = [0, 5, 12, 17, 24]
    script = tmp_path / "points.py"
    script.write_text(POINTS_SCRIPT)
    proc = subprocess.run(
        [str(_bpy_python()), str(script), str(p), json.dumps(frames)], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(next(line[4:] for line in proc.stdout.splitlines() if line.startswith("JSON")))
    assert out["names"][: len(m.shape_names)] == m.shape_names
    P = np.array(out["points"])
    theirs = np.stack([P[..., 0], P[..., 2], -P[..., 1]], axis=-1)  # Blender z-up -> glTF y-up
    ours = expected_points(m, m.tracks, np.array(frames) / 24.0)
    np.testing.assert_allclose(theirs, ours, atol=1e-5, rtol=0)


READ_BACK_SCRIPT = r"""
import json, sys
import bpy
args = json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = args["fps"]
if args["path"].endswith(".fbx"):
    bpy.ops.import_scene.fbx(filepath=args["path"], anim_offset=0.0)  # default 1: keys one frame late
else:
    bpy.ops.wm.alembic_import(filepath=args["path"])
obj = next(o for o in scene.objects if o.type == "MESH")
out = []
for f in args["frames"]:
    scene.frame_set(f)
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    out.append([list(ev.matrix_world @ v.co) for v in me.vertices])
    ev.to_mesh_clear()
keys = obj.data.shape_keys
names = [kb.name for kb in keys.key_blocks][1:] if keys else []
print("JSON" + json.dumps({"names": names, "points": out}))
"""


@pytest.mark.skipif(
    _bpy_python() is None and not in_ci(),
    reason="no Python with bpy (set WORKBENCH_BPY_PYTHON)",
)
@pytest.mark.parametrize("suffix", [".fbx", ".abc"])
def test_fbx_and_alembic_play_the_edited_head_in_blender(suffix, tmp_path):
    # written through Blender, read back by Blender's own FBX / Alembic importer:
    # every frame (Bezier keys in between included) equals model.evaluate_at
    assert _bpy_python() is not None, "CI must provide Blender (bpy) via WORKBENCH_BPY_PYTHON"
    m = painted_head("bezier")
    (p,) = export(m, m.tracks, tmp_path / f"edited{suffix}")
    fps = m.tracks.fps
    frames = [0, 5, 12, 17, round(m.tracks.end * fps)]
    script = tmp_path / "read_back.py"
    script.write_text(READ_BACK_SCRIPT)
    args = {"path": str(p), "fps": round(fps), "frames": frames}
    proc = subprocess.run(
        [str(_bpy_python()), str(script), json.dumps(args)], capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(next(line[4:] for line in proc.stdout.splitlines() if line.startswith("JSON")))
    if suffix == ".fbx":  # the blend shapes travel as shape keys, named as ours
        assert out["names"][: len(m.shape_names)] == m.shape_names
    P = np.array(out["points"])
    theirs = np.stack([P[..., 0], P[..., 2], -P[..., 1]], axis=-1)  # Blender z-up -> y-up
    ours = expected_points(m, m.tracks, np.array(frames) / fps)
    np.testing.assert_allclose(theirs, ours, atol=2e-5, rtol=0)
