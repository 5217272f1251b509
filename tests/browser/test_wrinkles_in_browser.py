"""Pose-space wrinkles while dragging (Bickel et al. 2008 §5–6) in a real JupyterLab + Chromium.

A notebook opens the Workbench on the ~20k-vertex sample head (the "25k"
level: fitting takes a few seconds there and the forehead furrows span
several triangles; on the 5k base head they are one broad wave). Like a
person, the test opens the Sculpt tab, presses **Fit wrinkles from examples**
(the progress label must show up), then drags the left middle brow marker up
with the mouse, and checks

* the kernel: one undo step, the feature-graph strain is non-zero, and the
  wrinkle detail on the forehead above the dragged brow is well above 0.1 mm;
* the front end: the strain it draws equals the kernel's, the edges at the
  dragged handle are coloured (not grey), and the legend is shown;
* the pixels: the same drag with wrinkles switched off (checkbox; undoable)
  changes the forehead much less than with wrinkles on, and the two
  dragged pictures differ on the forehead;
* dragging back down fades the detail to about zero, and Undo restores the
  rest pose exactly (no detail at all).

A second, quicker test draws the default handles' feature graph on the base
head (no fit) and orbits half a turn: seen from the front the edges are drawn,
seen from behind the head hides them (the lines are depth-tested).

Screenshots: ``test-artifacts/<test>/``; drag latencies (pointer event to the
frame showing it) with wrinkles on and off go to ``latency.json`` there.
"""

from __future__ import annotations

import json
import time
from typing import Any

import numpy as np
from harness import NotebookPage, clip_around, pixel_change

RESOLUTION = "25k"
#: the undo steps of pressing "Fit wrinkles from examples" on a model without handles
FIT = ["Default handles", "Fit wrinkles (6 examples)"]

CELLS = [
    f"""
import widgets, workbench
model = workbench.load_sample("head", resolution="{RESOLUTION}")
wb = widgets.Workbench(model, height=760)
wb
""",
]

# The dragged brow handle (subject's left, middle of the brow), its feature-graph edges,
# and the forehead above both middle brow handles (front-facing skin 0.05–0.4 dm above
# the handle, out to 0.2 dm beyond it on either side).
_FIND = """
import json, numpy as np
_h = model.handles
_k = list(_h.names).index("brows_L_2")
_V = np.asarray(model.vertices)
_skin = model.component_labels == model.component_names.index("skin")
_p = _V[_h.vertices[_k]]
_fh = np.flatnonzero(_skin & (np.abs(_V[:, 0]) < abs(_p[0]) + 0.2) & (_V[:, 1] > _p[1] + 0.05)
                     & (_V[:, 1] < _p[1] + 0.4) & (_V[:, 2] > _p[2] - 0.2))
_E = np.asarray(model.wrinkles.graph.edges)
_inc = [int(e) for e in np.flatnonzero((_E[:, 0] == _k) | (_E[:, 1] == _k))]
print(json.dumps({"index": _k, "vertex": int(_h.vertices[_k]), "name": _h.names[_k],
                  "forehead": [int(i) for i in _fh], "incident": _inc}))
"""

_STATE = """
import json, numpy as np
_w = model.wrinkles
_d = _w.details()
_f = _w.strain()
_fh = np.asarray(FOREHEAD)
print(json.dumps({
    "fitted": bool(_w.fitted),
    "undo": model.history.undo_labels,
    "interacting": model.interacting, "dragging": wb.viewport.dragging,
    "offsets": np.asarray(model.handles.offsets, float).tolist(),
    "enabled": bool(_w.enabled),
    "strain": None if _f is None else [float(x) for x in _f],
    "last_strain_max": None if _w.last_strain is None else float(np.abs(_w.last_strain).max()),
    "forehead_detail": 0.0 if _d is None else float(np.linalg.norm(_d[_fh], axis=1).max()),
    "detail_max": 0.0 if _d is None else float(np.abs(_d).max()),
    "errors": [o.get("text", "") for o in wb.errors.outputs],
    "status": wb.wrinkles.status.value,
}))
"""


