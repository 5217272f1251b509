"""Timeline playback rate in a real browser: frames the viewport actually draws per second.

For each sample resolution it opens a notebook in JupyterLab (Debian Chromium,
software WebGL) with ``widgets.Viewport`` above ``TimelineWidget`` and three
keyed expressions (jawOpen 0 s, smile 1 s, browInnerUp 2 s; every frame moves
the mouth and brows), ticks *Loop*, presses **Play** with the mouse, waits
``--warmup`` seconds, then measures for ``--seconds``:

* ``kernel fps``: ``model.set_time`` calls per second made by the playback task
  (counted with a ``model.events.time`` listener in the kernel);
* ``dropped``: frames the playback task skipped because the previous one was late
  (share of the frames due);
* ``viewport fps``: geometry updates the viewport rendered per second
  (its ``data-frame`` + ``data-draft-frame`` hooks, read in the page: a view whose
  full frame is slow draws fast-interaction drafts while the clip plays) — what a
  user sees move;
* ``renders/s``: all viewport renders (``data-render-count``; includes renders
  without new geometry);
* ``set_time ms`` / ``push ms``: kernel median per frame for ``set_time``
  (evaluate + every listener, the viewport's diff+send included) and for the
  viewport's geometry push alone;
* ``render ms``: the viewport's own JS time per render (``data-render-ms``:
  upload + normals + draw call), sampled every 0.2 s;
* ``page rAF/s``: animation frames the page ran per second (a counter on
  ``requestAnimationFrame``): near 60 means the page's main thread had time to
  spare, near ``viewport fps`` means the page itself (JS or rasterising) is the limit;
* ``draft``: whether the viewport drew at half resolution while playing (it does
  on software WebGL, see ``softwareWebGL()`` in ``widgets/js/src/viewport.js``).

Both viewport paths run in the same session (``--paths gpu stream``): ``gpu``
(``Viewport.gpu = True``: the browser plays the timeline's per-frame parameters
on its own clock, the kernel only moves the playhead, so ``kernel fps`` is 0)
and ``stream`` (the kernel evaluates every frame and streams vertex rows).

In the stream path, playback sends a frame only while fewer than ``FRAMES_IN_FLIGHT`` frames are
not yet drawn by the browser (see ``widgets/timeline/``), so ``kernel fps``
equals ``viewport fps`` when the browser is the bottleneck.

Then presses **Pause**. Prints one row per resolution and target fps.

Usage::

    .venv/bin/python benchmarks/bench_playback.py [--resolutions base 25k] [--fps 30 60] [--seconds 6] [--paths gpu stream]
"""

from __future__ import annotations

import argparse
import time

from browser_session import NotebookPage, chromium_missing, each_resolution

_SETUP = """
import ipywidgets as W
import widgets, workbench
from widgets.timeline import TimelineWidget
model = workbench.load_sample("head", resolution="{res}")
model.set_weights({{"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0}})
model.expressions.save("smile")
model.reset_weights()
model.key_expression(0.0, "jawOpen")
model.key_expression(1.0, "smile")
model.key_expression(2.0, "browInnerUp")
model.set_time(0.0)
vp = widgets.Viewport(model, height=360)
tl = TimelineWidget(model)
W.VBox([vp, tl])
"""

_COUNTER = """
import json, time
if "_bench_n" not in globals():
    _bench_n = [0]
    model.events.time.connect(lambda _t: _bench_n.__setitem__(0, _bench_n[0] + 1))
print(json.dumps([_bench_n[0], time.perf_counter(), tl.frames_dropped]))
"""

_PAGE_COUNTERS = """() => {
  const e = document.querySelector('.fwb-viewport');
  if (window.__fwbRaf === undefined) {
    window.__fwbRaf = 0;
    const tick = () => { window.__fwbRaf++; requestAnimationFrame(tick); };
    requestAnimationFrame(tick);
  }
  // full-detail frames + fast-interaction drafts (a slow view drafts while a clip plays)
  return [Number(e.getAttribute('data-frame')) + Number(e.getAttribute('data-draft-frame') || 0),
          Number(e.getAttribute('data-render-count')),
          performance.now(), window.__fwbRaf];
}"""


