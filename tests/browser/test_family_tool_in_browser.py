"""A method family's own viewport tool, used with the mouse in a real browser (issue #27).

The worked example's family (``tests/example_family/mouth_gain``, installed as a
user would: a package that names its family in the entry-point group) registers
a ``"gain_brush"`` stroke tool in its own folder; neither the viewport's Python
nor its JavaScript names it. A notebook puts that package on the kernel's path,
opens a viewport of the sample head and picks the tool. Like a person, the test
then paints one stroke across the lower lip with the mouse and checks

* the page: the tool is a brush there (``data-tool``, the brush cursor), the
  stroke's messages are acknowledged, and the mask is drawn as the magenta
  surface tint (the pixels under the stroke change);
* the kernel: exactly one undo step "Brush mouth gain mask", the brushed
  vertices are in the mask and the far side of the face is not; Undo clears the
  mask and the tint goes with it.

Screenshots: ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import itertools
import json
import os
from typing import Any

import numpy as np
from example_family.install import install
from harness import NotebookPage, clip_around, pixel_change, wait_until

_SETUP = """
import sys
sys.path.insert(0, {site!r})  # the installed package (its .dist-info names the family)
import json
import numpy as np
import widgets, workbench
model = workbench.load_sample("head")
vp = widgets.Viewport(model, height=640)
vp.tool = "gain_brush"
vp
"""

# The lower lip and chin: the vertices jawOpen moves most, facing the camera; the stroke runs
# across them through one vertex per x-bin (the one nearest their median height).
_FIND = """
_d = np.linalg.norm(model.shape("jawOpen").delta, axis=1)
_V = np.asarray(model.vertices)
_top = np.argsort(-_d)[:400]
_ym = np.median(_V[_top, 1])
_edges = np.linspace(np.percentile(_V[_top, 0], 10), np.percentile(_V[_top, 0], 90), 8)
_path = []
for _a, _b in zip(_edges[:-1], _edges[1:]):
    _in = _top[(_V[_top, 0] >= _a) & (_V[_top, 0] <= _b)]
    if _in.size:
        _path.append(int(_in[np.argmin(np.abs(_V[_in, 1] - _ym))]))
_far = int(np.argmax(_V[:, 1]))  # the top of the head: the brush never gets there
print(json.dumps({"path": _path, "far": _far}))
"""

_STATE = """
_m = model.slot("mouth_gain").mask
print(json.dumps({
    "undo": model.history.undo_labels,
    "mask": None if _m is None else np.flatnonzero(_m > 0).tolist(),
    "tool": vp.tool,
    "target": vp.stroke_target,
    "interacting": model.interacting,
    "stroking": vp.stroking,
    "error": vp._error,
}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _wait(nb: NotebookPage, pred: str, timeout: float = 30.0) -> None:
    """Wait until the kernel expression ``pred`` is true."""
    wait_until(pred, lambda: nb.kernel_eval(f"print(json.dumps(bool({pred})))"), bool, timeout)


def test_a_family_tool_paints_with_the_mouse_and_undoes(open_notebook, tmp_path) -> None:
    site = install(tmp_path)["PYTHONPATH"].split(os.pathsep)[0]
    nb = open_notebook([_SETUP.format(site=site)], viewport_size=(1400, 1000))
    page = nb.page
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    page.wait_for_function(
        "() => document.querySelector('.fwb-viewport').getAttribute('data-tool') === 'gain_brush'"
    )
    nb.viewport(0).scroll_into_view_if_needed()
    page.mouse.move(5, 5)
    page.wait_for_timeout(400)
    before = _state(nb)
    assert before["tool"] == "gain_brush" and before["target"] == "mouth gain mask", before
    assert before["mask"] is None and before["error"] == "", before

    info = nb.kernel_eval(_FIND)
    path = info["path"]
    assert len(path) >= 5, path
    pts = nb.project(path)
    assert (pts[:, 2] == 1).all(), "the lip is not in front of the camera"
    chin = clip_around(pts, pad=30)
    shot0 = nb.screenshot("chin-before", clip=chin)

    # --- One stroke across the chin
    frame0 = nb.frame(0)
    page.mouse.move(pts[0, 0], pts[0, 1])
    page.mouse.down()
    for a, b in itertools.pairwise(pts):
        for f in np.linspace(0.0, 1.0, 5)[1:]:
            page.mouse.move(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))
            page.wait_for_timeout(25)
    page.mouse.up()
    _wait(nb, f"len(model.history.undo_labels) == {len(before['undo']) + 1}")
    _wait(nb, "not vp.stroking")
    nb.wait_frame_after(0, frame0)
    page.mouse.move(5, 5)  # hides the brush cursor
    page.wait_for_function(
        "() => Number(document.querySelector('.fwb-viewport').getAttribute('data-stroke-updates') || 0) > 0"
    )
    page.wait_for_timeout(500)
    st = _state(nb)
    assert st["undo"] == [*before["undo"], "Brush mouth gain mask"], st["undo"]
    assert not st["interacting"] and st["error"] == "", st
    mask = set(st["mask"] or [])
    assert len(mask) >= 3 and info["far"] not in mask, (len(mask), info["far"])
    # the dabs are the vertices under the pointer: near the path, on the chin
    near = nb.kernel_eval(
        f"print(json.dumps(float(np.median(np.linalg.norm(np.asarray(model.vertices)[{sorted(mask)}][:, None]"
        f" - np.asarray(model.vertices)[{path}][None], axis=2).min(axis=1)))))"
    )
    face = nb.kernel_eval("print(json.dumps(float(np.ptp(np.asarray(model.vertices)[:, 1]))))")
    assert near < 0.05 * face, (near, face)
    shot1 = nb.screenshot("chin-tinted", clip=chin)
    tinted = pixel_change(shot0, shot1, threshold=12)
    nb.screenshot("page-tinted")

    # --- Undo: the mask and its tint go
    frame1 = nb.frame(0)
    nb.kernel_eval("model.history.undo()")
    _wait(nb, f"len(model.history.undo_labels) == {len(before['undo'])}")
    nb.wait_frame_after(0, frame1)
    page.wait_for_timeout(500)
    shot2 = nb.screenshot("chin-undone", clip=chin)
    back = pixel_change(shot0, shot2, threshold=12)
    nb.artifacts.mkdir(parents=True, exist_ok=True)
    (nb.artifacts / "tool.json").write_text(json.dumps(
        {"masked": len(mask), "tinted": tinted, "after_undo": back}, indent=1))
    assert tinted > 0.04, f"only {tinted:.1%} of the chin's pixels changed under the tint"
    assert back < 0.005, f"{back:.1%} of the chin still differs after undo"
    assert not _state(nb)["mask"]
    console = "\n".join(nb.console)
    assert "pageerror" not in console, console
