"""Erasing an example's wrinkles with the brush (Bickel et al. 2008 §6 paint-out) in a real browser.

A notebook opens the Workbench on the ~20k-vertex sample head (the forehead
furrows span several triangles there), fits the wrinkle layer and views the
"brow_raise" example (its forehead furrows show). Like a person, the test then
clicks **Erase wrinkles** on the brow_raise card of the Sculpt tab, paints one
stroke across the furrows with the mouse (press, moves, release) and checks

* the UI: the viewport switched to its paint tool (brush cursor) while the
  Sculpt tab stays open, and the stroke's mask is drawn as the magenta
  overlay while painting (and gone after the release);
* the kernel: exactly one undo step "Erase wrinkles of brow_raise", no paint
  layer, the detail under the stroke is gone and the detail the brush did not
  reach is kept;
* the pixels: the forehead changed; Undo in the top bar brings the furrows
  back exactly (details bit-exact, pixels as before).

Screenshots: ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import itertools
import json
import time
from typing import Any

import numpy as np
from harness import NotebookPage, clip_around, pixel_change

CELLS = [
    """
import json
import numpy as np
import widgets, workbench
model = workbench.load_sample("head", resolution="25k")
wb = widgets.Workbench(model, height=760)
wb.tabs.selected_index = 1  # Sculpt
wb.wrinkles.fit()
wb.wrinkles.view_example("brow_raise")
wb.wrinkles.show_graph.value = False  # the forehead pixels without the feature-graph lines
wb
""",
]

# The furrows: the skin vertices with the most detail at the brow_raise pose. The stroke
# runs across them from the subject's right to left, through one vertex per x-bin
# (the one nearest to their median height).
_FIND = """
_d = np.linalg.norm(model.wrinkles.details(), axis=1)
_top = np.argsort(-_d)[:300]
_V = np.asarray(model.vertices)
_ym = np.median(_V[_top, 1])
_edges = np.linspace(_V[_top, 0].min(), _V[_top, 0].max(), 10)
_path = []
for _a, _b in zip(_edges[:-1], _edges[1:]):
    _in = _top[(_V[_top, 0] >= _a) & (_V[_top, 0] <= _b)]
    if _in.size:
        _path.append(int(_in[np.argmin(np.abs(_V[_in, 1] - _ym))]))
