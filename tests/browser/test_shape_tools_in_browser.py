"""Shape tools (split L/R) in the Shapes tab, in a real JupyterLab + Chromium.

Used with the mouse like a person: open the Workbench on the sample head, drag
the ``jawOpen`` slider to 1 (the Shape tools' dropdown follows the last
slider touched), press *Preview* (the face turns orange on the subject's left,
blue on the right), press *Split L/R*, then drag the new ``jawOpen_L`` slider
to 0 and undo twice from the panel. Each step is checked in the kernel (shape
names, weights, exact halves, undo labels) and in the pixels: the preview
colours both sides of the jaw, the split leaves the face as it was, closing
the left half moves the left side of the jaw and not the right one, and undo
opens the whole jaw again. Screenshots: ``test-artifacts/<test>/``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from harness import NotebookPage, clip_around, pixel_change, wait_until
from test_viewport import _drag_slider

_CELLS = [
    "import json\nimport numpy as np\nimport workbench, widgets\nmodel = workbench.load_sample('head')",
    "wb = widgets.show_workbench(model)",
]

# The skin vertices jawOpen moves most, on the subject's left (+x) and right
# (-x), both well outside the split band around x = 0.
_FIND = """
import json, numpy as np
_skin = model.component_labels == model.component_names.index("skin")
_V = np.asarray(model.vertices)
_d = np.linalg.norm(model.shape("jawOpen").delta, axis=1) * _skin
_big = _d > 0.3 * _d.max()
print(json.dumps({"left": [int(i) for i in np.flatnonzero(_big & (_V[:, 0] > 0.15))],
                  "right": [int(i) for i in np.flatnonzero(_big & (_V[:, 0] < -0.15))],
                  "band": model.shape_tools.default_falloff()}))
