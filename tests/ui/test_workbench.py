"""The composed Workbench (widgets/app.py) without a browser.

Tabs are switched and buttons clicked from Python; the checks are on the
viewport's tool, the Regions panel's activation, the status line text, the
shared error Output and the autosaver. Runs on the sample head (5k vertices).
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("anywidget")

from kernel_loop import in_kernel_loop, on_ui_thread

import widgets
from widgets import TAB_TITLES, RecoveryPrompt, Workbench, recovery_prompt
from workbench import load, load_sample
from workbench.autosave import Autosaver, find_recoverable

pytestmark = pytest.mark.ui


def _wait(pred, timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise AssertionError("condition not reached in time")
        time.sleep(0.01)


@pytest.fixture
def wb():
    w = Workbench(load_sample("head"))
    yield w
    w.close()


def _select(wb: Workbench, title: str) -> None:
    wb.tabs.selected_index = TAB_TITLES.index(title)


def test_exports_the_tool_widgets() -> None:
    for name in ("TimelineWidget", "ExportPanel", "RegionsPanel", "PaintPanel", "SculptPanel"):
        assert name in widgets.__all__ and hasattr(widgets, name)


def test_tabs_exist_and_heavy_panels_wait_for_their_tab(wb: Workbench) -> None:
    assert tuple(wb.tabs.titles) == ("Shapes", "Sculpt", "Regions", "Paint", "Export", "Capture", "Live", "Enhance")
    assert not wb.panel_built("regions") and not wb.panel_built("paint")
    assert wb.timeline in wb.children[1].children[0].children  # under the viewport
    _select(wb, "Regions")
    assert wb.panel_built("regions") and not wb.panel_built("paint")
    assert wb.tabs.children[2].children == (wb.regions,)


def test_tabs_set_the_viewport_tool(wb: Workbench) -> None:
    _select(wb, "Sculpt")
    assert wb.viewport.tool == "sculpt"
    _select(wb, "Export")
    assert wb.viewport.tool == "orbit"
    _select(wb, "Paint")
    assert wb.viewport.tool == "paint" and wb.panel_built("paint")
    _select(wb, "Shapes")
    assert wb.viewport.tool == "orbit"
    assert wb.tabs.selected_index == 0
    assert wb.errors.outputs == ()


def test_regions_tab_activates_and_its_drag_mode_keeps_the_tab(wb: Workbench) -> None:
    _select(wb, "Regions")
    regions = wb.regions
    assert regions._active and wb.viewport.tool == "orbit"
    regions.drag_mode.value = True  # drag mode uses the viewport's sculpt tool ...
    assert wb.viewport.tool == "sculpt"
    assert wb.viewport.drag_handler is regions.drag_handler
    assert wb.tabs.selected_index == TAB_TITLES.index("Regions")  # ... without leaving the tab
    _select(wb, "Sculpt")
    assert not regions._active and wb.viewport.drag_handler is None
    assert wb.viewport.tool == "sculpt" and wb.tabs.selected_index == 1
    _select(wb, "Regions")  # drag mode is still on: back to the pins
    assert regions._active and wb.viewport.drag_handler is regions.drag_handler
    _select(wb, "Shapes")
    assert not regions._active and wb.viewport.tool == "orbit" and wb.tabs.selected_index == 0
    assert wb.errors.outputs == ()


def test_a_tool_change_from_elsewhere_follows_with_the_tab(wb: Workbench) -> None:
    wb.viewport.tool = "paint"
    assert wb.tabs.selected_index == TAB_TITLES.index("Paint")
    _select(wb, "Export")
    wb.viewport.tool = "orbit"  # Export orbits too: stays
    assert wb.tabs.selected_index == TAB_TITLES.index("Export")


def test_status_line_and_undo_redo_buttons_follow_edits(wb: Workbench) -> None:
    n = wb.model.n_vertices
    assert f"{n} vertices" in wb.status.value and "undo depth 0" in wb.status.value
    assert "autosave: off" in wb.status.value
    assert wb.undo_button.disabled and wb.redo_button.disabled
    wb.model.set_weight("jawOpen", 0.3)
    assert "undo depth 1" in wb.status.value
    assert not wb.undo_button.disabled
    wb.undo_button.click()
    assert wb.model.weights["jawOpen"] == 0.0
    assert "undo depth 0" in wb.status.value and not wb.redo_button.disabled
    wb.redo_button.click()
    assert wb.model.weights["jawOpen"] == pytest.approx(0.3)


def test_wireframe_checkbox_in_the_top_bar_is_view_state(wb: Workbench) -> None:
    top = wb.children[0]
    assert wb.wireframe in top.children and wb.wireframe.description == "Wireframe"
    assert wb.wireframe.value is False and wb.viewport.wireframe is False
    wb.wireframe.value = True
    assert wb.viewport.wireframe is True
    assert wb.model.history.undo_labels == [] and wb.undo_button.disabled  # not an edit
    wb.viewport.wireframe = False  # set from code (the notebook): the checkbox follows
    assert wb.wireframe.value is False
    assert wb.errors.outputs == ()


def test_last_drag_stats_are_shown(wb: Workbench) -> None:
    wb.viewport.last_drag = {
        "name": "h",
        "moves": 10,
        "seconds": 0.5,
        "median_ms": 8.0,
        "last_ms": 12.5,
        "updates_per_s": 20.0,
    }
    wb._on_drag(dict(wb.viewport.last_drag))
    assert "last drag 12.5 ms (20 updates/s)" in wb.status.value


def test_callback_errors_show_in_the_shared_output(wb: Workbench, monkeypatch) -> None:
    wb.model.set_weight("jawOpen", 0.3)

    def broken() -> None:
        raise RuntimeError("undo exploded")

    monkeypatch.setattr(wb.model, "undo", broken)
    wb.undo_button.click()  # must not raise
    text = "".join(o.get("text", "") for o in wb.errors.outputs)
    assert "[undo]" in text and "undo exploded" in text


async def _until(pred, timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise AssertionError("condition not reached in time")
        await asyncio.sleep(0.01)


def test_autosave_state_in_status_line_and_close_stops_it(tmp_path: Path) -> None:
    # timer and snapshot on the kernel's loop, the write on its own thread, every state
    # change (and so the status line) back on the UI thread
    model = load_sample("head")
    threads: dict[str, Any] = {}

    async def main():
        wb = Workbench(model, autosave="wbtest", autosave_delay=0.0, autosave_folder=tmp_path)
        assert isinstance(wb.autosaver, Autosaver)
        assert "autosave: no edits yet" in wb.status.value
        wb.autosaver.changed.connect(lambda st: threads.setdefault(st, threading.current_thread()))
        model.set_weight("jawOpen", 0.4)
        await _until(lambda: wb.autosaver.state == "saved")
        await _until(lambda: "autosave: saved " in wb.status.value)
        assert (tmp_path / "wbtest.recovery.fwb").is_file()
        saver = wb.autosaver
        wb.close()
        assert saver._closed
        saves = saver.saves
        model.set_weight("jawOpen", 0.1)
        await asyncio.sleep(0.1)
        assert saver.saves == saves and saver.state == "saved"
        return threading.current_thread()

    ui_thread = in_kernel_loop(main)
    assert threads["pending"] is ui_thread and threads["saved"] is ui_thread
    assert load(tmp_path / "wbtest.recovery.fwb").weights["jawOpen"] == pytest.approx(0.4)


def test_close_with_discard_removes_the_recovery_file(tmp_path: Path) -> None:
    model = load_sample("head")

    async def main():
        wb = Workbench(model, autosave="gone", autosave_delay=0.0, autosave_folder=tmp_path)
        model.set_weight("jawOpen", 0.4)
        await _until(lambda: wb.autosaver.state == "saved")
        wb.close(discard_autosave=True)

    in_kernel_loop(main)
    assert not (tmp_path / "gone.recovery.fwb").exists()


def test_without_an_event_loop_autosave_waits_for_save_now(tmp_path: Path) -> None:
    # a script has no kernel loop: nothing saves behind its back, save_now() does it
    # (on_ui_thread: this process's main thread may hold the Playwright fixture's loop)
    def script() -> None:
        model = load_sample("head")
        wb = Workbench(model, autosave="script", autosave_delay=0.0, autosave_folder=tmp_path)
        model.set_weight("jawOpen", 0.4)
        time.sleep(0.1)
        assert wb.autosaver.state == "pending" and wb.autosaver.saves == 0
        wb.autosaver.save_now()
        assert wb.autosaver.state == "saved" and "autosave: saved " in wb.status.value
        wb.close()

    on_ui_thread(script)


# ---------------------------------------------------------------- recovery prompt
def _crashed_session(folder: Path, name: str, weight: float) -> None:
    """A recovery file whose owner process is gone, as a crashed kernel leaves it."""
    model = load_sample("head")
    saver = Autosaver(model, name, delay=60.0, folder=folder)
    model.set_weight("jawOpen", weight)
    saver.save_now()
    saver.close()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    owner = folder / f"{name}.recovery.fwb.owner"
    owner.write_text(owner.read_text().replace(f'"pid": {os.getpid()}', f'"pid": {dead.pid}'))


def test_recovery_prompt_without_recoverables_loads_the_default(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("WORKBENCH_RECOVERY_DIR", str(tmp_path))
    sentinel = object()
    built = []
    prompt = recovery_prompt(lambda: sentinel, build=lambda m: built.append(m))
    assert isinstance(prompt, RecoveryPrompt)
    assert prompt.model is sentinel and built == [sentinel]
    assert prompt.recover_buttons == []


def test_recovery_prompt_offers_and_recovers_a_crashed_session(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("WORKBENCH_RECOVERY_DIR", str(tmp_path))
    _crashed_session(tmp_path, "crashed", 0.7)
    assert [r.name for r in find_recoverable()] == ["crashed"]
    loads = []
    prompt = recovery_prompt(lambda: loads.append(1), build=lambda m: None)
    assert prompt.model is None and loads == []  # nothing loaded before the choice
    assert len(prompt.recover_buttons) == 1
    assert prompt.recover_buttons[0].description.startswith("Recover crashed: autosaved")
    prompt.recover_buttons[0].click()
    assert prompt.errors.outputs == ()
    assert prompt.model.weights["jawOpen"] == pytest.approx(0.7)
    assert loads == []


def test_recovery_prompt_start_fresh(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("WORKBENCH_RECOVERY_DIR", str(tmp_path))
    _crashed_session(tmp_path, "crashed", 0.7)
    prompt = recovery_prompt(lambda: "fresh")
    prompt.fresh_button.click()
    assert prompt.model == "fresh"


# ------------------------------------------------- edits right after a slider drag
def _drag_slider(slider, values) -> None:
    """What the browser sends while a slider is dragged: comm "update" messages."""
    for v in values:
        slider._handle_msg(
            {
                "content": {
                    "data": {"method": "update", "state": {"value": v}, "buffer_paths": []}
                },
                "buffers": [],
            }
        )


def _errors(wb: Workbench) -> str:
    return "".join(o.get("text", "") for o in wb.errors.outputs)


def test_key_right_after_a_slider_drag_is_an_undo_step_of_its_own(wb: Workbench) -> None:
    m = wb.model
    _drag_slider(wb.panel.sliders["jawOpen"], (0.2, 0.5, 0.8))
    assert m.interacting  # the drag's step waits for the slider to go quiet ...
    wb.timeline.handle_message({"type": "key", "time": 0.0})  # ... but Key comes at once
    assert wb.timeline._error == "" and not m.interacting
    assert m.history.undo_labels == ["Drag jawOpen", "Key 1 weights at 0s"]
    assert "weights/jawOpen" in m.tracks.tracks
    m.undo()  # the key goes, the slider value stays
    assert "weights/jawOpen" not in m.tracks.tracks
    assert m.weights["jawOpen"] == pytest.approx(0.8)
    m.undo()
    assert m.weights["jawOpen"] == 0.0
    assert _errors(wb) == ""


def test_timeline_edits_and_scrub_right_after_a_slider_drag(wb: Workbench) -> None:
    m = wb.model
    m.set_weight("jawOpen", 0.5)
    m.timeline.key_weights(1.0, ["jawOpen"])
    _drag_slider(wb.panel.sliders["eyeBlinkLeft"], (0.3, 0.6))
    wb.timeline.handle_message({"type": "add_key", "track": "weights/jawOpen", "time": 2.0})
    assert m.history.undo_labels[-2:] == ["Drag eyeBlinkLeft", "Key 1 weights at 2s"]
    _drag_slider(wb.panel.sliders["eyeBlinkLeft"], (0.1,))
    wb.timeline.handle_message({"type": "scrub", "time": 0.5, "seq": 1})
    assert wb.timeline._error == "" and m.time == 0.5  # set_time refuses inside a drag
    assert m.history.undo_labels[-1] == "Drag eyeBlinkLeft"
    assert _errors(wb) == ""


def test_import_right_after_a_slider_drag_is_an_undo_step_of_its_own(
    wb: Workbench, tmp_path: Path
) -> None:
    m = wb.model
    csv = tmp_path / "anim.csv"
    csv.write_text("time,jawOpen\n0,0\n1,0.5\n")
    _drag_slider(wb.panel.sliders["mouthSmileLeft"], (0.4, 0.7))
    wb.export.import_path.value = str(csv)
    wb.export.import_button.click()
    assert "Imported" in wb.export.import_result.value, wb.export.import_result.value
    assert m.history.undo_labels == ["Drag mouthSmileLeft", "Import animation anim.csv"]
    assert _errors(wb) == ""


def test_handle_drag_right_after_a_slider_drag_is_an_undo_step_of_its_own(wb: Workbench) -> None:
    from workbench.methods.handles.presets import default_face_handles

    m = wb.model
    m.handles.set(default_face_handles(m), label="Default handles")
    _drag_slider(wb.panel.sliders["jawOpen"], (0.3, 0.6))
    vp = wb.viewport
    vp.begin_drag(0)
    p = m.evaluate()[int(m.handles.vertices[0])] + [0.0, 0.05, 0.0]
    vp.drag_to(p)
    vp.end_drag()
    name = m.handles.names[0]
    assert m.history.undo_labels == ["Default handles", "Drag jawOpen", f"Drag handle {name}"]
    assert not m.interacting and _errors(wb) == ""


# ------------------------------------------------------------------ viewport
def test_viewport_frames_the_neutral_mesh_whatever_the_expression() -> None:
    import numpy as np

    from widgets import Viewport
    from workbench.methods.handles.presets import default_face_handles

    fresh = load_sample("head")
    posed = load_sample("head")  # opened mid-expression, as a recovered session may be:
    posed.set_weight("jawOpen", 1.0)
    posed.handles.set(default_face_handles(posed))
    lips = int(np.argmax(np.asarray(posed.vertices)[posed.handles.vertices, 2]))
    posed.move_handle(lips, [0.0, 0.0, 0.6])  # sculpted out of the neutral box
    a, b = Viewport(fresh), Viewport(posed)
    V = np.asarray(fresh.vertices)
    lo, hi = V.min(axis=0), V.max(axis=0)
    for vp in (a, b):
        nb = vp._neutral_bounds
        np.testing.assert_allclose(nb["min"], lo)
        np.testing.assert_allclose(nb["max"], hi)
        r = np.linalg.norm(V - (lo + hi) / 2, axis=1).max()  # three.js's bounding sphere
        assert nb["radius"] == pytest.approx(r)
    # what the posed view first receives has other bounds: framing on it would differ
    P = posed.evaluate()
    assert P[:, 2].max() > hi[2] + 0.1
    a.close()
    b.close()


def test_changing_the_tool_clears_the_dragged_handle_highlight(wb: Workbench) -> None:
    from workbench.methods.handles.presets import default_face_handles

    m = wb.model
    m.handles.set(default_face_handles(m), label="Default handles")
    _select(wb, "Sculpt")
    wb.viewport.begin_drag(3)
    wb.viewport.end_drag()
    assert wb.viewport.selected_marker == 3
    _select(wb, "Shapes")  # the viewport's tool goes back to orbit
    assert wb.viewport.tool == "orbit" and wb.viewport.selected_marker == -1
