"""The README's worked example: a method family added as one folder, with no other file edited.

``tests/example_family/mouth_gain/`` (a gain on the face's motion inside a soft
mask) is installed as a separate package that declares its family in the
``face_workbench.families`` entry-point group; a fresh Python then finds it,
and the family evaluates, undoes, exports (linear: scaled morph targets; keyed:
baked), keys on the timeline and saves. The GPU path's half is in
``tests/ui/test_add_a_family_gpu.py``.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
from example_family.install import install

SCRIPT = r"""
import json, sys, tempfile, pathlib
import numpy as np
import workbench
from workbench.export import export
from workbench.export.encoding import MeshEncoding
from workbench.fileformat import load_model

out = {}
m = workbench.load_sample("head")
out["layers"] = m.pipeline.names
V = m.vertices32.astype(np.float64)
d = np.linalg.norm(m.shape("jawOpen").delta, axis=1)
mask = (d / d.max()).astype(np.float32)
m.set_weights({"jawOpen": 0.6, "mouthSmileLeft": 0.4})
before = np.array(m.evaluate(), np.float64)
m.mouth_gain.set(1.5, mask)
after = np.array(m.evaluate(), np.float64)
g = 1.0 + 0.5 * mask.astype(np.float64)
# evaluates: the motion below the layer, scaled by 1 + (1.5 - 1) m (no other layer is active)
out["evaluate_err"] = float(np.abs((after - V) - g[:, None] * (before - V)).max())
out["moved"] = float(np.abs(after - before).max())
m.history.undo()
out["undo_err"] = float(np.abs(np.array(m.evaluate(), np.float64) - before).max())
m.history.redo()

# keys weights on the timeline; the layer is linear in them: scaled shape targets, no baking
for t, w in ((0.0, 0.0), (1.0, 1.0)):
    m.set_weights({"jawOpen": w})
    m.timeline.key_weights(t, ["jawOpen"])
enc = MeshEncoding(m, m.tracks)
out["report_static"] = {r.name: r.encoding for r in enc.layers}
times = np.linspace(0.0, 1.0, 5)
W = enc.weights(times)
lin = enc.neutral[None] + np.einsum("fk,knc->fnc", W, enc.shape_targets) + (0 if enc.static is None else enc.static)
out["linear_err"] = float(np.abs(lin - np.stack([m.evaluate_at(t) for t in times])).max())

# a glb for three.js (the test plays it in Node): evaluate_at in metres at the same times
tmp = pathlib.Path(sys.argv[1])
export(m, m.tracks, tmp / "face.glb")
np.save(tmp / "expected.npy", np.stack([m.evaluate_at(t) for t in times]) * m.metadata.metres_per_unit)

# keys the gain itself: played by the timeline, exported baked (not linear in two keyed quantities)
m.mouth_gain.key(0.0, 1.0)
m.mouth_gain.key(1.0, 2.0)
m.set_time(0.5)
out["keyed_gain"] = float(m.view_at(0.5).slot("mouth_gain").gain)
enc = MeshEncoding(m, m.tracks)
out["report_keyed"] = {r.name: r.encoding for r in enc.layers}
out["keyed_points_err"] = float(np.abs(enc.points(times) - np.stack([m.evaluate_at(t) for t in times])).max())
lin = (enc.neutral[None] + np.einsum("fk,knc->fnc", enc.weights(times), enc.shape_targets)
       + (0 if enc.static is None else enc.static)
       + np.stack([np.zeros((m.n_vertices, 3)) if enc.baked(t) is None else enc.baked(t) for t in times]))
out["keyed_linear_err"] = float(np.abs(lin - np.stack([m.evaluate_at(t) for t in times])).max())

# the timeline keys "what the track shows now" by asking the family (TrackSpec.current), labels it by its title
from workbench.animation.timeline import track_title
m.mouth_gain.set(1.25)
m.timeline.key_track("mouth_gain", 2.0)
out["key_track"] = [float(m.tracks.tracks["mouth_gain"].evaluate(2.0)[0]), track_title("mouth_gain"),
                    m.history.undo_labels[-1]]

# saves and opens again: the gain, its mask and its keys
m.save(tmp / "face.fwb")
m2 = load_model(tmp / "face.fwb")
st = m2.mouth_gain.value
out["saved"] = [st.gain, float(np.abs(st.mask - mask).max()), list(m2.tracks.tracks)]
out["reopened_err"] = float(np.abs(np.array(m2.evaluate_at(0.5)) - np.array(m.evaluate_at(0.5))).max())
print(json.dumps(out))
"""


def test_a_family_in_one_folder_evaluates_exports_keys_and_saves(node_tools, tmp_path):
    env = install(tmp_path)
    run = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path)], env=env, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["layers"].index("paint") < out["layers"].index("mouth_gain") < out["layers"].index("wrinkles")
    assert out["moved"] > 1e-3
    assert out["evaluate_err"] < 1e-5 and out["undo_err"] == 0.0
    assert out["report_static"]["mouth_gain"] == "linear", out["report_static"]
    assert out["linear_err"] < 1e-5, out
    # three.js plays the glb (morph targets scaled by the gain, weights keyed) as the kernel evaluates it
    times = np.linspace(0.0, 1.0, 5)
    got = node_tools("three_sample.mjs", str(tmp_path / "face.glb"), json.dumps(times.tolist()), "positions")
    theirs = np.array(got["points"]).reshape(times.size, -1, 3)
    np.testing.assert_allclose(theirs, np.load(tmp_path / "expected.npy"), atol=1e-6)
    assert out["keyed_gain"] == 1.5
    assert out["report_keyed"]["mouth_gain"] == "baked", out["report_keyed"]
    assert out["keyed_points_err"] == 0.0 and out["keyed_linear_err"] < 1e-5, out
    assert out["key_track"] == [1.25, "mouth gain", "Key mouth gain at 2s"]
    gain, mask_err, tracks = out["saved"]
    assert gain == 1.25 and mask_err == 0.0 and "mouth_gain" in tracks
    assert out["reopened_err"] == 0.0


def test_without_the_package_the_workbench_knows_no_such_family(tmp_path):
    code = "import workbench; m = workbench.load_sample('head'); print('mouth_gain' in m.pipeline.names)"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == "False"
