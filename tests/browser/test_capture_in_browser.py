"""The Capture tab with the mouse in a real JupyterLab + Chromium, on a take with known answer.

The kernel generates a take on the sample head (known weight curves and head
motion, seen as noisy, partly occluded markers: ``workbench.capture.synthetic``)
and writes it as a user's files (a marker CSV in metres, a JSON marker map).
With the mouse: open the Capture tab, type the two paths, press *Load take*
(the markers appear over the face), *Track* (a progress bar, then the
frames/s line and the weight/error plot), drag the frame slider (the markers
move on screen), press *Apply to timeline* (one undo step: the timeline now
plays the take) and *Undo*. Checked in the kernel and on the pixels;
screenshots in ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from harness import NotebookPage, pixel_change, wait_until

_CELLS = [
    "import json, numpy as np, tempfile, pathlib\nimport workbench, widgets\n"
    "from workbench.capture.synthetic import synthetic_performance\n"
    "model = workbench.load_sample('head')\n"
    "perf = synthetic_performance(model, 90, fps=30.0, seed=4, markers=60, noise=0.002, occlusion=0.05)\n"
    "d = pathlib.Path(tempfile.mkdtemp())\n"
    "names = [f'M{i:02d}' for i in range(perf.markers.shape[1])]\n"
    "rows = ['frame,' + ','.join(f'{n}_{a}' for n in names for a in 'xyz')]\n"
    "for f, P in enumerate(perf.markers * 0.1):\n"
    "    rows.append(str(f) + ',' + ','.join('' if not np.isfinite(v) else f'{v:.6f}' for v in P.reshape(-1)))\n"
    "(d / 'take.csv').write_text('# units: m\\n# fps: 30\\n' + '\\n'.join(rows) + '\\n')\n"
    "(d / 'map.json').write_text(json.dumps({n: int(v) for n, v in zip(names, perf.marker_ids)}))",
    "wb = widgets.show_workbench(model)",
]

_STATE = """
import json, numpy as np
_c = wb.capture
print(json.dumps({
    "loaded": _c.take is not None, "tracked": _c.result is not None, "frame": _c.frame.value,
    "rmse": float(np.sqrt(np.mean((_c.result.weights - perf.weights) ** 2))) if _c.result is not None else None,
    "drawn": int(len(wb.viewport.overlay_points)), "undo": model.history.undo_labels,
    "keys": sum(len(t.times) for t in model.timeline.value.tracks.values()) if hasattr(model.timeline.value, 'tracks') else None,
    "status": _c.progress.label.value,
    "errors": [o.get("text", "") for o in wb.errors.outputs]}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _overlay(nb: NotebookPage) -> np.ndarray:
    return np.array(nb.viewport(0).evaluate("e => e.fwbOverlayProject ? e.fwbOverlayProject() : []"), float)


def _load_the_take(open_notebook: Any) -> NotebookPage:
    """Open the notebook, then with the mouse: the Capture tab, the take's two paths, *Load take*."""
    nb = open_notebook(_CELLS, viewport_size=(1500, 1200))
    page = nb.page
    page.evaluate("() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }")
    nb.wait_viewports(1)
    paths = nb.kernel_eval("print(json.dumps([str(d / 'take.csv'), str(d / 'map.json')]))")
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Capture").click()
    page.locator(".fwb-capture-path input").fill(paths[0])
    page.locator(".fwb-capture-map input").fill(paths[1])
    page.locator(".fwb-capture-load").click()
    return nb


def test_load_track_scrub_apply_and_undo_with_the_mouse(open_notebook) -> None:
    nb = _load_the_take(open_notebook)
    page = nb.page
    st = wait_until("the take", lambda: _state(nb), lambda s: s["loaded"] or s["errors"])
    assert st["loaded"] and not st["errors"], st
    wait_until("the markers over the face", lambda: int(nb.viewport(0).get_attribute("data-overlay-points") or 0),
           lambda n: n == st["drawn"] and n > 40)
    page.mouse.move(5, 5)
    nb.screenshot("loaded")
    # the drawn markers sit on the face: inside the canvas, over the head's pixels
    box = nb.canvas_box(0)
    pts = _overlay(nb)
    inside = (pts[:, 0] > box["x"]) & (pts[:, 0] < box["x"] + box["width"]) & (pts[:, 1] > box["y"]) & (
        pts[:, 1] < box["y"] + box["height"])
    assert inside.all(), pts

    # ---- Track
    page.locator(".fwb-capture-track").click()
    st = wait_until("the tracking", lambda: _state(nb), lambda s: s["tracked"], timeout=120)
    assert st["rmse"] < 0.08, st
    wait_until("the status line", page.locator(".fwb-capture-status").inner_text, lambda t: "frames/s" in t)
    plot = page.locator(".fwb-capture-plot")
    plot.wait_for(state="visible")
    pb = plot.bounding_box()
    assert pb is not None and pb["height"] > 100
    nb.screenshot("tracked")

    # ---- drag the frame slider: the markers move on screen
    before = _overlay(nb)
    root = page.locator(".fwb-capture-frame")
    handle, track = root.locator(".noUi-handle"), root.locator(".noUi-base")
    hb, tb = handle.bounding_box(), track.bounding_box()
    assert hb is not None and tb is not None
    page.mouse.move(hb["x"] + hb["width"] / 2, hb["y"] + hb["height"] / 2)
    page.mouse.down()
    page.mouse.move(tb["x"] + 0.6 * tb["width"], hb["y"] + hb["height"] / 2, steps=10)
    page.mouse.up()
    st = wait_until("the frame", lambda: _state(nb), lambda s: s["frame"] > 30)
    after = wait_until("the markers to move", lambda: _overlay(nb),
                   lambda p: p.shape != before.shape or np.abs(p - before).max() > 2.0)
    assert after.size
    nb.screenshot("scrubbed")

    # ---- Apply to timeline: one undo step; Undo from the top bar removes it
    n_undo = len(st["undo"])
    page.locator(".fwb-capture-apply").click()
    st = wait_until("the keys", lambda: _state(nb), lambda s: len(s["undo"]) == n_undo + 1)
    played = nb.kernel_eval(
        "model.set_time(1.0)\n"
        "print(json.dumps(float(np.abs(np.array([model.weights.get(n, 0.0) for n in wb.capture.result.shape_names])"
        " - wb.capture.result.weights[30]).max())))")
    assert played < 0.02, played
    nb.screenshot("applied")
    page.locator(".fwb-wb-undo").click()
    wait_until("the undo", lambda: _state(nb), lambda s: len(s["undo"]) == n_undo)
    assert json.dumps(_state(nb)["errors"]) == "[]"


_REPLAY_STATE = """
import json, numpy as np
_c = wb.capture
print(json.dumps({
    "loaded": _c.take is not None, "replayed": _c.replayed is not None, "mode": _c.mode.value,
    "handles": int(len(model.handles)), "markers_are_handles": bool(
        _c.take is not None and len(model.handles) == len(_c.take['vertex_ids'])
        and np.array_equal(model.handles.vertices, _c.take['vertex_ids'])),
    "undo": model.history.undo_labels, "status": _c.progress.label.value,
    "errors": [o.get("text", "") for o in wb.errors.outputs]}))
"""


def test_drive_handles_replays_the_markers_through_the_shell_with_the_mouse(open_notebook) -> None:
    """Capture ▸ markers: drive handles (shell) ▸ Track ▸ Apply: the face follows the markers, one undo step."""
    nb = _load_the_take(open_notebook)
    page = nb.page
    state = lambda: nb.kernel_eval(_REPLAY_STATE)  # noqa: E731
    st = wait_until("the take", state, lambda s: s["loaded"] or s["errors"])
    assert st["loaded"] and not st["errors"], st
    page.locator(".fwb-capture-mode button", has_text="drive handles").click()
    wait_until("the mode", state, lambda s: s["mode"] == "shell")
    page.locator(".fwb-capture-track").click()
    st = wait_until("the replay", state, lambda s: s["replayed"] or s["errors"], timeout=180)
    assert st["replayed"] and not st["errors"], st
    wait_until("the status line", page.locator(".fwb-capture-status").inner_text,
               lambda t: "through the shell" in t)
    page.mouse.move(5, 5)
    before = nb.canvas_shot("replayed")
    frame = nb.frame(0)
    n_undo = len(st["undo"])
    page.locator(".fwb-capture-apply").click()
    st = wait_until("the apply", state, lambda s: len(s["undo"]) == n_undo + 1)
    assert st["markers_are_handles"], st
    nb.wait_frame_after(0, frame)
    after = nb.canvas_shot("applied")
    # the face now plays the replay's frame 0 (its expression and head pose): the picture changed
    assert pixel_change(before, after) > 0.002
    page.locator(".fwb-wb-undo").click()
    st = wait_until("the undo", state, lambda s: len(s["undo"]) == n_undo)
    assert not st["markers_are_handles"] and not st["errors"], st
