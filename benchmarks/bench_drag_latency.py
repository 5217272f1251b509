"""Handle-drag latency in a real browser: pointer move -> new pixels, at several mesh sizes.

For each sample resolution it opens a notebook with ``widgets.Workbench`` in
JupyterLab (Debian Chromium, software WebGL), loads the default handle set,
switches the viewport to its sculpt tool, presses the mouse on the left
mouth-corner marker and drags it:

* ``step``: one pointer move at a time (6 px zig-zag), waiting for the frame
  that shows it before the next. This is the latency of one isolated update:
  pointermove -> JSON message -> ``model.move_handle`` (rank-1 shell update) ->
  ``evaluate`` -> binary patch -> three.js upload + normals + render.
* ``continuous``: an 80-event sweep out and back with ~16 ms between pointer
  events (mouse-like; each Playwright call adds a few ms, so about 40-50
  events/s). The front end keeps one move in flight and sends the newest
  position when the previous one is acknowledged (its geometry patch arrived),
  so this shows how many updates per second the whole loop sustains and the
  latency under load.

Latency is measured in the page (``performance.now()``): from the pointer
event's timestamp to the end of the first render that shows the geometry of
that move (the viewport's ``fwbDragStats`` hook), so it includes the browser's
work but not the compositor's final present (< one display frame).

The kernel columns come from ``Viewport.drag_ms``: the time of one
``move_handle`` call, and the part of it spent in the viewport's geometry
push (``drag_push_ms``: ``evaluate`` with the rank-1 shell update, diff against
what the browser has, serialise, send); "edit" is the rest (offsets, events).

Usage::

    .venv/bin/python benchmarks/bench_drag_latency.py [--trials 20] [--resolutions base 25k 100k]
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

from browser_session import NotebookPage, chromium_missing, each_resolution

_SETUP = """
import json, time
import numpy as np
import workbench, widgets
from workbench.methods.handles.presets import default_face_handles
model = workbench.load_sample("head", resolution="{res}")
model.handles.set(default_face_handles(model))
_skin = model.component_labels == model.component_names.index("skin")
_V = np.asarray(model.vertices)
_d = np.linalg.norm(model.shape("mouthSmileLeft").delta, axis=1) * _skin
_top = np.argsort(-_d)[:40]
_corner = int(_top[np.argmax(_V[_top, 0])])
HANDLE = int(np.argmin(np.linalg.norm(_V[model.handles.vertices] - _V[_corner], axis=1)))
# Build the shell basis now (it is built on the first move otherwise) and time it.
_t = time.perf_counter()
model.move_handle(HANDLE, [1e-3, 0, 0]); model.evaluate()
PRECOMPUTE_S = time.perf_counter() - _t
model.handles.reset_offsets()
wb = widgets.show_workbench(model)
wb.viewport.tool = "sculpt"
"""

_LAST_STAT = """(e) => e.fwbDragStats.length ? e.fwbDragStats[e.fwbDragStats.length - 1] : null"""

#: the draft frames' times since the last call (bench_viewport_latency's hook records them)
_CLEAR_DRAFTS = "() => (window.__fwbDraftT || []).splice(0)"


def _pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, round(q * (len(s) - 1)))] if s else float("nan")


def _med(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def _parts(st: dict[str, float]) -> tuple[float, float, float]:
    """(input -> send, send -> ack, ack -> frame) of one drag update, ms."""
    return (st["send"] - st["input"], st["ack"] - st["send"], st["frame"] - st["ack"])


def _stats_count(nb: NotebookPage) -> int:
    return int(nb.viewport(0).evaluate("e => e.fwbDragStats.length"))


#: step mode of the last measure(): pointer move -> first pixels (a draft or the full frame), ms
FIRST_MS: list[float] = []


def measure(nb: NotebookPage, trials: int) -> dict[str, Any]:
    page = nb.page
    FIRST_MS.clear()
    vp = nb.viewport(0)
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
    page.wait_for_timeout(500)
    k = nb.kernel_eval("import json; print(json.dumps(HANDLE))")
    x, y, _front = vp.evaluate("e => e.fwbMarkers()")[k]
    nb.kernel_eval("wb.viewport.drag_ms.clear(); wb.viewport.drag_push_ms.clear()")
    out: dict[str, Any] = {}

    # --- step: one move at a time
    page.mouse.move(x, y)
    page.mouse.down()
    page.wait_for_timeout(300)
    lat: list[float] = []
    render: list[float] = []
    parts: list[tuple[float, float, float]] = []
    for i in range(trials + 2):  # the first two warm up the path
        n0 = _stats_count(nb)
        dx = 6.0 * (1 + i % 4) * (1 if i % 2 == 0 else -1) * 0.5
        page.evaluate(_CLEAR_DRAFTS)
        page.mouse.move(x + dx, y - abs(dx) * 0.5)
        page.wait_for_function(
            "([e, n]) => e.fwbDragStats.length > n", arg=[vp.element_handle(), n0]
        )
        st = vp.evaluate(_LAST_STAT)
        if i >= 2 and st and st.get("frame") is not None:
            lat.append(st["frame"] - st["input"])
            # the GPU path draws the predicted drag (and a fast-interaction draft) first
            drafts = [t for t in page.evaluate(_CLEAR_DRAFTS) if t >= st["input"]]
            FIRST_MS.append(min([st["frame"], *drafts]) - st["input"])
            parts.append(_parts(st))
            render.append(float(vp.get_attribute("data-render-ms") or "nan"))
        page.wait_for_timeout(80)
    page.mouse.up()
    page.wait_for_timeout(500)
    kernel = nb.kernel_eval(
        "import json; print(json.dumps([list(wb.viewport.drag_ms), list(wb.viewport.drag_push_ms)]));"
        "wb.viewport.drag_ms.clear(); wb.viewport.drag_push_ms.clear()"
    )
    out["step"] = (lat, render, kernel, (float("nan"), float("nan")), parts)

    # --- continuous: as fast as the browser sends moves
    x, y, _front = vp.evaluate("e => e.fwbMarkers()")[k]
    page.mouse.move(x, y)
    page.mouse.down()
    page.wait_for_timeout(300)
    n0 = _stats_count(nb)
    # ~60 pointer events per second like a mouse (Playwright alone sends them as fast
    # as the page takes them, and Chromium then starves the websocket's tasks)
    steps = 80
    t_sweep = time.perf_counter()
    for i in range(1, steps + 1):
        f = 1 - abs(2 * i / steps - 1)  # out and back
        page.mouse.move(x + 60 * f, y - 30 * f)
        page.wait_for_timeout(16)
    events_per_s = steps / (time.perf_counter() - t_sweep)
    page.wait_for_timeout(800)
    page.mouse.up()
    page.wait_for_timeout(500)
    stats = vp.evaluate("(e, n) => e.fwbDragStats.slice(n)", n0)
    done = [s for s in stats if s.get("frame") is not None]
    lat = [s["frame"] - s["input"] for s in done]
    span = (done[-1]["frame"] - done[0]["input"]) / 1e3 if len(done) > 1 else float("nan")
    ups = len(done) / span if span and span == span else float("nan")
    kernel = nb.kernel_eval(
        "import json; print(json.dumps([list(wb.viewport.drag_ms), list(wb.viewport.drag_push_ms)]))"
    )
    out["continuous"] = (lat, [], kernel, (events_per_s, ups), [_parts(s) for s in done])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k", "100k"])
    args = ap.parse_args()
    if chromium_missing():
        return 2

    def run(res: str, nb: NotebookPage) -> list[tuple[Any, ...]]:
        rows: list[tuple[Any, ...]] = []
        n, pre = nb.kernel_eval("import json; print(json.dumps([model.n_vertices, PRECOMPUTE_S]))")
        results = measure(nb, args.trials)
        for mode, (lat, rms, (total, push), (eps, ups), parts) in results.items():
            core = [t - p for t, p in zip(total, push, strict=False)]
            split = [_med([p[i] for p in parts]) for i in range(3)]
            rows.append(
                (res, n, pre, mode, _med(lat), _pct(lat, 0.9), len(lat), eps, ups,
                 *split, _med(rms), _med(total), _med(core), _med(push))
            )  # fmt: skip
        nb.screenshot(f"after-{res}")
        return rows

    rows = each_resolution("drag", args.resolutions, lambda res: _SETUP.replace("{res}", res), run)

    print()
    print("Handle drag latency, pointer move -> first render showing the new geometry (ms)")
    print("  step: isolated moves; continuous: 80-event sweep at <= 60 events/s, one move in")
    print("  flight (the newest position wins)")
    print("  ev/s: pointer events per second Playwright managed to send (it waits for the page);")
    print("  upd/s: geometry updates rendered per second during the sweep")
    print("  in>send: pointer event -> message sent (waits while a move is in flight);")
    print("  send>ack: message -> kernel -> geometry patch + ack back; ack>frame: -> render done")
    print("  render: JS upload + normals + draw (step mode); kernel: one move_handle call =")
    print("  edit (offsets, events) + eval+send (rank-1 shell update in evaluate, diff, comm send)")
    print(f"{'resolution':>10} {'vertices':>9} {'basis s':>8} {'mode':>11} {'median':>7} "
          f"{'p90':>7} {'n':>3} {'ev/s':>5} {'upd/s':>6} {'in>send':>7} {'send>ack':>8} {'ack>frame':>9} "
          f"{'render':>7} {'kernel':>7} {'edit':>6} {'eval+send':>9}")  # fmt: skip
    for res, n, pre, mode, med, p90, count, eps, ups, a, b, c, rms, tot, core, push in rows:
        print(f"{res:>10} {n:>9} {pre:8.2f} {mode:>11} {med:7.1f} {p90:7.1f} {count:>3} "
              f"{eps:5.1f} {ups:6.1f} {a:7.1f} {b:8.1f} {c:9.1f} {rms:7.1f} {tot:7.2f} {core:6.2f} {push:9.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
