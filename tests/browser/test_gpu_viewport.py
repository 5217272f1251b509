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


def _open(open_notebook, gpu: bool = True, res: str = RESOLUTION, more: str = "") -> NotebookPage:
    nb = open_notebook([_SETUP.format(res=res, gpu=gpu) + more])  # `more`: displayed under the view
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


def _kernel_array(nb: NotebookPage, expr: str, dtype: str) -> np.ndarray:
    """A kernel array through base64 (large JSON lists do not come back whole)."""
    import base64

    b64 = nb.kernel_eval(
        "import base64\n"
        f"print(json.dumps(base64.b64encode(np.ascontiguousarray({expr}, '{dtype}').tobytes()).decode()))"
    )
    return np.frombuffer(base64.b64decode(b64), dtype).reshape(-1, 3)


def _kernel_positions(nb: NotebookPage) -> np.ndarray:
    return _kernel_array(nb, "model.evaluate()", "<f4").astype(np.float64)


def _assert_gpu_equals_kernel(nb: NotebookPage, size: float, normals: bool = False) -> float:
    gpu = _gpu_positions(nb)
    assert gpu is not None, "the view does not evaluate on the GPU"
    ref = _kernel_positions(nb)
    err = float(np.abs(gpu - ref).max()) / size
    assert err <= 1e-5, f"GPU and kernel differ by {err:.2e} of the face size"
    if normals:
        # area-weighted vertex normals of the kernel's mesh (util.js computeNormals)
        F = _kernel_array(nb, "model.faces", "<i4").astype(np.int64)
        e = np.cross(ref[F[:, 1]] - ref[F[:, 0]], ref[F[:, 2]] - ref[F[:, 0]])
        N = np.zeros_like(ref)
        for j in range(3):
            np.add.at(N, F[:, j], e)
        N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-30)
        out = nb.viewport(0).evaluate("e => Array.from(e.fwbGpuNormals())")
        G = np.asarray(out, np.float64).reshape(-1, 3)
        used = np.linalg.norm(N, axis=1) > 0.5
        cos = (G[used] * N[used]).sum(axis=1)
        assert cos.min() > 0.9999, f"GPU normals off by up to {np.degrees(np.arccos(cos.min())):.2f} deg"
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
    _assert_gpu_equals_kernel(nb, size, normals=True)
    # texture memory: at most twice the rig's float32 vertex data (neutral + deltas + basis)
    tex = int(vp.get_attribute("data-gpu-texture-bytes"))
    rig = nb.kernel_eval(
        "print(json.dumps(int(model.n_vertices * 3 * 4 * (1 + len(model.shape_names)))))"
    )
    assert tex <= 2 * rig, (tex, rig)


_HANDLES = """
from workbench.methods.handles.presets import default_face_handles
model.handles.set(default_face_handles(model))
model.handles.prepare()
vp.tool = "sculpt"
_k = next(i for i, n in enumerate(model.handles.names) if n.startswith("mouth_L"))
_v = int(model.handles.vertices[_k])
_d = np.linalg.norm(model.vertices - model.vertices[_v], axis=1)
vp.probe_ids = np.argsort(_d)[:60]
print(json.dumps({"index": _k, "vertex": _v, "n": len(model.handles)}))
"""


def _default_handles(nb: NotebookPage) -> tuple[dict, np.ndarray]:
    """Set the default handles and wait until the view draws them on the GPU.

    Returns the handle ``info`` and the mouth-corner marker's page ``(x, y, in_front)``.
    """
    vp = nb.viewport(0)
    info = nb.kernel_eval(_HANDLES, timeout=120)
    nb.page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=info["n"],
    )
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1")
    return info, np.array(vp.evaluate("e => e.fwbMarkers()"), float).reshape(-1, 3)[info["index"]]


