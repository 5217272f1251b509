"""The viewport on the GPU vs streaming vertex rows (issue 19), in a real browser.

For each sample resolution it opens ``widgets.show_workbench`` (default handles,
sculpt tool) in JupyterLab + Debian Chromium (software WebGL: SwiftShader) and
measures both paths of the same viewport in the same run, ``Viewport.gpu = True``
(the rig evaluated in the browser, :mod:`widgets.viewport.gpu`) and ``False``
(today's streaming of evaluated vertex rows, the peer):

* first pixels: the same inputs -> the first frame showing them at all, a
  fast-interaction draft (``Viewport.fast_interaction``: a simplified face evaluated
  on the GPU at its own vertices, drawn while parameters change when the view's full
  frame is slow) or the full frame; sliders move the face in the page before the
  kernel answers (``Viewport.follow_sliders``);
* ``slider``: a click on the jawOpen slider's track -> the first full-detail frame showing it, drawn:
  each render with new geometry ends with a one-pixel readback, so the time includes the
  GPU's (SwiftShader's) work, not only issuing the WebGL calls (``--no-sync``: issuing only);
  ``python``: ``model.set_weight`` sent as an execute request -> the same render
  (``bench_viewport_latency.measure``);
* ``drag``: isolated handle-marker moves with the mouse -> the first render showing
  each (``bench_drag_latency.measure``, step mode);
* ``payload``: bytes of each geometry message the kernel sent during the slider
  clicks / the drag (JSON + binary buffers, counted around ``Viewport.send``);
* ``texture MB``: what the GPU path holds in textures and render targets
  (``data-gpu-texture-bytes``) vs the rig's float32 vertex data (neutral + the
  52 shapes' deltas + the shell basis, ``rig MB``);
* ``eval ms`` / ``draw ms``: the GPU path's two passes and one draw of the scene,
  synchronised by a one-pixel readback (``el.fwbGpuTime``).

The machine is shared and noisy: compare the two paths within one run.

Usage::

    .venv/bin/python benchmarks/bench_gpu_viewport.py [--trials 12] [--resolutions 25k 100k 300k]
"""

from __future__ import annotations

import argparse
import statistics
from typing import Any

import bench_drag_latency
import bench_viewport_latency
from bench_drag_latency import _SETUP as DRAG_SETUP
from bench_drag_latency import measure as drag_measure
from bench_viewport_latency import measure as slider_measure
from browser_session import NotebookPage, chromium_missing, each_resolution

_RECORD = """
import json
if "_SIZES" not in globals():
    _SIZES = []
    _orig_send = wb.viewport.send
    def _send(content, buffers=None):
        if isinstance(content, dict) and content.get("type") in ("patch", "gpu_params"):
            _SIZES.append(len(json.dumps(content)) + sum(len(b) for b in buffers or []))
        return _orig_send(content, buffers)
    wb.viewport.send = _send
_SIZES.clear()
"""

#: --no-sync: frame times when the render's WebGL calls return (the older benchmarks' rule)
SYNC = True

_RIG = """
import json
B, _c = model.handles.basis()
print(json.dumps([model.n_vertices * 3 * 4 * (1 + len(model.shape_names)) + B.nbytes,
                  int(model.n_vertices)]))
"""


def _med(xs: list[float]) -> float:
    return statistics.median(xs) if xs else float("nan")


def _pct(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, round(q * (len(s) - 1)))] if s else float("nan")


def _mp(xs: list[float]) -> str:
    """median / p90"""
    return f"{_med(xs):5.1f} / {_pct(xs, 0.9):5.1f}"


def _sizes(nb: NotebookPage) -> list[int]:
    out = nb.kernel_eval("print(json.dumps(_SIZES)); _SIZES.clear()")
    return out if out else []


