"""The Enhance tab with the mouse in a real JupyterLab + Chromium.

The workbench opens on the 5k sample head with a smile keyed at 0.5 s. With
the mouse: open the Enhance tab, press *Build database* (the procedural
performance one subdivision finer: a progress bar, then the database line),
tick *Enhanced preview* in the top bar over the viewport (the detail appears on the face: pixels around the
mouth and eyes change, the kernel's layer is on), press *Undo* in the top bar
(the box unticks, the pixels go back), redo from Python, then *Bake enhanced
take* to a .pc2 (the status names the frames and s/frame; the file holds every
frame at the database's resolution). Screenshots in ``test-artifacts/<test>/``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from harness import NotebookPage, wait_until

_CELLS = [
    "import json, numpy as np, tempfile, pathlib\nimport workbench, widgets\n"
    "model = workbench.load_sample('head')\n"
    "SMILE = {'mouthSmileLeft': 1.0, 'mouthSmileRight': 1.0, 'cheekSquintLeft': 0.5, 'cheekSquintRight': 0.5,"
    " 'browInnerUp': 0.8}\n"
    "for t, w in ((0.0, dict.fromkeys(SMILE, 0.0)), (0.5, SMILE)):\n"
    "    model.set_weights(w); model.timeline.key_weights(t, list(w))\n"
    "model.set_time(0.5)\n"
    "d = pathlib.Path(tempfile.mkdtemp())",
    "wb = widgets.show_workbench(model)\nwb.enhance.n_frames.value = 24",
]

_STATE = """
import json
_e = wb.enhance
_db = model.enhance.database
print(json.dumps({
    "db": None if _db is None else int(_db.neutral_.shape[0]), "preview": model.enhance.preview,
    "box": bool(_e.preview.value), "undo": model.history.undo_labels, "status": _e.progress.label.value,
    "shown": float(abs(model.layer_displacement('enhance')).max()),
    "errors": [o.get("text", "") for o in wb.errors.outputs]}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def test_build_preview_undo_and_bake_with_the_mouse(open_notebook) -> None:
    nb = open_notebook(_CELLS, viewport_size=(1500, 1200))
    page = nb.page
    page.evaluate("() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }")
    nb.wait_viewports(1)
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Enhance").click()
    # the Enhanced preview box sits in the top bar over the viewport (and in the Enhance tab: one widget)
    box = page.locator(".fwb-topbar .fwb-enhance-preview input")
    tab_box = page.locator(".fwb-tabs .fwb-enhance-preview input")
    assert box.is_disabled() and tab_box.is_disabled()  # no database yet

    # ---- Build database: progress, then the database line
    page.locator(".fwb-enhance-build").click()
    st = wait_until("the database", lambda: _state(nb), lambda s: s["db"] or s["errors"], timeout=180)
    assert st["db"] and st["db"] > 18000 and not st["errors"], st
    wait_until("the info line", page.locator(".fwb-enhance-info").inner_text,
               lambda t: "procedural performance" in t and "loop" in t)
    wait_until("the box to be enabled", box.is_enabled, bool)
    page.mouse.move(5, 5)
    plain = nb.canvas_shot("database built")

    # ---- tick the Enhanced preview: the face changes on screen
    frame = nb.frame(0)
    box.click()
    st = wait_until("the preview", lambda: _state(nb), lambda s: s["preview"])
    assert st["box"] and st["shown"] > 1e-3 and st["undo"][-1] == "Enhanced preview on", st
    wait_until("the tab's view of the box", tab_box.is_checked, bool)
    nb.wait_frame_after(0, frame)
    page.mouse.move(5, 5)
    enhanced = wait_until("the enhanced pixels", lambda: nb.canvas_shot("enhanced"),
                          lambda img: np.abs(img.astype(int) - plain.astype(int)).max(axis=2).__gt__(30).sum() > 50)
    changed = np.abs(enhanced.astype(int) - plain.astype(int)).max(axis=2) > 30
    assert changed.sum() < 0.5 * changed.size  # detail, not a different face

    # ---- Undo from the top bar: the box unticks and the picture comes back
    frame = nb.frame(0)
    page.locator(".fwb-wb-undo").click()
    st = wait_until("the undo", lambda: _state(nb), lambda s: not s["preview"])
    wait_until("the box to untick", box.is_checked, lambda v: not v)
    nb.wait_frame_after(0, frame)
    page.mouse.move(5, 5)
    back = wait_until("the plain pixels", lambda: nb.canvas_shot("undone"),
                      lambda img: (np.abs(img.astype(int) - plain.astype(int)).max(axis=2) > 30).sum() < 20)
    assert back.shape == plain.shape
    nb.kernel_eval("model.redo()\nprint(json.dumps(model.enhance.preview))")
    wait_until("the box to tick again", box.is_checked, bool)

    # ---- Bake to a point cache at the database's resolution
    path = nb.kernel_eval("print(json.dumps(str(d / 'enhanced.pc2')))")
    page.locator(".fwb-enhance-bake-path input").fill(path)
    page.locator(".fwb-enhance-bake").click()
    wait_until("the bake", page.locator(".fwb-enhance-status").inner_text, lambda t: "s/frame" in t, timeout=180)
    nb.screenshot("baked")
    points = nb.kernel_eval(
        "import struct\n_b = (d / 'enhanced.pc2').read_bytes()\n"
        "print(json.dumps(list(struct.unpack_from('<12siiffi', _b, 0)[2::3])))")
    assert points[0] == st["db"] and points[1] == len(nb.kernel_eval(
        "print(json.dumps(list(model.tracks.frame_times())))"))
    assert _state(nb)["errors"] == []
