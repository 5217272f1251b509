"""Benchmark: pose-space wrinkles per frame (Bickel et al. 2008, §6.2) on the subdivided sample head.

Run: .venv/bin/python benchmarks/bench_wrinkles.py [--resolutions 25k 100k 300k] [--handles 89] [--repeat 30]

A full frame is the large-scale ``u = B·u_H`` (H = 89 handles), vertex normals
and local frames of the large-scale mesh, and WPSD with P = 6 example poses
plus the rest pose (16 edges per vertex at most), composed into positions.
Measured in the same run: the numba kernels (2 threads, BLAS limited to one
thread so the two pools never spin against each other) and the numpy peer
(BLAS ``B @ u_H``, scipy sparse WPSD, bincount normals). Also: the fit time
(details of 6 procedural examples + per-vertex systems) and a second normal
update (for rendering the detailed mesh). "drag frame" is what one handle drag in
the workbench pays: the rank-1 update of the large-scale displacement
(``ShellDeformer.update``, the handle layer's cache) + normals, frames and WPSD. Goals (issue #5): <= 6 ms at 100k,
<= 33 ms at 500k (the largest sample here is "300k", 317,669 vertices).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from threadpoolctl import threadpool_limits

import workbench
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.handles.shell import ShellDeformer
from workbench.methods.wrinkles import kernels as _kernels
from workbench.methods.wrinkles.examples import WrinkleSculptor
from workbench.methods.wrinkles.hybrid_deformer import HybridDeformer


def timed(fn, repeat: int) -> float:
    fn(0)
    ts = []
    for i in range(repeat):
        t0 = time.perf_counter()
        fn(i + 1)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e3


def handles_for(n_handles: int) -> np.ndarray:
    base = workbench.load_sample("head")
    h = default_face_handles(base, per_side=n_handles // 2 + 6)
    return np.asarray(h.vertices[:n_handles])  # Loop keeps base vertex ids valid at every level


def bench(res: str, H: np.ndarray, repeat: int) -> dict[str, float]:
    m = workbench.load_sample("head", resolution=res)
    t0 = time.perf_counter()
    shell = ShellDeformer(m.vertices, m.faces, H, component_labels=m.component_labels, component_names=m.component_names)
    t_shell = time.perf_counter() - t0
    sculptor = WrinkleSculptor(m)
    examples = np.stack(list(sculptor.examples().values()))  # P = 6
    t0 = time.perf_counter()
    hd = HybridDeformer(shell)
    t_graph = time.perf_counter() - t0
    t0 = time.perf_counter()
    ps = hd.fit(examples)
    t_fit = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    rest_h = m.vertices[H]
    # a drag: handle positions between the examples, different every frame
    poses = [examples[i % 6][H] * 0.6 + rest_h * 0.4 + rng.normal(0, 0.002, rest_h.shape) for i in range(repeat + 1)]
    out = np.empty((m.n_vertices, 3), np.float32)
    ev_nb = hd.evaluator("numba")
    ev_np = hd.evaluator("numpy")
    X = hd.frame(poses[0])
    row = {
        "n": m.n_vertices,
        "F": len(hd.graph),
        "K": int(np.diff(ps.alpha.matrix.indptr).max()),
        "shell": t_shell,
        "graph": t_graph,
        "fit": t_fit,
    }
    with threadpool_limits(1):  # numba frame loop: no BLAS threads around
        row["full_numba"] = timed(lambda i: hd.frame(poses[i], backend="numba", out=out), repeat)
        uH = np.ascontiguousarray((poses[1] - rest_h), np.float32)
        row["bu_numba"] = timed(lambda i: _kernels.bmul_add(shell.basis_, uH, hd._rest32, out), repeat)
        row["normals_numba"] = timed(lambda i: ev_nb.normals(X), repeat)
        f = hd.graph.strain(poses[1])
        row["wpsd_numba"] = timed(lambda i: ev_nb.apply(X, f, 1.0, out=out), repeat)
        shell.reset(poses[0] - rest_h)
        j = 3  # a brow handle moving up and down, as in a drag
        X_drag = np.empty_like(out)

        def drag(i: int) -> None:
            u = shell.update(j, poses[0][j] - rest_h[j] + [0.0, 0.01 * (i % 7), 0.0])
            np.add(hd._rest32, u, out=X_drag)
            p = poses[0].copy()
            p[j, 1] += 0.01 * (i % 7)
            ev_nb.apply(X_drag, hd.graph.strain(p), 1.0, out=out)

        row["drag_numba"] = timed(drag, repeat)
    row["full_numpy"] = timed(lambda i: hd.frame(poses[i], backend="numpy", out=out), max(5, repeat // 3))
    row["wpsd_numpy"] = timed(lambda i: ev_np.apply(X, f, 1.0, out=out), max(5, repeat // 3))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolutions", nargs="+", default=["25k", "100k", "300k"])
    ap.add_argument("--handles", type=int, default=89)
    ap.add_argument("--repeat", type=int, default=30)
    a = ap.parse_args()
    H = handles_for(a.handles)
    print(f"H = {H.size} handles, P = 6 examples + rest, numba available: {_kernels.AVAILABLE}")
    print(
        "| mesh | V | F edges | K | shell basis s | fit s | B·u_H numba ms | normals numba ms | "
        "WPSD+frames numba ms | **full frame numba ms** | **drag frame numba ms** | WPSD numpy ms | "
        "full frame numpy ms | numpy / numba (full frame) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for res in a.resolutions:
        r = bench(res, H, a.repeat)
        print(
            f"| {res} | {r['n']:,} | {r['F']} | {r['K']} | {r['shell']:.2f} | {r['graph'] + r['fit']:.2f} | "
            f"{r['bu_numba']:.2f} | {r['normals_numba']:.2f} | {r['wpsd_numba']:.2f} | **{r['full_numba']:.2f}** | "
            f"**{r['drag_numba']:.2f}** | {r['wpsd_numpy']:.1f} | {r['full_numpy']:.1f} | "
            f"{r['full_numpy'] / r['full_numba']:.1f}x |",
            flush=True,
        )
    print("full frame = B·u_H + normals + frames + WPSD (+ composition); drag frame = rank-1 update + the same;")
    print("'WPSD+frames' includes the normals of the vertices that have details; a second normal update for")
    print("rendering costs the 'normals' column again. Goals: <= 6 ms at 100k, <= 33 ms at 500k.")


if __name__ == "__main__":
    main()