def _median(xs: list[float]) -> float:
    s = sorted(xs)
    return s[len(s) // 2] if s else float("nan")


def measure(nb: NotebookPage, fps: float, warmup: float, seconds: float, gpu: bool) -> dict[str, float]:
    page = nb.page
    root = page.locator(".fwb-timeline")
    nb.kernel_eval(f"vp.gpu = {gpu}")
    page.wait_for_function(
        "(g) => document.querySelector('.fwb-viewport').getAttribute('data-gpu') === g",
        arg="1" if gpu else "0", timeout=120000,
    )
    nb.kernel_eval(
        f"model.timeline.set(model.tracks.replace(fps={fps}), 'bench fps'); model.set_time(0.0)"
    )
    if not root.locator(".fwb-tl-loop").is_checked():
        root.locator(".fwb-tl-loop").check()
    nb.kernel_eval(_COUNTER)
    nb.kernel_eval("vp.push_ms.clear()")
    root.locator(".fwb-tl-play").click()
    page.wait_for_function("() => document.querySelector('.fwb-timeline')"
                           ".getAttribute('data-playing') === '1'", timeout=20000)  # fmt: skip
    time.sleep(warmup)
    draft = nb.viewport(0).get_attribute("data-draft") == "1"
    n0, k0, d0 = nb.kernel_eval(_COUNTER)
    f0, r0, p0, a0 = page.evaluate(_PAGE_COUNTERS)
    render_ms = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        time.sleep(0.2)
        render_ms.append(float(nb.viewport(0).get_attribute("data-render-ms") or "nan"))
    f1, r1, p1, a1 = page.evaluate(_PAGE_COUNTERS)
    n1, k1, d1 = nb.kernel_eval(_COUNTER)
    stats = nb.kernel_eval("import json; print(json.dumps(tl.playback_stats))")
    push = nb.kernel_eval("import json; print(json.dumps(list(vp.push_ms)))")
    nb.screenshot(f"playing-{fps:g}-{'gpu' if gpu else 'stream'}")
    # force: during playback the page never idles long enough for Playwright's
    # "element is stable" check, which is about animation, not about the button
    root.locator(".fwb-tl-pause").click(force=True)
    page.wait_for_function("() => document.querySelector('.fwb-timeline')"
                           ".getAttribute('data-playing') === '0'", timeout=20000)  # fmt: skip
    kernel_fps = (n1 - n0) / (k1 - k0)
    dropped = d1 - d0
    return {
        "kernel_fps": kernel_fps,
        "dropped": dropped / max(dropped + (n1 - n0), 1),
        "viewport_fps": (f1 - f0) / ((p1 - p0) / 1e3),
        "renders": (r1 - r0) / ((p1 - p0) / 1e3),
        "raf": (a1 - a0) / ((p1 - p0) / 1e3),
        "set_time_ms": float(stats.get("set_time_ms", float("nan"))),
        "push_ms": _median(push),
        "render_ms": _median(render_ms),
        "draft": draft,
        "browser": bool(stats.get("browser")),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k"])
    ap.add_argument("--fps", nargs="+", type=float, default=[30.0])
    ap.add_argument("--warmup", type=float, default=1.5)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--paths", nargs="+", default=["gpu", "stream"], choices=["gpu", "stream"])
    args = ap.parse_args()
    if chromium_missing():
        return 2

    def run(res: str, nb: NotebookPage) -> list[tuple]:
        page = nb.page
        page.evaluate("() => { const s = window.jupyterapp.shell;"
                      " if (!s.leftCollapsed) s.collapseLeft(); }")  # fmt: skip
        nb.viewport(0).evaluate("e => e.scrollIntoView({block: 'start'})")
        page.wait_for_timeout(500)
        n = nb.kernel_eval("import json; print(json.dumps(model.n_vertices))")
        return [(res, n, fps, path, measure(nb, fps, args.warmup, args.seconds, path == "gpu"))
                for fps in args.fps for path in args.paths]

    rows = each_resolution("playback", args.resolutions, lambda res: _SETUP.format(res=res), run)

    print()
    print(f"Timeline playback in JupyterLab + Chromium (software WebGL), {args.seconds:g} s "
          "per row after warm-up")  # fmt: skip
    print("  kernel fps: set_time calls/s; viewport fps: geometry frames the viewport rendered/s")
    print(f"{'resolution':>10} {'vertices':>9} {'path':>6} {'target':>7} {'kernel fps':>10} {'dropped':>8} "
          f"{'viewport fps':>12} {'renders/s':>9} {'set_time ms':>11} {'push ms':>8} "
          f"{'render ms':>9} {'page rAF/s':>10} {'draft':>5}")  # fmt: skip
    for res, n, fps, path, m in rows:
        print(f"{res:>10} {n:>9} {path:>6} {fps:7.0f} {m['kernel_fps']:10.1f} {m['dropped']:8.0%} "
              f"{m['viewport_fps']:12.1f} {m['renders']:9.1f} {m['set_time_ms']:11.2f} "
              f"{m['push_ms']:8.2f} {m['render_ms']:9.1f} {m['raf']:10.1f} "
              f"{'yes' if m['draft'] else 'no':>5}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
