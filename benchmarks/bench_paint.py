"""Painterly blending benchmark: brush dab cost in the core, stroke -> pixels latency in a browser.

Part 1, **core** (no browser): for each sample resolution, time one brush dab
(``model.paint_dab`` inside a stroke: surface-distance Dijkstra + alpha-over of
the touched weights + the convexity guard + the undoable slot update) and the
``evaluate()`` after it (the paint layer recomputes only the touched vertices),
for the default brush radius (3% of the face height) and a 3x larger one.

Part 2, **browser** (JupyterLab + Debian Chromium, software WebGL): a
``widgets.Viewport`` with ``tool="paint"`` painting the saved expression
"smile" over the mouth with the real mouse:

* ``step``: one pointer move at a time (a 10 px zig-zag along the upper lip),
  waiting for the frame that shows it before the next. Latency = pointer event
  -> raycast -> JSON message -> ``model.paint_dab`` -> weight-overlay patch +
  geometry patch -> three.js colours/positions upload + normals + render (the
  viewport's ``fwbStrokeStats`` hook, page clock).
* ``continuous``: a 60-event sweep at ~16 ms per event; one message in flight,
  the dabs queued meanwhile go in the next message.

The kernel column is ``Viewport.paint_ms`` (one message: its dabs + overlay +
geometry send), "dab" is ``Viewport.dab_ms`` (one ``paint_dab``).

Usage::

    .venv/bin/python benchmarks/bench_paint.py [--trials 20] [--core base 25k 100k]
        [--browser 25k 100k]

The goal is <= 50 ms median stroke -> pixels at 25k.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np
from browser_session import NotebookPage, chromium_missing, each_resolution


def _med(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def _pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, round(q * (len(s) - 1)))] if s else float("nan")


def _mouth(model: Any, expression: str = "smile") -> tuple[list[int], int, int]:
    """Skin vertices the expression moves most, and the left / right mouth corners."""
    from workbench.methods.paint.expressions import expression_displacement

    skin = model.component_labels == model.component_names.index("skin")
    V = np.asarray(model.vertices)
    d = np.linalg.norm(expression_displacement(model, expression), axis=1) * skin
    top = np.argsort(-d)[:80]
    left = int(top[np.argmax(V[top, 0])])
    right = int(top[np.argmin(V[top, 0])])
    return [int(i) for i in top], left, right


# ----------------------------------------------------------------------------- core
def bench_core(resolutions: list[str], dabs: int = 40) -> list[tuple[Any, ...]]:
    import workbench
    from widgets.viewport import default_brush_radius
    from workbench.methods.paint.painting import Brush

    rows = []
    for res in resolutions:
        model = workbench.load_sample("head", resolution=res)
        model.set_weights({"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0})
        model.expressions.save("smile")
        model.reset_weights()
        top, _, _ = _mouth(model)
        t0 = time.perf_counter()
        surface = model.paint.surface
        setup = time.perf_counter() - t0
        model.evaluate()
        r0 = default_brush_radius(model)
        for scale in (1.0, 3.0):
            brush = Brush(radius=r0 * scale, opacity=0.5)
            dab_ms, eval_ms, touched = [], [], []
            with model.interaction("Paint smile"):
                for k in range(dabs):
                    v = top[k % len(top)]
                    touched.append(surface.within(v, brush.radius)[0].size)
                    t = time.perf_counter()
                    model.paint.dab("smile", v, brush)
                    t1 = time.perf_counter()
                    model.evaluate()
                    t2 = time.perf_counter()
                    dab_ms.append((t1 - t) * 1e3)
                    eval_ms.append((t2 - t1) * 1e3)
            model.undo()
            rows.append(
                (res, model.n_vertices, setup, brush.radius, int(np.median(touched)),
                 _med(dab_ms[2:]), _pct(dab_ms[2:], 0.9), _med(eval_ms[2:]))
            )  # fmt: skip
    return rows


# ----------------------------------------------------------------------------- browser
_SETUP = """
import json, time
import numpy as np
import workbench, widgets
from IPython.display import display
model = workbench.load_sample("head", resolution="{res}")
model.set_weights({"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0})
model.expressions.save("smile")
model.reset_weights()
_t = time.perf_counter(); model.paint.surface; SURFACE_S = time.perf_counter() - _t
vp = widgets.Viewport(model, height=560, tool="paint", brush_opacity=0.3)
vp.tools["paint"].expression = "smile"
display(vp)
"""

_LAST = "(e) => e.fwbStrokeStats.length ? e.fwbStrokeStats[e.fwbStrokeStats.length - 1] : null"


def _count(nb: NotebookPage) -> int:
    return int(nb.viewport(0).evaluate("e => e.fwbStrokeStats.length"))


def measure(nb: NotebookPage, trials: int, left: int, right: int) -> dict[str, Any]:
    page = nb.page
    vp = nb.viewport(0)
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    vp.evaluate("e => e.scrollIntoView({block: 'start'})")
    page.wait_for_timeout(500)
    a, b = nb.project([left, right])
    # along the upper lip: the mouth line raised by a tenth of the mouth width
    up = -0.1 * abs(a[0] - b[0])
    path = [
        (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]) + up) for f in np.linspace(0.1, 0.9, 8)
    ]
    bounce = path + path[-2:0:-1]  # back and forth along the lip
    nb.kernel_eval("vp.stroke_ms.clear(); vp.dab_ms.clear()")
    out: dict[str, Any] = {}

    # --- step
    page.mouse.move(*path[0])
    page.mouse.down()
    page.wait_for_timeout(300)
    lat: list[float] = []
    parts: list[tuple[float, float, float]] = []
    for i in range(trials + 2):
        n0 = _count(nb)
        x, y = bounce[(i + 1) % len(bounce)]
        page.mouse.move(x, y + (2 if i % 2 else -2))
        try:
            page.wait_for_function(
                "([e, n]) => e.fwbStrokeStats.length > n",
                arg=[vp.element_handle(), n0],
                timeout=5000,
            )
        except Exception:
            continue  # the move queued no dab (too close to the last one)
        st = vp.evaluate(_LAST)
        if i >= 2 and st and st.get("frame") is not None:
            lat.append(st["frame"] - st["input"])
            parts.append(
                (st["send"] - st["input"], st["ack"] - st["send"], st["frame"] - st["ack"])
            )
        page.wait_for_timeout(80)
    page.mouse.up()
    page.wait_for_timeout(500)
    kernel = nb.kernel_eval(
        "import json; print(json.dumps([list(vp.stroke_ms), list(vp.dab_ms)]));"
        "vp.stroke_ms.clear(); vp.dab_ms.clear()"
    )
    out["step"] = (lat, parts, kernel, float("nan"), float("nan"))

    # --- continuous
    page.mouse.move(*path[0])
    page.mouse.down()
    page.wait_for_timeout(300)
    n0 = _count(nb)
    steps = 60
    t_sweep = time.perf_counter()
    for i in range(1, steps + 1):
        f = 1 - abs(2 * i / steps - 1)
        x = path[0][0] + f * (path[-1][0] - path[0][0])
        y = path[0][1] + f * (path[-1][1] - path[0][1])
        page.mouse.move(x, y)
        page.wait_for_timeout(16)
    eps = steps / (time.perf_counter() - t_sweep)
    page.wait_for_timeout(800)
    page.mouse.up()
    page.wait_for_timeout(500)
    stats = vp.evaluate("(e, n) => e.fwbStrokeStats.slice(n)", n0)
    done = [s for s in stats if s.get("frame") is not None]
    lat = [s["frame"] - s["input"] for s in done]
    span = (done[-1]["frame"] - done[0]["input"]) / 1e3 if len(done) > 1 else float("nan")
    ups = len(done) / span if span and span == span else float("nan")
    kernel = nb.kernel_eval("import json; print(json.dumps([list(vp.stroke_ms), list(vp.dab_ms)]))")
    parts = [(s["send"] - s["input"], s["ack"] - s["send"], s["frame"] - s["ack"]) for s in done]
    out["continuous"] = (lat, parts, kernel, eps, ups)
    return out


def bench_browser(resolutions: list[str], trials: int) -> list[tuple[Any, ...]]:
    def run(res: str, nb: NotebookPage) -> list[tuple[Any, ...]]:
        rows: list[tuple[Any, ...]] = []
        page = nb.page
        n, left, right = nb.kernel_eval(
            "import json\n"
            "_s = model.component_labels == model.component_names.index('skin')\n"
            "_d = np.linalg.norm(model.expressions['smile'].displacement, axis=1) * _s\n"
            "_t = np.argsort(-_d)[:80]; _V = np.asarray(model.vertices)\n"
            "print(json.dumps([model.n_vertices, int(_t[np.argmax(_V[_t, 0])]),"
            " int(_t[np.argmin(_V[_t, 0])])]))"
        )
        for mode, (lat, parts, (msg_ms, dab_ms), eps, ups) in measure(
            nb, trials, left, right
        ).items():
            split = [_med([p[i] for p in parts]) for i in range(3)]
            rows.append(
                (res, n, mode, _med(lat), _pct(lat, 0.9), len(lat), eps, ups,
                 *split, _med(msg_ms), _med(dab_ms))
            )  # fmt: skip
        page.mouse.move(5, 5)
        nb.screenshot(f"after-{res}")
        return rows

    rows = each_resolution("paint", resolutions, lambda res: _SETUP.replace("{res}", res), run)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--core", nargs="*", default=["base", "25k", "100k"])
    ap.add_argument("--browser", nargs="*", default=["25k", "100k"])
    args = ap.parse_args()

    if args.core:
        rows = bench_core(args.core)
        print()
        print("Brush dab in the core (40 dabs over the mouth, opacity 0.5, smooth falloff)")
        print("  dab: model.paint_dab (Dijkstra within the radius + weights + undoable slot);")
        print("  eval: model.evaluate() after it (paint layer recomputes the touched rows only)")
        print(f"{'resolution':>10} {'vertices':>9} {'graph s':>8} {'radius':>7} {'touched':>8} "
              f"{'dab med':>8} {'dab p90':>8} {'eval med':>9}")  # fmt: skip
        for res, n, setup, r, touched, dmed, dp90, emed in rows:
            print(f"{res:>10} {n:>9} {setup:8.2f} {r:7.3f} {touched:>8} "
                  f"{dmed:8.2f} {dp90:8.2f} {emed:9.2f}")  # fmt: skip

    if args.browser:
        if chromium_missing():
            return 2
        rows = bench_browser(args.browser, args.trials)
        print()
        print("Paint stroke latency, pointer move -> first render showing the dab (ms)")
        print("  step: isolated moves; continuous: 60-event sweep at <= 60 events/s, one message")
        print("  in flight (dabs queued meanwhile go in the next message)")
        print("  in>send: pointer event -> message sent; send>ack: -> kernel dabs -> overlay +")
        print("  geometry patches back; ack>frame: -> colours/positions upload + normals + render")
        print("  kernel: one paint message (dabs + overlay + geometry send); dab: one paint_dab")
        print(f"{'resolution':>10} {'vertices':>9} {'mode':>11} {'median':>7} {'p90':>7} {'n':>3} "
              f"{'ev/s':>5} {'upd/s':>6} {'in>send':>7} {'send>ack':>8} {'ack>frame':>9} "
              f"{'kernel':>7} {'dab':>6}")  # fmt: skip
        for res, n, mode, med, p90, count, eps, ups, a, b, c, kms, dms in rows:
            print(f"{res:>10} {n:>9} {mode:>11} {med:7.1f} {p90:7.1f} {count:>3} {eps:5.1f} "
                  f"{ups:6.1f} {a:7.1f} {b:8.1f} {c:9.1f} {kms:7.2f} {dms:6.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
