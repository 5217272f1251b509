"""Benchmark: data-driven retiming of a key pair (Bermano et al. 2014, §6) against a 10k-frame database.

Run: .venv/bin/python benchmarks/bench_retime.py [--frames 10000] [--take 50] [--repeat 20]

The database is ``frames / take`` generated takes (neutral hold → transition with
a random monotone curve → hold → return) of 52 ARKit-like weights, and the same
takes as meshes of 500 vertices (``(T, 500, 3)``, 1500 numbers a frame). The key
pair is a held-out take's ends (poses with noise 0.01), ``n_frames = 48``.

Measured in the same run:

* ``retime`` — eq. 5 for both keys on every segment (numpy, one pass over the
  database), the eq. 6 DP per take, §6.2 on the matched take; also with
  ``extend=True``;
* peer "window search" — the brute-force alternative: for every take the
  distances of the keys to every frame and the best pair ``first < last`` from
  the full ``(T, T)`` table (frames only, no segments; ``O(T²)`` a take), then
  the matched frames' progress along the chord as the timing;
* peer "python DP" — the same eq. 5–6 written as plain Python loops over the
  frames (what a direct transcription of the paper costs).

No DTW library (``dtw-python``, ``tslearn``, ``dtaidistance``) is installed in
the venv; they would also answer a different question (frame-to-frame warping
with fixed ends, see :mod:`workbench.enhance.retime`). Goal (issue #18):
retime ≤ 100 ms against a 10k-frame database.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from threadpoolctl import threadpool_limits

from workbench.enhance import retime


def curve(rng: np.random.Generator):
    kind = rng.integers(3)
    p = rng.uniform(1.5, 4.0)
    if kind == 0:
        return lambda t: t**p
    if kind == 1:
        return lambda t: 1.0 - (1.0 - t) ** p
    c, k = rng.uniform(0.25, 0.75), rng.uniform(8.0, 16.0)

    def logistic(t):
        f = 1.0 / (1.0 + np.exp(-k * (t - c)))
        f0, f1 = 1.0 / (1.0 + np.exp(k * c)), 1.0 / (1.0 + np.exp(-k * (1.0 - c)))
        return (f - f0) / (f1 - f0)

    return logistic


def make_database(rng: np.random.Generator, frames: int, take: int, k: int = 52):
    seqs, truths = [], []
    for _ in range(frames // take):
        a, b = np.zeros(k), rng.uniform(0.0, 1.0, k)
        c = curve(rng)
        n = take - 3 - 3 - take // 4
        up = a + c(np.linspace(0, 1, n))[:, None] * (b - a)
        down = b + (np.linspace(0, 1, take // 4) ** 2)[:, None] * (a - b)
        seqs.append(np.vstack([np.repeat(a[None], 3, 0), up, np.repeat(b[None], 3, 0), down]))
        truths.append((a, b, c))
    return seqs, truths


def window_search(seqs, start, end, n_frames):
    """Brute force: best frame pair first < last over every take from the (T, T) table."""
    best = (math.inf, -1, -1, -1)
    for i, beta in enumerate(seqs):
        d0 = np.linalg.norm(beta - start, axis=1)
        d1 = np.linalg.norm(beta - end, axis=1)
        table = d0[:, None] + d1[None, :]
        table[np.tril_indices(len(beta))] = np.inf
        a, b = np.unravel_index(int(np.argmin(table)), table.shape)
        if table[a, b] < best[0]:
            best = (float(table[a, b]), i, int(a), int(b))
    _, i, a, b = best
    sub = seqs[i][a : b + 1]
    d = sub[-1] - sub[0]
    p = np.maximum.accumulate(np.clip((sub - sub[0]) @ d / (d @ d), 0.0, 1.0))
    s = np.interp(np.linspace(0, len(sub) - 1, n_frames), np.arange(len(sub)), p)
    return start + s[:, None] * (end - start)


def python_dp(seqs, start, end):
    """Eq. 5–6 for the key pair, as plain Python loops (the matching only)."""
    keys = [start.tolist(), end.tolist()]
    best = (math.inf, -1, -1, -1)
    for i, beta in enumerate(seqs):
        rows = beta.tolist()
        E = [[0.0] * (len(rows) - 1) for _ in range(2)]
        for j in range(len(rows) - 1):
            p, q = rows[j], rows[j + 1]
            d = [x - y for x, y in zip(p, q, strict=True)]
            dd = sum(x * x for x in d)
            for r in range(2):
                v = [x - y for x, y in zip(keys[r], q, strict=True)]
                t = min(1.0, max(0.0, sum(x * y for x, y in zip(v, d, strict=True)) / dd)) if dd > 0 else 0.0
                E[r][j] = math.sqrt(sum((x - t * y) ** 2 for x, y in zip(v, d, strict=True)))
        run, arg = math.inf, -1
        for j in range(1, len(rows) - 1):
            if E[0][j - 1] <= run:
                run, arg = E[0][j - 1], j - 1
            if E[1][j] + run < best[0]:
                best = (E[1][j] + run, i, arg, j)
    return best


def timed(fn, repeat: int) -> float:
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--take", type=int, default=50)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--vertices", type=int, default=500)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    seqs, truths = make_database(rng, args.frames, args.take)
    a, b, c = truths[len(truths) // 2]
    start = a + 0.01 * rng.normal(size=a.shape)
    end = b + 0.01 * rng.normal(size=b.shape)
    n = 48
    u = np.linspace(0, 1, n)
    truth = start + c(u)[:, None] * (end - start)

    def rms(x):
        return float(np.sqrt(np.mean((x - truth) ** 2)))

    k = seqs[0].shape[1]
    basis = rng.normal(scale=0.01, size=(k, args.vertices * 3))
    neutral = rng.normal(size=args.vertices * 3) + 10.0
    mesh_seqs = [(neutral + w @ basis).reshape(len(w), args.vertices, 3) for w in seqs]
    mstart = (neutral + start @ basis).reshape(args.vertices, 3)
    mend = (neutral + end @ basis).reshape(args.vertices, 3)
    flat = [m.reshape(len(m), -1) for m in mesh_seqs]

    rows = []
    with threadpool_limits(limits=1):
        r = retime(seqs, start, end, n)
        rows.append(("retime (weights)", timed(lambda: retime(seqs, start, end, n), args.repeat), rms(r.frames)))
        r = retime(seqs, start, end, n, extend=True)
        rows.append(
            (
                "retime extend=True (weights)",
                timed(lambda: retime(seqs, start, end, n, extend=True), args.repeat),
                rms(r.frames),
            )
        )
        f = window_search(seqs, start, end, n)
        rows.append(
            ("peer: window search (weights)", timed(lambda: window_search(seqs, start, end, n), args.repeat), rms(f))
        )
        rows.append(("peer: python DP, match only (weights)", timed(lambda: python_dp(seqs, start, end), 2), math.nan))
        rows.append(("linear in-betweens", math.nan, rms(start + u[:, None] * (end - start))))
        rows.append(("smoothstep ease-in/out", math.nan, rms(start + (u * u * (3 - 2 * u))[:, None] * (end - start))))
        mtruth = (neutral + truth @ basis).reshape(n, args.vertices, 3)

        def mrms(x):
            return float(np.sqrt(np.mean((np.reshape(x, mtruth.shape) - mtruth) ** 2)))

        rm = retime(mesh_seqs, mstart, mend, n)
        rows.append(
            (
                f"retime (meshes, {args.vertices} vertices)",
                timed(lambda: retime(mesh_seqs, mstart, mend, n), args.repeat),
                mrms(rm.frames),
            )
        )
        fm = window_search(flat, mstart.ravel(), mend.ravel(), n)
        rows.append(
            (
                f"peer: window search (meshes, {args.vertices} vertices)",
                timed(lambda: window_search(flat, mstart.ravel(), mend.ravel(), n), args.repeat),
                mrms(fm),
            )
        )
        lin_m = mstart[None] + u[:, None, None] * (mend - mstart)[None]
        rows.append(("linear in-betweens (meshes)", math.nan, mrms(lin_m)))
    print(
        f"database: {len(seqs)} takes x {args.take} frames = {sum(map(len, seqs))} frames; "
        f"weights k = {k}; n_frames = {n}; matched take {r.matched} (truth: take {len(truths) // 2}); "
        f"mesh match {rm.matched}; BLAS 1 thread"
    )
    print(f"{'method':<52} {'median ms':>10} {'rms vs truth':>13}")
    for name, ms, err in rows:
        ms_s = f"{ms:10.1f}" if not math.isnan(ms) else f"{'-':>10}"
        err_s = f"{err:13.2e}" if not math.isnan(err) else f"{'-':>13}"
        print(f"{name:<52} {ms_s} {err_s}")
    print("goal (issue #18): retime <= 100 ms against a 10k-frame database")


if __name__ == "__main__":
    main()
