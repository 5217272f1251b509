"""Benchmark: one iteration of example-based rig refinement (issue 16 item 3, Li et al. 2010 §3).

Run: .venv/bin/python benchmarks/bench_rig_refine.py [--resolutions base 25k] [--iterations 3] [--repeat 3]

The paper's setting: an 11k-vertex template, 29 blendshapes, 14 training
poses, 45 s per iteration (unoptimised, 2010). Goal: one iteration <= 5 s at
~11k vertices. The sample head comes at 5,084 ("base") and 20,051 ("25k",
one Loop step) vertices; there is no 11k level, so both are measured (the
cost is linear in the vertex count: 11k lies between them, and the 20k row is
the conservative check).

Set-up: 29 of the sample's ARKit shapes; the examples are poses of an
"actor" whose shapes are the sample's scaled (×0.65–1.35) and turned
(±0.3 rad) by smooth per-shape fields (:func:`workbench.testing.restyled_shapes`), 2–4 shapes per pose at weights in
[0.4, 1]; the rough weights are the true ones ± up to 0.3.

Measured, from the progress callback of ``refine_rig``:

* **set-up** — frames of the rig and the examples, regularisation weights,
  one CHOLMOD factorisation per shape (kept for all iterations);
* **iteration** — step A (per-triangle blend solve for all shapes at once +
  one Poisson back-substitution per shape) and step B (per-example bounded
  QP); the median over the iterations after the first and over repeats;
* **peer, same run**: the vertex-space fit (``space="vertex"``, the paper's
  ablation: the same energy on vertex displacements, no reconstruction).

The machine is shared and noisy: compare rows of one run, not across runs.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import workbench
from workbench.geometry.sparse_cholesky import cholmod_available
from workbench.model import FaceModel
from workbench.rigging import refine_rig
from workbench.testing import restyled_shapes

#: 29 shapes, as the paper's rig: brows, eyes, cheeks, nose, jaw and mouth, both sides
SHAPES = [
    "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "eyeBlinkLeft", "eyeBlinkRight", "eyeWideLeft", "eyeWideRight", "eyeSquintLeft",
    "eyeSquintRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
    "noseSneerRight", "jawOpen", "jawLeft", "jawRight", "mouthClose", "mouthSmileLeft",
    "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight", "mouthPucker", "mouthFunnel",
    "mouthStretchLeft", "mouthStretchRight", "mouthUpperUpLeft",
]  # fmt: skip
N_EXAMPLES = 14


def build(resolution: str) -> tuple[FaceModel, list[np.ndarray], list[dict[str, float]]]:
    head = workbench.load_sample("head", resolution=resolution)
    rig = FaceModel(
        head.vertices,
        head.faces,
        [head.shape(nm) for nm in SHAPES],
        polygons=head.polygons,
        component_labels=head.component_labels,
        component_names=head.component_names,
        metadata=head.metadata,
    )
    V = rig.vertices
    actor = restyled_shapes(rig, gain=0.35, turn=0.3, wavelength=0.4).deltas.astype(np.float64)
    rng = np.random.default_rng(1)
    examples, rough = [], []
    for _ in range(N_EXAMPLES):
        idx = rng.choice(len(actor), size=rng.integers(2, 5), replace=False)
        w = rng.uniform(0.4, 1.0, idx.size)
        examples.append(V + np.tensordot(w, actor[idx], axes=1))
        noisy = np.clip(w + rng.uniform(-0.3, 0.3, idx.size), 0.0, 1.0)
        rough.append({SHAPES[i]: float(x) for i, x in zip(idx, noisy, strict=True)})
    return rig, examples, rough


def timed_run(
    rig: FaceModel,
    examples: list[np.ndarray],
    rough: list[dict[str, float]],
    iterations: int,
    space: str,
) -> dict[str, object]:
    marks: list[tuple[float, str]] = []
    t0 = time.perf_counter()
    res = refine_rig(
        rig,
        examples,
        rough,
        iterations=iterations,
        space=space,  # type: ignore[arg-type]
        progress=lambda f, m: marks.append((time.perf_counter() - t0, m)),
    )
    total = time.perf_counter() - t0
    starts = [t for t, m in marks if m.endswith(")") and ": blendshapes" in m]
    weights_at = [t for t, m in marks if ": weights" in m]
    done = next(t for t, m in marks if m == "done")
    ends = [*starts[1:], done]
    return {
        "setup": starts[0],
        "iterations": [e - s for s, e in zip(starts, ends, strict=True)],
        "step_a": [w - s for s, w in zip(starts, weights_at, strict=True)],
        "step_b": [e - w for w, e in zip(weights_at, ends, strict=True)],
        "total": total,
        "fit": float(res.errors[:, -1].mean() / res.initial_errors.mean()),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k"])
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    print(
        f"CHOLMOD: {'yes' if cholmod_available() else 'no (SuperLU)'}; "
        f"{len(SHAPES)} shapes, {N_EXAMPLES} examples, {args.iterations} iterations per run, "
        f"{args.repeat} runs\n"
    )
    print(
        "| vertices | triangles | method | set-up s | one iteration s (median) | step A s | step B s "
        "| fit after / before |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for resolution in args.resolutions:
        rig, examples, rough = build(resolution)
        for space, label in (
            ("gradient", "ours: gradient space (Li §3)"),
            ("vertex", "peer: vertex-space fit (Li §4 ablation)"),
        ):
            runs = [
                timed_run(rig, examples, rough, args.iterations, space) for _ in range(args.repeat)
            ]
            per_it = [t for r in runs for t in r["iterations"][1:] or r["iterations"]]  # type: ignore[index]
            a = [t for r in runs for t in r["step_a"][1:] or r["step_a"]]  # type: ignore[index]
            b = [t for r in runs for t in r["step_b"][1:] or r["step_b"]]  # type: ignore[index]
            setup = statistics.median(float(r["setup"]) for r in runs)  # type: ignore[arg-type]
            print(
                f"| {rig.n_vertices:,} | {len(rig.faces):,} | {label} | {setup:.2f} | "
                f"{statistics.median(per_it):.2f} | {statistics.median(a):.2f} | "
                f"{statistics.median(b):.3f} | {runs[0]['fit']:.3f} |"
            )
    print(
        "\nLi et al. 2010: 45 s per iteration at 11k vertices, 29 shapes, 14 poses (2010 hardware)."
    )


if __name__ == "__main__":
    main()