_LAST_DRAG = """
import json
_d = wb.viewport.last_drag
print(json.dumps({"median_ms": _d.get("median_ms"), "moves": _d.get("moves")}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _handles_on_screen(nb: NotebookPage) -> np.ndarray:
    pts = nb.viewport(0).evaluate("e => e.fwbMarkers()")
    return np.array(pts, dtype=float).reshape(-1, 3)


def _wait_drag_closed(nb: NotebookPage, timeout: float = 20.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    st = _state(nb)
    while (st["interacting"] or st["dragging"]) and time.monotonic() < deadline:
        time.sleep(0.1)
        st = _state(nb)
    assert not st["interacting"] and not st["dragging"], "the handle drag never ended"
    return st


def _drag(nb: NotebookPage, index: int, dy: float, steps: int = 12) -> dict[str, Any]:
    """Drag marker ``index`` vertically by ``dy`` page pixels; wait until the kernel closed it."""
    page = nb.page
    start = _handles_on_screen(nb)[index]
    assert start[2] == 1, "the marker is behind the camera"
    frame0 = nb.frame(0)
    page.mouse.move(float(start[0]), float(start[1]))
    page.mouse.down()
    page.mouse.move(float(start[0]), float(start[1]) + dy, steps=steps)
    page.mouse.up()
    nb.wait_frame_after(0, frame0)
    st = _wait_drag_closed(nb)
    page.mouse.move(5, 5)
    page.wait_for_timeout(500)  # the final exact frame
    return st


def _click_undo(nb: NotebookPage, geometry: bool = True) -> None:
    """Click the top bar's Undo; wait for the new frame (``geometry``) or the shorter history."""
    frame = nb.frame(0)
    depth = len(_state(nb)["undo"])
    nb.page.locator(".fwb-wb-undo").click()
    if geometry:
        nb.wait_frame_after(0, frame)
    deadline = time.monotonic() + 10
    while len(_state(nb)["undo"]) != depth - 1:
        assert time.monotonic() < deadline, "Undo did not happen"
        time.sleep(0.1)
    nb.page.wait_for_timeout(400)


def _latencies(nb: NotebookPage, since: int) -> list[float]:
    stats = nb.viewport(0).evaluate("e => e.fwbDragStats")
    return [s["frame"] - s["input"] for s in stats[since:] if s.get("frame") is not None]


def _set_checkbox(nb: NotebookPage, css: str, value: bool, python: str) -> None:
    """Click the checkbox ``css`` (a person's click) until the kernel expression ``python`` is ``value``."""
    box = nb.page.locator(f"{css} input")
    if box.is_checked() != value:
        box.click()
    deadline = time.monotonic() + 10
    while nb.kernel_eval(f"import json; print(json.dumps(bool({python})))") != value:
        assert time.monotonic() < deadline, f"{css} did not reach {value}"
        time.sleep(0.1)
    nb.page.wait_for_timeout(400)  # the overlay / geometry frame


