"""Benchmark: blend-region segmentation, region drag solve, marker fitting (issue #6, Joshi et al. 2003).

Run: .venv/bin/python benchmarks/bench_regions.py [--resolutions base 25k 100k] [--frames 20]

Measured:
  * ``segment_blend_regions`` (52 shapes, t = 0.25, 3 levels) per resolution.
    Goal: <= 1 s at 25k (the paper: "less than a minute").
  * one region-drag solve (``solve_region_drag``: system build + NNLS with a
    BVLS fallback), goal
    <= 5 ms, for 1 and 3 pinned points at the coarse and fine level. Peer on
    the same system: OSQP through qpsolvers (setup + solve each call, as a drag
    would), if installed.
  * marker fitting per frame (71 markers, level 0): block Gauss–Seidel over
    regions, each block by NNLS (the core's method). Peer: OSQP on the joint problem with the matrix
    factorised once and warm starts (the best case for OSQP).
The machine is shared and noisy: compare rows of one run, not across runs.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

import workbench
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.regions.blend import (
    RegionWeights,
    drag_system,
    region_blend_positions,
    solve_region_drag,
)
from workbench.methods.regions.marker_fit import fit_markers, generate_synthetic_marker_performance
from workbench.methods.regions.segmentation import segment_blend_regions


def timeit(fn: Callable[[], object], repeat: int = 20) -> tuple[float, float]:
    """Median and minimum wall time in ms (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), min(times)


def osqp_drag(model: workbench.FaceModel, regions, level: int, rw: RegionWeights, pinned: dict) -> object:  # type: ignore[no-untyped-def]
    import scipy.sparse as sp
    from qpsolvers import solve_qp

    J, b, ri, ki, rw = drag_system(model, regions, level, rw, pinned)
    u = J.shape[1]
    lam = 1e-3 * float(np.mean((J**2).sum(0)))
    w0 = rw.values[ri, ki].astype(np.float64)
    lo = np.array([model.shapes[k].slider_min for k in ki]) - w0
    hi = np.array([model.shapes[k].slider_max for k in ki]) - w0
    P = sp.csc_matrix(J.T @ J + lam * np.eye(u))
    return solve_qp(P, -J.T @ b, lb=np.minimum(lo, 0), ub=np.maximum(hi, 0), solver="osqp", eps_abs=1e-8, eps_rel=1e-8)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k", "100k"])
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args()

    print("## Segmentation (52 shapes, t = 0.25, 3 levels)\n")
    print("| resolution | vertices | regions per level | median ms | min ms |")
    print("|---|---|---|---|---|")
    for res in args.resolutions:
        m = workbench.load_sample("head", resolution=res)
        R = segment_blend_regions(m)
        med, mn = timeit(lambda m=m: segment_blend_regions(m), repeat=5)
        counts = "/".join(str(R.n_regions(lv)) for lv in range(R.n_levels))
        print(f"| {res} | {m.n_vertices} | {counts} | {med:.0f} | {mn:.0f} |")

    try:
        import qpsolvers

        has_osqp = "osqp" in qpsolvers.available_solvers
    except ImportError:
        has_osqp = False

    print("\n## Region drag solve\n")
    print("| resolution | level | pins | unknowns | NNLS/BVLS (core) median / min ms | OSQP via qpsolvers median / min ms |")
    print("|---|---|---|---|---|---|")
    for res in args.resolutions[:2]:
        m = workbench.load_sample("head", resolution=res)
        R = segment_blend_regions(m)
        corner = int(np.argmax(np.linalg.norm(m.deltas[m.shape_names.index("mouthSmileLeft")], axis=1)))
        brow = int(np.argmax(np.linalg.norm(m.deltas[m.shape_names.index("browOuterUpLeft")], axis=1)))
        cheek = int(np.argmax(np.linalg.norm(m.deltas[m.shape_names.index("cheekSquintLeft")], axis=1)))
        for lv in (R.n_levels - 1, 0):
            rw = RegionWeights.from_global(m, R, lv)
            for pins in ([corner], [corner, brow, cheek]):
                X = region_blend_positions(m, R, rw, lv, vertices=pins)
                pinned = {v: X[i] + (np.array([0.03, 0.02, 0.0]) if i == 0 else 0.0) for i, v in enumerate(pins)}
                pinned = {v: t for v, t in pinned.items() if R.regions_at(lv, v)}
                J = drag_system(m, R, lv, rw, pinned)[0]
                med, mn = timeit(lambda m=m, R=R, lv=lv, rw=rw, p=pinned: solve_region_drag(m, R, lv, rw, p))
                peer = "n/a"
                if has_osqp:
                    pm, pn = timeit(lambda m=m, R=R, lv=lv, rw=rw, p=pinned: osqp_drag(m, R, lv, rw, p))
                    peer = f"{pm:.2f} / {pn:.2f}"
                print(f"| {res} | {lv} | {len(pinned)} | {J.shape[1]} | {med:.2f} / {mn:.2f} | {peer} |")

    print(f"\n## Marker fitting (71 markers, {args.frames} frames, level 0, base)\n")
    m = workbench.load_sample("head")
    R = segment_blend_regions(m)
    mk = np.asarray(default_face_handles(m).vertices)
    perf = generate_synthetic_marker_performance(m, mk, args.frames, seed=1, noise=0.002)
    rows = []
    for sweeps in (1, 3):
        t0 = time.perf_counter()
        fit = fit_markers(m, R, mk, perf.marker_positions, 0, sweeps=sweeps)
        dt = (time.perf_counter() - t0) * 1e3 / args.frames
        rows.append((f"core: block Gauss–Seidel, NNLS per region, {sweeps} sweep(s)", dt, float(np.sqrt(np.mean(fit.marker_error_region**2)))))
    t0 = time.perf_counter()
    fit = fit_markers(m, R, mk, perf.marker_positions, 0, use_regions=False)
    rows.append(("core: global fit only (NNLS, 52 unknowns)", (time.perf_counter() - t0) * 1e3 / args.frames,
                 float(np.sqrt(np.mean(fit.marker_error_global**2)))))
    if has_osqp:
        rows.append(_osqp_joint_fit(m, R, mk, perf.marker_positions, fit.global_weights))
    print("| method | ms per frame | marker RMS before RBF (dm) |")
    print("|---|---|---|")
    for name, ms, err in rows:
        print(f"| {name} | {ms:.1f} | {err:.2e} |")


