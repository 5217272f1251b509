"""The Rig tab (``widgets.RigStudio``) used with the mouse in a real JupyterLab + Chromium.

Template: the sample head; your face: the head re-triangulated and warped, in
centimetres (``tests/rig_faces.py``). With the mouse: click the left cheek on
the template, then the same point on the face (a mirrored pair appears on both),
orbit the template view (the face's view follows: the same direction and zoom,
no kernel message), press *Transfer shapes* (progress, then "52 shapes"), look
at the Report and Gallery tabs, undo the transfer and redo it from the studio's
buttons, and open the rig in the Workbench (a third viewport draws it). Each
step is checked in the kernel and on the pixels; screenshots in
``test-artifacts/<test>/``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from harness import NotebookPage, pixel_change, wait_until

TESTS = Path(__file__).resolve().parents[1]

_CELLS = [
    f"import sys, json\nsys.path.insert(0, {str(TESTS)!r})\nimport numpy as np\nimport workbench, widgets\n"
    "from rig_faces import Actor, WARP\nhead = workbench.load_sample('head')\nactor = Actor(head)",
    "studio = widgets.RigStudio(head, actor.model, height=340)\nstudio",
]

_FIND = """
import json, numpy as np
_skin = np.flatnonzero(head.component_labels == 0)
_V = head.vertices
# a left-cheek point well off the mid-plane, facing the camera
_a = int(_skin[np.argmax(_V[_skin, 0] * (_V[_skin, 2] > np.percentile(_V[_skin, 2], 80)))])
_b = int(np.argmin(np.linalg.norm(actor.model.vertices - WARP(_V[_a][None])[0], axis=1)))
print(json.dumps({"a": _a, "b": _b}))
"""

_STATE = """
import json
_s = studio.session
print(json.dumps({"landmarks": [list(p) for p in _s.landmarks], "pending": studio.landmarks.pending,
                  "done": list(_s.stages_done), "undo": _s.history.undo_labels,
                  "transfer_status": studio.stages.rows["transfer"].label.value,
                  "opened": studio.workbench is not None,
                  "dist_a": float(np.linalg.norm(head.vertices[_s.landmarks[0][0]] - head.vertices[A]))
                            if _s.landmarks else None,
                  "dist_b": float(np.linalg.norm(actor.model.vertices[_s.landmarks[0][1]] - actor.model.vertices[B]))
                            if _s.landmarks else None,
                  "errors": [o.get("text", "") for o in studio.errors.output.outputs]}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _markers(nb: NotebookPage, index: int) -> list[Any]:
    import json

    return json.loads(nb.viewport(index).get_attribute("data-markers") or "[]")


def test_click_pairs_orbit_linked_transfer_undo_and_open(open_notebook) -> None:
    nb = open_notebook(_CELLS, viewport_size=(1500, 1300))
    page = nb.page
    page.evaluate("() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }")
    nb.wait_viewports(2)
    found = nb.kernel_eval(_FIND)
    nb.kernel_eval(f"A, B = {found['a']}, {found['b']}")
    page.locator(".fwb-rig-template-view").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.mouse.move(5, 5)
    nb.screenshot("start")

    # ---- click the cheek on the template, then on the face: a mirrored pair on both
    at = nb.project([found["a"]], 0)[0]
    assert at[2] == 1, "the template point is not in view"
    page.mouse.click(at[0], at[1])
    st = wait_until("the pending template point", lambda: _state(nb), lambda s: s["pending"]["template"] is not None)
    assert st["landmarks"] == [] and not st["errors"], st
    bt = nb.project([found["b"]], 1)[0]
    assert bt[2] == 1, "the face point is not in view"
    page.mouse.click(bt[0], bt[1])
    st = wait_until("the pair", lambda: _state(nb), lambda s: len(s["landmarks"]) == 2)
    assert st["undo"] == [f"Landmark {st['landmarks'][0][0]} \u2194 {st['landmarks'][0][1]} (mirrored)"], st
    # the clicked vertices are the ones under the pointer (a few mm at most on a head of ~2.5 dm)
    assert st["dist_a"] < 0.08 and st["dist_b"] < 0.8, st
    wait_until("two markers on the template", lambda: _markers(nb, 0), lambda m: len(m) == 2)
    wait_until("two markers on the face", lambda: _markers(nb, 1), lambda m: len(m) == 2)
    marks = np.array(_markers(nb, 1))
    # the mirror marker is on the other side of the face
    assert abs(marks[0][0] - marks[1][0]) > 40, marks
    page.mouse.move(5, 5)
    nb.screenshot("pair")

    # ---- orbit the template view: the face's camera follows, no kernel message
    msgs0 = nb.kernel_eval("print(json.dumps(studio.landmarks.views['target'].frontend_msg_count))")
    face_before = nb.canvas_shot("face-before-orbit", 1)
    box = nb.canvas_box(0)
    cx, cy = box["x"] + box["width"] * 0.15, box["y"] + box["height"] * 0.85
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx + 120, cy - 10, steps=12)
    page.mouse.up()
    cam = wait_until("the linked cameras",
                 lambda: [nb.viewport(i).get_attribute("data-camera") for i in (0, 1)],
                 lambda c: c[0] is not None and c[0] == c[1])
    direction = np.array([float(x) for x in cam[0].split(",")[:3]])
    assert abs(direction[0]) > 0.3, f"the orbit did not turn the view: {cam}"
    face_after = wait_until("the face view to turn", lambda: nb.canvas_shot("face-after-orbit", 1),
                        lambda img: pixel_change(face_before, img) > 0.05)
    assert pixel_change(face_before, face_after) > 0.05
    msgs1 = nb.kernel_eval("print(json.dumps(studio.landmarks.views['target'].frontend_msg_count))")
    assert msgs1 == msgs0, "the linked orbit sent kernel messages"
    nb.screenshot("orbited")

    # ---- Transfer shapes: a progress bar, then the report line
    page.locator(".fwb-rig-transfer").scroll_into_view_if_needed()
    page.locator(".fwb-rig-transfer").click()
    st = wait_until("the transfer", lambda: _state(nb), lambda s: s["done"] == ["transfer"], timeout=120)
    assert "52 shapes" in st["transfer_status"] and not st["errors"], st
    wait_until("the status line", page.locator(".fwb-rig-transfer-status").inner_text, lambda t: "52 shapes" in t)
    nb.screenshot("transferred")

    # ---- Report and Gallery tabs
    page.locator(".fwb-rig-tabs .lm-TabBar-tab", has_text="Report").click()
    table = page.locator(".fwb-rig-report table")
    table.wait_for(state="visible")
    assert table.locator("tr").count() == 53
    nb.screenshot("report")
    page.locator(".fwb-rig-tabs .lm-TabBar-tab", has_text="Gallery").click()
    thumbs = page.locator(".fwb-rig-gallery img")
    wait_until("the gallery pictures", thumbs.count, lambda n: n >= 8)
    thumbs.first.wait_for(state="visible")
    gallery = nb.screenshot("gallery", clip=page.locator(".fwb-rig-gallery").bounding_box())
    assert gallery.std() > 20, "the gallery is blank"

    # ---- undo / redo the transfer with the studio's buttons: one step each way
    page.locator(".fwb-rig-undo").click()
    st = wait_until("the undo", lambda: _state(nb), lambda s: s["done"] == [])
    assert len(st["undo"]) == 1 and len(st["landmarks"]) == 2
    wait_until("the gallery to drop the column", thumbs.count, lambda n: n == 4)
    page.locator(".fwb-rig-redo").click()
    wait_until("the redo", lambda: _state(nb), lambda s: s["done"] == ["transfer"])

    # ---- Open in Workbench: a third viewport draws the rig
    page.locator(".fwb-rig-open").click()
    wait_until("the workbench", lambda: _state(nb), lambda s: s["opened"])
    nb.wait_viewports(3)
    wb = nb.viewport(2)
    wb.scroll_into_view_if_needed()
    page.mouse.move(5, 5)
    assert int(wb.get_attribute("data-vertex-count") or 0) == nb.kernel_eval(
        "print(json.dumps(actor.model.n_vertices))")
    shot = nb.canvas_shot("workbench", 2)
    assert shot.std() > 10, "the workbench view is blank"
    nb.screenshot("opened")
