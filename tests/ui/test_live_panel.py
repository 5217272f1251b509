"""The Live tab in the kernel (``widgets.live``): camera messages as the page sends them, on a rendered take.

The page's side (getUserMedia, JPEG frames, one in flight) is the browser test's
(``tests/browser/test_live_in_browser.py``); here the rendered take of
``tests/capture_takes.py`` arrives as the page's JPEG frame messages.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from capture_takes import JAW, render_take

import workbench

pytestmark = pytest.mark.ui


@pytest.fixture(scope="module")
def jpegs():
    pytest.importorskip("mediapipe")
    from PIL import Image

    model = workbench.load_sample("head")
    out = []
    for img in render_take(model):
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, format="JPEG", quality=80)
        out.append(buf.getvalue())
    return out


@pytest.fixture
def live_wb():
    """A Workbench on the sample head whose Live panel's messages to the page land in ``acks``."""
    from widgets import Workbench

    model = workbench.load_sample("head")
    wb = Workbench(model, height=240)
    acks: list = []
    wb.live.camera.send = lambda content, buffers=None: acks.append(content)  # the page's inbox
    try:
        yield model, wb, wb.live, acks
    finally:
        wb.close()


def _page_sends(camera, content, buffers=()):
    """What the page's comm message does: the widget's handler with its buffers."""
    camera._handle_custom_msg(content, list(buffers))


def test_live_frames_drive_the_face_record_keys_a_take_and_stop_restores(jpegs, live_wb, tmp_path) -> None:
    model, wb, live, acks = live_wb
    assert "Live" in wb.tabs.titles and live.record_button.disabled
    live.start_button.click()
    assert live.camera.active and live.start_button.description == "Stop camera"
    _page_sends(live.camera, {"type": "camera", "state": "on", "message": ""})
    n_undo = len(model.history.undo_labels)
    jaw = []
    for f in range(12):
        _page_sends(live.camera, {"type": "frame", "t": f / 30.0, "width": 480, "height": 480}, [jpegs[f]])
        jaw.append(model.weights["jawOpen"])
    assert len(acks) == 12 and all(a == {"type": "ack"} for a in acks), wb.errors.outputs
    assert live.last is not None and live.last.ok
    assert np.corrcoef(jaw[1:], JAW[1:12])[0, 1] > 0.9  # the face follows the video
    assert len(model.history.undo_labels) == n_undo  # watching adds no undo step
    assert "ms each" in live.status.value
    # the range calibration on frames 6..12 (the jaw ramp's upper part) scales the jaw up
    assert live.range_button.description == "Calibrate range" and not live.range_button.disabled
    live.range_button.click()
    assert live.range_button.description == "End calibration"
    for f in range(6, 12):
        _page_sends(live.camera, {"type": "frame", "t": (100 + f) / 30.0}, [jpegs[f]])
    live.range_button.click()
    assert live.tracker.gains_ is not None and "range set" in live.status.value, live.status.value
    assert len(model.history.undo_labels) == n_undo
    # record frames 12..24: one undo step with their keys
    live.record_button.click()
    assert live.record_button.description == "Stop recording"
    for f in range(12, 24):
        _page_sends(live.camera, {"type": "frame", "t": (200 + f) / 30.0, "width": 480, "height": 480},
                    [jpegs[f]])
    live.record_button.click()
    assert len(model.history.undo_labels) == n_undo + 1 and "Record live take" in model.history.undo_labels[-1]
    take = live.recorded
    assert take.n_frames == 12 and take.info["rate"] == pytest.approx(30.0)
    np.testing.assert_allclose(take.times(), np.arange(12) / 30.0, atol=1e-9)
    tl = model.slot("tracks")
    assert "weights/jawOpen" in tl.tracks and "head_pose" in tl.tracks
    # the raw take saves; stopping the camera leaves the sliders as they were
    out = live.save_take(str(tmp_path / "take.npz"))
    saved = np.load(out)
    assert saved["landmarks"].shape == (30, 478, 3) and saved["timestamps"].shape == (30,)
    live.start_button.click()
    assert not live.camera.active and len(model.history.undo_labels) == n_undo + 1
    # no permission: a clear message, the camera off
    live.start_button.click()
    _page_sends(live.camera, {"type": "camera", "state": "error", "message": "NotAllowedError: Permission denied"})
    assert not live.camera.active and "Permission denied" in live.status.value


def test_a_frame_without_a_face_holds_the_face_and_says_so(jpegs, live_wb) -> None:
    model, wb, live, _acks = live_wb
    live.start_button.click()
    for f in range(6):
        _page_sends(live.camera, {"type": "frame", "t": f / 30.0}, [jpegs[f + 20]])
    before = dict(model.weights)
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.full((480, 480, 3), 40, np.uint8)).save(buf, format="JPEG")
    _page_sends(live.camera, {"type": "frame", "t": 6 / 30.0}, [buf.getvalue()])
    assert not live.last.ok and "no face" in live.status.value
    assert dict(model.weights) == before
    # leaving the tab stops the camera
    wb.tabs.selected_index = wb.tabs.titles.index("Live")
    wb.tabs.selected_index = 0
    assert not live.camera.active


def test_a_frame_arriving_after_stop_is_dropped(jpegs, live_wb) -> None:
    """The page may have a frame on its way when the camera stops: it must not reopen the live preview."""
    model, _wb, live, acks = live_wb
    live.start_button.click()
    _page_sends(live.camera, {"type": "frame", "t": 0.0}, [jpegs[0]])
    assert model.interacting
    live.start_button.click()  # stop
    assert not model.interacting
    n = live.tracker.n_frames_
    _page_sends(live.camera, {"type": "frame", "t": 1.0}, [jpegs[5]])
    assert not model.interacting and live.tracker.n_frames_ == n and acks[-1] == {"type": "ack"}


def test_a_camera_unplugged_mid_take_keeps_the_take_so_far(jpegs, live_wb) -> None:
    model, _wb, live, _acks = live_wb
    live.start_button.click()
    n_undo = len(model.history.undo_labels)
    live.record_button.click()
    for f in range(8):
        _page_sends(live.camera, {"type": "frame", "t": f / 30.0}, [jpegs[f]])
    _page_sends(live.camera, {"type": "camera", "state": "error", "message": "the camera stopped (unplugged?)"})
    assert not live.camera.active and "unplugged" in live.status.value
    assert live.recorded is not None and live.recorded.n_frames == 8
    assert len(model.history.undo_labels) == n_undo + 1 and not model.interacting
