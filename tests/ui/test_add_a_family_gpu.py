"""The worked example's family on the viewport's GPU path (see tests/consumers/test_add_a_family.py).

The page evaluates ``neutral + a ⊙ Σ w δ + c ⊙ B u`` itself and adds the
kernel's residual; a linear layer the workbench has never heard of must land in
the gains ``a``, not in the residual, so a slider drag under it needs no
residual rows.
"""

from __future__ import annotations

import json
import subprocess
import sys

from example_family.install import install

SCRIPT = r"""
import json, numpy as np, workbench
from widgets.viewport.gpu import linear_layers
m = workbench.load_sample("head")
d = np.linalg.norm(m.shape("jawOpen").delta, axis=1)
mask = (d / d.max()).astype(np.float32)
m.mouth_gain.set(1.5, mask)
out = {}
for w in (0.2, 0.9):
    m.set_weights({"jawOpen": w, "mouthSmileLeft": 0.3})
    gains, controls = linear_layers(m, m.view())
    V = m.vertices32
    page = V + gains[:, :1] * (np.asarray(m.blended(), np.float32) - V)
    out[str(w)] = float(np.abs(np.asarray(m.evaluate(posed=False)) - page).max())
out["gain_max"] = float(gains[:, 0].max())
out["controls"] = None if controls is None else controls.name
print(json.dumps(out))
"""


def _run_with_the_family(script: str, tmp_path) -> dict:
    """Run ``script`` in a Python that has the example family installed; its last line's JSON."""
    run = subprocess.run([sys.executable, "-c", script], env=install(tmp_path), capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_an_unknown_linear_layer_is_drawn_by_the_page_not_the_residual(tmp_path):
    out = _run_with_the_family(SCRIPT, tmp_path)
    assert abs(out["gain_max"] - 1.5) < 1e-6  # the mask reaches 1 where the jaw moves most
    # the page's own evaluation is the kernel's to float rounding: the residual stays empty
    assert out["0.2"] < 1e-5 and out["0.9"] < 1e-5, out
    assert out["controls"] is None  # the sample head has no handles: no shell basis to send


TOOL_SCRIPT = r"""
import json, numpy as np, workbench, widgets
from widgets.viewport.tools import tool_names
m = workbench.load_sample("head")
vp = widgets.Viewport(m)
out = {"names": list(tool_names()), "kinds": vp._tool_kinds}
vp.tool = "gain_brush"
out["target"] = vp.stroke_target
sent = []
vp.send = lambda content, buffers=None: sent.append(content)
# the page's messages for one stroke: press, one move, release
ids = np.flatnonzero(np.linalg.norm(m.shape("jawOpen").delta, axis=1) > 0)[:12].tolist()
for seq, (phase, v) in enumerate((("start", ids[:4]), ("move", ids[4:8]), ("end", ids[8:]))):
    vp._on_frontend_msg(vp, {"type": "stroke", "phase": phase, "vertices": v, "seq": seq}, [])
mask = m.slot("mouth_gain").mask
out["painted"] = sorted(np.flatnonzero(mask).tolist()) == sorted(ids)
out["undo"] = list(m.history.undo_labels)
out["acks"] = [c["seq"] for c in sent if c.get("type") == "stroke_ack"]
tint = np.frombuffer(vp._tint, "<f4")
out["tint"] = bool(tint.size == m.n_vertices and np.array_equal(tint, mask))
vp.tool = "paint"  # another tool: its tint (none: no expression picked) is drawn
out["tint_after"] = len(vp._tint)
m.history.undo()
out["undone"] = m.slot("mouth_gain").mask is None or not np.any(m.slot("mouth_gain").mask)
vp.close()
print(json.dumps(out))
"""


def test_a_family_adds_a_viewport_tool_without_editing_the_viewport(tmp_path):
    out = _run_with_the_family(TOOL_SCRIPT, tmp_path)
    assert out["names"][0] == "orbit" and {"sculpt", "paint", "gain_brush"} <= set(out["names"])
    assert out["kinds"]["gain_brush"] == "stroke" and out["kinds"]["sculpt"] == "drag"
    assert out["target"] == "mouth gain mask"  # the page strokes only while there is a target
    assert out["painted"], out  # the brushed vertices, and only those, are in the mask
    assert out["undo"] == ["Brush mouth gain mask"]  # one stroke, one undo step
    assert out["acks"] == [0, 1, 2]  # every message of the stroke acknowledged
    assert out["tint"] and out["tint_after"] == 0
    assert out["undone"]