def test_brow_drag_wrinkles_the_forehead_then_undo(open_notebook) -> None:
    nb = open_notebook(CELLS, viewport_size=(1600, 1300))
    page = nb.page
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Sculpt").click()
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-tool') === 'sculpt'"
    )

    # --- Fit, with visible progress (the model has no handles: the default set comes first)
    t0 = time.monotonic()
    page.locator(".fwb-wrinkle-fit").click()
    page.wait_for_function(
        "() => /sculpt|fitting|preparing|render/.test("
        "(document.querySelector('.fwb-wrinkle-progress-label') || {}).textContent || '')",
        timeout=30_000,
    )
    nb.screenshot("fit-progress")
    page.wait_for_function(
        "() => document.querySelectorAll('.fwb-wrinkle-card').length >= 6", timeout=120_000
    )
    fit_wall = time.monotonic() - t0
    fit_s = nb.kernel_eval("import json; print(json.dumps(wb.wrinkles.last_fit_s))")
    n_handles = nb.kernel_eval("import json; print(json.dumps(len(model.handles)))")
    page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=n_handles,
    )
    page.wait_for_function(
        "() => Number(document.querySelector('.fwb-viewport').getAttribute('data-feature-edges')) > 0"
    )
    info = nb.kernel_eval(_FIND)
    nb.kernel_eval(f"FOREHEAD = {info['forehead']}")
    k = info["index"]
    assert len(info["forehead"]) > 30 and info["incident"], info
    # Zoom in on the face with the mouse wheel (camera only: no kernel message).
    box = nb.canvas_box(0)
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    for _ in range(4):  # about 1.2x (the face is framed to fill the height of the view)
        page.mouse.wheel(0, -120)
        page.wait_for_timeout(60)
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    # Symmetric: the mirror brow handle follows (a brow raise on both sides).
    page.locator(".fwb-symmetric").click()
    assert nb.kernel_eval("import json; print(json.dumps(wb.viewport.symmetric))") is True
    page.mouse.move(5, 5)
    page.wait_for_timeout(400)
    rest = _state(nb)
    assert rest["fitted"] and rest["errors"] == [], rest
    assert rest["undo"] == FIT, rest["undo"]
    assert rest["detail_max"] == 0.0  # the rest pose has no detail
    graph0 = nb.viewport(0).evaluate("e => e.fwbFeatureGraph()")
    assert graph0["visible"] and graph0["count"] == len(rest["strain"])
    assert all(abs(s) < 1e-6 for s in graph0["strain"])
    forehead_clip = clip_around(nb.project(info["forehead"]), pad=30)
    fh_rest_graph = nb.screenshot("forehead-rest-graph", clip=forehead_clip)
    nb.screenshot("page-rest")

    # --- Drag the brow up with wrinkles on (feature graph shown)
    stats0 = len(nb.viewport(0).evaluate("e => e.fwbDragStats"))
    dy = -20.0
    st = _drag(nb, k, dy)
    lat_on = _latencies(nb, stats0)
    kernel_on = nb.kernel_eval(_LAST_DRAG)
    assert st["undo"] == [*FIT, f"Drag handle {info['name']}"], st["undo"]
    off = np.array(st["offsets"])[k]
    assert off[1] > 0.02, off  # up by a few mm (dm units)
    strain = np.array(st["strain"])
    assert st["last_strain_max"] > 0.02 and np.abs(strain).max() > 0.02, st
    assert st["forehead_detail"] > 0.001, st  # > 0.1 mm on the forehead above the brow
    nb.screenshot("forehead-wrinkles-on-graph", clip=forehead_clip)
    nb.screenshot("page-wrinkles-on")
    # what the front end draws is the kernel's strain, and the dragged handle's edges are coloured
    graph = nb.viewport(0).evaluate("e => e.fwbFeatureGraph()")
    np.testing.assert_allclose(graph["strain"], strain, atol=2e-4)
    coloured = [e for e in info["incident"] if abs(strain[e]) > 0.02]
    assert coloured, "no edge at the dragged handle is strained"
    for e in coloured:
        r, _g, b = graph["colors"][e]
        assert (r > b + 0.1) if strain[e] > 0 else (b > r + 0.1), (e, strain[e], graph["colors"][e])
    assert page.locator(".fwb-strain-legend").is_visible()
    status = page.locator(".fwb-wrinkle-status").inner_text()
    assert "max detail" in status and "strain" in status, status

    # --- Pixels without the overlay: the same drag with wrinkles on / off
    _set_checkbox(nb, ".fwb-feature-graph", False, "wb.viewport.feature_graph")
    assert not page.locator(".fwb-strain-legend").is_visible()
    fh_on = nb.screenshot("forehead-wrinkles-on", clip=forehead_clip)
    _click_undo(nb)
    fh_rest = nb.screenshot("forehead-rest", clip=forehead_clip)
    _set_checkbox(nb, ".fwb-wrinkles-on", False, "model.wrinkles.enabled")
    assert _state(nb)["undo"][-1] == "Wrinkles off"
    stats1 = len(nb.viewport(0).evaluate("e => e.fwbDragStats"))
    st = _drag(nb, k, dy)
    lat_off = _latencies(nb, stats1)
    kernel_off = nb.kernel_eval(_LAST_DRAG)
    assert st["forehead_detail"] == 0.0 and np.abs(np.array(st["strain"])).max() > 0.02
    np.testing.assert_allclose(np.array(st["offsets"])[k], off, atol=2e-3)
    fh_off = nb.screenshot("forehead-wrinkles-off", clip=forehead_clip)
    nb.screenshot("page-wrinkles-off")
    # Wrinkle shading is a few grey levels: count pixels changed by more than 6 of 255.
    change_on = pixel_change(fh_rest, fh_on, threshold=6)
    change_off = pixel_change(fh_rest, fh_off, threshold=6)
    between = pixel_change(fh_on, fh_off, threshold=6)
    assert change_on > change_off + 0.02, (change_on, change_off)
    assert between > 0.02, between

    # --- Back to wrinkles on (undo the drag and the switch), drag up, then drag back down
    _click_undo(nb)
    _click_undo(nb, geometry=False)  # "Wrinkles off" at the rest pose: nothing to redraw
    st = _state(nb)
    assert st["enabled"] is True and st["undo"] == FIT, st
    _drag(nb, k, dy)
    peak = _state(nb)["forehead_detail"]
    st = _drag(nb, k, -dy)
    assert st["forehead_detail"] < 0.15 * peak, (st["forehead_detail"], peak)
    nb.screenshot("forehead-dragged-back", clip=forehead_clip)
    _click_undo(nb)
    _click_undo(nb)
    st = _state(nb)
    assert st["undo"] == FIT
    assert np.abs(np.array(st["offsets"])).max() == 0.0
    assert st["detail_max"] == 0.0 and np.abs(np.array(st["strain"])).max() < 1e-4
    fh_back = nb.screenshot("forehead-undone", clip=forehead_clip)
    assert pixel_change(fh_rest, fh_back, threshold=6) < 0.005

    # --- The feature graph toggles back on: grey edges over the forehead, legend shown
    _set_checkbox(nb, ".fwb-feature-graph", True, "wb.viewport.feature_graph")
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-feature-visible') === '1'"
    )
    assert page.locator(".fwb-strain-legend").is_visible()
    fh_graph = nb.screenshot("forehead-rest-graph-again", clip=forehead_clip)
    assert pixel_change(fh_rest_graph, fh_graph) < 0.03
    assert pixel_change(fh_rest, fh_graph) > 0.002  # the edges are drawn
    graph = nb.viewport(0).evaluate("e => e.fwbFeatureGraph()")
    assert max(abs(s) for s in graph["strain"]) < 1e-3

    assert _state(nb)["errors"] == []
    console = "\n".join(nb.console)
    assert "pageerror" not in console, console
    nb.artifacts.mkdir(parents=True, exist_ok=True)
    (nb.artifacts / "latency.json").write_text(
        json.dumps(
            {
                "resolution": RESOLUTION,
                "fit_s": fit_s,
                "fit_wall_s_with_thumbnails": fit_wall,
                "latency_ms_wrinkles_on": lat_on,
                "latency_ms_wrinkles_off": lat_off,
                "median_on": float(np.median(lat_on)) if lat_on else None,
                "median_off": float(np.median(lat_off)) if lat_off else None,
                "kernel_ms_per_update_on": kernel_on,
                "kernel_ms_per_update_off": kernel_off,
                "pixel_change": {"on": change_on, "off": change_off, "on_vs_off": between},
            },
            indent=1,
        )
    )


