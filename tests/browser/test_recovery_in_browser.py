"""Autosave and crash recovery of the Workbench, with a real kernel crash in JupyterLab + Chromium.

The test opens ``notebooks/workbench.ipynb`` in a clean lab (no recovery
files), edits with the mouse (drags the ``jawOpen`` slider, loads the default
handles and drags a brow marker), waits until the status line says the
autosave happened, and records the model (weights, handles, the evaluated
mesh) and the viewport's pixels. Then it starts another handle drag and,
with the mouse button still down, kills the kernel process (SIGKILL to the
pid of the kernel the test's own JupyterLab started). JupyterLab restarts the
kernel; the test dismisses the "kernel restarting" dialog, clears the outputs
and runs the notebook again. The recovery prompt must appear instead of the
app; "Recover workbench ..." is clicked, and the recovered model must equal
the autosaved one (the half-done drag is the only thing lost), in the kernel
and in pixels. Screenshots: ``test-artifacts/<test>/``.

How autosave works: ``workbench/autosave.py`` (debounced atomic save after
each history event, ``<name>.recovery.fwb`` + ``.owner`` with the pid) and
``widgets.recovery_prompt`` / ``RecoveryPrompt`` in ``widgets/recovery.py``
(a file whose owner pid is gone is offered).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
from harness import NotebookPage, pixel_change
from test_sculpt import _drag, _handles_on_screen, _wait_drag_closed
from test_viewport import _drag_slider, _wait_settled

REPO = Path(__file__).resolve().parents[2]
WORKBENCH_NB = REPO / "notebooks" / "workbench.ipynb"

_SNAPSHOT = """
import json, numpy as np
_h = model.handles
np.save({path!r}, np.asarray(model.evaluate(), np.float64))
print(json.dumps({{
    "weights": {{k: v for k, v in model.weights.items() if v}},
    "handle_names": list(_h.names), "handle_vertices": [int(v) for v in _h.vertices],
    "offsets": np.asarray(_h.offsets, float).tolist(),
    "shapes": list(model.shape_names), "paint": sorted(model.paint),
    "expressions": sorted(model.expressions), "tracks": model.tracks.to_json(),
    "interacting": model.interacting,
    "autosave": {{"state": wb.autosaver.state, "saves": wb.autosaver.saves,
                 "path": str(wb.autosaver.path)}},
    "errors": [o.get("text", "") for o in wb.errors.outputs]}}))
