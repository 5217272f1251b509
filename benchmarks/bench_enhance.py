"""Benchmark: spatial performance enhancement per frame (Bermano et al. 2014, §5) at 80k and 318k vertices.

Run: .venv/bin/python benchmarks/bench_enhance.py [--resolutions 100k 300k] [--frames 4]

Set-up as the §7 validation test (``tests/test_enhance_spatial.py``): the
database is the procedural detailed performance of the sample head
(``WrinkleSculptor``: the six example expressions + the first half of
``performance_weights(120)``: 66 frames at 80k as in the test; 36 at 318k by
default, the examples + every other frame, to keep the run short — ``--database-frames``)
with the four voluntary regions of ``face_voluntary_cores``; inputs are held-out frames of the second half
restricted to the next coarser head's vertices (25k → 80k, 80k → 318k) and
mapped back by ``Correspondence.loop`` (Loop subdivision had moved those rows,
so the input is smoothed as well as downsampled). ``--frames`` held-out frames are
enhanced (after one warm-up frame) and the per-frame time of every stage of
``EnhanceResult.seconds`` reported.

Peers measured in the same run, matching only (eq. 2–3):

* **ours** — encoding (Horn + gradients + ~100-vertex patch means, 9 numbers a
  patch) then ``simplex_lsq`` per voluntary region on the precomputed normal
  matrices ``D̃ᵀ diag(ω_r) D̃`` (what the ``match`` stage is);
* **OSQP on the same compressed problem** — ``qpsolvers.solve_qp(..., solver="osqp")``
  on the same four region normal matrices (a solver swap only);
* **one dense QP, no patches, no regions** — features per triangle (the
  aligned low band's deformation gradients, 9 per triangle, rows weighted by
  √area), the database as a (9m × D) matrix ``A``; per frame ``q = Aᵀa`` and
  ``P = AᵀA`` formed and the simplex QP solved by OSQP (``P`` precomputed
  listed separately: then only ``q`` and the solve are per frame). Its
  weights (one set for the whole face) are also used for the validation below.

Reference row, quoted not measured: the paper reports ≈ 30 s per frame at 500k
vertices and 55 s at 850k on an i7 with 12 GB, MOSEK for the QPs (§7).

Validation at 80k (every held-out frame, 15): per-frame RMS error to the
truth, enhanced / input (median of the ratios), and the same for the detail
band ``x − f(x)``; with the dense peer's weights too.

Measured (2 shared cores, nice -n 5, BLAS on 1 thread — ``--blas-threads`` —, other work
running; 2026-11-25). Run A, load ≈ 4 (before the CPU-time row was added):

=============================================  ====================  ======================
                                               80k (79,673 v), D=66  318k (317,669 v), D=36
=============================================  ====================  ======================
total per frame (ours)                         0.223 s               1.009 s
  correspondence (Loop map)                    1 ms                  4 ms
  filter (eq. 1, back-substitution)            20 ms                 92 ms
  match (encode + 4 region QPs)                28 ms                 136 ms
  blend (eq. 4 + composition)                  114 ms                499 ms
  reconstruct (Poisson + piece placement)      59 ms                 277 ms
match: ours (patches, 4 regions, simplex_lsq)  31 ms                 135 ms
match: OSQP on the same 4 region QPs           83 ms                 170 ms
match: dense QP, OSQP, AᵀA per frame (peer)    189 ms                473 ms
match: dense QP, OSQP, AᵀA precomputed (peer)  54 ms                 263 ms
features per frame: ours / dense               7,488 / 1,425,024     29,979 / 5,700,096
paper, 500k, i7 + MOSEK (quoted)               ≈ 30 s
=============================================  ====================  ======================

Run B, load ≈ 6 (the script as it is): total 0.370 / 1.360 s per frame at
80k / 318k, **CPU time of the process 0.262 / 1.092 s**; blend 176 / 596 ms,
reconstruct 122 / 416 ms, match 38 / 199 ms; matching peers: OSQP on the same
region QPs 142 / 156 ms, dense QP 119 / 376 ms (AᵀA precomputed) and
424 / 551 ms (formed per frame). Two runs at load ≈ 7 gave 2.9 and 3.1 s per
frame at 318k (the database set-up was 2.4× slower too).

Whole run A 2.5 min, run B 3.5 min (set-up at 318k in A: procedural frames
21 s, database build 40 s, dense peer's matrix 12 s, 821 MB). OSQP reaches the same eq. 3 objective as
``simplex_lsq`` (relative difference ≤ 1e-9; the weights themselves may differ
where the optimum is not unique, e.g. frames at rest). In the dense peer the
time goes into the per-triangle features and the products with the 9m × D
matrix; the OSQP solve itself is cheap (3–8 ms, 36–66 unknowns).

Validation at 80k (15 held-out frames, median of per-frame ratios enhanced /
input): error 0.81 (0.123 vs 0.153 mm; lower in 12 of 15 frames), detail band
0.47 (0.034 vs 0.072 mm); median 3 database frames active per region. With the
dense peer's single set of weights for the whole face (uncompressed features):
0.90 and 0.59 — the per-region match on compressed features is both faster and closer.

Run C, after blend + composition were fused per triangle in numba, the matching
factored once per region and BLAS held to one thread around the frame loop, on
a quiet machine (load ≈ 1, ``--no-validation``): total 0.204 / 0.896 s per
frame at 80k / 318k (CPU 0.224 / 0.944 s); filter 20 / 93 ms, match 27 / 126 ms,
blend + compose 86 / 408 ms, reconstruct 70 / 264 ms; matching peers: OSQP on
the same region QPs 69 / 155 ms, dense QP 56 / 179 ms (AᵀA precomputed) and
193 / 378 ms (formed per frame). The 318k target (≤ 1 s per frame) is met with
a 10 % margin when the cores are free; the remaining blend time is the
low-frequency frames and gradients (numpy) around the fused kernel.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

import workbench
from workbench.enhance import Correspondence, PerformanceDatabase
from workbench.enhance.gradients import rigid_align
from workbench.enhance.voluntary import face_voluntary_cores, voluntary_region_weights
from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor, performance_weights

N_PERF = 120
COARSER = {"100k": "25k", "300k": "100k", "25k": "base"}
STAGES = ("correspondence", "filter", "match", "blend", "reconstruct")


def rms_mm(a: np.ndarray, b: np.ndarray, mpu: float) -> np.ndarray:
    return np.sqrt(((np.asarray(a) - np.asarray(b)) ** 2).sum(-1).mean(-1)) * mpu * 1e3


def band(db: PerformanceDatabase, X: np.ndarray) -> np.ndarray:
    return np.stack([x - db.lowpass(x) for x in X])


def osqp_simplex(G: np.ndarray, b: np.ndarray) -> np.ndarray:
    """min wᵀGw − 2bᵀw on the simplex by OSQP, preconditioned without changing the minimiser.

    On the simplex the columns may be centred (``G`` double-centred, ``b − G1/D``):
    the common part of the features (the identity gradient) otherwise leaves OSQP
    "solved inaccurate". ``P`` is then scaled to a unit mean diagonal.
    """
    D = len(b)
    g1 = G.mean(axis=1)
    Gc = G - g1[:, None] - g1[None, :] + g1.mean()
    bc = b - g1
    s = 1.0 / max(float(np.mean(np.diag(Gc))), 1e-300)
    w = qpsolvers.solve_qp(sp.csc_matrix(2.0 * s * Gc), -2.0 * s * bc, A=sp.csc_matrix(np.ones((1, D))),
                           b=np.ones(1), lb=np.zeros(D), solver="osqp", eps_abs=1e-8, eps_rel=1e-8,
                           max_iter=50000, polish=True, verbose=False)
    if w is None:
        raise RuntimeError("OSQP found no solution")
    w = np.clip(w, 0.0, None)
    return w / w.sum()


class DenseMatcher:
    """The peer: one QP over every triangle's low-band gradients (no patch means, no regions)."""

    def __init__(self, db: PerformanceDatabase, train: np.ndarray) -> None:
        self.db = db
        self.sqrt_area = np.sqrt(db._face_area / db._face_area.mean()).astype(np.float32)
        self.A = np.empty((9 * len(db.faces_), len(train)), np.float32)  # (9m, D)
        for i, x in enumerate(train):
            self.A[:, i] = self.features(db.lowpass(np.asarray(x, np.float64)))
        self.P = self.gram()

    def features(self, low: np.ndarray) -> np.ndarray:
        R, t = rigid_align(low, self.db.neutral_low_)
        T = self.db.low_gradients(low @ R.T + t).reshape(-1, 9)
        return (T * self.sqrt_area[:, None]).astype(np.float32).ravel()

    def gram(self) -> np.ndarray:
        return (self.A.T @ self.A).astype(np.float64)

    def match(self, low: np.ndarray, *, form_gram: bool) -> tuple[np.ndarray, dict[str, float]]:
        t0 = time.perf_counter()
        a = self.features(low)
        t1 = time.perf_counter()
        q = (self.A.T @ a).astype(np.float64)
        P = self.gram() if form_gram else self.P
        t2 = time.perf_counter()
        w = osqp_simplex(P, q)  # wᵀPw − 2qᵀw = |Aw − a|² − |a|²
        t3 = time.perf_counter()
        return w, {"features": t1 - t0, "products": t2 - t1, "osqp": t3 - t2}


