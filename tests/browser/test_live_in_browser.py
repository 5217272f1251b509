"""The Live tab in Chromium with a fake camera playing a video rendered from the rig.

Chromium's fake capture device plays ``take.y4m`` (``--use-fake-device-for-media-stream
--use-file-for-fake-video-capture``; ``--use-fake-ui-for-media-stream`` answers the
permission prompt as a user clicking *Allow*): the sample head rendered with known
weights (tests/capture_takes.py: a jawOpen ramp, a blink, a head turn), looped. With
the mouse: open the Live tab, *Start camera* (the page sends frames, one in flight,
the kernel acks each), the face follows (the viewport's pixels change with the video
and jawOpen moves), *Calibrate* shows its instructions (taking the neutral from its relax prompt) and ends early
when pressed again, *Neutral* takes the next frame as the neutral, *Record* / *Stop recording* (one undo step of keys), the take
exports as .glb and Live Link CSV, *Stop camera* (the page lets the camera go). Behind
the Live tab the Shapes tab's sliders stay still (no slider traffic per camera frame) and
show the played weights once that tab is shown.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from harness import NotebookPage, pixel_change, wait_until


@pytest.fixture(scope="module")
def fake_camera(tmp_path_factory: Any) -> Path:
    pytest.importorskip("mediapipe")
    from capture_takes import render_take, write_y4m

    import workbench

    frames = render_take(workbench.load_sample("head"))  # (T, 480, 480, 3)
    wide = np.full((frames.shape[0], 480, 640, 3), 235, np.uint8)  # a 640×480 camera, the face in the middle
    wide[:, :, 80:560] = frames
    path = tmp_path_factory.mktemp("camera") / "take.y4m"
    write_y4m(path, wide)
    return path


_CELLS = [
    "import json, numpy as np, tempfile, pathlib\nimport workbench, widgets\n"
    "model = workbench.load_sample('head')\nd = pathlib.Path(tempfile.mkdtemp())",
    "wb = widgets.show_workbench(model)",
]

_STATE = """
import json, numpy as np
_l = wb.live
print(json.dumps({
    "active": bool(_l.camera.active), "state": _l.camera.state, "received": _l.camera.frames_received,
    "tracked": 0 if _l.tracker is None else _l.tracker.n_frames_,
    "neutral": None if _l.tracker is None else _l.tracker.neutral_at_,
    "ok": bool(_l.last is not None and _l.last.ok), "jaw": float(model.weights["jawOpen"]),
    "undo": model.history.undo_labels, "recorded": None if _l.recorded is None else _l.recorded.n_frames,
    "status": _l.status.value, "errors": [o.get("text", "") for o in wb.errors.outputs]}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def test_the_face_follows_the_fake_camera_and_a_recorded_take_exports(open_notebook, fake_camera) -> None:
    args = ("--use-fake-device-for-media-stream", f"--use-file-for-fake-video-capture={fake_camera}",
            "--use-fake-ui-for-media-stream")
    nb = open_notebook(_CELLS, viewport_size=(1500, 1200), browser_args=args)
    page = nb.page
    page.evaluate("() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }")
    nb.wait_viewports(1)
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Live").click()
    # count every change of the (hidden) Shapes tab's jawOpen readout while the camera runs
    readout = page.locator(".fwb-slider-jawOpen .widget-readout")
    still = readout.text_content()
    page.evaluate("""() => { window.__fwbReadouts = 0;
        new MutationObserver(() => { window.__fwbReadouts += 1; }).observe(
            document.querySelector('.fwb-slider-jawOpen .widget-readout'),
            {childList: true, characterData: true, subtree: true}); }""")
    page.locator(".fwb-live-start").click()
    cam = page.locator(".fwb-camera")
    wait_until("the camera", lambda: cam.get_attribute("data-camera"), lambda s: s in ("on", "error"), timeout=60)
    assert cam.get_attribute("data-camera") == "on", cam.get_attribute("data-error")
    st = wait_until("tracked frames", lambda: _state(nb), lambda s: s["tracked"] >= 15 or s["errors"], timeout=120)
    assert st["ok"] and not st["errors"], st
    # one frame in flight: the page never gets more than one ahead of the kernel's acks
    # (both counters read in one evaluation: two reads let a frame be sent and acked between them)
    sent, acked = cam.evaluate("e => [Number(e.dataset.sent), Number(e.dataset.acked)]")
    assert 0 <= sent - acked <= 1, (sent, acked)
    # the page's latency report, camera frame to drawn face (numbers: benchmarks/bench_live_page.py)
    lat = wait_until("the latency report", lambda: cam.get_attribute("data-latency"), bool, timeout=30)
    report = json.loads(lat)
    print("live latency, ms (median, p90):", report)
    stages = report["stages"]
    assert report["n"] >= 1 and all(len(v) == 2 for v in stages.values()), report
    assert stages["total"][0] >= stages["kernel"][0] > 0 and stages["draw"][0] > 0, report
    page.mouse.move(5, 5)
    a = nb.canvas_shot("live-1")
    jaws = [st["jaw"]]
    for _ in range(6):
        jaws.append(wait_until("the next frames", lambda: _state(nb), lambda s, n=st["tracked"]: s["tracked"] > n + 3,
                               timeout=60)["jaw"])
    b = nb.canvas_shot("live-2")
    assert max(jaws) - min(jaws) > 0.05, jaws  # the video's jaw ramp moves the face
    assert pixel_change(a, b) > 0.001
    # calibrate: the session's instructions show beside the camera and move on with its clock;
    # pressed again, it ends early, fitted on the prompts reached
    page.locator(".fwb-live-calibrate").click()
    prompt = page.locator(".fwb-live-prompt")
    wait_until("the first instruction", lambda: prompt.text_content() or "", lambda s: "1/10" in s, timeout=30)
    wait_until("the second instruction", lambda: prompt.text_content() or "",
               lambda s: "2/10" in s and "jaw" in s, timeout=60)
    nb.screenshot("calibrating")
    n_cal = _state(nb)["tracked"]
    wait_until("frames of the jaw prompt", lambda: _state(nb), lambda s: s["tracked"] > n_cal + 3, timeout=60)
    page.locator(".fwb-live-calibrate").click()
    st = wait_until("calibrated", lambda: _state(nb), lambda s: "calibrated:" in s["status"] or s["errors"], timeout=30)
    assert not st["errors"] and (prompt.text_content() or "") == "", st
    # the session took the neutral from its relax prompt's later half (a span of frames)
    first, last = st["neutral"]
    assert 0 < first < last, st["neutral"]
    # record: one undo step of keys
    n_undo = len(st["undo"])
    page.locator(".fwb-live-record").click()
    n0 = _state(nb)["tracked"]
    wait_until("recorded frames", lambda: _state(nb), lambda s: s["tracked"] >= n0 + 12, timeout=90)
    page.locator(".fwb-live-record").click()
    st = wait_until("the keys", lambda: _state(nb), lambda s: len(s["undo"]) == n_undo + 1 or s["errors"])
    assert st["recorded"] and st["recorded"] >= 12 and not st["errors"], st
    out = nb.kernel_eval(
        "from workbench.export import export\n"
        "paths = export(model, model.tracks, d / 'live.glb') + export(model, model.tracks, d / 'live.csv')\n"
        "print(json.dumps([str(p) for p in paths]))")
    assert any(p.endswith(".glb") for p in out) and any(p.endswith(".csv") for p in out)
    nb.screenshot("recorded")
    # the sliders behind the Live tab did not follow the camera, though the played jaw moved away from them
    wait_until("the jaw away from the still slider", lambda: _state(nb)["jaw"],
               lambda j: abs(j - float(still)) > 0.05, timeout=60)
    assert page.evaluate("() => window.__fwbReadouts") == 0 and readout.text_content() == still
    # Neutral (last: the fake camera's next frame may be mid-jaw): that frame is taken as the neutral
    page.locator(".fwb-live-neutral").click()
    st = wait_until("the neutral taken again", lambda: _state(nb),
                    lambda s: s["neutral"][0] == s["neutral"][1] > last or s["errors"], timeout=60)
    assert not st["errors"], st
    # stop: the page lets the camera go
    page.locator(".fwb-live-start").click()
    wait_until("the camera off", lambda: cam.get_attribute("data-camera"), lambda s: s == "off")
    st = _state(nb)
    assert not st["active"] and len(st["undo"]) == n_undo + 1, st
    assert json.dumps(st["errors"]) == "[]"
    # shown again, the Shapes tab's sliders show the weights the camera left
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Shapes").click()
    wait_until("the jawOpen slider catching up", lambda: float(readout.text_content() or "nan"),
               lambda v: abs(v - st["jaw"]) < 0.006, timeout=30)
    nb.screenshot("shapes-after-live")