print(json.dumps({"furrows": [int(i) for i in _top], "path": _path}))
"""

_STATE = """
_d = model.wrinkles.details()
_n = np.zeros(model.n_vertices) if _d is None else np.linalg.norm(_d, axis=1)
_e = wb.wrinkles.eraser
_m = None if _e is None or _e.last_mask is None else np.asarray(_e.last_mask)
_f = np.asarray(FURROWS)
print(json.dumps({
    "undo": model.history.undo_labels,
    "erasing": wb.wrinkles.erasing,
    "tab": wb.tabs.selected_index,
    "tool": wb.viewport.tool,
    "painted": len(model.paint),
    "interacting": model.interacting,
    "detail": _n.tolist(),
    "furrow_detail": float(_n[_f].sum()),
    "mask": None if _m is None else _m.tolist(),
    "errors": [o.get("text", "") for o in wb.errors.outputs],
    "wrinkle_errors": wb.wrinkles.error_line.value,
}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _wait(nb: NotebookPage, pred: str, timeout: float = 20.0) -> None:
    """Wait until the kernel expression ``pred`` is true."""
    deadline = time.monotonic() + timeout
    while not nb.kernel_eval(f"print(json.dumps(bool({pred})))"):
        assert time.monotonic() < deadline, f"kernel never reached {pred}"
        time.sleep(0.1)


def test_erase_the_brow_raise_furrows_with_the_brush_then_undo(open_notebook) -> None:
    nb = open_notebook(CELLS, viewport_size=(1600, 1300))
    page = nb.page
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    page.wait_for_function(
        "() => document.querySelectorAll('.fwb-wrinkle-card').length >= 6", timeout=120_000
    )
    info = nb.kernel_eval(_FIND)
    nb.kernel_eval(f"FURROWS = {info['furrows']}")
    path = info["path"]
    assert len(path) >= 6, path
    nb.kernel_eval("wb.wrinkles.erase_radius.value = 0.25")  # 2.5 cm (decimetres)

    # --- The brow_raise card's toggle: the paint tool brushes, the Sculpt tab stays
    toggle = page.locator(".fwb-wrinkle-card", has_text="brow_raise").locator(".fwb-wrinkle-erase")
    toggle.click()
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-tool') === 'paint'"
    )
    _wait(nb, "wb.wrinkles.erasing == 'brow_raise'")
    assert page.locator(".fwb-wrinkle-erase-note").inner_text().startswith("Erasing brow_raise")

    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.mouse.move(5, 5)
    page.wait_for_timeout(400)
    before = _state(nb)
    assert before["tab"] == 1 and before["tool"] == "paint", before
    assert before["errors"] == [] and before["painted"] == 0
    d0 = np.array(before["detail"])
    assert d0[info["furrows"]].max() > 0.001  # > 0.1 mm furrows to erase
    pts = nb.project(path)
    assert (pts[:, 2] == 1).all(), "the forehead is not in front of the camera"
    forehead_clip = clip_around(nb.project(info["furrows"]), pad=30)
    band_clip = clip_around(pts, pad=25)  # along the stroke
    fh0 = nb.screenshot("forehead-before", clip=forehead_clip)
    band0 = nb.screenshot("band-before", clip=band_clip)
    nb.screenshot("page-before")

    # --- One stroke across the furrows
    pv0 = int(nb.viewport(0).get_attribute("data-tint-version") or 0)
    frame0 = nb.frame(0)
    page.mouse.move(pts[0, 0], pts[0, 1])
    page.mouse.down()
    for a, b in itertools.pairwise(pts):
        for f in np.linspace(0.0, 1.0, 4)[1:]:
            page.mouse.move(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))
            page.wait_for_timeout(25)
    page.wait_for_timeout(400)  # the last dab's overlay patch
    # while painting: the stroke's mask is the magenta overlay, nothing is edited yet
    assert int(nb.viewport(0).get_attribute("data-tint-version") or 0) > pv0
    nb.screenshot("forehead-mask-while-painting", clip=forehead_clip)
    assert len(_state(nb)["undo"]) == len(before["undo"])
    page.mouse.up()
    _wait(nb, f"len(model.history.undo_labels) == {len(before['undo']) + 1}")
    nb.wait_frame_after(0, frame0)
    page.mouse.move(5, 5)  # hides the brush cursor
    page.wait_for_timeout(600)

    st = _state(nb)
    assert st["undo"] == [*before["undo"], "Erase wrinkles of brow_raise"], st["undo"]
    assert st["errors"] == [] and st["wrinkle_errors"] == "", st["errors"]
    assert st["painted"] == 0 and not st["interacting"]
    assert st["erasing"] == "brow_raise" and st["tab"] == 1  # still erasing, same tab
    d1, mask = np.array(st["detail"]), np.array(st["mask"])
    under, untouched = mask >= 0.9, mask == 0  # (the brush's smooth falloff: 0.9 within 0.23 r)
    # the detail the brush did not reach is kept (the refit moves it a little)
    keep = untouched & (d0 > 0.2 * d0.max())
    kept = float(np.median(d1[keep] / d0[keep])) if keep.any() else 0.0
    nb.artifacts.mkdir(parents=True, exist_ok=True)
    (nb.artifacts / "erase.json").write_text(
        json.dumps(
            {
                "under_brush": int(under.sum()),
                "masked": int((mask > 0).sum()),
                "under_max_before_after": [float(d0[under].max()), float(d1[under].max())],
                "furrow_detail_before_after": [before["furrow_detail"], st["furrow_detail"]],
                "kept_ratio": kept,
            },
            indent=1,
        )
    )
    assert under.sum() > 50, under.sum()
    assert d1[under].max() < 0.1 * d0[under].max(), (d1[under].max(), d0[under].max())
    assert kept > 0.7, kept
    assert st["furrow_detail"] < 0.6 * before["furrow_detail"], (
        st["furrow_detail"],
        before["furrow_detail"],
    )
    pv = int(nb.viewport(0).get_attribute("data-tint-version") or 0)
    assert pv > pv0  # the overlay went with the stroke (an empty one was sent)
    fh1 = nb.screenshot("forehead-erased", clip=forehead_clip)
    band1 = nb.screenshot("band-erased", clip=band_clip)
    nb.screenshot("page-erased")
    # The reference: the same pose with wrinkles switched off (checkbox; an undo step).
    box = page.locator(".fwb-wrinkles-on input")
    box.click()
    _wait(nb, "not model.wrinkles.enabled")
    page.wait_for_timeout(600)
    band_off = nb.screenshot("band-wrinkles-off", clip=band_clip)
    frame2 = nb.frame(0)
    page.locator(".fwb-wb-undo").click()  # undoes "Wrinkles off"
    _wait(nb, "model.wrinkles.enabled")
    nb.wait_frame_after(0, frame2)
    page.wait_for_timeout(600)
    # furrow shading is a few grey levels: count pixels changed by more than 6 of 255
    changed = pixel_change(band0, band1, threshold=6)
    furrows_left = pixel_change(band_off, band1, threshold=6)
    furrows_before = pixel_change(band_off, band0, threshold=6)
    (nb.artifacts / "pixels.json").write_text(
        json.dumps(
            {
                "band_changed": changed,
                "forehead_changed": pixel_change(fh0, fh1, threshold=6),
                "band_vs_off_before": furrows_before,
                "band_vs_off_after": furrows_left,
            }
        )
    )
    assert changed > 0.02, f"only {changed:.1%} of the stroke's band changed"
    # ... to what the face looks like without wrinkles there (before: the furrows)
    assert furrows_before > 0.02, furrows_before
    assert furrows_left < 0.005, f"{furrows_left:.1%} of the band still differs from no wrinkles"

    # --- Undo (top bar): the furrows come back exactly
    frame1 = nb.frame(0)
    page.locator(".fwb-wb-undo").click()
    _wait(nb, f"len(model.history.undo_labels) == {len(before['undo'])}")
    nb.wait_frame_after(0, frame1)
    page.wait_for_timeout(600)
    st = _state(nb)
    np.testing.assert_array_equal(np.array(st["detail"]), d0)
    fh2 = nb.screenshot("forehead-undone", clip=forehead_clip)
    back = max(
        pixel_change(fh0, fh2, threshold=6),
        pixel_change(band0, nb.screenshot("band-undone", clip=band_clip), threshold=6),
    )
    assert back < 0.005, f"{back:.1%} of the forehead still differs after undo"

    # --- Untoggle: the sculpt tool comes back
    toggle.click()
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-tool') === 'sculpt'"
    )
    _wait(nb, "wb.wrinkles.erasing is None")
    console = "\n".join(nb.console)
    assert "pageerror" not in console, console
