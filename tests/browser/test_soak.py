"""Soak: random user actions with the mouse on the Workbench at 25k, two CPU hogs beside it.

Issue #26's "no lost or stale view": after every action, once the page is idle,
the positions the page drew (read back from the GPU evaluation) equal the
kernel's ``model.evaluate()`` within 1e-5 of the face size, the shape sliders
show the model's weights, and the undo depth is what the actions imply. The
harness then also requires zero resyncs, zero reopened notebooks and zero
widget changes off the UI thread (``conftest.open_notebook``).

Actions, drawn with a fixed seed: shape-slider drags (Shapes tab), handle
drags (Sculpt tab, the default handles), region-pin drags (Regions tab, *Drag to
sculpt*), paint dabs (Paint tab, one picked expression), the top bar's *Enhanced
preview* on and off, timeline scrubs, keys, play then pause, undo and redo with
the top bar's buttons, and tab switches. ``WORKBENCH_SOAK_ACTIONS`` sets how many
(the test command runs 40 to stay in CI's time; the issue's soak is 300:
``WORKBENCH_SOAK_ACTIONS=300 .venv/bin/python -m pytest tests/browser/test_soak.py``).
The set-up is what a person does once: default handles, *Find regions*, an
expression to paint (with the mouse) and a detail database (a small procedural
one on this mesh, from Python: the Enhance tab's build is its own browser test).
"""

from __future__ import annotations

import base64
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from harness import NotebookPage, wait_until
from test_end_to_end import _pick, _tab
from test_timeline import _hooks, _x_of
from test_viewport import _drag_slider

N_ACTIONS = int(os.environ.get("WORKBENCH_SOAK_ACTIONS", "40"))
SEED = int(os.environ.get("WORKBENCH_SOAK_SEED", "26"))

_SETUP = ("""
import json, numpy as np, workbench
from IPython.display import display
from widgets import Workbench
model = workbench.load_sample("head", resolution="25k")
wb = Workbench(model)
display(wb)
SOAK_SLIDERS = {sliders!r}
""",
    """
from workbench.enhance.performance import procedural_database
model.enhance.set_database(procedural_database(model, n_frames=12).database, source="soak")
""")

SLIDERS = ("jawOpen", "mouthSmileLeft", "browInnerUp", "eyeBlinkRight", "mouthFunnel", "cheekPuff")

_KERNEL = """
import base64, json, numpy as np
_vp = wb.viewport
print(json.dumps({
    "version": int(_vp._version), "interacting": bool(model.interacting),
    "undo": len(model.history.undo_labels), "redo": len(model.history.redo_labels),
    "weights": {k: float(model.weights[k]) for k in SOAK_SLIDERS},
    "positions": base64.b64encode(np.ascontiguousarray(model.evaluate(), "<f4").tobytes()).decode(),
}))
"""

_PAGE = """
(names) => {
  const vp = document.querySelector('.fwb-viewport');
  const p = vp.fwbGpuPositions ? vp.fwbGpuPositions() : null;
  const readout = {};
  for (const n of names) {
    const r = document.querySelector(`.fwb-slider-${n} .widget-readout`);
    readout[n] = r ? r.textContent : null;
  }
  return {version: Number(vp.getAttribute('data-version')), detail: vp.getAttribute('data-detail'),
          gpu: vp.getAttribute('data-gpu'), positions: p ? Array.from(p) : null, readout};
}
"""


@pytest.fixture
def cpu_hogs() -> Iterator[None]:
    """Two busy processes beside the browser and the kernel (ended by their pids).

    ``WORKBENCH_SOAK_HOGS`` sets how many (0 when a script runs its own beside the whole suite).
    """
    hogs = [
        subprocess.Popen([sys.executable, "-c", "while True: pass"])
        for _ in range(int(os.environ.get("WORKBENCH_SOAK_HOGS", "2")))
    ]
    try:
        yield
    finally:
        for p in hogs:
            p.kill()
            p.wait(timeout=10)


def _kernel(nb: NotebookPage) -> dict[str, Any]:
    st = nb.kernel_eval(_KERNEL, timeout=120)
    st["positions"] = np.frombuffer(base64.b64decode(st["positions"]), "<f4").reshape(-1, 3)
    return st  # type: ignore[no-any-return]


def _page(nb: NotebookPage) -> dict[str, Any]:
    st = nb.page.evaluate(_PAGE, list(SLIDERS))
    if st["positions"] is not None:
        st["positions"] = np.asarray(st["positions"], np.float64).reshape(-1, 3)
    return st  # type: ignore[no-any-return]


