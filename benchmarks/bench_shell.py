"""Benchmark: linear-shell handle editing (Bickel et al. 2008, §4) on the subdivided sample head.

Run: .venv/bin/python benchmarks/bench_shell.py [--resolutions 25k 100k 300k] [--handles 89]

For each resolution: basis precompute (assemble + factor + solve H columns) with
CHOLMOD and with SuperLU, the per-drag update (full ``B @ u_H`` and the rank-1
update of one moved handle), and, measured in the same run, the peer
``igl.harmonic(V, F, b, bc, k=2)`` solving the biharmonic system per frame (what a
tool without a precomputed basis pays for every mouse move).
Goals (issue #4): precompute <= 2 s at 100k, <= 12 s at 500k; drag <= 1 ms at 100k,
<= 5 ms at 500k. The largest sample here is "300k" (317,669 vertices, 3 Loop levels).
"""

from __future__ import annotations

import argparse
import statistics
import time

import igl
import numpy as np

import workbench
from workbench.handle_presets import default_face_handles
from workbench.shell import ShellDeformer
from workbench.sparse_cholesky import cholmod_available


def ms(fn, repeat: int = 20) -> float:
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e3


def handles_for(n_handles: int) -> np.ndarray:
    base = workbench.load_sample("head")
    per_side = n_handles // 2 + 6
    h = default_face_handles(base, per_side=per_side)
    ids = h.vertices[:n_handles]
    return ids  # Loop subdivision keeps original vertices first: valid at every level


def bench_resolution(res: str, H: np.ndarray, no_peer_above: int) -> tuple:
    m = workbench.load_sample("head", resolution=res)
    V, F = m.vertices, m.faces
    backends = ["cholmod", "superlu"] if cholmod_available() else ["superlu"]
    pre: dict[str, float] = {}
    d = None
    for b in backends:
        if b == "superlu" and m.n_vertices > 150_000:
            continue  # minutes and many GB; the anchors note has the number
        t0 = time.perf_counter()
        d = ShellDeformer(
            V, F, H, backend=b, component_labels=m.component_labels,
            component_names=m.component_names,
        )
        pre[b] = time.perf_counter() - t0
    assert d is not None
    uH = np.random.default_rng(0).normal(scale=0.05, size=(len(H), 3))
    full = ms(lambda: d.displacement(uH))
    d.reset(uH)
    step = [0]

    def one() -> None:
        step[0] += 1
        d.update(3, [0.0, 0.01 * (step[0] % 7), 0.0])

    rank1 = ms(one, repeat=50)
    peer = float("nan")
    if m.n_vertices <= no_peer_above:
        # igl.harmonic needs every component constrained: give it the skin only
        skin = m.component_vertices("skin")
        keep = np.isin(F, skin).all(axis=1)
        remap = np.full(m.n_vertices, -1, np.int64)
        remap[skin] = np.arange(skin.size)
        Fs = remap[F[keep]]
        t0 = time.perf_counter()
        igl.harmonic(V[skin], Fs, remap[H], V[H] + uH, 2)
        peer = (time.perf_counter() - t0) * 1e3
    nan = float("nan")
    return (res, m.n_vertices, len(H), pre.get("cholmod", nan), pre.get("superlu", nan), full, rank1, peer)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolutions", nargs="+", default=["25k", "100k", "300k"])
    ap.add_argument("--handles", type=int, default=89)
    ap.add_argument("--no-peer-above", type=int, default=150_000,
                    help="skip the slow igl.harmonic peer above this many vertices")
    args = ap.parse_args()
    H = handles_for(args.handles)
    rows = [bench_resolution(res, H, args.no_peer_above) for res in args.resolutions]
    print(f"linear shell, H = {len(H)} handles (k_s, k_b defaults); times on this machine")
    print("| res | vertices | H | precompute CHOLMOD s | precompute SuperLU s | drag: B@u_H ms | drag: rank-1 ms | peer igl.harmonic k=2 per frame ms | peer / ours (rank-1) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = r[7] / r[6] if np.isfinite(r[7]) else float("nan")
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.2f} | {r[4]:.2f} | {r[5]:.2f} | {r[6]:.3f} | {r[7]:.0f} | {ratio:.0f}x |")


if __name__ == "__main__":
    main()
