"""Viewport latency in a real browser: input -> new pixels, at several mesh sizes.

For each sample resolution it opens a notebook with ``widgets.Workbench`` in
JupyterLab (Debian Chromium, software WebGL) and measures, over ``--trials``
trials each:

* ``slider``: a mouse click on the jawOpen slider's track (``pointerdown`` time
  in the page) -> the viewport's first render showing the new geometry
  (``data-frame-time``). This is the whole loop a user feels: ipywidgets comm
  message -> ``model.set_weight`` -> viewport diff -> binary patch -> three.js
  upload + normals + render.
* ``python``: ``model.set_weight`` sent from the page as an execute request
  (as another cell would) -> the same render.

Prints a table of median and p90 (ms). The goal is <= 50 ms median at 25k.
Timing is on the page's clock (``performance.now()``), so it includes the
browser's work but not the compositor's final present (< one display frame).

Usage::

    .venv/bin/python benchmarks/bench_viewport_latency.py [--trials 20] [--resolutions base 25k 100k]
"""

from __future__ import annotations

import argparse
import statistics
import time

from browser_session import NotebookPage, chromium_missing, each_resolution

_HOOK = """() => {
  if (window.__fwbHook) return;
  window.__fwbHook = true;
  window.__fwbT0 = null;
  window.__fwbDraftT = [];
  document.addEventListener('pointerdown', () => { window.__fwbT0 = performance.now(); }, true);
  // the fast-interaction drafts (widgets/js/src/viewport/gpu_draft.js): data-frame counts
  // full-detail frames only, so the first pixels are the first draft's, if any
  const e = document.querySelector('.fwb-viewport');
  new MutationObserver(() => window.__fwbDraftT.push(Number(e.getAttribute('data-draft-frame-time'))))
    .observe(e, {attributes: true, attributeFilter: ['data-draft-frame-time']});
}"""

#: per trial of the last measure(): input -> first pixels (a draft or the full frame), ms
FIRST_MS: dict[str, list[float]] = {}


def _first_pixels(nb: NotebookPage, t0: float, full: float) -> float:
    drafts = [t for t in nb.page.evaluate("() => window.__fwbDraftT.splice(0)") if t >= t0]
    return min([full, *drafts]) - t0

_PY_TRIGGER = """async ([code]) => {
  const kernel = window.jupyterapp.shell.currentWidget.sessionContext.session.kernel;
  window.__fwbT0 = performance.now();
  kernel.requestExecute({code, silent: true, store_history: false});
  return window.__fwbT0;
}"""


RENDER_MS: list[float] = []
WAIT_MS: list[float] = []  # geometry message arrived -> frame rendered


def _frame_time_after(nb: NotebookPage, previous: int, timeout: float = 30.0) -> float:
    nb.wait_frame_after(0, previous, timeout=timeout)
    vp = nb.viewport(0)
    RENDER_MS.append(float(vp.get_attribute("data-render-ms") or "nan"))
    frame_t = float(vp.get_attribute("data-frame-time") or "nan")
    WAIT_MS.append(frame_t - float(vp.get_attribute("data-update-time") or "nan"))
    return frame_t


def _pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, round(q * (len(s) - 1)))]


def _python_trials(nb: NotebookPage, shape: str, trials: int) -> list[float]:
    out = []
    first = FIRST_MS.setdefault(f"python {shape}", [])
    for i in range(trials):
        prev = nb.frame(0)
        value = 0.1 + 0.8 * ((i * 7) % 10) / 10
        nb.page.evaluate("() => window.__fwbDraftT.splice(0)")
        t0 = float(nb.page.evaluate(_PY_TRIGGER, [f'model.set_weight("{shape}", {value:.3f})']))
        t1 = _frame_time_after(nb, prev)
        out.append(t1 - t0)
        first.append(_first_pixels(nb, t0, t1))
        nb.page.wait_for_timeout(120)
    return out