def test_handle_drag_sends_offsets_and_the_gpu_matches_the_kernel(open_notebook):
    nb = _open(open_notebook)
    size = float(nb.kernel_eval(_SIZE))
    page = nb.page
    info, start = _default_handles(nb)
    assert start[2] == 1, "the mouth-corner marker is behind the camera"
    clip = clip_around(np.array([start, start + np.array([40.0, -32.0, 0.0])]), pad=50)
    page.mouse.move(5, 5)
    before = nb.screenshot("gpu_drag_before", clip=clip)
    sent0 = nb.kernel_eval("print(json.dumps(len(vp.gpu_payload)))")
    frame = nb.frame()
    page.mouse.move(float(start[0]), float(start[1]))
    page.mouse.down()
    page.mouse.move(float(start[0]) + 30, float(start[1]) - 24, steps=12)
    page.mouse.up()
    nb.wait_frame_after(0, frame)
    wait_until(
        "the drag to end in the kernel",
        lambda: nb.kernel_eval("print(json.dumps(vp.dragging or model.interacting))"),
        lambda v: v is False,
    )
    _wait_version(nb, _kernel_version(nb))
    page.mouse.move(5, 5)
    payload = nb.kernel_eval("print(json.dumps(list(vp.gpu_payload)))")[sent0:]
    assert payload, "the drag sent no parameter messages"
    assert max(payload) <= 2048, f"a drag update sent {max(payload)} bytes"
    offsets = np.array(nb.kernel_eval("print(json.dumps(model.handles.offsets.tolist()))"))
    assert np.linalg.norm(offsets[info["index"]]) > 0
    after = nb.screenshot("gpu_drag_after", clip=clip)
    changed = pixel_change(before, after)
    assert changed > 0.03, f"only {changed:.1%} of the pixels around the mouth corner changed"
    _assert_gpu_equals_kernel(nb, size)
    # the vertex is drawn where the mouse let go
    moved_to = nb.project([info["vertex"]])[0]
    assert np.linalg.norm(moved_to[:2] - (start[:2] + np.array([30.0, -24.0]))) < 3.0, moved_to


_TIMELINE = """
from widgets.timeline import TimelineWidget
model.timeline.set_fps(30)
for _t, _w in ((0.0, 0.0), (0.5, 1.0), (7.5, 1.0), (8.0, 0.0)):
    model.set_weight("jawOpen", _w)
    model.timeline.key_weights(_t, ["jawOpen"], interpolation="linear")
model.set_time(0.0)
tl = TimelineWidget(model)
display(tl)
"""


def test_playback_runs_in_the_browser_and_ends_on_the_kernels_frame(open_notebook):
    nb = _open(open_notebook)
    vp = nb.viewport(0)
    size = float(nb.kernel_eval(_SIZE))
    ids = nb.kernel_eval(_PROBE)
    nb.kernel_eval(_TIMELINE)
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1")
    clip = clip_around(nb.project(ids), pad=60)
    before = nb.screenshot("gpu_play_before", clip=clip)
    calls0 = nb.kernel_eval("print(json.dumps(vp.sync.gpu.updates_sent['params']))")
    nb.kernel_eval("tl.play(loop=False)")
    wait_until("the browser to play", lambda: vp.get_attribute("data-clip-playing"), lambda v: v == "1")
    # the jaw is held open from 0.5 to 7.5 s: pixels differ from the closed mouth
    wait_until(
        "the clip past 0.6 s",
        lambda: float(vp.get_attribute("data-clip-time") or 0),
        lambda t: t >= 0.6,
        timeout=30,
    )
    mid = nb.screenshot("gpu_play_mid", clip=clip, full_detail=False)  # drafts while playing
    t_mid = float(vp.get_attribute("data-clip-time") or 0)
    assert t_mid < 7.4, f"the screenshot came too late ({t_mid} s)"
    wait_until(
        "playback to end",
        lambda: nb.kernel_eval("print(json.dumps(tl.playing))"),
        lambda v: v is False,
        timeout=60,
    )
    stats = nb.kernel_eval("print(json.dumps(tl.playback_stats))")
    assert stats.get("browser") is True, stats
    frames = int(vp.get_attribute("data-clip-frames") or 0)
    assert frames >= 10, f"the browser drew only {frames} frames"
    # while the browser played, the kernel sent no per-frame parameters
    calls = nb.kernel_eval("print(json.dumps(vp.sync.gpu.updates_sent['params']))")
    assert calls - calls0 <= 2, (calls0, calls)
    assert pixel_change(before, mid) > 0.05
    _wait_version(nb, _kernel_version(nb))
    assert nb.kernel_eval("print(json.dumps(model.time))") == 8.0
    _assert_gpu_equals_kernel(nb, size)
    print(f"browser playback at 80k: {vp.get_attribute('data-clip-fps')} fps drawn, {frames} frames")