def _osqp_joint_fit(m, R, mk, P, G):  # type: ignore[no-untyped-def]
    """Peer: the joint region problem with OSQP, factorised once, warm-started per frame."""
    import osqp
    import scipy.sparse as sp


    D = m.effective_deltas[:, mk].astype(np.float64)
    M, k = mk.size, D.shape[0]
    Wm = R.weight_matrix(0)[mk].toarray()
    touched = np.flatnonzero(Wm.max(0) > 0)
    J = (Wm[:, touched][:, :, None, None] * D.transpose(1, 0, 2)[:, None]).transpose(0, 3, 1, 2).reshape(3 * M, -1)
    ki = np.tile(np.arange(k), touched.size)
    keep = np.abs(J).max(0) > 0
    J, ki = J[:, keep], ki[keep]
    u = J.shape[1]
    lam = 1e-2 * float(np.mean((J**2).sum(0)))
    Jg = D.transpose(1, 2, 0).reshape(3 * M, k)
    prob = osqp.OSQP()
    t0 = time.perf_counter()
    err = []
    for t in range(P.shape[0]):
        g = G[t].astype(np.float64)
        b = (P[t] - m.vertices[mk]).reshape(-1) - Jg @ g
        q = -J.T @ b
        lo, hi = np.minimum(-g[ki], 0.0), np.maximum(1.0 - g[ki], 0.0)
        if t == 0:
            prob.setup(sp.csc_matrix(J.T @ J + lam * np.eye(u)), q, sp.identity(u, format="csc"), lo, hi,
                       verbose=False, eps_abs=1e-7, eps_rel=1e-7, polish=True)
        else:
            prob.update(q=q, l=lo, u=hi)
        x = prob.solve().x
        err.append(np.mean(np.sum((b - J @ x).reshape(M, 3) ** 2, axis=1)))
    ms = (time.perf_counter() - t0) * 1e3 / P.shape[0]
    return (f"OSQP joint ({u} unknowns, factorised once, warm start)", ms, float(np.sqrt(np.mean(err))))


if __name__ == "__main__":
    main()