# The feature graph of the default handles (what a fit draws), no fit needed; the
# model has no handles, so no marker covers the lines.
_GRAPH_CELLS = [
    """
import numpy as np, widgets, workbench
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.wrinkles.features import FeatureGraph
model = workbench.load_sample("head")
_h = default_face_handles(model)
graph = FeatureGraph.from_handles(np.asarray(model.vertices)[_h.vertices])
PAIRS = np.asarray(_h.vertices)[graph.edges]
vp = widgets.Viewport(model, height=480)
vp.layout.width = "640px"
vp.set_feature_graph(PAIRS)
vp
""",
]


def _line_samples(nb: NotebookPage, pairs: np.ndarray) -> np.ndarray:
    """(k, 2) page points on the drawn edges (a quarter, half and three quarters along)."""
    ends = nb.project(np.unique(pairs))
    at = {int(v): ends[i, :2] for i, v in enumerate(np.unique(pairs))}
    return np.array(
        [at[a] + t * (at[b] - at[a]) for a, b in pairs.tolist() for t in (0.25, 0.5, 0.75)]
    )


def _drawn_fraction(nb: NotebookPage, name: str, pts: np.ndarray) -> float:
    """Fraction of the points ``pts`` whose pixel the overlay changes (graph off, then on)."""
    box = nb.canvas_box(0)
    shots = {}
    for shown in (False, True):  # (it is on: each assignment changes it and redraws)
        renders = int(nb.viewport(0).get_attribute("data-render-count"))
        nb.kernel_eval(f"vp.feature_graph = {shown}")
        nb.page.wait_for_function(
            "(r) => Number(document.querySelector('.fwb-viewport')"
            ".getAttribute('data-render-count')) > r",
            arg=renders,
        )
        nb.page.wait_for_timeout(200)
        shots[shown] = nb.screenshot(f"{name}-{'on' if shown else 'off'}", clip=box)
    diff = np.abs(shots[True].astype(int) - shots[False].astype(int)).max(axis=2)
    xy = np.round(pts - [box["x"], box["y"]]).astype(int)
    h, w = diff.shape
    inside = (xy[:, 0] >= 0) & (xy[:, 0] < w) & (xy[:, 1] >= 0) & (xy[:, 1] < h)
    xy = xy[inside]
    return float((diff[xy[:, 1], xy[:, 0]] > 12).mean())