def test_gpu_false_streams_vertex_rows_and_says_so(open_notebook):
    nb = _open(open_notebook, gpu=False, res="base")
    vp = nb.viewport(0)
    wait_until("the note", lambda: vp.get_attribute("data-gpu-note") or "", lambda t: "stream" in t)
    assert vp.locator(".fwb-gpu-note").is_visible()
    assert vp.get_attribute("data-gpu") == "0"
    ids = nb.kernel_eval(_PROBE)
    clip = clip_around(nb.project(ids), pad=60)
    before = nb.screenshot("stream_before", clip=clip)
    sent0 = nb.kernel_eval("print(json.dumps(vp.updates_sent))")
    frame = nb.frame()
    nb.kernel_eval('model.set_weight("jawOpen", 0.8)')
    nb.wait_frame_after(0, frame)
    after = nb.screenshot("stream_after", clip=clip)
    assert pixel_change(before, after) > 0.05
    sent = nb.kernel_eval("print(json.dumps([vp.updates_sent, len(vp.gpu_payload)]))")
    # vertex rows (a patch, or the whole buffer when jawOpen moves most of the 5k head)
    assert sum(sent[0].values()) > sum(sent0.values()) and sent[1] == 0, (sent0, sent)
    # and back to the GPU
    nb.kernel_eval("vp.gpu = True")
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1")
    assert vp.get_attribute("data-gpu-note") == ""


def test_a_browser_without_float_targets_falls_back_with_a_note(open_notebook):
    nb = open_notebook([_SETUP.format(res="base", gpu=True)], run=False)
    # what a browser without WebGL2 float render targets reports (gpu_morph.js gpuUnsupported)
    nb.page.evaluate("() => { globalThis.fwbDisableGpu = true; }")
    nb.run_all()
    nb.wait_viewports(1)
    vp = nb.viewport(0)
    wait_until("the note", lambda: vp.get_attribute("data-gpu-note") or "", lambda t: "unavailable" in t)
    assert vp.locator(".fwb-gpu-note").is_visible()
    wait_until(
        "the kernel to stream",
        lambda: nb.kernel_eval("print(json.dumps([vp.gpu_active, vp.gpu_unavailable]))"),
        lambda v: v[0] is False and "fwbDisableGpu" in v[1],
    )
    sent0 = nb.kernel_eval("print(json.dumps(sum(vp.updates_sent.values())))")
    frame = nb.frame()
    nb.kernel_eval('model.set_weight("jawOpen", 0.5)')
    nb.wait_frame_after(0, frame)
    assert nb.kernel_eval("print(json.dumps(sum(vp.updates_sent.values())))") > sent0
    assert nb.kernel_eval("print(json.dumps(len(vp.gpu_payload)))") == 0


_BUSY_SLIDER = """
import time, ipywidgets as W
slider = W.FloatSlider(min=0, max=1, step=0.01, value=0, description="jawOpen")
slider.add_class("fwb-test-slider")
_slept = []
def _on_slider(ch):
    if not _slept:  # a busy kernel: the page must not wait for it
        _slept.append(1)
        time.sleep(4.0)
    model.set_weight("jawOpen", ch["new"])
slider.observe(_on_slider, "value")
vp.follow_sliders({"jawOpen": slider})
display(slider)
"""


def test_a_followed_slider_moves_the_face_before_the_kernel_answers(open_notebook):
    nb = _open(open_notebook, res="25k", more=_BUSY_SLIDER)
    vp = nb.viewport(0)
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1", timeout=60)
    size = float(nb.kernel_eval(_SIZE))
    ids = nb.kernel_eval(_PROBE)
    track = nb.page.locator(".fwb-test-slider .noUi-base")
    track.wait_for()
    clip = clip_around(nb.project(ids), pad=60)
    before = nb.screenshot("local_slider_before", clip=clip)
    frame, version = nb.frame(), int(vp.get_attribute("data-version"))
    box = track.bounding_box()
    nb.page.mouse.click(box["x"] + 0.8 * box["width"], box["y"] + box["height"] / 2)
    # the page draws the new weight itself while the kernel sleeps in the slider's handler
    nb.wait_frame_after(0, frame, timeout=3.5)
    assert int(vp.get_attribute("data-version")) == version, "the frame came from the kernel"
    after = nb.screenshot("local_slider_after", clip=clip)
    changed = pixel_change(before, after)
    assert changed > 0.05, f"only {changed:.1%} of the mouth pixels changed"
    # then the kernel answers, and its evaluation is what the GPU shows
    wait_until(
        "the kernel to take the slider's value",
        lambda: nb.kernel_eval('print(json.dumps(model.weights["jawOpen"]))'),
        lambda w: abs(w - 0.8) < 0.02,
        timeout=60,
    )
    _wait_version(nb, _kernel_version(nb))
    _assert_gpu_equals_kernel(nb, size)