def region_problems(db: PerformanceDatabase, low: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What ``db.match`` solves: per region ``b_r = D̃ᵀ diag(ω_r) ã`` (R, D) and ``|ã|²_ω_r`` (R,)."""
    a = db.encode(low).ravel()
    Dt = db.features_.reshape(db.n_frames_, -1)
    om = np.repeat(db.region_patch_weights_, 9, axis=1)
    return (om * a) @ Dt.T, (om * a * a).sum(axis=1)


def ours_osqp(db: PerformanceDatabase, low: np.ndarray) -> np.ndarray:
    rhs, _ = region_problems(db, low)
    return np.stack([osqp_simplex(db.region_gram_[r], rhs[r]) for r in range(len(rhs))])


def objective_gap(db: PerformanceDatabase, low: np.ndarray, w_ours: np.ndarray, w_peer: np.ndarray) -> float:
    """max over regions of (peer's eq. 3 objective − ours) / |ã|²_ω (> 0: ours is lower)."""
    rhs, c = region_problems(db, low)
    gaps = []
    for r, G in enumerate(db.region_gram_):
        f = [w @ G @ w - 2 * rhs[r] @ w for w in (w_ours[r], w_peer[r])]
        gaps.append((f[1] - f[0]) / max(float(c[r]), 1e-300))
    return float(max(gaps, key=abs))


def enhance_with(db: PerformanceDatabase, weights: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """Blend, compose and reconstruct given weights (R, D) per frame, as ``enhance_frames`` does."""
    out = []
    for W, x in zip(weights, inputs, strict=True):
        low = db.lowpass(x)
        X = db.reconstruct(db.compose(db.blend_detail(W), low), low)
        out.append(X + db.place_pieces(X, low))
    return np.stack(out)


def run(res: str, n_frames: int, validate: bool, n_db: int) -> dict[str, Any]:
    t_all = time.perf_counter()
    fine = workbench.load_sample("head", res)
    coarse = workbench.load_sample("head", COARSER[res])
    mpu = fine.metadata.metres_per_unit
    sc = WrinkleSculptor(fine)
    W = performance_weights(N_PERF)
    first = W[: N_PERF // 2]
    keep = np.linspace(0, len(first) - 1, max(0, min(len(first), n_db - len(EXAMPLE_POSES)))).round().astype(int)
    train_w = list(EXAMPLE_POSES.values()) + [first[i] for i in keep]
    held = W[N_PERF // 2 :: 4]  # 15 frames
    n_time = min(n_frames, len(held))
    timed = np.linspace(0, len(held) - 1, n_time).round().astype(int)
    # the validation needs every held-out frame; timing alone only the timed ones (+ one warm-up)
    use = np.arange(len(held)) if validate else np.unique(np.concatenate([timed, [len(held) - 1]]))
    test_w = [held[i] for i in use]
    V = np.asarray(fine.vertices, np.float64)
    F = np.asarray(fine.faces, np.int64)
    t0 = time.perf_counter()
    neutral = sc.detail_of(V).astype(np.float64)
    train = np.stack([sc.detailed(w) for w in train_w])
    truth = np.stack([sc.detailed(w) for w in test_w]).astype(np.float64)
    t_gen = time.perf_counter() - t0
    regions = voluntary_region_weights(neutral, F, face_voluntary_cores(fine), sigma=0.1)
    t0 = time.perf_counter()
    db = PerformanceDatabase.from_frames(neutral, F, train, regions=regions, metres_per_unit=mpu)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    corr = Correspondence.loop(coarse.faces, coarse.n_vertices, 1)
    t_corr = time.perf_counter() - t0
    inputs = truth[:, : coarse.n_vertices]
    print(f"\n{res}: {len(V):,} vertices, {len(F):,} triangles; database {db.n_frames_} frames, "
          f"{db.n_patches_} patches, {len(db.region_names_)} regions; inputs {coarse.n_vertices:,} vertices "
          f"({COARSER[res]})\n  set-up: procedural frames {t_gen:.1f} s, build {t_build:.1f} s, "
          f"Loop correspondence {t_corr:.2f} s", flush=True)

    # ours: warm-up frame, then --frames frames
    db.enhance_result(inputs[-1:], correspondence=corr)
    idx = np.searchsorted(use, timed)
    t0, c0 = time.perf_counter(), time.process_time()
    res_ours = db.enhance_result(inputs[idx], correspondence=corr)
    total = (time.perf_counter() - t0) / len(idx)
    cpu = (time.process_time() - c0) / len(idx)  # this process's CPU time: what the other work on the cores does not inflate
    per_stage = {k: v / len(idx) for k, v in res_ours.seconds.items()}
    print(f"  ours, {len(idx)} frames: {total:.3f} s/frame (CPU {cpu:.3f} s) = "
          + ", ".join(f"{k} {per_stage[k] * 1e3:.0f} ms" for k in STAGES), flush=True)

    # matching peers on the same frames (low bands computed once, outside the timings)
    lows = [db.lowpass(x) for x in res_ours.inputs]
    t_ours = []
    for low in lows:
        t0 = time.perf_counter()
        db.match(low)
        t_ours.append(time.perf_counter() - t0)
    t_sosqp, gap_sosqp = [], []
    for low, w_ref in zip(lows, res_ours.weights, strict=True):
        t0 = time.perf_counter()
        w = ours_osqp(db, low)
        t_sosqp.append(time.perf_counter() - t0)
        gap_sosqp.append(objective_gap(db, low, w_ref, w))
    t0 = time.perf_counter()
    dense = DenseMatcher(db, train)
    t_pre = time.perf_counter() - t0
    del train
    t0 = time.perf_counter()
    dense.gram()
    t_gram = time.perf_counter() - t0
    dense_form, dense_pre, dense_w = [], [], []
    for low in lows:
        w, parts = dense.match(low, form_gram=True)
        dense_form.append(sum(parts.values()))
        w2, parts2 = dense.match(low, form_gram=False)
        dense_pre.append(parts2)
        dense_w.append(w2)
    mean_pre = {k: float(np.mean([p[k] for p in dense_pre])) for k in dense_pre[0]}
    print(f"  matching per frame: ours {np.mean(t_ours) * 1e3:.1f} ms; OSQP on the same compressed problem "
          f"{np.mean(t_sosqp) * 1e3:.1f} ms (its objective − ours, relative to |ã|²: {min(gap_sosqp):+.1e} … {max(gap_sosqp):+.1e}); dense QP "
          f"{np.mean(dense_form) * 1e3:.0f} ms with AᵀA per frame, "
          f"{sum(mean_pre.values()) * 1e3:.0f} ms with AᵀA precomputed ("
          + ", ".join(f"{k} {v * 1e3:.0f} ms" for k, v in mean_pre.items())
          + f"); dense set-up {t_pre:.1f} s + AᵀA {t_gram:.2f} s, A {dense.A.nbytes / 1e6:.0f} MB "
          f"({dense.A.shape[0]:,} × {dense.A.shape[1]}) vs ours {db.features_.shape[1] * 9:,} × {db.n_frames_}",
          flush=True)
    out: dict[str, Any] = {
        "res": res, "n": len(V), "total": total, "cpu": cpu, "stages": per_stage, "match_ours": float(np.mean(t_ours)),
        "match_osqp_compressed": float(np.mean(t_sosqp)), "dense_form": float(np.mean(dense_form)),
        "dense_pre": sum(mean_pre.values()), "dense_parts": mean_pre, "features_ours": db.features_.shape[1] * 9,
        "features_dense": dense.A.shape[0], "build": t_build, "D": db.n_frames_,
    }
    if validate:
        full = db.enhance_result(inputs, correspondence=corr)
        e_in = rms_mm(full.inputs, truth, mpu)
        e_out = rms_mm(full.frames, truth, mpu)
        b_true = band(db, truth)
        b_in = rms_mm(band(db, full.inputs), b_true, mpu)
        b_out = rms_mm(band(db, full.frames), b_true, mpu)
        lows_all = [db.lowpass(x) for x in full.inputs]
        Wd = np.stack([np.repeat(dense.match(lo, form_gram=False)[0][None], len(db.region_names_), 0)
                       for lo in lows_all])
        dense_frames = enhance_with(db, Wd, full.inputs)
        e_dn = rms_mm(dense_frames, truth, mpu)
        b_dn = rms_mm(band(db, dense_frames), b_true, mpu)
        active = np.median((full.weights > 1e-3).sum(axis=2))
        # the paper's blend of the detail (polar parts) on the same database and frames
        db.set_detail_blend("polar")
        polar = db.enhance_result(inputs, correspondence=corr)
        db.set_detail_blend("matrix")
        e_pol = rms_mm(polar.frames, truth, mpu)
        b_pol = rms_mm(band(db, polar.frames), b_true, mpu)
        out["validation"] = {
            "err_ratio": float(np.median(e_out / e_in)), "band_ratio": float(np.median(b_out / b_in)),
            "err_ratio_dense": float(np.median(e_dn / e_in)), "band_ratio_dense": float(np.median(b_dn / b_in)),
            "better": int((e_out < e_in).sum()), "frames": len(e_in), "e_in": float(np.median(e_in)),
            "e_out": float(np.median(e_out)), "b_in": float(np.median(b_in)), "b_out": float(np.median(b_out)),
            "active": float(active),
            "err_ratio_polar": float(np.median(e_pol / e_in)), "band_ratio_polar": float(np.median(b_pol / b_in)),
        }
        v = out["validation"]
        print(f"  validation ({len(e_in)} held-out frames): error enhanced/input median {v['err_ratio']:.3f} "
              f"({v['e_out']:.3f} / {v['e_in']:.3f} mm; better in {v['better']}/{len(e_in)}), detail band "
              f"{v['band_ratio']:.3f} ({v['b_out']:.3f} / {v['b_in']:.3f} mm); dense-QP weights: "
              f"{v['err_ratio_dense']:.3f} / band {v['band_ratio_dense']:.3f}; detail blended in polar parts "
              f"(the paper's): {v['err_ratio_polar']:.3f} / band {v['band_ratio_polar']:.3f}; "
              f"median {active:.0f} active frames per region", flush=True)
    print(f"  ({time.perf_counter() - t_all:.0f} s for {res})", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolutions", nargs="+", default=["100k", "300k"], choices=sorted(COARSER))
    ap.add_argument("--frames", type=int, default=4, help="held-out frames timed per resolution (max 15)")
    ap.add_argument("--database-frames", type=int, default=None,
                    help="database size (default 66 at 80k as in the validation test, 36 at 318k to keep the run short)")
    ap.add_argument("--blas-threads", type=int, default=1,
                    help="BLAS threads (default 1: on 2 shared, busy cores threaded BLAS waits, e.g. AᵀA 20x slower)")
    ap.add_argument("--no-validation", action="store_true", help="skip the 80k quality numbers")
    args = ap.parse_args()
    with threadpool_limits(args.blas_threads):
        rows = [run(r, args.frames, validate=(r == "100k" and not args.no_validation),
                    n_db=args.database_frames or (36 if r == "300k" else 66)) for r in args.resolutions]

    heads = [f"{r['n'] / 1000:.0f}k ({r['n']:,} v), D={r['D']}" for r in rows]
    table = [("total per frame (ours)", [f"{r['total']:.3f} s" for r in rows]),
             ("  CPU time of this process", [f"{r['cpu']:.3f} s" for r in rows])]
    for k in STAGES:
        table.append((f"  {k}", [f"{r['stages'][k] * 1e3:.0f} ms" for r in rows]))
    table += [
        ("match: ours (patches, 4 regions, simplex_lsq)", [f"{r['match_ours'] * 1e3:.0f} ms" for r in rows]),
        ("match: OSQP on the same 4 region QPs", [f"{r['match_osqp_compressed'] * 1e3:.0f} ms" for r in rows]),
        ("match: dense QP, OSQP, AᵀA per frame (peer)", [f"{r['dense_form'] * 1e3:.0f} ms" for r in rows]),
        ("match: dense QP, OSQP, AᵀA precomputed (peer)", [f"{r['dense_pre'] * 1e3:.0f} ms" for r in rows]),
        ("features per frame: ours / dense", [f"{r['features_ours']:,} / {r['features_dense']:,}" for r in rows]),
        ("paper, 500k, i7 + MOSEK (quoted)", ["≈ 30 s"] + [""] * (len(rows) - 1)),
    ]
    w0 = max(len(t[0]) for t in table)
    ws = [max(len(h), *(len(t[1][i]) for t in table)) for i, h in enumerate(heads)]
    sep = "  ".join(["=" * w0] + ["=" * w for w in ws])
    print("\n" + sep)
    print("  ".join([" " * w0] + [h.ljust(w) for h, w in zip(heads, ws, strict=True)]))
    print(sep)
    for name, cells in table:
        print("  ".join([name.ljust(w0)] + [c.ljust(w) for c, w in zip(cells, ws, strict=True)]))
    print(sep)
    for r in rows:
        if "validation" in r:
            v = r["validation"]
            print(f"validation at {r['n'] / 1000:.0f}k, {v['frames']} held-out frames (median of per-frame ratios, "
                  f"enhanced / input): error {v['err_ratio']:.2f}, detail band {v['band_ratio']:.2f} "
                  f"(dense-QP weights: {v['err_ratio_dense']:.2f}, {v['band_ratio_dense']:.2f})")


if __name__ == "__main__":
    main()