"""

_STATE = """
import json, numpy as np
_n = list(model.shape_names)
_split = "jawOpen_L" in _n
print(json.dumps({
    "names": [n for n in _n if n.startswith("jawOpen")],
    "weights": {n: model.weights[n] for n in _n if n.startswith("jawOpen")},
    "exact": bool(_split and np.array_equal(model.shape("jawOpen_L").delta + model.shape("jawOpen_R").delta,
                                             JAW)),
    "undo": model.history.undo_labels, "interacting": model.interacting,
    "previewing": wb.shape_tools.previewing, "selected": wb.shape_tools.selected,
    "colours": wb.viewport.vertex_colors is not None,
    "errors": [o.get("text", "") for o in wb.errors.outputs]}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _settled(nb: NotebookPage) -> dict[str, Any]:
    """Wait until the slider burst ended (its undo step is recorded)."""
    return wait_until(
        "the slider interaction to end", lambda: _state(nb), lambda s: not s["interacting"]
    )


def _drawn(nb: NotebookPage) -> None:
    """Wait until the view drew the kernel's newest geometry, then two more animation frames."""
    version = nb.kernel_eval("import json; print(json.dumps(wb.viewport._version))")
    nb.page.wait_for_function(
        "(v) => Number(document.querySelector('.fwb-viewport').getAttribute('data-version')) >= v",
        arg=version,
    )
    nb.page.evaluate(
        "() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))"
    )


def _mean_rgb(img: np.ndarray) -> np.ndarray:
    return img.reshape(-1, 3).astype(float).mean(axis=0)


def test_split_the_jaw_with_the_mouse_then_close_one_half(open_notebook) -> None:
    nb = open_notebook(_CELLS, viewport_size=(1600, 1200))
    page = nb.page
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    info = nb.kernel_eval(_FIND)
    nb.kernel_eval("JAW = model.shape('jawOpen').delta.copy()")
    assert len(info["left"]) >= 10 and len(info["right"]) >= 10, info

    # ---- open the jaw with the jawOpen slider (the Shape tools follow it)
    page.locator(".fwb-slider-jawOpen").evaluate("e => e.scrollIntoView({block: 'center'})")
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    frame0 = nb.frame(0)
    _drag_slider(nb, "jawOpen", 1.05)
    nb.wait_frame_after(0, frame0)
    st = _settled(nb)
    assert st["weights"] == {"jawOpen": 1.0}, st["weights"]
    assert st["selected"] == "jawOpen" and st["undo"] == ["Drag jawOpen"], st
    page.locator(".fwb-shape-tools-shape select").wait_for(state="visible")
    wait_until(
        "the dropdown to show jawOpen",
        lambda: page.locator(".fwb-shape-tools-shape select").input_value(),
        lambda v: v == "jawOpen",
    )
    page.mouse.move(5, 5)
    _drawn(nb)
    left_at = nb.project(info["left"])
    left_clip = clip_around(left_at, pad=6)
    right_clip = clip_around(nb.project(info["right"]), pad=6)
    left0 = nb.screenshot("left-jaw-open", clip=left_clip)
    right0 = nb.screenshot("right-jaw-open", clip=right_clip)
    nb.screenshot("page-open")

    # ---- Preview: the left side orange, the right one blue
    page.locator(".fwb-split-preview").click()
    wait_until("the preview", lambda: _state(nb), lambda s: s["previewing"] and s["colours"])
    left1 = wait_until(
        "the left jaw to be coloured",
        lambda: nb.screenshot("left-jaw-preview", clip=left_clip),
        lambda img: pixel_change(left0, img) > 0.5,
    )
    right1 = wait_until(
        "the right jaw to be coloured",
        lambda: nb.screenshot("right-jaw-preview", clip=right_clip),
        lambda img: pixel_change(right0, img) > 0.5,
    )
    lr, rr = _mean_rgb(left1), _mean_rgb(right1)
    assert lr[0] > lr[2] + 40, f"left jaw not orange: {lr}"
    assert rr[2] > rr[0] + 40, f"right jaw not blue: {rr}"
    nb.screenshot("page-preview")

    # ---- Split L/R with the mouse: one undo step, exact halves, the face as it was
    page.locator(".fwb-split").click()
    st = wait_until("the split", lambda: _state(nb), lambda s: "jawOpen_L" in s["names"])
    assert st["names"] == ["jawOpen_L", "jawOpen_R"], st["names"]
    assert st["weights"] == {"jawOpen_L": 1.0, "jawOpen_R": 1.0}
    assert st["exact"] and st["undo"] == ["Drag jawOpen", "Split jawOpen"], st
    assert not st["previewing"] and not st["colours"] and st["selected"] == "jawOpen_L"
    status = page.locator(".fwb-shape-tools-status")
    wait_until(
        "the status line",
        status.inner_text,
        lambda t: f"split jawOpen into jawOpen_L + jawOpen_R (band {info['band']:.3g} dm)" in t,
    )
    page.mouse.move(5, 5)
    _drawn(nb)
    for name, clip, before in (("left", left_clip, left0), ("right", right_clip, right0)):
        wait_until(
            f"the {name} jaw's own colours",
            lambda clip=clip, name=name: nb.screenshot(f"{name}-jaw-split", clip=clip),
            lambda img, before=before: pixel_change(before, img) < 0.01,
        )
    nb.screenshot("page-split")

    # ---- close the left half only: the left jaw moves, the right one does not
    page.locator(".fwb-slider-jawOpen_L").evaluate("e => e.scrollIntoView({block: 'center'})")
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    moved_on_screen = np.abs(nb.project(info["left"])[:, :2] - left_at[:, :2]).max()
    assert moved_on_screen < 1.0, "the head moved on screen: the clips no longer apply"
    frame1 = nb.frame(0)
    _drag_slider(nb, "jawOpen_L", -0.05)
    nb.wait_frame_after(0, frame1)
    st = _settled(nb)
    assert st["weights"] == {"jawOpen_L": 0.0, "jawOpen_R": 1.0}, st["weights"]
    assert st["undo"][-1] == "Drag jawOpen_L"
    page.mouse.move(5, 5)
    _drawn(nb)
    left2 = nb.screenshot("left-jaw-closed", clip=left_clip)
    right2 = nb.screenshot("right-jaw-closed", clip=right_clip)
    nb.screenshot("page-closed")
    moved, still = pixel_change(left0, left2), pixel_change(right0, right2)
    assert moved > 0.05, f"only {moved:.1%} of the left jaw changed"
    assert still < 0.01, f"{still:.1%} of the right jaw changed"

    # ---- undo twice from the panel: the open jaw of one jawOpen again
    page.locator(".fwb-undo").click()
    wait_until("the first undo", lambda: _state(nb), lambda s: s["undo"][-1] == "Split jawOpen")
    page.locator(".fwb-undo").click()
    st = wait_until("the second undo", lambda: _state(nb), lambda s: s["names"] == ["jawOpen"])
    assert st["weights"] == {"jawOpen": 1.0} and st["undo"] == ["Drag jawOpen"]
    page.mouse.move(5, 5)
    _drawn(nb)
    wait_until(
        "the left jaw open again",
        lambda: nb.screenshot("left-jaw-undone", clip=left_clip),
        lambda img: pixel_change(left0, img) < 0.01,
    )
    nb.screenshot("page-undone")
    assert _state(nb)["errors"] == []

    # ---- a corrective of jawOpen × mouthSmileLeft: read-only slider, badged, follows its drivers
    page.locator(".fwb-corrective-driver-a select").select_option("jawOpen")
    page.locator(".fwb-corrective-driver-b select").select_option("mouthSmileLeft")
    page.locator(".fwb-add-corrective").click()
    name = "jawOpen_mouthSmileLeft"
    wait_until(
        "the corrective",
        lambda: nb.kernel_eval(
            "import json; print(json.dumps(dict(model.shape_tools.correctives)))"
        ),
        lambda c: c == {name: ["jawOpen", "mouthSmileLeft"]},
    )
    badge = page.locator(f".fwb-corrective-badge-{name}")
    badge.wait_for(state="visible")
    assert badge.inner_text().strip() == "= jawOpen × mouthSmileLeft"
    slider = page.locator(f".fwb-slider-{name}")
    slider.evaluate("e => e.scrollIntoView({block: 'center'})")
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    assert slider.locator(".noUi-target[disabled]").count() == 1, (
        "the corrective's slider is not read-only"
    )
    readout = slider.locator(".widget-readout")
    assert readout.inner_text().strip() == "0.00"
    page.locator(".fwb-slider-mouthSmileLeft").evaluate("e => e.scrollIntoView({block: 'center'})")
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    _drag_slider(nb, "mouthSmileLeft", 0.5)
    _settled(nb)
    w = nb.kernel_eval(
        f"import json; print(json.dumps([model.weights['mouthSmileLeft'], model.weights['{name}']]))"
    )
    assert 0.3 < w[0] < 0.7 and w[1] == w[0], (
        w
    )  # jawOpen is at 1: the product is the smile's weight
    wait_until(
        "the corrective's readout",
        lambda: readout.inner_text().strip(),
        lambda t: t == f"{w[1]:.2f}",
    )
    slider.evaluate("e => e.scrollIntoView({block: 'center'})")
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.locator(".fwb-tabs").screenshot(path=str(nb.artifacts / "shapes-tab-corrective.png"))
    assert _state(nb)["errors"] == []
