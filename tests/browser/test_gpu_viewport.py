"""The viewport evaluates the rig on the GPU (issue 19), in JupyterLab + Chromium.

Sliders, handle drags and playback send only weights, handle offsets and the
head pose (``widgets/viewport/gpu.py``); the browser evaluates neutral + Σ w δ
+ B u_H in float render targets (``widgets/js/src/viewport/gpu_morph.js``).
Each test checks the pixels where the face moves, and that the positions the
GPU evaluated (read back from the render target) equal the kernel's
``model.evaluate()`` within 1e-5 of the face size. ``gpu=False`` streams vertex
rows as before and says so in the view.
"""

from __future__ import annotations

import numpy as np
from harness import NotebookPage, clip_around, pixel_change, wait_until

RESOLUTION = "100k"  # 79,673 vertices

_SETUP = """
import json, numpy as np, workbench
from IPython.display import display
from widgets.viewport import Viewport
model = workbench.load_sample("head", resolution={res!r})
vp = Viewport(model, height=420, gpu={gpu})
display(vp)
"""

_PROBE = """
import json, numpy as np
_d = np.linalg.norm(model.shape("jawOpen").delta, axis=1)
_skin = model.component_labels == model.component_names.index("skin")
_ids = np.argsort(-(_d * _skin))[:80]
vp.probe_ids = _ids
print(json.dumps([int(i) for i in _ids]))
"""

_SIZE = "print(json.dumps(float(np.linalg.norm(np.ptp(model.vertices, axis=0)))))"


def _open(open_notebook, gpu: bool = True, res: str = RESOLUTION) -> NotebookPage:
    nb = open_notebook([_SETUP.format(res=res, gpu=gpu)])
    nb.page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1, timeout=120)
    return nb


def _gpu_positions(nb: NotebookPage) -> np.ndarray | None:
    out = nb.viewport(0).evaluate(
        "e => { const p = e.fwbGpuPositions(); return p ? Array.from(p) : null; }"
    )
    return None if out is None else np.asarray(out, np.float64).reshape(-1, 3)


def _kernel_positions(nb: NotebookPage) -> np.ndarray:
    b64 = nb.kernel_eval(
        "import base64\n"
        "print(json.dumps(base64.b64encode(np.ascontiguousarray(model.evaluate(), '<f4').tobytes()).decode()))"
    )
    import base64

    return np.frombuffer(base64.b64decode(b64), "<f4").reshape(-1, 3).astype(np.float64)


def _assert_gpu_equals_kernel(nb: NotebookPage, size: float) -> float:
    gpu = _gpu_positions(nb)
    assert gpu is not None, "the view does not evaluate on the GPU"
    ref = _kernel_positions(nb)
    err = float(np.abs(gpu - ref).max()) / size
    assert err <= 1e-5, f"GPU and kernel differ by {err:.2e} of the face size"
    return err


def _wait_version(nb: NotebookPage, version: int) -> None:
    wait_until(
        "the view drew the kernel's last update",
        lambda: int(nb.viewport(0).get_attribute("data-version") or -1),
        lambda v: v >= version,
    )


def _kernel_version(nb: NotebookPage) -> int:
    return int(nb.kernel_eval("print(json.dumps(vp._version))"))


def test_slider_update_is_weights_only_and_the_gpu_matches_the_kernel(open_notebook):
    nb = _open(open_notebook)
    vp = nb.viewport(0)
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1", timeout=60)
    ids = nb.kernel_eval(_PROBE)
    size = float(nb.kernel_eval(_SIZE))
    nb.page.wait_for_timeout(0)
    pts = nb.project(ids)
    clip = clip_around(pts, pad=60)
    before = nb.screenshot("gpu_slider_before", clip=clip)
    frame = nb.frame()
    nb.kernel_eval('model.set_weight("jawOpen", 0.8)')
    _wait_version(nb, _kernel_version(nb))
    nb.wait_frame_after(0, frame)
    after = nb.screenshot("gpu_slider_after", clip=clip)
    changed = pixel_change(before, after)
    assert changed > 0.05, f"only {changed:.1%} of the mouth pixels changed"
    payload = nb.kernel_eval("print(json.dumps(list(vp.gpu_payload)))")
    assert payload and max(payload[-1:]) <= 2048, payload
    assert vp.get_attribute("data-gpu-note") == ""
    _assert_gpu_equals_kernel(nb, size)
    # texture memory: at most twice the rig's float32 vertex data (neutral + deltas + basis)
    tex = int(vp.get_attribute("data-gpu-texture-bytes"))
    rig = nb.kernel_eval(
        "print(json.dumps(int(model.n_vertices * 3 * 4 * (1 + len(model.shape_names)))))"
    )
    assert tex <= 2 * rig, (tex, rig)