_DIAGNOSE = """
import json, numpy as np
_p = np.frombuffer(wb.viewport._gpu_params, "<f4")
_r = np.frombuffer(wb.viewport._gpu_residual, "<f4")
print(json.dumps({"params": _p.tolist(), "residual_len": int(_r.size),
                  "names": list(model.shape_names), "time": model.time,
                  "labels": model.history.undo_labels[-6:],
                  "paint": {k: float(np.max(w)) for k, w in model.paint.items()},
                  "components": list(model.component_names),
                  "label_of": {str(i): model.component_names[int(model.component_labels[i])] for i in %s}}))
"""


def _diagnose(nb: NotebookPage, p: dict[str, Any], k: dict[str, Any], size: float) -> dict[str, Any]:
    """Where page and kernel differ, and both sides' GPU parameters (for the artifacts)."""
    err = np.abs(p["positions"] - k["positions"]).max(axis=1) / size
    bad = np.flatnonzero(err > 1e-5)
    worst = [int(i) for i in bad[np.argsort(-err[bad])][:10]]
    kern = nb.kernel_eval(_DIAGNOSE % (worst,))
    page = nb.viewport(0).evaluate("e => e.fwbGpuState()")
    kp, pp = np.asarray(kern.pop("params")), np.asarray(page.get("params") or [])
    diff = (
        [[int(i), float(kp[i]), float(pp[i])] for i in np.flatnonzero(np.abs(kp - pp) > 1e-6)]
        if kp.shape == pp.shape else f"shapes {kp.shape} vs {pp.shape}"
    )
    return {"n_bad": int(bad.size), "worst": worst, "worst_err": [float(err[i]) for i in worst],
            "param_diff (index, kernel, page)": diff, "page_missing": page.get("missing"), **kern}


def _in_step(nb: NotebookPage, size: float, depth: int, what: str, timeout: float = 90.0) -> dict[str, Any]:
    """Wait until page and kernel agree; then assert it. Returns the kernel's state."""
    deadline = time.monotonic() + timeout
    while True:
        k = _kernel(nb)
        p = _page(nb)
        err = (
            float(np.abs(p["positions"] - k["positions"]).max()) / size
            if p["positions"] is not None and p["positions"].shape == k["positions"].shape
            else np.inf
        )
        sliders_ok = all(
            p["readout"][n] is not None and abs(float(p["readout"][n]) - k["weights"][n]) <= 0.0051
            for n in SLIDERS
        )
        settled = (
            not k["interacting"] and p["version"] == k["version"] and p["detail"] != "draft"
        )
        if settled and err <= 1e-5 and sliders_ok:
            break
        if time.monotonic() > deadline:
            nb.screenshot(f"out-of-step-{what}")
            (nb.artifacts / "out-of-step.json").write_text(json.dumps(_diagnose(nb, p, k, size), indent=1))
            raise AssertionError(
                f"after {what}: page and kernel out of step: GPU - kernel {err:.2e} of the face size, "
                f"versions page {p['version']} kernel {k['version']}, detail {p['detail']}, "
                f"interacting {k['interacting']}, readouts {p['readout']} vs {k['weights']}"
            )
        time.sleep(0.2)
    if k["undo"] != depth:
        nb.screenshot(f"depth-{what}")
        labels = nb.kernel_eval("print(json.dumps(model.history.undo_labels))")
        raise AssertionError(f"after {what}: undo depth {k['undo']}, expected {depth} (last steps {labels})")
    return k


