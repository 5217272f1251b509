"""Benchmark: which voluntary regions should enhancement match in (Bermano et al. 2014, §4.3)?

Run: .venv/bin/python benchmarks/bench_enhance_regions.py

The §7 validation of ``tests/test_enhance_spatial.py`` (procedural detailed
performance of the 25k head: the six example expressions + the first half of
``performance_weights(120)`` train, every 4th frame of the second half is held
out), enhanced with four choices of regions, everything else equal:

* **one region** — the whole face matched at once (the naive peer);
* **names** — ``face_voluntary_cores``: the vertices the brow / mouth shapes move
  most (needs ARKit-like names);
* **motion, shapes** — ``motion_regions`` on the rig's shapes (neutral + each
  delta), then ``voluntary_cores_from_motion``: no names used;
* **motion, database** — the same clustering on the database's own frames (what a
  scanned database without a rig has).

Two faces: the sample head (inputs at the 5k head's vertices through the Loop
map) and the head warped, rotated and in centimetres driven by a smooth rig on a
re-triangulated base head through closest points (inputs carry no detail). Per
choice: median over held-out frames of enhanced / input RMS error and of the
detail band ``x − f(x)`` (lower is better), over the frames with detail to add
(input band > 0.01 mm: the second face's frames at rest have none, their error
is 0).

Measured (2 shared cores beside the browser suite and two CPU hogs, 2026-11-28;
106 s), median enhanced / input over the frames with detail, error / band:

=====================  ======================  ==================================
regions                sample head             warped head, other mesh (cm)
=====================  ======================  ==================================
one region             0.841 / 0.480           1.061 / 0.512
names                  0.833 / 0.473           0.663 / 0.330
motion, shapes         0.833 / 0.474           0.692 / 0.326
motion, database       0.833 / 0.474           0.699 / 0.329
=====================  ======================  ==================================

Regions from motion do as well as the names' without reading a name (the
names' cores are tighter on the lips; the motion's take the whole mouth and
jaw), and all beat one region, which on the warped head adds detail where the
face barely moved. Clustering takes 0.4–1.1 s at 20k vertices.
"""

from __future__ import annotations

import time

import numpy as np

import workbench
from workbench.enhance import Correspondence, PerformanceDatabase
from workbench.enhance.motion_regions import motion_regions, voluntary_cores_from_motion
from workbench.enhance.voluntary import face_voluntary_cores, voluntary_region_weights
from workbench.geometry.axes import face_axes
from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor, performance_weights
from workbench.rigging import synthetic as syn

N_PERF = 120


def rms_mm(a: np.ndarray, b: np.ndarray, mpu: float) -> np.ndarray:
    return np.sqrt(((np.asarray(a) - np.asarray(b)) ** 2).sum(-1).mean(-1)) * mpu * 1e3


def band(db: PerformanceDatabase, X: np.ndarray) -> np.ndarray:
    return np.stack([x - db.lowpass(x) for x in X])


def main() -> None:
    t_all = time.perf_counter()
    fine = workbench.load_sample("head", "25k")
    base = workbench.load_sample("head", "base")
    sc = WrinkleSculptor(fine)
    W = performance_weights(N_PERF)
    train_w = list(EXAMPLE_POSES.values()) + W[: N_PERF // 2]
    test_w = W[N_PERF // 2 :: 4]
    V = np.asarray(fine.vertices, np.float64)
    F = np.asarray(fine.faces, np.int64)
    shapes = V + np.stack([np.asarray(s.delta, np.float64) for s in fine.shapes])
    rig = WrinkleSculptor(base)
    V2, F2, Wmap = syn.split_remesh(base.vertices, base.faces, seed=5)
    warp = syn.sample_head_warp()
    rows: dict[str, list[str]] = {}
    for face in ("sample", "warped"):
        move = (lambda P: np.asarray(P, np.float64)) if face == "sample" else warp
        mpu = fine.metadata.metres_per_unit if face == "sample" else 0.01
        neutral = move(sc.detail_of(V))
        train = np.stack([move(sc.detailed(w)) for w in train_w])
        truth = np.stack([move(sc.detailed(w)) for w in test_w])
        # the warped head's left/up/front: the sample's, turned by the warp's rotation
        axes = face_axes(fine) if face == "sample" else face_axes(fine) @ np.asarray(warp.rotation).T
        sigma = 0.1 * fine.metadata.metres_per_unit / mpu
        t0 = time.perf_counter()
        choices: dict[str, dict[str, np.ndarray] | None] = {"one region": None}
        choices["names"] = face_voluntary_cores(fine)
        by_shapes = motion_regions(neutral, F, np.stack([move(s) for s in shapes]))
        choices["motion, shapes"] = voluntary_cores_from_motion(neutral, by_shapes, axes)
        by_db = motion_regions(neutral, F, train)
        choices["motion, database"] = voluntary_cores_from_motion(neutral, by_db, axes)
        print(f"{face}: regions found in {time.perf_counter() - t0:.1f} s: "
              + "; ".join(f"{k}: " + ", ".join(f"{n} {len(v)}" for n, v in c.items())
                          for k, c in choices.items() if c), flush=True)
        if face == "sample":
            corr = Correspondence.loop(base.faces, base.n_vertices, 1)
            inputs = truth[:, : base.n_vertices]
        else:
            corr = Correspondence.from_surface(warp(V2), F2, neutral, F)
            inputs = np.stack([warp(Wmap @ rig.blend(w)) for w in test_w])
        for name, cores in choices.items():
            regions = None if cores is None else voluntary_region_weights(neutral, F, cores, sigma=sigma)
            db = PerformanceDatabase.from_frames(neutral, F, train, regions=regions, metres_per_unit=mpu)
            res = db.enhance_result(inputs, correspondence=corr)
            e_in, e_out = rms_mm(res.inputs, truth, mpu), rms_mm(res.frames, truth, mpu)
            bt = band(db, truth)
            b_in, b_out = rms_mm(band(db, res.inputs), bt, mpu), rms_mm(band(db, res.frames), bt, mpu)
            moving = b_in > 0.01
            cell = f"{np.median(e_out[moving] / e_in[moving]):.3f} / {np.median(b_out[moving] / b_in[moving]):.3f}"
            rows.setdefault(name, []).append(cell)
            print(f"  {name:18s} error {cell.split(' / ')[0]}  band {cell.split(' / ')[1]}  "
                  f"(mean band {b_out[moving].mean():.4f} vs input {b_in[moving].mean():.4f} mm)", flush=True)
    print(f"\n{'regions':22s} {'sample head err / band':24s} warped head, other mesh err / band")
    for name, cells in rows.items():
        print(f"{name:22s} {cells[0]:24s} {cells[1]}")
    print(f"({time.perf_counter() - t_all:.0f} s)")


if __name__ == "__main__":
    main()