"""

_COMPARED = ("weights", "handle_names", "handle_vertices", "offsets", "shapes", "paint")


def _snapshot(nb: NotebookPage, name: str) -> tuple[dict[str, Any], np.ndarray]:
    nb.artifacts.mkdir(parents=True, exist_ok=True)
    path = nb.artifacts / f"{name}.npy"
    st = nb.kernel_eval(_SNAPSHOT.format(path=str(path)))
    return st, np.load(path)


def _py(nb: NotebookPage, expr: str, timeout: float = 60.0) -> Any:
    return nb.kernel_eval(f"import json; print(json.dumps({expr}))", timeout=timeout)


def _wait_py(nb: NotebookPage, expr: str, pred, what: str, timeout: float = 30.0) -> Any:
    deadline = time.monotonic() + timeout
    value = _py(nb, expr)
    while not pred(value) and time.monotonic() < deadline:
        time.sleep(0.2)
        value = _py(nb, expr)
    assert pred(value), f"{what}: {expr} is still {value!r}"
    return value


def _show_workbench(nb: NotebookPage) -> None:
    page = nb.page
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    _top(nb)


def _top(nb: NotebookPage) -> None:
    nb.page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    nb.page.mouse.move(5, 5)
    nb.page.wait_for_timeout(400)


def _tab(nb: NotebookPage, title: str, tool: str) -> None:
    nb.page.locator(".fwb-tabs .lm-TabBar-tab", has_text=title).click()
    nb.page.wait_for_function(
        "(t) => document.querySelector('.fwb-viewport').getAttribute('data-tool') === t", arg=tool
    )


def _aligned_change(a: np.ndarray, b: np.ndarray, max_shift: int = 3) -> float:
    """:func:`pixel_change` of two canvas shots after the best shift of ``b`` by <= ``max_shift`` px.

    The viewport frames its camera on the first mesh it receives (viewport.js
    ``frameCamera``): the fresh app on the neutral face, the recovered app on
    the recovered (edited) face, so the two framings differ by a pixel or two.
    """
    m = max_shift
    best = 1.0
    for dy in range(-m, m + 1):
        for dx in range(-m, m + 1):
            shifted = np.roll(np.roll(b, dy, axis=0), dx, axis=1)
            best = min(best, pixel_change(a[m:-m, m:-m], shifted[m:-m, m:-m]))
    return best


def _parent_pid(pid: int) -> int:
    # /proc/<pid>/stat: "pid (comm) state ppid ..."; comm may contain spaces
    stat = Path(f"/proc/{pid}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[1])


def _wait_restarted(nb: NotebookPage, old_pid: int, timeout: float = 120.0) -> int:
    """Dismiss JupyterLab's "kernel restarting" dialog; return the new kernel's pid.

    The server's restarter notices the dead kernel within a few seconds and
    starts a new one under the same kernel id; if it has not after half the
    timeout, the test restarts it through the REST API.
    """
    page = nb.page
    deadline = time.monotonic() + timeout
    asked = False
    shot = False
    while time.monotonic() < deadline:
        dialog = page.locator(".jp-Dialog")
        if dialog.count():
            if not shot:
                nb.screenshot("3-kernel-restarting-dialog")
                shot = True
            with contextlib.suppress(Exception):
                dialog.locator(".jp-Dialog-button.jp-mod-accept").first.click(timeout=2000)
        st = nb.state()
        if st and st["kernel"] == "idle" and not dialog.count():
            with contextlib.suppress(Exception):
                pid = int(_py(nb, "__import__('os').getpid()", timeout=10))
                if pid != old_pid:
                    return pid
        if not asked and time.monotonic() > deadline - timeout / 2 and st and st["kernelId"]:
            nb.lab.api("POST", f"/api/kernels/{st['kernelId']}/restart")
            asked = True
        time.sleep(0.5)
    raise AssertionError(f"the kernel did not come back after it was killed: {nb.state()}")


def _dismiss_dialogs(nb: NotebookPage) -> None:
    """Click OK on JupyterLab's dialogs, as a user would.

    After a websocket reconnect JupyterLab may show its "kernel appears to have
    died" notice late, over a notebook whose new kernel already ran.
    """
    dialog = nb.page.locator(".jp-Dialog")
    for _ in range(20):
        if not dialog.count():
            return
        with contextlib.suppress(Exception):
            dialog.locator(".jp-Dialog-button.jp-mod-accept").first.click(timeout=2000)
        nb.page.wait_for_timeout(250)
    raise AssertionError("a JupyterLab dialog would not close")


def test_kill_kernel_mid_edit_then_recover_with_the_mouse(open_notebook, lab) -> None:
    recovery = lab.base / "recovery"  # emptied by open_notebook: a clean start
    nb = open_notebook(WORKBENCH_NB, viewport_size=(1600, 1200))
    page = nb.page
    assert page.locator(".fwb-recover").count() == 0
    _show_workbench(nb)
    fresh = nb.canvas_shot("0-fresh-canvas")
    assert _py(nb, "wb.autosave_text()") == "no edits yet"

    # ---- edits with the mouse: a slider, the default handles, a handle drag
    page.locator(".fwb-slider-jawOpen").evaluate("e => e.scrollIntoView({block: 'center'})")
    _top(nb)
    _drag_slider(nb, "jawOpen", 0.5)
    _wait_settled(nb)
    _tab(nb, "Sculpt", "sculpt")
    page.locator(".fwb-default-handles").click()
    names = _wait_py(nb, "list(model.handles.names)", lambda v: len(v) > 40, "Default handles")
    page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport').getAttribute('data-markers')"
        " || '[]').length === n",
        arg=len(names),
    )
    _top(nb)
    pts = _handles_on_screen(nb)
    brows = {
        side: min(
            (k for k, n in enumerate(names) if n.startswith(f"brows_{side}_") and pts[k][2] == 1),
            key=lambda k: pts[k][1],
        )
        for side in ("L", "R")
    }
    frame = nb.frame(0)
    _drag(nb, pts[brows["L"]], (6.0, -20.0))
    nb.wait_frame_after(0, frame)
    _wait_drag_closed(nb)

    # ---- the autosave happens a couple of seconds later; the status line says so
    _tab(nb, "Shapes", "orbit")
    page.wait_for_function(
        "() => (document.querySelector('.fwb-wb-status') || {}).innerText.includes('autosave: saved')",
        timeout=60_000,
    )
    before, X_before = _snapshot(nb, "before-crash")
    assert before["autosave"]["state"] == "saved" and before["autosave"]["saves"] >= 1
    assert Path(before["autosave"]["path"]).parent == recovery
    assert before["errors"] == [] and not before["interacting"]
    assert before["weights"]["jawOpen"] > 0.2
    assert np.array(before["offsets"])[brows["L"], 1] > 0.01
    _top(nb)
    shot_before = nb.canvas_shot("1-before-crash-canvas")
    nb.screenshot("1-before-crash")
    assert _aligned_change(fresh, shot_before) > 0.015, "the edits do not show in the viewport"

    # ---- mid-edit: press on the right brow marker, move, and kill the kernel meanwhile
    old_pid = int(_py(nb, "__import__('os').getpid()"))
    assert _parent_pid(old_pid) == lab.proc.pid, "not a kernel of the test's own JupyterLab"
    _tab(nb, "Sculpt", "sculpt")
    _top(nb)
    p = _handles_on_screen(nb)[brows["R"]]
    page.mouse.move(p[0], p[1])
    page.mouse.down()
    page.mouse.move(p[0] - 6, p[1] - 25, steps=10)
    _wait_py(nb, "model.interacting", bool, "the second drag started in the kernel")
    nb.screenshot("2-mid-edit")
    os.kill(old_pid, signal.SIGKILL)
    page.mouse.move(p[0] - 8, p[1] - 30, steps=3)
    page.mouse.up()

    # ---- the kernel comes back; run the notebook again
    new_pid = _wait_restarted(nb, old_pid)
    assert new_pid != old_pid
    page.evaluate("() => window.jupyterapp.commands.execute('notebook:clear-all-cell-outputs')")
    page.wait_for_function(
        "() => window.jupyterapp.shell.currentWidget.content.model.cells.get(1).executionCount"
        " === null"
    )
    nb.run_all()

    # ---- the recovery prompt shows (not the app); accept it with the mouse
    button = page.locator(".fwb-recover")
    button.first.wait_for(state="visible", timeout=60_000)
    assert button.count() == 1
    text = button.first.inner_text()
    assert text.startswith("Recover workbench: autosaved") and "5084 vertices" in text, text
    assert page.locator(".fwb-start-fresh").is_visible()
    assert page.locator(".fwb-viewport").count() == 0, "the app must wait for the choice"
    page.locator(".fwb-recovery").first.evaluate("e => e.scrollIntoView({block: 'start'})")
    _dismiss_dialogs(nb)
    # the kernel that ran the notebook is still the one that came back (no second death)
    assert int(_py(nb, "__import__('os').getpid()", timeout=10)) == new_pid
    nb.screenshot("4-recovery-prompt")
    _dismiss_dialogs(nb)
    button.first.click()
    _show_workbench(nb)

    after, X_after = _snapshot(nb, "recovered")
    for key in _COMPARED:
        assert after[key] == before[key], f"{key}: {after[key]} != {before[key]}"
    assert json.loads(json.dumps(after["tracks"])) == json.loads(json.dumps(before["tracks"]))
    err = float(np.abs(X_after - X_before).max())
    assert err < 1e-6, f"the recovered face differs by {err}"
    status = page.locator(".fwb-wb-status").inner_text()
    assert "5084 vertices" in status, status
    shot_after = nb.canvas_shot("5-recovered-canvas")
    nb.screenshot("5-recovered")
    changed = _aligned_change(shot_before, shot_after)
    assert changed < 0.008, f"{changed:.2%} of the viewport differs from before the crash"
    assert _aligned_change(fresh, shot_after) > 0.015, "the recovered edits do not show"
    # the half-done drag of the right brow is the only thing lost
    assert np.array(after["offsets"])[brows["R"]].tolist() == [0.0, 0.0, 0.0]
    assert page.locator(".fwb-errors").inner_text().strip() == ""