def test_feature_graph_is_hidden_by_the_head_seen_from_behind(open_notebook) -> None:
    nb = open_notebook(_GRAPH_CELLS)
    nb.page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    nb.viewport(0).evaluate("e => e.scrollIntoView({block: 'center'})")
    nb.page.wait_for_timeout(300)
    pairs = np.array(nb.kernel_eval("import json; print(json.dumps(PAIRS.tolist()))"))
    assert nb.viewport(0).get_attribute("data-feature-edges") == str(len(pairs))

    # From the front the edges lie on the face: (nearly) all of them are drawn ...
    front = _drawn_fraction(nb, "front", _line_samples(nb, pairs))
    assert front > 0.9, front
    assert nb.page.locator(".fwb-strain-legend").is_visible()

    # ... orbit half a turn (OrbitControls: 2 pi per canvas height dragged) ...
    box = nb.canvas_box(0)
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    nb.page.mouse.move(cx - box["height"] / 4, cy)
    nb.page.mouse.down()
    nb.page.mouse.move(cx + box["height"] / 4, cy, steps=20)
    nb.page.mouse.up()
    nb.page.mouse.move(5, 5)
    pts = _line_samples(nb, pairs)
    assert pts[:, 0].min() > box["x"] and pts[:, 0].max() < box["x"] + box["width"]
    # ... and the head hides them: none shows through the back of the head.
    back = _drawn_fraction(nb, "back", pts)
    assert back < 0.03, back
    assert nb.page.locator(".fwb-strain-legend").is_visible()  # the legend stays
    console = "\n".join(nb.console)
    assert "pageerror" not in console, console
