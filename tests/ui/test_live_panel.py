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
    assert "Live" in wb.tabs.titles and live.record_button.disabled and live.neutral_button.disabled
    live.start_button.click()
    assert live.camera.active and live.start_button.description == "Stop camera"
    _page_sends(live.camera, {"type": "camera", "state": "on", "message": ""})
    n_undo = len(model.history.undo_labels)
    jaw = []
    for f in range(12):
        _page_sends(live.camera, {"type": "frame", "t": f / 30.0, "width": 480, "height": 480}, [jpegs[f]])
        jaw.append(model.weights["jawOpen"])
    assert len(acks) == 12 and all(a["type"] == "ack" for a in acks), wb.errors.outputs
    # each ack says the kernel's time on the frame (the page's latency report splits its round trip)
    assert all(0.0 < a["kernel_ms"] < 60_000 for a in acks), acks
    assert live.last is not None and live.last.ok
    assert np.corrcoef(jaw[1:], JAW[1:12])[0, 1] > 0.9  # the face follows the video
    assert len(model.history.undo_labels) == n_undo  # watching adds no undo step
    assert "ms each" in live.status.value
    assert live.tracker.neutral_at_ == (0.0, 0.0)  # the first face
    # Neutral: the next frame is taken as the actor's neutral
    assert not live.neutral_button.disabled
    live.neutral_button.click()
    assert "neutral from the next frame" in live.status.value
    _page_sends(live.camera, {"type": "frame", "t": 50.0, "width": 480, "height": 480}, [jpegs[0]])
    assert live.tracker.neutral_at_ == (50.0, 50.0) and "neutral set on this frame" in live.status.value
    assert len(model.history.undo_labels) == n_undo
    # the guided calibration: the prompt shows beside the camera and moves on with the frames' clock
    assert live.calibrate_button.description == "Calibrate" and not live.calibrate_button.disabled
    live.calibrate_button.click()
    assert live.calibrate_button.description == "End calibration"
    assert "1/10" in live.prompt.value and "Relax" in live.prompt.value
    seen = []
    for i in range(21):  # a frame a second through the 20-second session
        _page_sends(live.camera, {"type": "frame", "t": 100.0 + i}, [jpegs[(6 * i) % len(jpegs)]])
        seen.append(live.prompt.value)
    assert "2/10" in seen[2] and "Open your jaw wide" in seen[2] and "8/10" in seen[15]
    assert live.tracker.neutral_at_ == (101.0, 101.0)  # the relax prompt's later half: its frame at 101 s
    assert "10/10" in seen[19] and "nod" in seen[19]  # the relaxed face nodding ends it
    # it ended by itself: the map applies, the prompt is gone, the status says so
    assert not live.tracker.calibrating and live.tracker.calibration_ is not None
    assert live.prompt.value == "" and live.calibrate_button.description == "Calibrate"
    assert "calibrated:" in live.status.value, live.status.value
    assert len(model.history.undo_labels) == n_undo
    # ended early: fitted on the prompts reached
    live.calibrate_button.click()
    for i in range(5):
        _page_sends(live.camera, {"type": "frame", "t": 130.0 + i}, [jpegs[(5 * i) % len(jpegs)]])
    live.calibrate_button.click()
    assert not live.tracker.calibrating and live.prompt.value == "" and "calibrated:" in live.status.value
    # record frames 12..24: one undo step with their keys
    live.record_button.click()
    assert live.record_button.description == "Stop recording"
    for f in range(12, 24):
        _page_sends(live.camera, {"type": "frame", "t": 200.0 + f / 30.0, "width": 480, "height": 480},
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
    assert saved["landmarks"].shape == (51, 478, 3) and saved["timestamps"].shape == (51,)
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
    assert not model.interacting and live.tracker.n_frames_ == n and acks[-1]["type"] == "ack"


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


def test_the_viewport_shows_the_tracked_head_turn_without_keying_it(jpegs, live_wb) -> None:
    """The face turns with the actor's head in the viewport (a view-only pose); Stop puts the model's back."""
    from capture_takes import YAW

    model, wb, live, _acks = live_wb
    vp = wb.viewport
    live.start_button.click()
    n_undo = len(model.history.undo_labels)
    yaw = []
    for f in range(len(YAW)):
        _page_sends(live.camera, {"type": "frame", "t": f / 30.0}, [jpegs[f]])
        M = vp.sync.view_pose
        assert M is not None and np.array_equal(M, live.last.pose)
        yaw.append(np.arctan2(M[0, 2], M[2, 2]))
        # what the view draws is the unposed face under the tracked pose
        local = model.evaluate(posed=False)
        np.testing.assert_allclose(vp.sync.shown_positions(), local @ M[:3, :3].T + M[:3, 3], atol=1e-4)
    yaw = np.array(yaw)
    print("tracked yaw (deg)", np.round(np.rad2deg(yaw), 1))
    assert np.corrcoef(yaw, YAW)[0, 1] > 0.9
    assert 0.6 < np.ptp(yaw) / np.ptp(YAW) < 1.4
    assert model.slot("tracks").head_pose is None and len(model.history.undo_labels) == n_undo
    # a pointer position on the shown face maps back through the shown pose
    p = np.array([1.0, 2.0, 3.0])
    M = vp.sync.view_pose
    np.testing.assert_allclose(vp.unposed(M[:3, :3] @ p + M[:3, 3]), p, atol=1e-9)
    # unticked: the model's pose (none keyed: the identity); ticked again: the last tracked pose
    live.follow_head.value = False
    assert vp.sync.view_pose is None
    np.testing.assert_allclose(vp.sync.shown_positions(), model.evaluate(), atol=1e-6)
    live.follow_head.value = True
    assert np.array_equal(vp.sync.view_pose, live.last.pose)
    live.start_button.click()  # stop
    assert vp.sync.view_pose is None


def test_show_head_pose_refuses_what_is_not_rigid(live_wb) -> None:
    _model, wb, _live, _acks = live_wb
    with pytest.raises(ValueError, match=r"show_head_pose: pose must be a finite \(4, 4\)"):
        wb.viewport.show_head_pose(np.eye(3))
    with pytest.raises(ValueError, match="rigid"):
        wb.viewport.show_head_pose(np.diag([2.0, 1.0, 1.0, 1.0]))
    assert wb.viewport.sync.view_pose is None


def test_the_sliders_follow_a_live_stream_at_their_own_pace_and_catch_up() -> None:
    # the face follows every frame; 52 sliders (each echoed by the page) follow at STREAM_FOLLOW_S,
    # not at all while hidden behind the Live tab, and catch up when shown or when the stream ends
    import asyncio

    from kernel_loop import in_kernel_loop

    from widgets.panels.expressions import STREAM_FOLLOW_S, ExpressionPanel

    async def main() -> None:
        model = workbench.load_sample("head")
        panel = ExpressionPanel(model)
        a, b = model.shape_names[:2]
        slider = panel.sliders[a]
        updates: list[float] = []
        slider.observe(lambda ch: updates.append(ch["new"]), "value")
        try:
            model.set_weights({a: 0.1})  # no stream: at once
            assert slider.value == pytest.approx(0.1)
            tok = model.begin_interaction("Live camera", kind="live")
            for v in (0.2, 0.3, 0.4):
                model.set_weights({a: v, b: v / 2})
            assert slider.value == pytest.approx(0.1)  # frames came faster than the sliders follow
            await asyncio.sleep(STREAM_FOLLOW_S + 0.2)
            assert slider.value == pytest.approx(0.4) and panel.sliders[b].value == pytest.approx(0.2)
            assert updates == pytest.approx([0.1, 0.4])  # one update for three frames
            panel.set_shown(False)
            model.set_weights({a: 0.6})
            await asyncio.sleep(STREAM_FOLLOW_S + 0.2)
            assert slider.value == pytest.approx(0.4)  # hidden: nothing sent
            panel.set_shown(True)
            assert slider.value == pytest.approx(0.6)
            panel.set_shown(False)
            model.set_weights({a: 0.7, b: 0.7})
            model.cancel_interaction(tok)  # Stop camera: the weights go back, the sliders with them
            assert model.weights[a] == pytest.approx(0.1) and slider.value == pytest.approx(0.1)
            assert panel.sliders[b].value == pytest.approx(model.weights[b])
            model.set_weights({a: 0.25})  # hidden, but no stream: at once
            assert slider.value == pytest.approx(0.25)
        finally:
            panel.close()

    in_kernel_loop(main)


def test_the_shapes_tab_tells_its_sliders_when_they_are_hidden(live_wb) -> None:
    _model, wb, _live, _acks = live_wb
    assert wb.panel.shown
    wb.tabs.selected_index = wb.tabs.titles.index("Live")
    assert not wb.panel.shown
    wb.tabs.selected_index = wb.tabs.titles.index("Shapes")
    assert wb.panel.shown