_FOLLOWED_SLIDER = """
import ipywidgets as W
slider = W.FloatSlider(min=0, max=1, step=0.01, value=0, description="jawOpen")
slider.add_class("fwb-test-slider")
def _to_slider(_w):  # the model moves the slider, as the Shapes tab does
    slider.value = model.weights["jawOpen"]
model.events.weights.connect(_to_slider)
vp.follow_sliders({"jawOpen": slider})
display(slider)
"""


def test_a_slider_the_kernel_moves_does_not_override_its_exact_weight(open_notebook):
    # A scrub, undo or Python edit sets a weight off the slider's 0.01 grid; the slider (its
    # value snapped by the browser) follows. The page must play the kernel's exact weight,
    # not predict one from the snapped slider (a soak found the view 1.7e-4 of the face off).
    nb = _open(open_notebook, res="25k", more=_FOLLOWED_SLIDER)
    vp = nb.viewport(0)
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1", timeout=60)
    size = float(nb.kernel_eval(_SIZE))
    nb.page.locator(".fwb-test-slider .noUi-base").wait_for()
    for w in (0.6269747, 0.3333333, 0.9051):
        nb.kernel_eval(f'model.set_weight("jawOpen", {w})')
        _wait_version(nb, _kernel_version(nb))
        wait_until("the slider to follow", lambda: nb.page.locator(
            ".fwb-test-slider .widget-readout").text_content(), lambda t, w=w: t == f"{w:.2f}")
        nb.page.wait_for_timeout(100)
        _assert_gpu_equals_kernel(nb, size)


_CANVAS_LOG = """() => {
  const e = document.querySelector('.fwb-viewport');
  window.__shots = {};
  new MutationObserver(() => {
    const d = e.getAttribute('data-detail');
    // the full frame that follows the draft (not a full frame of the pose before it)
    if (d && !(d in window.__shots) && (d === 'draft' || 'draft' in window.__shots))
      window.__shots[d] = e.querySelector('canvas').toDataURL();
  }).observe(e, {attributes: true, attributeFilter: ['data-render-count']});
  return e.querySelector('canvas').toDataURL();
}"""


def _png(url: str) -> np.ndarray:
    import base64
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))


def test_fast_interaction_draws_a_draft_then_the_full_face(open_notebook):
    nb = _open(open_notebook, res="25k")
    vp = nb.viewport(0)
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1", timeout=60)
    size = float(nb.kernel_eval(_SIZE))
    nb.kernel_eval('vp.fast_interaction = "on"; model.set_weight("jawOpen", 0.1)')
    wait_until("the draft to be built", lambda: vp.get_attribute("data-draft-triangles"), bool)
    tris, faces = int(vp.get_attribute("data-draft-triangles")), int(vp.get_attribute("data-face-count"))
    assert 1000 < tris < faces / 2, (tris, faces)
    # the page idle on the full face of jawOpen 0.1 first: a late full frame of it would
    # otherwise be logged as the full frame of 0.9 (on a busy machine)
    _wait_version(nb, _kernel_version(nb))
    wait_until("the full face of 0.1", lambda: vp.get_attribute("data-detail"), lambda d: d == "full")
    nb.page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    before = _png(nb.page.evaluate(_CANVAS_LOG))
    frame, drafts = nb.frame(), int(vp.get_attribute("data-draft-frame") or 0)
    nb.kernel_eval('model.set_weight("jawOpen", 0.9)')
    nb.wait_frame_after(0, frame)
    # the draft is drawn at once, the full face a frame or more later (many on a busy machine)
    wait_until("the full face after the draft", lambda: (vp.get_attribute("data-detail"),
               sorted(nb.page.evaluate("() => Object.keys(window.__shots || {})"))),
               lambda v: v == ("full", ["draft", "full"]), timeout=30)
    assert int(vp.get_attribute("data-draft-frame")) > drafts
    shots = nb.page.evaluate("() => window.__shots")
    draft, full = _png(shots["draft"]), _png(shots["full"])
    moved = pixel_change(before, full)
    assert moved > 0.01, f"the jaw moved only {moved:.1%} of the canvas"
    # the draft shows the new pose: far closer to the full frame than the old pose was
    assert pixel_change(draft, full, threshold=40) < 0.25 * moved, (pixel_change(draft, full, 40), moved)
    _assert_gpu_equals_kernel(nb, size, normals=True)  # read back after a draft: full evaluation
    # "off": the full mesh every time
    nb.kernel_eval('vp.fast_interaction = "off"')
    frame, drafts = nb.frame(), int(vp.get_attribute("data-draft-frame"))
    nb.kernel_eval('model.set_weight("jawOpen", 0.4)')
    nb.wait_frame_after(0, frame)
    assert int(vp.get_attribute("data-draft-frame")) == drafts