def test_random_actions_keep_page_and_kernel_in_step(open_notebook, cpu_hogs) -> None:
    rng = np.random.default_rng(SEED)
    nb = open_notebook([_SETUP[0].format(sliders=SLIDERS), _SETUP[1]])
    page = nb.page
    page.evaluate("() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }")
    nb.wait_viewports(1, timeout=180)
    vp = nb.viewport(0)
    wait_until("GPU mode", lambda: vp.get_attribute("data-gpu"), lambda v: v == "1", timeout=120)
    size = float(nb.kernel_eval(
        "print(json.dumps(float(np.linalg.norm(np.ptp(model.vertices, axis=0)))))"
    ))
    face = [int(i) for i in nb.kernel_eval(
        "_d = sum(np.linalg.norm(model.shape(n).delta, axis=1) for n in "
        "('jawOpen', 'mouthSmileLeft', 'browInnerUp'))\n"
        "_skin = model.component_labels == model.component_names.index('skin')\n"
        "print(json.dumps([int(i) for i in np.argsort(-_d * _skin)[:60]]))"
    )]
    # set-up steps a person takes once: default handles, an expression to paint
    _tab(nb, "Sculpt", "sculpt")
    page.locator(".fwb-default-handles").click()
    wait_until("default handles", lambda: nb.kernel_eval(
        "print(json.dumps(len(model.handles)))"), lambda n: n and n > 0, timeout=60)
    _tab(nb, "Regions", "orbit")
    page.locator(".fwb-find-regions").click()
    wait_until("regions", lambda: nb.kernel_eval(
        "print(json.dumps(model.regions.segmented))"), bool, timeout=120)
    _tab(nb, "Paint", "paint")
    _pick(nb, "mouthSmileLeft")
    depth = _in_step(nb, size, depth=int(nb.kernel_eval(
        "print(json.dumps(len(model.history.undo_labels)))")), what="set-up")["undo"]
    redo = 0
    tab = "Paint"
    done: list[str] = []

    def goto(title: str, tool: str) -> None:
        """Click the tab; wait until the kernel has switched (its tool) and the page shows that tool.

        (The page's tool alone is no sign: coming from Sculpt to Regions in drag mode
        it is "sculpt" before the switch, then "orbit" for a moment, then "sculpt".)
        """
        nonlocal tab
        if tab != title:
            if title == "Regions" and nb.kernel_eval("print(json.dumps(wb.regions.drag_mode.value))"):
                tool = "sculpt"  # its drag mode comes back on with the tab
            page.locator(".fwb-tabs .lm-TabBar-tab", has_text=title).click()
            wait_until(f"the {title} tab in the kernel", lambda: nb.kernel_eval(
                "print(json.dumps([wb.tab_specs[wb.tabs.selected_index].title, wb.viewport.tool]))"),
                lambda v: v == [title, tool], timeout=60)
            page.wait_for_function(
                "(t) => document.querySelector('.fwb-viewport').getAttribute('data-tool') === t", arg=tool)
            tab = title

    def top() -> None:
        page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")

    def drag_a_marker() -> int | None:
        """Drag one visible, grabbable marker 12-30 px in a random direction; its index or None."""
        top()
        pts = np.array(vp.evaluate("e => e.fwbMarkers()"), float).reshape(-1, 3)
        box = vp.bounding_box()
        inside = np.flatnonzero(
            (pts[:, 2] == 1) & (pts[:, 0] > box["x"] + 20) & (pts[:, 0] < box["x"] + box["width"] - 20)
            & (pts[:, 1] > box["y"] + 20) & (pts[:, 1] < box["y"] + box["height"] - 20)
        )
        # markers a press grabs (not hidden behind the surface, not under another one)
        grabbable = [int(k) for k in inside
                     if vp.evaluate("(e, p) => e.fwbPickMarker(p[0], p[1])", pts[k, :2].tolist()) == k]
        if not grabbable:
            return None
        k = int(rng.choice(grabbable))
        angle, length = rng.uniform(0, 2 * np.pi), rng.uniform(12, 30)  # a drag, not a click
        dx, dy = length * np.cos(angle), length * np.sin(angle)
        page.mouse.move(pts[k, 0], pts[k, 1])
        page.mouse.down()
        page.mouse.move(pts[k, 0] + dx, pts[k, 1] + dy, steps=10)
        page.mouse.up()
        return k

    for step in range(N_ACTIONS):
        action = rng.choice(
            ["slider", "handle", "pin", "paint", "enhance", "scrub", "key", "play", "undo", "redo", "tab"],
            p=[0.18, 0.12, 0.08, 0.11, 0.05, 0.11, 0.07, 0.06, 0.11, 0.06, 0.05],
        )
        what = f"#{step} {action}"
        if action == "slider":
            goto("Shapes", "orbit")
            name = str(rng.choice(SLIDERS))
            now = _kernel(nb)["weights"][name]
            target = float(rng.uniform(0.05, 0.95))
            if abs(target - now) < 0.15:
                target = 0.95 if now < 0.5 else 0.05
            page.locator(f".fwb-slider-{name}").evaluate("e => e.scrollIntoView({block: 'center'})")
            _drag_slider(nb, name, target)
            depth, redo, what = depth + 1, 0, f"{what} {name} -> {target:.2f}"
        elif action == "handle":
            goto("Sculpt", "sculpt")
            k = drag_a_marker()
            if k is None:
                continue
            depth, redo, what = depth + 1, 0, f"{what} handle {k}"
        elif action == "pin":
            if not nb.kernel_eval("print(json.dumps(model.regions.segmented))"):
                continue  # the segmentation was undone: no pins to drag (the toggle is disabled)
            goto("Regions", "orbit")
            if not nb.kernel_eval("print(json.dumps(wb.regions.drag_mode.value))"):  # it stays on with the tab
                page.locator(".fwb-region-drag").click()
            # the page shows the pins, not the Sculpt tab's handles it showed a moment ago (coming from
            # Sculpt the tool is "sculpt" on both sides of the switch: only the markers tell; seed 302
            # picked a stale handle's place, where no pin was, and the drag orbited)
            n_pins = nb.kernel_eval("print(json.dumps(len(wb.regions.pins)))")
            page.wait_for_function(
                "(n) => { const v = document.querySelector('.fwb-viewport');"
                " return v.getAttribute('data-tool') === 'sculpt'"
                " && JSON.parse(v.getAttribute('data-markers') || '[]').length === n; }", arg=n_pins)
            k = drag_a_marker()
            if k is None:
                continue
            depth, redo, what = depth + 1, 0, f"{what} pin {k}"
        elif action == "paint":
            goto("Paint", "paint")
            top()
            xy = nb.project(face)
            box = vp.bounding_box()
            seen = xy[(xy[:, 2] == 1) & (xy[:, 0] > box["x"]) & (xy[:, 0] < box["x"] + box["width"])
                      & (xy[:, 1] > box["y"]) & (xy[:, 1] < box["y"] + box["height"])]
            if not len(seen):
                continue
            a, b = seen[rng.integers(len(seen))], seen[rng.integers(len(seen))]
            page.mouse.move(a[0], a[1])
            page.mouse.down()
            page.mouse.move(b[0] + 3, b[1] + 3, steps=6)
            page.mouse.up()
            depth, redo = depth + 1, 0
        elif action == "scrub":
            root = page.locator(".fwb-timeline")
            root.scroll_into_view_if_needed()
            h = _hooks(root)
            t = float(rng.uniform(0.0, 2.0))
            page.mouse.click(_x_of(h, t), h["ruler_y"])
            what = f"{what} to {t:.2f} s"
        elif action == "key":
            root = page.locator(".fwb-timeline")
            root.scroll_into_view_if_needed()
            nb.kernel_eval("wb.timeline.status = ''")
            root.locator(".fwb-tl-key").first.click()
            # the status says what happened: keyed, or nothing to key (every weight 0)
            status = wait_until("the key", lambda: nb.kernel_eval(
                "print(json.dumps(wb.timeline.status))"), bool, timeout=30)
            if status.startswith("keyed"):
                depth, redo = depth + 1, 0
            what = f"{what} ({status})"
        elif action == "play":
            root = page.locator(".fwb-timeline")
            root.scroll_into_view_if_needed()
            root.locator(".fwb-tl-play").click()
            page.wait_for_timeout(int(rng.uniform(300, 1200)))
            pause = root.locator(".fwb-tl-pause")
            if pause.is_enabled():  # not when the range played out, or there was nothing to play
                pause.click(force=True)  # force: it may play out meanwhile (a disabled button ignores it)
            wait_until("paused", lambda: nb.kernel_eval("print(json.dumps(wb.timeline.playing))"),
                       lambda v: v is False, timeout=30)
        elif action == "enhance":
            top()
            box = page.locator(".fwb-topbar .fwb-enhance-preview input")
            on = not box.is_checked()
            box.click()
            wait_until("the preview", lambda: nb.kernel_eval(
                "print(json.dumps(model.enhance.preview))"), lambda v, on=on: v is on, timeout=60)
            depth, redo, what = depth + 1, 0, f"{what} {'on' if on else 'off'}"
        elif action == "undo":
            top()
            if depth == 0:
                continue
            page.locator(".fwb-wb-undo").click()
            depth, redo = depth - 1, redo + 1
        elif action == "redo":
            top()
            if redo == 0:
                continue
            page.locator(".fwb-wb-redo").click()
            depth, redo = depth + 1, redo - 1
        elif action == "tab":
            title = str(rng.choice(["Shapes", "Sculpt", "Regions", "Paint", "Export"]))
            goto(title, {"Sculpt": "sculpt", "Paint": "paint"}.get(title, "orbit"))
            what = f"{what} {title}"
        done.append(what)
        (nb.artifacts / "actions.json").parent.mkdir(parents=True, exist_ok=True)
        (nb.artifacts / "actions.json").write_text(json.dumps(done, indent=1))
        _in_step(nb, size, depth, what)
    nb.screenshot("end")
    assert len(done) >= N_ACTIONS // 2, done
