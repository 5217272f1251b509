"""Benchmark: live tracking from camera frames, per stage, and what it recovers (issue 30).

Run: .venv/bin/python benchmarks/bench_live.py [--loops 3]

The camera: the sample head rendered at 480×480 into 640×480 frames playing a
known take (``tests/capture_takes.py``: a jawOpen ramp 0 → 1, a blink, a head turn
of ±10°), JPEG-encoded as the page sends them, looped ``--loops`` times. The
kernel side of the Live tab per frame: JPEG decode, FaceMesh landmarks, the
solve (pose + weights; with the rig adapting every ``adapt_every`` frames), and
the face update (``model.set_weights`` with the Workbench's views subscribed).

Tables:

1. milliseconds per stage, median / p90, and the frames/s the kernel sustains
   (the page sends the next frame only after the kernel's ack: this is the rate);
2. what the take recovers against the truth: jawOpen correlation and amplitude
   (the tracked peak over the true 1.0), the blink's weight, the RMSE over all
   shapes (the truth is 0 for every shape but jawOpen and the blinks);
3. adaptation on an actor who is not the rig (the head under the capture tests'
   smooth warp: longer nose and chin): the landmark fit error over the first and
   the last 10 frames, adapting or not.
"""

from __future__ import annotations

import argparse
import io
import sys
import time
from pathlib import Path

import numpy as np

import workbench
from workbench.capture import LiveTracker

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from capture_takes import BLINK, JAW, render_take, warped_actor


def camera_frames(model, loops: int) -> list[bytes]:
    from PIL import Image

    out = []
    for img in render_take(model):
        wide = np.full((480, 640, 3), 235, np.uint8)
        wide[:, 80:560] = img
        buf = io.BytesIO()
        Image.fromarray(wide).save(buf, format="JPEG", quality=80)
        out.append(buf.getvalue())
    return out * loops


def run(model, jpegs, *, adapt: bool, adapt_every: int = 5, workbench_view=None, calibrate: int = 0):
    """Push the frames; ``calibrate``: a range calibration over the first that many frames."""
    from widgets.live.camera import decode_jpeg

    live = LiveTracker(model, adapt=adapt, adapt_every=adapt_every)
    if calibrate:
        live.begin_range()
    stages: dict[str, list[float]] = {"decode": [], "landmarks": [], "solve": [], "face": [], "total": []}
    for f, data in enumerate(jpegs):
        t0 = time.perf_counter()
        img = decode_jpeg(data)
        t1 = time.perf_counter()
        fr = live.push(img, f / 30.0)
        t2 = time.perf_counter()
        if calibrate and f == calibrate - 1:
            live.end_range()
        if workbench_view is not None and fr.ok:
            model.set_weights(dict(zip(model.shape_names, fr.weights.tolist(), strict=True)))
        t3 = time.perf_counter()
        if f == 0:
            continue  # the first frame registers (once per session)
        stages["decode"].append(t1 - t0)
        stages["landmarks"].append(fr.seconds.get("landmarks", 0.0))
        stages["solve"].append(fr.seconds.get("solve", 0.0))
        stages["face"].append(t3 - t2)
        stages["total"].append(t3 - t0)
    live.close()
    return live.take(), stages


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--loops", type=int, default=3)
    args = ap.parse_args()
    from widgets import Workbench

    head = workbench.load_sample("head")
    jpegs = camera_frames(head, args.loops)
    names = list(head.shape_names)
    wb = Workbench(head, height=240)  # the views a live session updates
    print(f"camera: 640×480 JPEG frames, {len(jpegs)} frames; the sample head rig ({head.n_vertices} vertices)")
    print(f"{'setting':26s} " + " ".join(f"{s + ' ms':>16s}" for s in ("decode", "landmarks", "solve", "face", "total"))
          + f" {'frames/s':>9s}")
    takes = {}
    for label, adapt, every in (("adapt off (default)", False, 5), ("adapt every 5", True, 5),
                                ("adapt every frame", True, 1)):
        take, st = run(head, jpegs, adapt=adapt, adapt_every=every, workbench_view=wb)
        takes[label] = take
        cells = [f"{1000 * np.median(v):7.1f} /{1000 * np.percentile(v, 90):6.1f}" for v in st.values()]
        print(f"{label:26s} " + " ".join(f"{c:>16s}" for c in cells) + f" {1.0 / np.median(st['total']):9.1f}")
    takes["range calibrated (loop 1)"] = run(head, jpegs, adapt=False, calibrate=JAW.size)[0]
    wb.close()

    print("\nagainst the truth (median over the loops)")
    print(f"{'setting':26s} {'jaw corr':>8s} {'jaw peak':>8s} {'blink':>6s} {'RMSE':>6s}")
    T = JAW.size
    truth = np.zeros((T, len(names)))
    truth[:, names.index("jawOpen")] = JAW
    truth[:, names.index("eyeBlinkLeft")] = BLINK
    truth[:, names.index("eyeBlinkRight")] = BLINK
    for label, take in takes.items():
        W = take.weights[-T:]  # the last loop: settled
        jaw = W[:, names.index("jawOpen")]
        blink = W[:, [names.index("eyeBlinkLeft"), names.index("eyeBlinkRight")]].mean(1)
        rmse = float(np.sqrt(np.mean((W - truth) ** 2)))
        print(f"{label:26s} {np.corrcoef(jaw, JAW)[0, 1]:8.3f} {jaw.max():8.2f} "
              f"{blink[BLINK == 1].mean() - blink[BLINK == 0].mean():6.2f} {rmse:6.3f}")

    from workbench.testing import warped

    actor = warped(head, warped_actor(head), shapes=True, name="actor").model
    ajpegs = camera_frames(actor, args.loops)
    print("\nan actor who is not the rig (warped head): landmark fit error (model units) and weight RMSE, "
          "first loop vs last loop")
    print(f"{'setting':26s} {'err 1st':>8s} {'err last':>8s} {'ratio':>6s} {'RMSE 1st':>8s} {'RMSE last':>9s} "
          f"{'jaw peak':>8s}")
    for label, adapt, every in (("adapt off (default)", False, 5), ("adapt every 5", True, 5),
                                ("adapt every frame", True, 1)):
        take, _ = run(head, ajpegs, adapt=adapt, adapt_every=every)
        e, W = take.errors, take.weights
        a, b = float(np.nanmean(e[1:T])), float(np.nanmean(e[-T + 1:]))
        r1 = float(np.sqrt(np.mean((W[:T] - truth) ** 2)))
        r2 = float(np.sqrt(np.mean((W[-T:] - truth) ** 2)))
        print(f"{label:26s} {a:8.4f} {b:8.4f} {a / b:6.2f} {r1:8.3f} {r2:9.3f} "
              f"{W[-T:, names.index('jawOpen')].max():8.2f}")


if __name__ == "__main__":
    main()
