"""The acceptance scenario of the whole product, in a real JupyterLab + Chromium.

A clean JupyterLab (no recovery files) opens ``notebooks/workbench.ipynb`` — the
notebook the README's run command opens — and runs all cells. Then, with the
mouse like a user:

1. **Sculpt**: "Default handles", drag the left and the right brow marker up
   (two separate drags, two undo steps).
2. **Paint**: pick ``mouthSmileLeft`` in the palette and paint the left mouth
   corner, pick ``mouthSmileRight`` and paint the right one: a smile. The
   overlay is switched off and the paint is baked into a new shape
   ("Bake to new shape"), as an animator keeps a painted look to animate it
   (the exporter would also write unbaked paint, as one constant target).
3. **Timeline**: three times, click the ruler at a time (0, 0.5, 1 s), drag the
   ``jawOpen`` slider and press "◆ Key".
4. **Export**: in the Export tab type a path and press "Export" (glTF binary).
5. **Consumers**: the Khronos glTF-Validator reports 0 errors and 0 warnings; three.js
   (GLTFLoader + AnimationMixer in Node) plays the file: the morph weights vary
   over time as keyed, the handle targets carry the brow offsets, and the
   CPU-morphed vertex positions equal the model's own ``evaluate()`` at each
   sampled time (handles + baked paint + keyed jaw).

Every step is checked in the kernel (model state) and in pixels (screenshots
cropped around the region that should change, and one that should not).
Screenshots, the exported .glb, the validator report and a pyvista render of
what three.js computed are kept in ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from harness import NotebookPage, clip_around, in_ci, pixel_change
from test_sculpt import _drag, _handles_on_screen, _wait_drag_closed
from test_timeline import _hooks, _x_of
from test_viewport import _drag_slider, _wait_settled

REPO = Path(__file__).resolve().parents[2]
WORKBENCH_NB = REPO / "notebooks" / "workbench.ipynb"
CONSUMERS = REPO / "tests" / "consumers"

#: the times keyed on the timeline and the jawOpen slider fraction set before each key
KEYS = ((0.0, 0.15), (0.5, 0.75), (1.0, -0.1))

_FIND = """
import json, numpy as np
_skin = model.component_labels == model.component_names.index("skin")
_V = np.asarray(model.vertices)
def _top(name, k):
    return np.argsort(-np.linalg.norm(model.shape(name).delta, axis=1) * _skin)[:k]
_l, _r = _top("mouthSmileLeft", 40), _top("mouthSmileRight", 40)
_lc = int(_l[np.argmax(_V[_l, 0])])   # left mouth corner: farthest out in +x
_rc = int(_r[np.argmin(_V[_r, 0])])   # right mouth corner: farthest out in -x
_lip = _top("mouthUpperUpLeft", 60)
_mid = int(_lip[np.argmin(np.abs(_V[_lip, 0]))])  # upper lip near the middle
_brow = np.concatenate([_top("browInnerUp", 40), _top("browOuterUpLeft", 30),
                        _top("browOuterUpRight", 30)])
print(json.dumps({"left_corner": _lc, "right_corner": _rc, "mid": _mid,
                  "mouth": [int(i) for i in np.union1d(_l, _r)],
                  "brow": [int(i) for i in np.unique(_brow)]}))
"""

_STATE = """
import json, numpy as np
_h = model.handles
print(json.dumps({
    "undo": model.history.undo_labels, "interacting": model.interacting,
    "dragging": wb.viewport.dragging, "painting": wb.viewport.stroking,
    "weights": {k: v for k, v in model.weights.items() if v},
    "handle_names": list(_h.names), "offsets": np.asarray(_h.offsets, float).tolist(),
    "paint": {k: float(np.max(w)) for k, w in model.paint.items()},
    "shapes": list(model.shape_names), "time": model.time,
    "tracks": {k: [tr.times.tolist(), np.asarray(tr.values, float).ravel().tolist()]
               for k, tr in model.tracks.tracks.items()},
    "errors": [o.get("text", "") for o in wb.errors.outputs]}))
