"""Handle dragging (Bickel et al. 2008 §4 shell editing) in a real JupyterLab + Chromium.

The tests open ``notebooks/workbench.ipynb``, switch to the "Sculpt" tab, load
the default handle set with the panel's button and then use the mouse like a
person: drag the left mouth-corner marker, undo from the panel, drag with
"Symmetric" on, Shift-click to add a handle and Alt-click to remove it, and
hover or drag a marker, then leave the view or change the tool (its highlight
ends). Each step is checked on both sides: the model in the kernel (offsets,
undo labels) and the pixels (the mouth region changes, the forehead does
not). Screenshots are kept in ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from harness import NotebookPage, clip_around, pixel_change

REPO = Path(__file__).resolve().parents[2]
WORKBENCH_NB = REPO / "notebooks" / "workbench.ipynb"

# The left mouth corner: among the skin vertices mouthSmileLeft moves most, the one
# farthest out in +x (the subject's left); its handle is the handle nearest to it.
# Forehead: front-facing skin well above the brows, far from any mouth handle.
_FIND = """
import json, numpy as np
_skin = model.component_labels == model.component_names.index("skin")
_V = np.asarray(model.vertices)
_d = np.linalg.norm(model.shape("mouthSmileLeft").delta, axis=1) * _skin
_top = np.argsort(-_d)[:40]
_corner = int(_top[np.argmax(_V[_top, 0])])
_h = model.handles
_k = int(np.argmin(np.linalg.norm(_V[_h.vertices] - _V[_corner], axis=1)))
_brow = np.argsort(-np.linalg.norm(model.shape("browInnerUp").delta, axis=1) * _skin)[:20]
_by = _V[_brow, 1].mean()
_front = _skin & (np.abs(_V[:, 0]) < 0.35) & (_V[:, 2] > _V[_skin, 2].max() - 0.35)
_fh = np.flatnonzero(_front & (_V[:, 1] > _by + 0.2) & (_V[:, 1] < _by + 0.5))
print(json.dumps({"index": _k, "vertex": int(_h.vertices[_k]), "name": _h.names[_k],
                  "mirror": int(_h.mirror[_k]), "corner": _corner,
                  "mouth": [int(i) for i in _top], "forehead": [int(i) for i in _fh[::3]]}))
