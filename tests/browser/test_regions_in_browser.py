"""Region sculpting (Joshi et al. 2003 §4) in a real JupyterLab + Chromium.

A notebook shows a :class:`widgets.Viewport` beside a :class:`widgets.RegionsPanel`.
The test uses the mouse like a person: "Find regions", "Drag to sculpt", then
drags the left mouth-corner marker up and out. Checked on both sides: in the
kernel the region weights under the pin changed (one undo step) and no vertex
outside those regions (``Regions.members``) moved; on screen the mouth pixels
changed and the forehead's did not. Then "Split…" and two clicks on its markers split
the selected region (one undo step). Screenshots go to ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from harness import NotebookPage, clip_around, pixel_change

CELLS = [
    """
import ipywidgets as W
from workbench import load_sample
from widgets.viewport import Viewport
from widgets.regions import RegionsPanel
model = load_sample("head")
vp = Viewport(model, height=560)
vp.layout = W.Layout(flex="1 1 auto", min_width="320px")
panel = RegionsPanel(model, vp)
panel.layout.width = "520px"
W.HBox([vp, panel], layout=W.Layout(width="100%"))
""",
]

# The left mouth corner: among the skin vertices mouthSmileLeft moves most, the one
# farthest out in +x; its pin is the drag-mode marker nearest to it.
_FIND = """
import json, numpy as np
_skin = model.component_labels == model.component_names.index("skin")
_V = np.asarray(model.vertices)
_d = np.linalg.norm(model.shape("mouthSmileLeft").delta, axis=1) * _skin
_top = np.argsort(-_d)[:40]
_corner = int(_top[np.argmax(_V[_top, 0])])
_pins = panel.pins
_k = int(np.argmin(np.linalg.norm(_V[_pins] - _V[_corner], axis=1)))
_v = int(_pins[_k])
_st = model.regions.state
_touched = sorted(_st.regions.regions_at(_st.level, _v))
_inside = np.unique(np.concatenate([_st.regions.members(_st.level, r) for r in _touched]))
_brow = np.argsort(-np.linalg.norm(model.shape("browInnerUp").delta, axis=1) * _skin)[:20]
_by = _V[_brow, 1].mean()
_front = _skin & (np.abs(_V[:, 0]) < 0.35) & (_V[:, 2] > _V[_skin, 2].max() - 0.35)
_fh = np.flatnonzero(_front & (_V[:, 1] > _by + 0.2) & (_V[:, 1] < _by + 0.5))
_X0 = np.array(model.evaluate(), dtype=np.float64)
print(json.dumps({"index": _k, "vertex": _v, "n_pins": int(len(_pins)), "level": _st.level,
                  "touched": [_st.regions.names[_st.level][r] for r in _touched],
                  "n_inside": int(_inside.size), "mouth": [int(i) for i in _top],
                  "forehead": [int(i) for i in _fh[::3]]}))
"""

_AFTER = """
import json, numpy as np
_st = model.regions.state
_X1 = np.array(model.evaluate(), dtype=np.float64)
_out = np.setdiff1d(np.arange(model.n_vertices), _inside)
_rw = _st.weights
_g = np.array([model.weights[n] for n in model.shape_names])
_dw = (np.abs(_rw.values - _g[None, :]).max(axis=1) if _rw is not None
       else np.zeros(_st.regions.n_regions(_st.level)))
print(json.dumps({"undo": model.history.undo_labels, "interacting": model.interacting,
                  "dragging": panel.drag_handler.dragging,
                  "changed_regions": [_st.regions.names[_st.level][r] for r in np.flatnonzero(_dw > 0)],
                  "max_dw": float(_dw.max()),
                  "outside_max": float(np.abs(_X1[_out] - _X0[_out]).max()),
                  "pin_moved": float(np.linalg.norm(_X1[_v] - _X0[_v])),
                  "pin_disp": (_X1[_v] - _X0[_v]).tolist(),
                  "errors": panel.errors.count + vp.errors.count,
                  "status": panel.status.value}))
"""

_FRONT_MARKERS = """
import json, numpy as np
_n = model.to_trimesh().vertex_normals[panel.edits.markers]
print(json.dumps((_n[:, 2] > 0.6).tolist()))
"""

_SPLIT_STATE = """
import json
_st = model.regions.state
print(json.dumps({"undo": model.history.undo_labels, "n_regions": _st.regions.n_regions(_st.level),
                  "selected": panel.region.label, "split_mode": panel.edits.split_mode.value,
                  "tool": vp.tool, "errors": panel.errors.count + vp.errors.count,
                  "edit": panel.edits.message}))