"""


def _state(nb: NotebookPage) -> dict[str, Any]:
    return nb.kernel_eval(_STATE)  # type: ignore[no-any-return]


def _wait_state(nb: NotebookPage, pred, what: str, timeout: float = 30.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    st = _state(nb)
    while not pred(st) and time.monotonic() < deadline:
        time.sleep(0.15)
        st = _state(nb)
    assert pred(st), f"{what}: the model never got there; last state {_short(st)}"
    return st


def _short(st: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in st.items() if k not in ("offsets", "handle_names", "shapes")}


def _tab(nb: NotebookPage, title: str, tool: str) -> None:
    page = nb.page
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text=title).click()
    page.wait_for_function(
        "(t) => document.querySelector('.fwb-viewport').getAttribute('data-tool') === t", arg=tool
    )


def _top_of_workbench(nb: NotebookPage) -> None:
    nb.page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    nb.page.mouse.move(5, 5)  # no hover highlight or brush cursor in the pictures
    nb.page.wait_for_timeout(300)


def _settle(nb: NotebookPage, frame: int) -> None:
    """Wait for a new geometry frame after ``frame`` and let it draw."""
    nb.wait_frame_after(0, frame)
    nb.page.wait_for_timeout(300)


def _stroke(nb: NotebookPage, a: np.ndarray, b: np.ndarray, steps: int = 12) -> None:
    """One paint stroke from page point ``a`` to ``b`` (press, moves, release)."""
    page = nb.page
    page.mouse.move(a[0], a[1])
    page.mouse.down()
    for f in np.linspace(0.0, 1.0, steps)[1:]:
        page.mouse.move(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))
        page.wait_for_timeout(30)
    page.mouse.up()


def _pick(nb: NotebookPage, expression: str) -> None:
    nb.page.locator(".fwb-paint-palette .fw-thumb-button", has_text=expression).first.click()
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        got = nb.kernel_eval("import json; print(json.dumps(wb.viewport.tools['paint'].expression))")
        if got == expression:
            return
        time.sleep(0.1)
    raise AssertionError(f"picking {expression} in the palette did not reach the viewport")


def _node_tools() -> tuple[str, Any]:
    """``run(script, *args) -> JSON`` for the node scripts of tests/consumers (installs them once)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        msg = "node/npm are missing: the glTF-Validator and three.js checks need them"
        if in_ci():
            pytest.fail(msg + " (CI is set)")
        pytest.skip(msg)
    assert node is not None and npm is not None
    modules = CONSUMERS / "node_modules"
    if not (modules / "gltf-validator").is_dir() or not (modules / "three").is_dir():
        subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund", "--prefix", str(CONSUMERS)],
            check=True,
            capture_output=True,
            timeout=600,
        )

    def run(script: str, *args: str) -> Any:
        proc = subprocess.run(
            [node, str(CONSUMERS / script), *args],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=CONSUMERS,
        )
        assert proc.returncode == 0, f"node {script} failed:\n{proc.stderr[-3000:]}"
        return json.loads(proc.stdout)

    return node, run