"""

_STATE = """
import json, numpy as np
_h = model.handles
print(json.dumps({"offsets": np.asarray(_h.offsets, float).tolist(),
                  "vertices": [int(v) for v in _h.vertices], "names": list(_h.names),
                  "undo": model.history.undo_labels, "interacting": model.interacting,
                  "dragging": wb.viewport.dragging}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _handles_on_screen(nb: NotebookPage) -> np.ndarray:
    """(h, 3) page (x, y, in_front) of the handle markers, computed now."""
    pts = nb.viewport(0).evaluate("e => e.fwbMarkers()")
    return np.array(pts, dtype=float).reshape(-1, 3)


def _open_sculpt(nb: NotebookPage) -> dict[str, Any]:
    """Collapse the sidebar, open the Sculpt tab, press "Default handles"; find the mouth corner."""
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
    page.locator(".fwb-default-handles").click()
    n = None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        n = nb.kernel_eval("import json; print(json.dumps(len(model.handles)))")
        if n:
            break
        time.sleep(0.1)
    assert n and n > 40, f"Default handles gave {n} handles"
    page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=n,
    )
    info: dict[str, Any] = nb.kernel_eval(_FIND)
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.mouse.move(5, 5)  # no hover highlight in the "before" pictures
    page.wait_for_timeout(300)
    return info


def _wait_drag_closed(nb: NotebookPage, timeout: float = 10.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    st = _state(nb)
    while (st["interacting"] or st["dragging"]) and time.monotonic() < deadline:
        time.sleep(0.1)
        st = _state(nb)
    assert not st["interacting"] and not st["dragging"], "the handle drag never ended"
    return st


def _drag(nb: NotebookPage, start: np.ndarray, delta: tuple[float, float], steps: int = 15) -> None:
    page = nb.page
    x0, y0 = float(start[0]), float(start[1])
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move(x0 + delta[0], y0 + delta[1], steps=steps)
    page.mouse.up()


def test_drag_mouth_corner_moves_the_vertex_then_undo(open_notebook):
    nb = open_notebook(WORKBENCH_NB)
    info = _open_sculpt(nb)
    k, v = info["index"], info["vertex"]
    assert info["name"].startswith("mouth_L"), info["name"]
    before_state = _state(nb)
    mouth_clip = clip_around(nb.project([*info["mouth"], v]), pad=60)
    forehead_clip = clip_around(nb.project(info["forehead"]), pad=10)
    mouth0 = nb.screenshot("mouth-before", clip=mouth_clip)
    forehead0 = nb.screenshot("forehead-before", clip=forehead_clip)
    nb.screenshot("page-before")

    # Drag the marker up and out (the viewer's right is the subject's left): a half smile.
    start = _handles_on_screen(nb)[k]
    assert start[2] == 1, "the mouth-corner marker is behind the camera"
    delta = (30.0, -24.0)
    frame0 = nb.frame(0)
    _drag(nb, start, delta)
    nb.wait_frame_after(0, frame0)
    st = _wait_drag_closed(nb)
    nb.page.wait_for_timeout(300)

    # The model: exactly one undo step for the whole drag ...
    assert st["undo"] == [*before_state["undo"], f"Drag handle {info['name']}"]
    offsets = np.array(st["offsets"])
    # ... only the dragged handle has an offset (symmetric is off) ...
    others = np.delete(offsets, k, axis=0)
    assert np.abs(others).max() == 0.0
    off = offsets[k]
    # ... in the view plane (the default camera looks along -z) ...
    assert abs(off[2]) < 1e-4 * np.linalg.norm(off), off
    assert off[0] > 0 and off[1] > 0, off  # right and up on screen = +x, +y
    # ... and by the dragged amount: the vertex is drawn where the mouse let go.
    moved_to = nb.project([v])[0]
    target = np.array([start[0] + delta[0], start[1] + delta[1]])
    assert np.linalg.norm(moved_to[:2] - target) < 3.0, (moved_to, target)
    # The vertex follows its handle exactly (handles are interpolated).
    disp = nb.kernel_eval(
        f"import json; print(json.dumps((model.evaluate()[{v}] - model.blended()[{v}]).tolist()))"
    )
    np.testing.assert_allclose(disp, off, atol=1e-5)

    mouth1 = nb.screenshot("mouth-after", clip=mouth_clip)
    forehead1 = nb.screenshot("forehead-after", clip=forehead_clip)
    nb.page.mouse.move(5, 5)
    nb.page.wait_for_timeout(200)
    nb.screenshot("page-after")
    changed = pixel_change(mouth0, mouth1)
    assert changed > 0.03, f"only {changed:.1%} of the mouth region changed"
    still = pixel_change(forehead0, forehead1)
    assert still < 0.01, f"{still:.1%} of the forehead changed"

    # Undo from the Sculpt panel: the face returns.
    frame1 = nb.frame(0)
    nb.page.locator(".fwb-sculpt-undo").click()
    nb.wait_frame_after(0, frame1)
    nb.page.wait_for_timeout(300)
    st = _state(nb)
    assert st["undo"] == before_state["undo"]
    assert np.abs(np.array(st["offsets"])).max() == 0.0
    mouth2 = nb.screenshot("mouth-undone", clip=mouth_clip)
    back = pixel_change(mouth0, mouth2)
    assert back < 0.01, f"{back:.1%} of the mouth still differs after undo"
    status = nb.page.locator(".fwb-sculpt-status").inner_text()
    assert f"last drag {info['name']}" in status and "ms per update" in status, status


def test_symmetric_drag_then_shift_click_adds_and_alt_click_removes(open_notebook):
    nb = open_notebook(WORKBENCH_NB)
    info = _open_sculpt(nb)
    k, m = info["index"], info["mirror"]
    assert m >= 0, "the mouth-corner handle has no mirror"
    page = nb.page
    nb.kernel_eval(f"CORNER = {info['corner']}")
    page.locator(".fwb-symmetric").click()
    # the toggle's comm message reaches the kernel before this execute request
    assert nb.kernel_eval("import json; print(json.dumps(wb.viewport.symmetric))") is True
    before = _state(nb)
    mirror_vertex = before["vertices"][m]
    m0 = nb.project([mirror_vertex])[0]

    start = _handles_on_screen(nb)[k]
    frame0 = nb.frame(0)
    _drag(nb, start, (24.0, -20.0))
    nb.wait_frame_after(0, frame0)
    st = _wait_drag_closed(nb)
    nb.page.wait_for_timeout(300)
    nb.screenshot("page-symmetric")
    assert st["undo"] == [*before["undo"], f"Drag handle {info['name']}"]
    off = np.array(st["offsets"])
    np.testing.assert_array_equal(off[m], off[k] * np.array([-1.0, 1.0, 1.0]))
    assert np.abs(np.delete(off, [k, m], axis=0)).max() == 0.0
    # on screen the mirror corner moved left and up by about the same amount
    m1 = nb.project([mirror_vertex])[0]
    assert m1[0] < m0[0] - 10 and m1[1] < m0[1] - 8, (m0, m1)

    # Shift-click on the cheek, away from every handle: a mirrored pair is added.
    nb.page.mouse.move(5, 5)
    spot = nb.kernel_eval(
        """
import json, numpy as np
_V = np.asarray(model.evaluate())
_skin = np.flatnonzero(model.component_labels == model.component_names.index("skin"))
_hv = _V[model.handles.vertices]
_y0 = _V[CORNER, 1]  # the cheek: above the mouth corner, below the eye, front-facing
_c = _skin[(_V[_skin, 0] > 0.2) & (_V[_skin, 0] < 0.5) & (_V[_skin, 2] > 1.0)
           & (_V[_skin, 1] > _y0 + 0.05) & (_V[_skin, 1] < _y0 + 0.3)]
_gap = np.min(np.linalg.norm(_V[_c][:, None] - _hv[None], axis=2), axis=1)
print(json.dumps(int(_c[np.argmax(_gap)])))
"""
    )
    p = nb.project([spot])[0]
    n0 = len(st["vertices"])
    page.keyboard.down("Shift")
    page.mouse.click(p[0], p[1])
    page.keyboard.up("Shift")
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and len(_state(nb)["vertices"]) == n0:
        time.sleep(0.1)
    st = _state(nb)
    assert len(st["vertices"]) == n0 + 2, "Shift-click did not add a mirrored handle pair"
    assert st["undo"][-1].startswith("Add handle pair")
    # the new handle sits on the clicked spot (a vertex of the triangle under the pointer)
    added = nb.project([st["vertices"][n0]])[0]
    nb.screenshot("page-added")
    off = float(np.hypot(added[0] - p[0], added[1] - p[1]))
    assert off < 8.0, f"the new handle is drawn {off:.1f} px from the click"
    page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=n0 + 2,
    )
    page.mouse.move(5, 5)
    page.wait_for_timeout(300)
    nb.screenshot("page-added-markers")

    # Alt-click on the new marker removes it (and, symmetric, its mirror).
    q = _handles_on_screen(nb)[n0]
    page.keyboard.down("Alt")
    page.mouse.click(q[0], q[1])
    page.keyboard.up("Alt")
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and len(_state(nb)["vertices"]) != n0:
        time.sleep(0.1)
    st = _state(nb)
    assert len(st["vertices"]) == n0, "Alt-click did not remove the handle pair"
    assert st["undo"][-1].startswith("Remove handle pair")
    console = "\n".join(nb.console)
    assert "pageerror" not in console, console


# Marker colours (sRGB, widgets/js/src/viewport.js): idle, hovered, last dragged.
_MARKER_COLOURS = {"idle": (255, 140, 26), "hover": (255, 225, 77), "selected": (46, 230, 255)}


def _marker_colour(nb: NotebookPage, k: int) -> str:
    """The colour name nearest to the pixels at the centre of marker ``k``."""
    x, y, _ = _handles_on_screen(nb)[k]
    img = nb.screenshot(f"marker-{k}", clip={"x": x - 1, "y": y - 1, "width": 3, "height": 3})
    c = img.reshape(-1, 3).mean(axis=0)
    return min(_MARKER_COLOURS, key=lambda n: float(np.abs(c - _MARKER_COLOURS[n]).sum()))


def _wait_hover(nb: NotebookPage, k: int) -> None:
    nb.page.wait_for_function(
        "(k) => document.querySelector('.fwb-viewport').getAttribute('data-hover') === String(k)",
        arg=k,
        timeout=5000,
    )
    nb.page.wait_for_timeout(200)  # the render that shows it


def _hover(nb: NotebookPage, k: int) -> None:
    x, y, _ = _handles_on_screen(nb)[k]
    nb.page.mouse.move(x + 25, y)
    nb.page.mouse.move(x, y, steps=5)
    _wait_hover(nb, k)


def _selected(nb: NotebookPage) -> int:
    return int(nb.kernel_eval("import json; print(json.dumps(wb.viewport.selected_marker))"))


def test_marker_highlight_ends_when_the_pointer_leaves_or_the_tool_changes(open_notebook):
    nb = open_notebook(WORKBENCH_NB)
    info = _open_sculpt(nb)
    k, page = info["index"], nb.page
    assert _marker_colour(nb, k) == "idle"

    # Hovered: yellow. Leaving the view in one move (no pointer move lands on it on
    # the way out) ends the highlight.
    _hover(nb, k)
    assert _marker_colour(nb, k) == "hover"
    page.mouse.move(5, 5)
    _wait_hover(nb, -1)
    assert _marker_colour(nb, k) == "idle"

    # Dragged: cyan after the release (selected_marker) until the pointer leaves the view.
    x, y, _ = _handles_on_screen(nb)[k]
    _drag(nb, np.array([x, y]), (0.0, -15.0), steps=6)
    _wait_drag_closed(nb)
    assert _selected(nb) == k
    page.wait_for_timeout(300)
    assert _marker_colour(nb, k) == "selected"
    page.mouse.move(5, 5)
    deadline = time.monotonic() + 10
    while _selected(nb) != -1:
        assert time.monotonic() < deadline, "selected_marker was not cleared"
        time.sleep(0.1)
    page.wait_for_timeout(200)
    assert _marker_colour(nb, k) == "idle"

    # Hovered, then the tool changes under the resting pointer (here: from the kernel).
    _hover(nb, k)
    nb.kernel_eval('wb.viewport.tool = "orbit"')
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-tool') === 'orbit'"
    )
    _wait_hover(nb, -1)
    assert _marker_colour(nb, k) == "idle"
    assert nb.kernel_eval("import json; print(json.dumps(wb.errors.outputs == ()))") is True