def measure(nb: NotebookPage, gpu: bool, trials: int) -> dict[str, Any]:
    page = nb.page
    vp = nb.viewport(0)
    nb.kernel_eval(f"wb.viewport.gpu = {gpu}")
    page.wait_for_function(
        "(g) => document.querySelector('.fwb-viewport').getAttribute('data-gpu') === g",
        arg="1" if gpu else "0", timeout=120000,
    )
    nb.kernel_eval(_RECORD)
    # frame times once the GPU has drawn the frame (a one-pixel readback after each render
    # with new geometry): WebGL calls return before SwiftShader has drawn anything
    page.evaluate(f"() => {{ globalThis.fwbSyncFrames = {'true' if SYNC else 'false'}; }}")
    out: dict[str, Any] = {}
    page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Shapes").click()
    nb.kernel_eval('wb.viewport.tool = "orbit"')
    res = slider_measure(nb, trials)
    out["slider"] = res["slider jawOpen"][0]
    out["python"] = res["python jawOpen"][0]
    out["slider_first"] = bench_viewport_latency.FIRST_MS["slider jawOpen"]
    out["python_first"] = bench_viewport_latency.FIRST_MS["python jawOpen"]
    sizes = _sizes(nb)
    out["slider_bytes"] = _med([float(s) for s in sizes])
    nb.kernel_eval('wb.viewport.tool = "sculpt"')
    d = drag_measure(nb, trials)
    out["drag"] = d["step"][0]
    out["drag_first"] = list(bench_drag_latency.FIRST_MS)
    out["draft_tris"] = int(vp.get_attribute("data-draft-triangles") or 0)
    out["full_ms"] = float(vp.get_attribute("data-full-frame-ms") or "nan")
    out["drag_bytes"] = _med([float(s) for s in _sizes(nb)])
    out["tex"] = float(vp.get_attribute("data-gpu-texture-bytes") or "nan") if gpu else float("nan")
    t = vp.evaluate("e => e.fwbGpuTime ? e.fwbGpuTime(8) : null") if gpu else None
    out["eval_ms"] = t["evalMs"] if t else float("nan")
    out["draw_ms"] = t["drawMs"] if t else float("nan")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=12)
    ap.add_argument("--resolutions", nargs="+", default=["25k", "100k", "300k"])
    ap.add_argument("--no-sync", action="store_true", help="do not wait for the GPU to draw each frame")
    args = ap.parse_args()
    global SYNC
    SYNC = not args.no_sync
    if chromium_missing():
        return 2

    def run(res: str, nb: NotebookPage) -> list[tuple[Any, ...]]:
        rig, n = nb.kernel_eval(_RIG)
        rows = []
        for gpu in (True, False):
            m = measure(nb, gpu, args.trials)
            rows.append((res, n, "gpu" if gpu else "stream", m, rig))
            nb.screenshot(f"{res}-{'gpu' if gpu else 'stream'}")
        return rows

    rows = each_resolution("gpu", args.resolutions, lambda res: DRAG_SETUP.replace("{res}", res), run)
    print()
    print("Fast interaction (GPU path): input -> first pixels, a draft of the face or the full")
    print("  frame, whichever came first (ms, median / p90); full ms: the view's calibration of")
    print("  one full evaluation + draw; the full mesh follows each burst of changes (table below)")
    print(f"{'resolution':>10} {'vertices':>9} {'path':>6} {'slider':>13} {'python':>13} {'drag':>13} "
          f"{'draft tris':>10} {'full ms':>7}")  # fmt: skip
    for res, n, path, m, _rig in rows:
        print(f"{res:>10} {n:>9} {path:>6} {_mp(m['slider_first']):>13} {_mp(m['python_first']):>13} "
              f"{_mp(m['drag_first']):>13} {m['draft_tris']:>10} {m['full_ms']:7.1f}")  # fmt: skip
    print()
    print("Viewport on the GPU vs streaming, input -> first full-detail render showing it (ms, median / p90)")
    print("  bytes: median size of one geometry message (JSON + buffers) for a slider / drag update")
    print(f"{'resolution':>10} {'vertices':>9} {'path':>6} {'slider':>13} {'python':>13} {'drag':>13} "
          f"{'slider B':>9} {'drag B':>8} {'texture MB':>10} {'rig MB':>7} {'eval ms':>7} {'draw ms':>7}")  # fmt: skip
    for res, n, path, m, rig in rows:
        print(f"{res:>10} {n:>9} {path:>6} {_mp(m['slider']):>13} {_mp(m['python']):>13} "
              f"{_mp(m['drag']):>13} {m['slider_bytes']:9.0f} {m['drag_bytes']:8.0f} "
              f"{m['tex'] / 1e6:10.1f} {rig / 1e6:7.1f} {m['eval_ms']:7.1f} {m['draw_ms']:7.1f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