"""


def _wait(nb: NotebookPage, code: str, ok: Any, timeout: float = 30.0) -> Any:
    """Poll a kernel expression until ``ok(value)``."""
    deadline = time.monotonic() + timeout
    val = nb.kernel_eval(code)
    while not ok(val) and time.monotonic() < deadline:
        val = nb.kernel_eval(code)
    assert ok(val), f"timed out waiting: {code!r} -> {val!r}"
    return val


def _drawn(nb: NotebookPage) -> None:
    """Wait until the view drew the kernel's newest geometry, then two more animation frames.

    (Call it after moving the pointer off the face: the render that drops the
    marker's hover highlight is requested by then, and drawn within them.)
    """
    version = nb.kernel_eval("import json; print(json.dumps(vp._version))")
    nb.page.wait_for_function(
        "(v) => Number(document.querySelector('.fwb-viewport').getAttribute('data-version')) >= v",
        arg=version,
    )
    nb.page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


def _canvas_changes(nb: NotebookPage, before: Any, name: str, least: float, timeout: float = 30.0) -> Any:
    """Canvas screenshots until more than ``least`` of the pixels differ from ``before``."""
    deadline = time.monotonic() + timeout
    shot = nb.canvas_shot(name)
    while pixel_change(before, shot) <= least and time.monotonic() < deadline:
        shot = nb.canvas_shot(name)
    return shot


def test_drag_mouth_corner_in_region_mode_moves_only_its_region(open_notebook):
    nb = open_notebook(CELLS)
    page = nb.page
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    page.locator(".fwb-viewport").evaluate("e => e.scrollIntoView({block: 'start'})")
    nb.screenshot("page-start")

    # Find regions: the overlay appears (the face is no longer one skin colour)
    face0 = nb.canvas_shot("face-before-regions")
    page.locator(".fwb-find-regions").click()
    _wait(nb, "import json; print(json.dumps(model.regions.state is not None))", bool)
    page.wait_for_function(
        "() => document.querySelector('.fwb-region-status').innerText.includes('segmentation')"
    )
    face1 = _canvas_changes(nb, face0, "face-regions", 0.05)
    assert pixel_change(face0, face1) > 0.05, "the region colours did not show"

    # Drag mode: the viewport switches to its sculpt tool with one marker per pin
    page.locator(".fwb-region-drag").click()
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-tool') === 'sculpt'"
    )
    info = nb.kernel_eval(_FIND)
    assert info["touched"] and all(t.startswith("mouth") for t in info["touched"]), info
    page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=info["n_pins"],
    )
    page.mouse.move(5, 5)
    _drawn(nb)
    mouth_clip = clip_around(nb.project([*info["mouth"], info["vertex"]]), pad=60)
    forehead_clip = clip_around(nb.project(info["forehead"]), pad=10)
    mouth0 = nb.screenshot("mouth-before", clip=mouth_clip)
    forehead0 = nb.screenshot("forehead-before", clip=forehead_clip)
    nb.screenshot("page-before")

    # Drag the mouth-corner marker up and out (viewer's right = subject's left)
    start = np.array(page.locator(".fwb-viewport").evaluate("e => e.fwbMarkers()"), float)
    start = start.reshape(-1, 3)[info["index"]]
    assert start[2] == 1, "the mouth-corner marker is hidden"
    frame0 = nb.frame(0)
    page.mouse.move(start[0], start[1])
    page.mouse.down()
    page.mouse.move(start[0] + 40, start[1] - 32, steps=15)
    page.mouse.up()
    nb.wait_frame_after(0, frame0)
    st = _wait(nb, _AFTER, lambda s: not s["interacting"] and not s["dragging"])
    page.mouse.move(5, 5)
    _drawn(nb)

    # Python side: region weights of the touched regions changed, nothing outside moved
    assert st["errors"] == 0, st
    assert st["undo"][-1].startswith("Region drag mouth"), st["undo"]
    assert st["undo"][-2].startswith("Segment regions"), "the drag was not ONE undo step"
    assert st["changed_regions"] and set(st["changed_regions"]) <= set(info["touched"]), st
    assert st["max_dw"] > 0.02, st
    assert st["outside_max"] == 0.0, st
    assert st["pin_moved"] > 0.01, st
    dx, dy, _ = st["pin_disp"]
    assert dx > 0 and dy > 0, st["pin_disp"]  # right and up on screen = +x, +y
    assert "solve" in st["status"], st["status"]

    # Pixels: the mouth changed, the forehead did not
    mouth1 = nb.screenshot("mouth-after", clip=mouth_clip)
    forehead1 = nb.screenshot("forehead-after", clip=forehead_clip)
    nb.screenshot("page-after")
    changed = pixel_change(mouth0, mouth1)
    assert changed > 0.03, f"only {changed:.1%} of the mouth region changed"
    still = pixel_change(forehead0, forehead1)
    assert still < 0.01, f"{still:.1%} of the forehead changed"

    # Split the selected region with two clicks on its split-mode markers
    before = nb.kernel_eval(_SPLIT_STATE)
    page.locator(".fwb-region-split").click()
    page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=nb.kernel_eval("import json; print(json.dumps(len(panel.edits.markers)))"),
    )
    # (clicking the button may have scrolled the page: bring the face back into view)
    page.locator(".fwb-viewport").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.mouse.move(5, 5)
    _drawn(nb)
    pts = np.array(page.locator(".fwb-viewport").evaluate("e => e.fwbMarkers()"), float)
    pts = pts.reshape(-1, 3)
    height = page.viewport_size["height"] if page.viewport_size else 10**6
    # markers on skin facing the camera (+z): a lip region also has markers inside the mouth
    front = np.array(nb.kernel_eval(_FRONT_MARKERS), bool)
    vis = np.flatnonzero(front & (pts[:, 2] == 1) & (pts[:, 1] > 0) & (pts[:, 1] < height))
    assert vis.size >= 2, "fewer than two split markers are visible"
    d = np.linalg.norm(pts[vis, None, :2] - pts[None, vis, :2], axis=2)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    page.mouse.click(pts[vis[i], 0], pts[vis[i], 1])
    _wait(nb, _SPLIT_STATE, lambda s: "second marker" in s["edit"])
    page.mouse.click(pts[vis[j], 0], pts[vis[j], 1])
    after = _wait(nb, _SPLIT_STATE, lambda s: s["undo"][-1].startswith("Split region"))
    assert after["undo"][-1] == f"Split region {before['selected']}", after
    assert after["n_regions"] == before["n_regions"] + 1, after
    assert not after["split_mode"] and after["tool"] == "orbit", after  # viewport given back
    assert after["errors"] == 0, after
    nb.screenshot("page-split")
    console = "\n".join(nb.console)
    assert "pageerror" not in console, console
