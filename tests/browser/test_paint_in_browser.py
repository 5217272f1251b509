"""Painterly expression blending (Pighin et al. 1998 §4.2) in a real JupyterLab + Chromium.

The first test uses the mouse like a person: open the Workbench on the sample
head, go to the "Paint" tab, click the saved expression "smile"
(mouthSmileLeft + mouthSmileRight at 1) in the palette, and paint one stroke
over the left half of the mouth (press, several moves, release), aiming with
the viewport's projection hook. It checks the model in the kernel (one undo
step "Paint smile", weights > 0 under the stroke and 0 on the forehead, the
mouth vertices moved), the pixels (the mouth changed, with the weight overlay
and without it; the forehead did not), and that Undo from the panel restores
the face. The second test builds the paper's Figure 7 "debauched smile" from
Python in the notebook (smile on the mouth, a half-opacity "sleepy" blink on
the lids, an outer brow raise on one side), saves it as an expression and
checks that it appears in the palette. Screenshots: ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from harness import NotebookPage, clip_around, pixel_change

_CELLS = [
    """import json
import numpy as np
import workbench, widgets
from workbench.methods.paint.painting import Brush

model = workbench.load_sample("head")
# "smile" = both smile shapes at 1, saved as an expression (a palette colour)
model.set_weights({"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0})
model.expressions.save("smile")
model.reset_weights()
""",
    "wb = widgets.show_workbench(model)",
]

# Mouth: the skin vertices the smile moves most; the stroke runs from the left
# mouth corner (largest x among them) to the middle of the upper lip (x ~ 0).
# Forehead: front-facing skin well above the brows.
_FIND = """
import json, numpy as np
_skin = model.component_labels == model.component_names.index("skin")
_V = np.asarray(model.vertices)
_d = np.linalg.norm(model.expressions["smile"].displacement, axis=1) * _skin
_top = np.argsort(-_d)[:60]
_left = _top[_V[_top, 0] > 0]
_corner = int(_left[np.argmax(_V[_left, 0])])
_mid = int(_top[np.argmin(np.abs(_V[_top, 0]) + 0.5 * np.abs(_V[_top, 1] - _V[_corner, 1]))])
_path = [_corner, _mid]
_brow = np.argsort(-np.linalg.norm(model.shape("browInnerUp").delta, axis=1) * _skin)[:20]
_by = _V[_brow, 1].mean()
_front = _skin & (np.abs(_V[:, 0]) < 0.35) & (_V[:, 2] > _V[_skin, 2].max() - 0.35)
_fh = np.flatnonzero(_front & (_V[:, 1] > _by + 0.2) & (_V[:, 1] < _by + 0.5))
print(json.dumps({"corner": _corner, "mid": _mid, "mouth": [int(i) for i in _top],
                  "forehead": [int(i) for i in _fh[::3]]}))
"""

_STATE = """
import json, numpy as np
_w = model.paint.get("smile")
print(json.dumps({"undo": model.history.undo_labels, "interacting": model.interacting,
                  "painting": wb.viewport.stroking,
                  "weights": None if _w is None else np.asarray(_w, float).tolist(),
                  "moved": np.linalg.norm(model.evaluate() - model.vertices.astype(np.float32),
                                          axis=1).tolist()}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _open_paint(nb: NotebookPage) -> None:
    """Collapse the sidebar, open the Paint tab, wait for the palette."""
    page = nb.page
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Paint").click()
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-tool') === 'paint'"
    )
    # the palette is built (thumbnails rendered offscreen) when the tab first opens
    page.locator(".fwb-paint-palette .fw-thumb-button").first.wait_for(timeout=60_000)


def _wait_stroke_closed(nb: NotebookPage, timeout: float = 10.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    st = _state(nb)
    while (st["interacting"] or st["painting"]) and time.monotonic() < deadline:
        time.sleep(0.1)
        st = _state(nb)
    assert not st["interacting"] and not st["painting"], "the paint stroke never ended"
    return st


def test_pick_smile_in_the_palette_paint_the_mouth_then_undo(open_notebook):
    nb = open_notebook(_CELLS)
    _open_paint(nb)
    page = nb.page
    info = nb.kernel_eval(_FIND)
    before = _state(nb)
    assert before["weights"] is None

    # Pick "smile" by clicking its thumbnail button in the palette.
    tile = page.locator(".fwb-paint-palette .fw-thumb-button", has_text="★ smile")
    tile.click()
    deadline = time.monotonic() + 10
    picked = None
    while time.monotonic() < deadline:
        picked = nb.kernel_eval("import json; print(json.dumps(wb.viewport.tools['paint'].expression))")
        if picked == "smile":
            break
        time.sleep(0.1)
    assert picked == "smile"
    assert "painting with <b>smile</b>" in nb.kernel_eval(
        "import json; print(json.dumps(wb.paint.picked.value))"
    )
    # A 1.5 cm soft brush at full opacity (the model is in decimetres).
    nb.kernel_eval("wb.paint.radius.value = 0.15; wb.paint.opacity.value = 1.0")

    page.locator(".fwb-viewport").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.mouse.move(5, 5)
    page.wait_for_timeout(300)
    mouth_clip = clip_around(nb.project(info["mouth"]), pad=40)
    forehead_clip = clip_around(nb.project(info["forehead"]), pad=10)
    mouth0 = nb.screenshot("mouth-before", clip=mouth_clip)
    forehead0 = nb.screenshot("forehead-before", clip=forehead_clip)
    nb.screenshot("page-before")

    # One stroke: press on the left mouth corner, move to the middle of the lip, release.
    corner, mid = nb.project([info["corner"], info["mid"]])
    assert corner[2] == 1 and mid[2] == 1
    frame0 = nb.frame(0)
    page.mouse.move(corner[0], corner[1])
    page.mouse.down()
    for f in np.linspace(0.0, 1.0, 12)[1:]:
        page.mouse.move(corner[0] + f * (mid[0] - corner[0]), corner[1] + f * (mid[1] - corner[1]))
        page.wait_for_timeout(30)
    page.mouse.up()
    nb.wait_frame_after(0, frame0)
    st = _wait_stroke_closed(nb)
    page.wait_for_timeout(300)
    nb.screenshot("page-stroke-cursor")

    # The model: exactly one undo step for the whole stroke ...
    assert st["undo"] == [*before["undo"], "Paint smile"]
    w = np.array(st["weights"])
    # ... paint under the stroke, none on the forehead ...
    # (the lip-line vertex can sit in the lip crease, a little off the dabs along the surface)
    assert w[info["corner"]] > 0.5 and w[info["mid"]] > 0.1, (w[info["corner"]], w[info["mid"]])
    assert w[info["forehead"]].max() == 0.0
    # ... and the painted face moved at the mouth (toward the saved smile), not the forehead.
    moved = np.array(st["moved"])
    assert moved[info["corner"]] > 0.05, moved[info["corner"]]
    assert moved[info["forehead"]].max() == 0.0
    stats = nb.viewport(0).evaluate("e => e.fwbStrokeStats.length")
    assert stats >= 2, f"only {stats} paint messages were acknowledged"

    page.mouse.move(5, 5)  # hides the brush cursor
    page.wait_for_timeout(300)
    mouth1 = nb.screenshot("mouth-after-overlay", clip=mouth_clip)
    forehead1 = nb.screenshot("forehead-after", clip=forehead_clip)
    nb.screenshot("page-after-overlay")
    changed = pixel_change(mouth0, mouth1)
    assert changed > 0.05, f"only {changed:.1%} of the mouth region changed"
    still = pixel_change(forehead0, forehead1)
    assert still < 0.01, f"{still:.1%} of the forehead changed"

    # Overlay off (the toggle in the panel): the geometry alone still changed the mouth.
    pv = int(nb.viewport(0).get_attribute("data-tint-version") or 0)
    page.locator(".fwb-paint-overlay").click()
    page.wait_for_function(
        "(v) => Number(document.querySelector('.fwb-viewport')"
        ".getAttribute('data-tint-version')) > v",
        arg=pv,
    )
    page.wait_for_timeout(300)
    mouth2 = nb.screenshot("mouth-after-geometry", clip=mouth_clip)
    nb.screenshot("page-after-geometry")
    geo = pixel_change(mouth0, mouth2)
    assert geo > 0.02, f"only {geo:.1%} of the mouth changed without the overlay"
    assert pixel_change(mouth1, mouth2) > 0.02, "the overlay toggle changed nothing"

    # Undo from the Paint panel: the face returns.
    frame1 = nb.frame(0)
    page.locator(".fwb-paint-undo").click()
    nb.wait_frame_after(0, frame1)
    page.wait_for_timeout(300)
    st = _state(nb)
    assert st["undo"] == before["undo"] and st["weights"] is None
    mouth3 = nb.screenshot("mouth-undone", clip=mouth_clip)
    back = pixel_change(mouth0, mouth3)
    assert back < 0.01, f"{back:.1%} of the mouth still differs after undo"
    status = page.locator(".fwb-paint-status").inner_text()
    assert "last stroke smile" in status and "ms per dab" in status, status
    console = "\n".join(nb.console)
    assert "pageerror" not in console, console


_DEBAUCHED = """
import json, numpy as np
from workbench.methods.paint.expressions import expression_displacement
_skin = model.component_labels == model.component_names.index("skin")
def _top(name, k, side=None):
    d = np.linalg.norm(expression_displacement(model, name), axis=1) * _skin
    ids = np.argsort(-d)[:k]
    return [int(i) for i in ids if side is None or side * model.vertices[i, 0] > 0]
_soft = Brush(radius=0.15, opacity=1.0, falloff="smooth")
# 1. a smile on the mouth (both corners: mirror painting)
model.paint_stroke("smile", _top("smile", 40, +1)[:6], Brush(0.15, 1.0, "smooth", mirror=True))
# 2. a partial "sleepy" look: one half-opacity dab of blink on each lid
model.paint_stroke("eyeBlinkLeft", _top("eyeBlinkLeft", 1), Brush(0.12, 0.5, "smooth"))
model.paint_stroke("eyeBlinkRight", _top("eyeBlinkRight", 1), Brush(0.12, 0.5, "smooth"))
# 3. a raised outer brow on one side only
model.paint_stroke("browOuterUpLeft", _top("browOuterUpLeft", 6), _soft)
model.expressions.save("debauched")
_W = model.paint
print(json.dumps({"undo": model.history.undo_labels[-5:],
                  "painted": sorted(_W),
                  "max_total": float(_W.total(model.n_vertices).max()),
                  "palette": wb.paint.gallery.names[:3],
                  "lids": float(np.max(_W["eyeBlinkLeft"])),
                  "brow_right": float(np.max(_W["browOuterUpLeft"][model.vertices[:, 0] < -0.3]))}))
"""


def test_debauched_smile_from_python_appears_in_the_palette(open_notebook):
    nb = open_notebook(_CELLS)
    _open_paint(nb)
    res = nb.kernel_eval(_DEBAUCHED)
    assert res["undo"] == [
        "Paint smile",
        "Paint eyeBlinkLeft",
        "Paint eyeBlinkRight",
        "Paint browOuterUpLeft",
        "Save expression debauched",
    ]
    assert res["painted"] == ["browOuterUpLeft", "eyeBlinkLeft", "eyeBlinkRight", "smile"]
    assert res["max_total"] <= 1.0 + 1e-6  # convex per vertex
    assert abs(res["lids"] - 0.5) < 1e-6  # partial: one dab at opacity 0.5
    assert res["brow_right"] == 0.0  # one side only
    # saved expressions come first in the palette
    assert res["palette"][:2] == ["smile", "debauched"]
    page = nb.page
    tile = page.locator(".fwb-paint-palette .fw-thumb-button", has_text="★ debauched")
    tile.wait_for(timeout=30_000)
    tile.scroll_into_view_if_needed()
    page.wait_for_timeout(300)
    nb.screenshot("palette-with-debauched", clip=page.locator(".fwb-paint-palette").bounding_box())
    page.locator(".fwb-viewport").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.mouse.move(5, 5)
    page.wait_for_timeout(300)
    nb.screenshot("page-debauched")
    # picking it in the palette makes it the brush's colour
    tile.click()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        if nb.kernel_eval("import json; print(json.dumps(wb.viewport.tools['paint'].expression))") == (
            "debauched"
        ):
            break
        time.sleep(0.1)
    assert nb.kernel_eval("import json; print(json.dumps(wb.viewport.tools['paint'].expression))") == (
        "debauched"
    )
