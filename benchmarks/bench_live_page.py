"""Live tab in a real browser: camera frame → drawn face, per stage, and the rate kept (issue 30).

Chromium's fake camera plays the sample head rendered with known weights
(``tests/capture_takes.py``: jaw ramp, blink, head turn; 640×480, looped) into
the Workbench's **Live** tab in JupyterLab (Debian Chromium, software WebGL),
for ``--seconds`` at each sample resolution. The page itself measures each
frame (``widgets/js/src/camera.js``, its ``data-latency`` report):

* ``grab``: the video frame drawn into a canvas and JPEG-encoded;
* ``wait``: encoded → sent (the next frame is encoded while one is in
  flight, timed to be ready about when the ack comes);
* ``kernel``: decode, FaceMesh, the solve, the face's update sent (as the
  kernel's ack says);
* ``transport``: the rest of the send → ack round trip (websocket, server,
  the kernel's queue);
* ``draw``: ack → the second animation frame after it (an upper bound: the
  face's update reaches the page before the ack and is drawn by the first);
* ``total``: grab → drawn.

Prints median / p90 per stage (ms) and the frames/s the page sent and the kernel
acked (one frame in flight: the round trip's pace is the rate). Targets (issue 30):
≥ 15 frames/s at 640×480 and ≤ 150 ms camera → face on 2 CPU cores.

Usage::

    .venv/bin/python benchmarks/bench_live_page.py [--seconds 20] [--resolutions base 25k]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from browser_session import REPO, NotebookPage, chromium_missing, each_resolution

sys.path.insert(0, str(REPO / "tests"))
from capture_takes import render_take, write_y4m

STAGES = ("grab", "wait", "kernel", "transport", "draw", "total")


def fake_camera(folder: Path) -> Path:
    import workbench

    frames = render_take(workbench.load_sample("head"))
    wide = np.full((frames.shape[0], 480, 640, 3), 235, np.uint8)
    wide[:, :, 80:560] = frames
    path = folder / "take.y4m"
    write_y4m(path, wide)
    return path


def setup_cell(res: str) -> str:
    return (f"import workbench, widgets\nmodel = workbench.load_sample('head', {res!r})\n"
            "wb = widgets.show_workbench(model)")


def measure(seconds: float):
    def run(res: str, nb: NotebookPage) -> list[tuple]:
        page = nb.page
        page.evaluate("() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }")
        page.locator(".fwb-tabs .lm-TabBar-tab", has_text="Live").click()
        page.locator(".fwb-live-start").click()
        cam = page.locator(".fwb-camera")
        deadline = time.monotonic() + 120
        while cam.get_attribute("data-camera") not in ("on", "error") or not cam.get_attribute("data-latency"):
            if time.monotonic() > deadline:
                raise TimeoutError(f"the camera did not start: {cam.get_attribute('data-error')}")
            page.wait_for_timeout(200)
        if cam.get_attribute("data-camera") != "on":
            raise RuntimeError(f"camera: {cam.get_attribute('data-error')}")
        page.wait_for_timeout(2000)  # FaceMesh and the registration settle
        s0, a0, t0 = int(cam.get_attribute("data-sent")), int(cam.get_attribute("data-acked")), time.monotonic()
        page.wait_for_timeout(1000 * seconds)
        s1, a1, t1 = int(cam.get_attribute("data-sent")), int(cam.get_attribute("data-acked")), time.monotonic()
        report = json.loads(cam.get_attribute("data-latency"))
        page.locator(".fwb-live-start").click()
        nb.screenshot(f"live-{res}")
        return [(res, report["n"], *[report["stages"][k] for k in STAGES], (s1 - s0) / (t1 - t0),
                 (a1 - a0) / (t1 - t0))]
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k"])
    args = ap.parse_args()
    if chromium_missing():
        sys.exit(1)
    with tempfile.TemporaryDirectory(prefix="fwb-live-") as tmp:
        cam = fake_camera(Path(tmp))
        switches = ("--use-fake-device-for-media-stream", f"--use-file-for-fake-video-capture={cam}",
                    "--use-fake-ui-for-media-stream")
        rows = each_resolution("live", args.resolutions, setup_cell, measure(args.seconds),
                               viewport={"width": 1500, "height": 1200}, browser_args=switches)
    print(f"\nLive tab, camera frame → drawn face (ms, median / p90 over the last ≤120 frames), {args.seconds:g} s each")
    print(f"{'mesh':<6} {'frames':>6} " + " ".join(f"{k:>14}" for k in STAGES) + f" {'sent/s':>7} {'acked/s':>8}")
    for res, n, *st, sent, acked in rows:
        cells = " ".join(f"{m:6.1f} / {p:5.1f}" if m is not None else f"{'–':>14}" for m, p in st)
        print(f"{res:<6} {n:>6} {cells} {sent:7.1f} {acked:8.1f}")


if __name__ == "__main__":
    main()