def test_sculpt_paint_key_export_then_validator_and_three_js(open_notebook) -> None:
    # ------------------------------------------------------------ 0. clean lab, open the app
    # open_notebook empties the server's recovery folder first: a clean lab
    nb = open_notebook(WORKBENCH_NB, viewport_size=(1600, 1200))
    page = nb.page
    assert page.locator(".fwb-recover").count() == 0, "a clean lab must not offer recovery"
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    _top_of_workbench(nb)
    st0 = _state(nb)
    assert st0["undo"] == [] and st0["weights"] == {} and st0["errors"] == []
    info = nb.kernel_eval(_FIND)
    shot0 = nb.canvas_shot("0-opened-canvas")
    nb.screenshot("0-opened")
    covered = (np.abs(shot0.astype(int) - shot0[2, 2].astype(int)).max(axis=2) > 30).mean()
    assert 0.08 < covered < 0.95, f"the head covers {covered:.0%} of the canvas"

    # ------------------------------------------------------------ 1. Sculpt: drag two brow handles
    _tab(nb, "Sculpt", "sculpt")
    page.locator(".fwb-default-handles").click()
    st = _wait_state(nb, lambda s: len(s["handle_names"]) > 40, "Default handles")
    names = st["handle_names"]
    page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=len(names),
    )
    _top_of_workbench(nb)
    brow_clip = clip_around(nb.project(info["brow"]), pad=25)
    mouth_clip = clip_around(nb.project(info["mouth"]), pad=8)  # lips, not the nose
    brow0 = nb.screenshot("1-brow-before", clip=brow_clip)
    mouth0 = nb.screenshot("1-mouth-before", clip=mouth_clip)
    nb.screenshot("1-sculpt-before")
    dragged = []
    for side in ("L", "R"):
        # the brow marker highest on the screen of this side
        pts = _handles_on_screen(nb)
        ks = [k for k, n in enumerate(names) if n.startswith(f"brows_{side}_") and pts[k][2] == 1]
        assert ks, f"no visible brows_{side} marker"
        k = min(ks, key=lambda j: pts[j][1])
        frame = nb.frame(0)
        _drag(nb, pts[k], (0.0, -22.0))
        _settle(nb, frame)
        _wait_drag_closed(nb)
        dragged.append(k)
    st1 = _state(nb)
    assert st1["undo"][-2:] == [f"Drag handle {names[k]}" for k in dragged]
    off = np.array(st1["offsets"])
    assert np.abs(np.delete(off, dragged, axis=0)).max() == 0.0  # only the two dragged handles
    for k in dragged:
        assert off[k, 1] > 0.01 and abs(off[k, 2]) < 1e-4 * np.linalg.norm(off[k]), off[k]
    _top_of_workbench(nb)
    brow1 = nb.screenshot("1-brow-after", clip=brow_clip)
    mouth1 = nb.screenshot("1-mouth-after", clip=mouth_clip)
    nb.screenshot("1-sculpt-after")
    assert pixel_change(brow0, brow1) > 0.03, "the brows did not move on screen"
    assert pixel_change(mouth0, mouth1) < 0.01, "dragging the brows changed the mouth"

    # ------------------------------------------------------------ 2. Paint a smile, bake it
    _tab(nb, "Paint", "paint")
    page.locator(".fwb-paint-palette .fw-thumb-button").first.wait_for(timeout=120_000)
    nb.kernel_eval("wb.paint.radius.value = 0.15; wb.paint.opacity.value = 1.0")
    _top_of_workbench(nb)
    mouth2a = nb.screenshot("2-mouth-before", clip=mouth_clip)
    brow2a = nb.screenshot("2-brow-before", clip=brow_clip)
    for expression, corner in (
        ("mouthSmileLeft", "left_corner"),
        ("mouthSmileRight", "right_corner"),
    ):
        _pick(nb, expression)
        _top_of_workbench(nb)
        a, mid = nb.project([info[corner], info["mid"]])
        assert a[2] == 1 and mid[2] == 1
        frame = nb.frame(0)
        _stroke(nb, a, a + 0.6 * (mid - a))
        _settle(nb, frame)
        _wait_state(nb, lambda s: not s["interacting"] and not s["painting"], "stroke end")
    st2 = _state(nb)
    assert st2["undo"][-2:] == ["Paint mouthSmileLeft", "Paint mouthSmileRight"]
    assert set(st2["paint"]) == {"mouthSmileLeft", "mouthSmileRight"}
    assert min(st2["paint"].values()) > 0.5
    _top_of_workbench(nb)
    nb.screenshot("2-painted-overlay")
    page.locator(".fwb-paint-overlay").click()  # overlay off: the geometry alone
    _wait_py_true(nb, "not wb.viewport.tools['paint'].overlay")
    page.wait_for_timeout(400)
    mouth2b = nb.screenshot("2-mouth-painted", clip=mouth_clip)
    brow2b = nb.screenshot("2-brow-painted", clip=brow_clip)
    nb.screenshot("2-painted")
    assert pixel_change(mouth2a, mouth2b) > 0.03, "the painted smile does not show"
    assert pixel_change(brow2a, brow2b) < 0.01, "painting the mouth changed the brows"
    nb.kernel_eval("import numpy as np; _X_painted = np.array(model.evaluate())")
    frame = nb.frame(0)
    page.locator(".fwb-paint-bake").click()
    st = _wait_state(nb, lambda s: "paint_1" in s["shapes"] and not s["paint"], "Bake to new shape")
    assert st["weights"] == {"paint_1": 1.0} and st["undo"][-1] == "Bake paint to paint_1"
    same = nb.kernel_eval(
        "import json; print(json.dumps(float(np.abs(model.evaluate() - _X_painted).max())))"
    )
    assert same < 1e-5, f"baking changed the face by {same}"
    _settle(nb, frame)
    _top_of_workbench(nb)
    mouth2c = nb.screenshot("2-mouth-baked", clip=mouth_clip)
    nb.screenshot("2-baked")
    assert pixel_change(mouth2b, mouth2c) < 0.01, "the baked face looks different"

    # ------------------------------------------------------------ 3. Key three times
    _tab(nb, "Shapes", "orbit")
    page.locator(".fwb-slider-jawOpen").evaluate("e => e.scrollIntoView({block: 'center'})")
    _top_of_workbench(nb)
    root = page.locator(".fwb-timeline")
    keyed: list[float] = []
    mouths = []
    for i, (t, fraction) in enumerate(KEYS):
        h = _hooks(root)
        page.mouse.click(_x_of(h, t), h["ruler_y"])  # the playhead jumps there
        _wait_state(nb, lambda s, t=t: abs(s["time"] - t) < 1e-9, f"scrub to {t}")
        frame = nb.frame(0)
        _drag_slider(nb, "jawOpen", fraction)
        _wait_settled(nb)
        w = _wait_state(nb, lambda s: not s["interacting"], "slider")["weights"]
        keyed.append(w.get("jawOpen", 0.0))
        page.locator(".fwb-tl-key").click()
        _wait_state(
            nb,
            lambda s, i=i: len(s["tracks"].get("weights/jawOpen", [[]])[0]) == i + 1,
            f"key {i + 1}",
        )
        if nb.frame(0) > frame:
            nb.page.wait_for_timeout(300)
        _top_of_workbench(nb)
        mouths.append(nb.screenshot(f"3-mouth-key{i + 1}", clip=mouth_clip))
        nb.screenshot(f"3-key{i + 1}")
    st3 = _state(nb)
    times, values = st3["tracks"]["weights/jawOpen"]
    assert times == [t for t, _ in KEYS]
    np.testing.assert_allclose(values, keyed, atol=1e-9)
    assert keyed[1] > keyed[0] + 0.3 and keyed[2] == 0.0, keyed
    assert st3["tracks"]["weights/paint_1"][1] == [1.0, 1.0, 1.0]
    assert sum(lbl.startswith("Key ") for lbl in st3["undo"]) == 3
    assert pixel_change(mouths[0], mouths[1]) > 0.03, "the keyed jaw does not show at 0.5 s"
    keys_drawn = json.loads(root.get_attribute("data-keys") or "[]")
    assert sorted({k[2] for k in keys_drawn if k[0] == "weights/jawOpen"}) == [0.0, 0.5, 1.0]
    root.screenshot(path=str(nb.artifacts / "3-timeline.png"))

    # ------------------------------------------------------------ 4. Export a .glb
    _tab(nb, "Export", "orbit")
    glb = nb.artifacts / "scenario.glb"
    glb.unlink(missing_ok=True)
    page.locator(".fwb-export-path input").fill(str(glb))
    _wait_py_true(nb, f"wb.export.path.value == {str(glb)!r}")
    page.locator(".fwb-export-button").click()
    page.locator(".fwb-export-files").wait_for(timeout=120_000)
    page.locator(".fwb-export-panel").screenshot(path=str(nb.artifacts / "4-exported.png"))
    written = nb.kernel_eval(
        "import json; print(json.dumps([str(p) for p in wb.export.last_written]))"
    )
    assert written == [str(glb.resolve())] and glb.stat().st_size > 10_000
    assert str(glb) in page.locator(".fwb-export-result").inner_text()
    assert _state(nb)["errors"] == []

    # ------------------------------------------------------------ 5. Validator and three.js
    sample_t = [0.0, 0.25, 0.5, 0.75, 1.0]
    expected_path = nb.artifacts / "expected_points.npy"
    nb.kernel_eval(
        "import numpy as np\n"
        f"_P = []\nfor _t in {sample_t!r}:\n"
        "    model.set_time(_t)\n"
        "    _P.append(np.array(model.evaluate(), np.float64) * model.metadata.metres_per_unit)\n"
        f"np.save({str(expected_path)!r}, np.stack(_P))\nmodel.set_time(0.0)"
    )
    expected = np.load(expected_path)
    _node, run = _node_tools()
    report = run("validate.mjs", str(glb))[str(glb)]
    (nb.artifacts / "5-validator.json").write_text(json.dumps(report, indent=1))
    assert report["numErrors"] == 0, report["messages"]
    assert report["numWarnings"] == 0, report["messages"]
    got = run("three_sample.mjs", str(glb), json.dumps(sample_t), "positions")
    names_3 = got["targetNames"]
    W = np.array(got["weights"])
    jaw = W[:, names_3.index("jawOpen")]
    np.testing.assert_allclose(jaw[[0, 2, 4]], keyed, atol=1e-6)  # the keys, played back
    assert np.ptp(jaw) > 0.3, f"jawOpen does not vary over time: {jaw}"
    np.testing.assert_allclose(W[:, names_3.index("paint_1")], 1.0, atol=1e-6)
    # the handle offsets are not keyed: the handle layer is one constant target
    # (weight 1), checked below through the positions three.js computes
    np.testing.assert_allclose(W[:, names_3.index("layer:static")], 1.0, atol=1e-6)
    assert not any(n.startswith("handle:") for n in names_3), names_3
    pts = np.array(got["points"]).reshape(expected.shape)
    err = np.abs(pts - expected).max()
    assert err < 2e-5, f"three.js positions differ from the model by {err * 1000:.3f} mm"
    # the edits are in the file: the brow handles' vertices moved up by their offsets, the
    # painted mouth corners moved (the baked shape), and the picture shows it
    import workbench

    head = workbench.load_sample("head")
    mpu = head.metadata.metres_per_unit
    neutral = np.asarray(head.vertices, float) * mpu
    hv = nb.kernel_eval("import json; print(json.dumps([int(v) for v in model.handles.vertices]))")
    for k in dragged:
        np.testing.assert_allclose(pts[0, hv[k]] - neutral[hv[k]], off[k] * mpu, atol=2e-5)
    for corner in ("left_corner", "right_corner"):
        moved = np.linalg.norm(pts[0, info[corner]] - neutral[info[corner]])
        assert moved > 1e-3, f"the {corner} moved only {moved * 1000:.2f} mm in the .glb"
    _render_three(nb, head, pts[[0, 2, 4]] / mpu)


def _wait_py_true(nb: NotebookPage, expr: str, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if nb.kernel_eval(f"import json; print(json.dumps(bool({expr})))"):
            return
        time.sleep(0.1)
    raise AssertionError(f"{expr} never became true")


def _render_three(nb: NotebookPage, head: Any, frames: np.ndarray) -> None:
    """Keep a picture of the vertex positions three.js computed (pyvista, offscreen)."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import io

    from PIL import Image

    from widgets.render import render_png

    ims = [
        Image.open(io.BytesIO(render_png(head, points=p, camera="face", size=(300, 300))))
        for p in frames
    ]
    row = Image.new("RGB", (sum(i.width for i in ims), ims[0].height), "white")
    for j, im in enumerate(ims):
        row.paste(im.convert("RGB"), (j * ims[0].width, 0))
    row.save(nb.artifacts / "5-three-js-at-0-0.5-1s.png")
