"""Benchmark: FaceModel.evaluate() with 52 shapes, and save/load of the workbench file.

Run: .venv/bin/python benchmarks/bench_evaluate.py [--resolutions base 25k 100k]

Peers measured in the same run:
  * ``einsum``: a straightforward float64 ``V + einsum('k,knc->nc', w, D)``;
  * ``per-key loop``: one float64 ``+= w_k * D_k`` per shape key, which is how
    a shape-key stack is commonly evaluated (Blender needs 14-17 ms at 100k,
    see shared/notes/performance-anchors.md).
Goal (issue #2): evaluate() <= 2 ms at 100k with all 52 weights non-zero.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import workbench
from workbench.fileformat import load_model


def timeit(fn: Callable[[], object], repeat: int = 30) -> tuple[float, float]:
    """Median and minimum wall time in ms."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), min(times)


def bench_resolution(res: str) -> list[str]:
    t0 = time.perf_counter()
    model = workbench.load_sample("head", resolution=res)
    first_load = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    names = model.shape_names
    V = model.vertices
    D64 = model.deltas.astype(np.float64)
    rows = []

    def ours_all() -> object:
        model.pipeline.invalidate()  # measure the computation, not the cache
        return model.evaluate()

    model.set_weights({n: float(w) for n, w in zip(names, rng.uniform(0.05, 1.0, len(names)), strict=True)})
    w = model.weight_vector().astype(np.float64)
    med, mn = timeit(ours_all)
    e_med, _ = timeit(lambda: V + np.einsum("k,knc->nc", w, D64), repeat=10)

    def per_key() -> np.ndarray:
        out = V.copy()
        for k in range(len(w)):
            out += w[k] * D64[k]
        return out

    l_med, _ = timeit(per_key, repeat=10)
    np.testing.assert_allclose(model.evaluate(), per_key(), atol=1e-4)
    rows.append(
        f"| {res:>5} | {model.n_vertices:>7} | 52 active | {med:7.3f} | {mn:7.3f} | {e_med:8.2f} | {l_med:8.2f} | {l_med / med:5.1f}x |"
    )
    model.reset_weights()
    model.set_weights({"jawOpen": 0.7, "mouthSmileLeft": 0.4, "mouthSmileRight": 0.4})
    med3, mn3 = timeit(ours_all)
    rows.append(f"| {res:>5} | {model.n_vertices:>7} |  3 active | {med3:7.3f} | {mn3:7.3f} |        - |        - |     - |")

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "head.fwb"
        s_med, _ = timeit(lambda: model.save(p), repeat=3)
        l_med2, _ = timeit(lambda: load_model(p), repeat=3)
        size = p.stat().st_size / 2**20
    io_row = f"| {res:>5} | {model.n_vertices:>7} | {s_med:8.1f} | {l_med2:8.1f} | {size:7.1f} | {first_load:8.2f} |"
    return [*rows, io_row]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k", "100k"])
    args = ap.parse_args()
    eval_rows, io_rows = [], []
    for res in args.resolutions:
        r = bench_resolution(res)
        eval_rows += r[:2]
        io_rows.append(r[2])
    print("evaluate(), 52 shapes, float32 (ours) vs float64 peers in the same run; times in ms")
    print("|   res | vertices |  weights  | ours med | ours min | einsum | per-key loop | loop/ours |")
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(eval_rows))
    print("\nworkbench file (.fwb) save / load, ms; first load_sample includes subdivision when not cached (s)")
    print("|   res | vertices |  save ms |  load ms | size MiB | load_sample s |")
    print("|---|---|---|---|---|---|")
    print("\n".join(io_rows))


if __name__ == "__main__":
    main()