_BUSY = """() => {
  const kernel = window.jupyterapp.shell.currentWidget.sessionContext.session.kernel;
  kernel.requestExecute({code: "import time; time.sleep(6)", silent: true, store_history: false});
}"""


def test_a_handle_drag_moves_the_face_before_the_kernel_answers(open_notebook):
    nb = _open(open_notebook, res="25k")
    vp = nb.viewport(0)
    page = nb.page
    size = float(nb.kernel_eval(_SIZE))
    info, start = _default_handles(nb)
    clip = clip_around(np.array([start, start + np.array([30.0, -24.0, 0.0])]), pad=50)
    page.mouse.move(5, 5)
    before = nb.screenshot("predicted_drag_before", clip=clip)
    frame, version = nb.frame(), int(vp.get_attribute("data-version"))
    page.evaluate(_BUSY)  # another cell keeps the kernel busy for 6 s
    page.mouse.move(float(start[0]), float(start[1]))
    page.mouse.down()
    page.mouse.move(float(start[0]) + 30, float(start[1]) - 24, steps=6)
    # the page moves the face itself: a frame before the kernel has said anything
    nb.wait_frame_after(0, frame, timeout=4.0)
    assert int(vp.get_attribute("data-version")) == version, "the frame came from the kernel"
    moved = pixel_change(before, nb.screenshot("predicted_drag_moved", clip=clip))
    assert moved > 0.03, f"only {moved:.1%} of the pixels around the mouth corner changed"
    # the handle's vertex is drawn under the pointer
    at = nb.project([info["vertex"]])[0]
    assert np.linalg.norm(at[:2] - (start[:2] + np.array([30.0, -24.0]))) < 3.0, at
    page.mouse.up()
    # then the kernel takes the drag, and the GPU shows exactly its evaluation
    wait_until(
        "the drag to end in the kernel",
        lambda: nb.kernel_eval("print(json.dumps(vp.dragging or model.interacting))", timeout=30),
        lambda v: v is False,
    )
    offsets = np.array(nb.kernel_eval("print(json.dumps(model.handles.offsets.tolist()))"))
    assert np.linalg.norm(offsets[info["index"]]) > 0
    _wait_version(nb, _kernel_version(nb))
    _assert_gpu_equals_kernel(nb, size)
    at = nb.project([info["vertex"]])[0]
    assert np.linalg.norm(at[:2] - (start[:2] + np.array([30.0, -24.0]))) < 3.0, at


# The kernel sends parameters (a message, version v + 2) and then the full update they
# follow (state, v + 1) in the opposite order: what the page sees when the widget manager
# is still decoding a full update as the next message arrives (it decodes state updates
# asynchronously, custom messages fire at once).
_OVERTAKE = """
_v = vp._version
vp._trait_values["_version"] = _v + 1
model.set_weight("eyeBlinkLeft", 0.7)
assert vp._version == _v + 2
vp._trait_values["_version"] = _v
vp._version = _v + 1
vp._trait_values["_version"] = _v + 2
print(json.dumps(_v + 2))
"""


def test_parameters_that_overtake_their_full_update_wait_for_it(open_notebook):
    nb = _open(open_notebook, res="base")
    vp = nb.viewport(0)
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1", timeout=60)
    size = float(nb.kernel_eval(_SIZE))
    fulls = nb.kernel_eval("print(json.dumps(vp.sync.updates_sent['full']))")
    version = nb.kernel_eval(_OVERTAKE)
    _wait_version(nb, version)
    assert vp.get_attribute("data-gpu") == "1"
    _assert_gpu_equals_kernel(nb, size)
    # no full buffer was asked for: the held parameters were applied after the full update
    assert nb.kernel_eval("print(json.dumps(vp.sync.updates_sent['full']))") == fulls
    # a real gap (a message never sent) still ends in a full update, after a short wait
    nb.expected_resyncs += 1
    nb.kernel_eval('vp._trait_values["_version"] += 1\nmodel.set_weight("eyeBlinkLeft", 0.2)')
    wait_until("the full update a gap asks for",
               lambda: nb.kernel_eval("print(json.dumps(vp.sync.updates_sent['full']))"),
               lambda n: n == fulls + 1, timeout=30)
    _wait_version(nb, _kernel_version(nb))
    assert vp.get_attribute("data-gpu") == "1"
    _assert_gpu_equals_kernel(nb, size)
