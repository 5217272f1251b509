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


def test_an_unknown_linear_layer_is_drawn_by_the_page_not_the_residual(tmp_path):
    env = install(tmp_path)
    run = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert abs(out["gain_max"] - 1.5) < 1e-6  # the mask reaches 1 where the jaw moves most
    # the page's own evaluation is the kernel's to float rounding: the residual stays empty
    assert out["0.2"] < 1e-5 and out["0.9"] < 1e-5, out
    assert out["controls"] is None  # the sample head has no handles: no shell basis to send