def measure(
    nb: NotebookPage, trials: int
) -> dict[str, tuple[list[float], list[float], list[float], list[float]]]:
    """Per trigger: (latencies, JS render ms, message->frame ms, kernel push ms)."""
    page = nb.page
    page.evaluate(_HOOK)
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    page.locator(".fwb-slider-jawOpen").evaluate("e => e.scrollIntoView({block: 'center'})")
    page.wait_for_timeout(300)
    track = page.locator(".fwb-slider-jawOpen .noUi-base")
    results = {}
    fractions = [0.15, 0.85, 0.35, 0.65, 0.5, 0.95]

    def push_ms() -> list[float]:
        return nb.kernel_eval(  # type: ignore[no-any-return]
            "import json; print(json.dumps(list(wb.viewport.push_ms))); wb.viewport.push_ms.clear()"
        )

    push_ms()
    RENDER_MS.clear()
    WAIT_MS.clear()
    FIRST_MS.clear()
    lat = []
    first = FIRST_MS.setdefault("slider jawOpen", [])
    for i in range(trials):
        box = track.bounding_box()
        assert box is not None
        f = fractions[i % len(fractions)]
        prev = nb.frame(0)
        page.evaluate("() => window.__fwbDraftT.splice(0)")
        page.mouse.click(box["x"] + f * box["width"], box["y"] + box["height"] / 2)
        t1 = _frame_time_after(nb, prev)
        t0 = float(page.evaluate("() => window.__fwbT0"))
        lat.append(t1 - t0)
        first.append(_first_pixels(nb, t0, t1))
        # noUiSlider animates a tap for ~300 ms and drops a tap made meanwhile
        page.wait_for_timeout(500)
    time.sleep(0.8)  # let the slider interaction close
    results["slider jawOpen"] = (lat, list(RENDER_MS), list(WAIT_MS), push_ms())
    for shape in ("jawOpen", "eyeBlinkLeft"):
        RENDER_MS.clear()
        WAIT_MS.clear()
        lat = _python_trials(nb, shape, trials)
        results[f"python {shape}"] = (lat, list(RENDER_MS), list(WAIT_MS), push_ms())
    return results


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k", "100k"])
    args = ap.parse_args()
    if chromium_missing():
        return 2

    def setup_cell(res: str) -> str:
        return (
            "import workbench, widgets\n"
            f'model = workbench.load_sample("head", resolution="{res}")\n'
            "wb = widgets.show_workbench(model)"
        )

    def run(res: str, nb: NotebookPage) -> list[tuple]:
        rows = []
        n = nb.kernel_eval("import json; print(json.dumps(model.n_vertices))")
        moved = nb.kernel_eval(
            "import json, numpy as np; print(json.dumps({s.name: int("
            "(np.abs(s.delta).sum(1) > 0).sum()) for s in model.shapes}))"
        )
        for mode, (lat, rms, wms, pms) in measure(nb, args.trials).items():
            shape = mode.split()[-1]
            rows.append(
                (res, n, f"{moved[shape] / n:.0%}", mode, statistics.median(lat),
                 _pct(lat, 0.9), len(lat), statistics.median(rms), statistics.median(wms),
                 statistics.median(pms) if pms else float("nan"))
            )  # fmt: skip
        return rows

    rows = each_resolution("viewport", args.resolutions, setup_cell, run)

    print()
    print("Viewport latency, input -> first render showing the new geometry (ms)")
    print("  moved: share of vertices the shape moves (< 1/3 -> sparse patch, else full buffer)")
    print("  render: JS upload + normals + draw call; msg->frame: geometry message arrived ->")
    print("  frame rendered (includes render); kernel: evaluate + diff + serialise + send")
    print(f"{'resolution':>10} {'vertices':>9} {'moved':>6} {'trigger':>20} "
          f"{'median':>7} {'p90':>7} {'n':>3} {'render':>7} {'msg->frame':>10} {'kernel':>7}")  # fmt: skip
    for res, n, moved, mode, med, p90, count, rms, wms, pms in rows:
        print(f"{res:>10} {n:>9} {moved:>6} {mode:>20} {med:7.1f} {p90:7.1f} {count:>3} "
              f"{rms:7.1f} {wms:10.1f} {pms:7.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
