"""Benchmark: performance capture (issue #17, Bouaziz et al. 2013 §3.1) — markers onto 52 shapes, and point clouds.

Run: nice .venv/bin/python benchmarks/bench_capture.py [--frames 300] [--markers 100] [--peer-frames 60] [--skip-clouds]

Measured on generated ground truth (``workbench.capture.synthetic_performance``: known weight
curves, head motion, 0.5 mm marker noise, 5 % occlusions, the sample head in dm):

* **Markers, the whole tracker** (``workbench.capture.track``: robust pose + weights, 2
  alternations per frame). Goal: ≥ 500 frames/s at 100 markers × 52 shapes.
* **The weight stage alone**, every frame's markers brought into the model frame with the
  tracker's poses, then solved by: the core's ``WeightSolver`` (L1 + temporal, warm-started; and
  plain bounded L2), the peer ``scipy.optimize.lsq_linear`` per frame (bounded L2: no L1, no
  temporal term, no warm start — what a tracker without a hand-written solver would call), and,
  if installed, OSQP through ``qpsolvers`` on the same L1 + temporal QP per frame (L1 is linear
  with ``w ≥ 0``; set up per frame, as a general QP solver is called).
* **Point clouds** (``track`` without ``vertex_ids``: ``workbench.capture.clouds``), 5k points
  on the 25k-vertex head, with and without adaptation, when that module is present. Goals:
  ≥ 10 frames/s, ≥ 5 with adaptation. (This section is the clouds tracker's: add rows in
  :func:`clouds_section`.)

Weight RMSE is against the true weights (all 52 shapes; the markers cannot see the eyeball and
tongue shapes, which is why L2 without priors does badly). The machine is shared and noisy:
compare rows of one run, not across runs; each time is the best of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.optimize import lsq_linear
from scipy.spatial.transform import Rotation

import workbench
from workbench.capture import WeightSolver, synthetic_performance, track
from workbench.capture.rig import ExpressionSpace
from workbench.capture.track import DEFAULT_L1, DEFAULT_TEMPORAL


def best_of(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Best wall time in seconds over ``repeat`` runs (after one warm-up) and the last result."""
    out = fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def rmse(W: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean((W - truth) ** 2)))


def rotation_error(poses: np.ndarray, truth: np.ndarray) -> float:
    R = np.einsum("tji,tjk->tik", poses[:, :3, :3], truth[:, :3, :3])
    return float(np.degrees(Rotation.from_matrix(R).magnitude()).mean())


def markers_section(args: argparse.Namespace) -> None:
    model = workbench.load_sample("head")
    T = args.frames
    perf = synthetic_performance(model, T, seed=1, markers=args.markers, noise=0.005, occlusion=0.05)
    ids, Y = perf.marker_ids, perf.markers
    k = len(model.shape_names)
    print(f"## Markers: {args.markers} markers × {k} shapes, {T} frames (sample head, dm; 0.5 mm noise, 5 % occluded)\n")
    print("| tracker | frames/s | weight RMSE | rotation error (deg) | active weights per frame |")
    print("|---|---|---|---|---|")
    rows = [("core `track` (L1 + temporal, defaults)", {}), ("core `track`, l1 = 0, temporal = 0 (plain L2)",
                                                         {"l1": 0.0, "temporal": 0.0})]
    tracked = None
    for name, kw in rows:
        dt, res = best_of(lambda kw=kw: track(model, Y, vertex_ids=ids, **kw), args.repeat)
        tracked = tracked or res
        print(f"| {name} | {T / dt:.0f} | {rmse(res.weights, perf.weights):.4f} | "
              f"{rotation_error(res.poses, perf.poses):.3f} | {(res.weights > 1e-3).sum(1).mean():.1f} |")
    assert tracked is not None
    print(f"| (truth) | | | | {(perf.weights > 1e-3).sum(1).mean():.1f} |")

    # ---- the weight stage alone, on the tracker's poses
    space = ExpressionSpace.from_model(model)
    X0, D = space.marker_basis(ids)
    size2 = space.size**2
    frames = []
    for f in range(T):
        vis = np.isfinite(Y[f]).all(1)
        M = tracked.poses[f]
        local = (Y[f, vis] - M[:3, 3]) @ M[:3, :3]
        A = D[vis].reshape(-1, k) / np.sqrt(size2 * vis.sum())
        c = (local - X0[vis]).reshape(-1) / np.sqrt(size2 * vis.sum())
        frames.append((A, c))
    ref = float(np.trace(D.reshape(-1, k).T @ D.reshape(-1, k))) / k / len(ids) / size2
    lo, hi = space.lo, space.hi

    def core(l1: float, temporal: float) -> np.ndarray:
        s = WeightSolver(lo, hi, l1=l1 * ref, temporal=temporal * ref, relative=False, tol=1e-6 * np.sqrt(ref))
        W = np.zeros((T, k))
        for f, (A, c) in enumerate(frames):
            W[f] = s.solve(A, c, W[f - 1] if f else None, W[f - 2] if f > 1 else None)
        return W

    P = min(T, args.peer_frames)  # the slow peers run on the first frames only (frames/s is per frame)

    print(f"\n## The weight stage alone ({T} frames, on the tracker's poses)\n")
    print("| solver | frames/s | weight RMSE | active weights per frame |")
    print("|---|---|---|---|")
    table = [
        ("core `WeightSolver`, L1 + temporal, warm-started (numba)" if _numba() else
         "core `WeightSolver`, L1 + temporal, warm-started (Python fallback)",
         lambda: core(DEFAULT_L1, DEFAULT_TEMPORAL)),
        ("core `WeightSolver`, bounded L2 (l1 = 0, temporal = 0)", lambda: core(0.0, 0.0)),
        ("peer `scipy.optimize.lsq_linear` (BVLS) per frame, bounded L2",
         lambda: np.stack([lsq_linear(A, c, bounds=(lo, hi), method="bvls").x for A, c in frames[:P]])),
        ("peer `scipy.optimize.lsq_linear` (TRF, the default) per frame, bounded L2",
         lambda: np.stack([lsq_linear(A, c, bounds=(lo, hi)).x for A, c in frames[:P]])),
    ]
    osqp = _osqp_peer(frames, lo, hi, ref, T, k)
    if osqp is not None:
        table.append(("peer OSQP via `qpsolvers` per frame, the same L1 + temporal QP", osqp))
    for name, fn in table:
        dt, W = best_of(fn, args.repeat if "peer" not in name else 1)
        n = W.shape[0]
        print(f"| {name}{'' if n == T else f' (first {n} frames)'} | {n / dt:.0f} | {rmse(W, perf.weights[:n]):.4f} | "
              f"{(W > 1e-3).sum(1).mean():.1f} |")


def _numba() -> bool:
    from workbench.capture.solver import NUMBA

    return NUMBA


def _osqp_peer(frames: list, lo: np.ndarray, hi: np.ndarray, ref: float, T: int, k: int) -> Callable[[], np.ndarray] | None:
    try:
        import qpsolvers
    except ImportError:
        return None
    if "osqp" not in qpsolvers.available_solvers:
        return None
    import scipy.sparse as sp

    def run() -> np.ndarray:
        W = np.zeros((T, k))
        for f, (A, c) in enumerate(frames):
            P = A.T @ A
            q = -(A.T @ c) + 0.5 * DEFAULT_L1 * ref
            if f:
                p = 2 * W[f - 1] - W[f - 2] if f > 1 else W[f - 1]
                t = DEFAULT_TEMPORAL * ref
                P = P + t * np.eye(k)
                q = q - t * p
            x = qpsolvers.solve_qp(sp.csc_matrix(2 * P), 2 * q, lb=lo, ub=hi, solver="osqp",
                                   eps_abs=1e-7, eps_rel=1e-7, initvals=W[f - 1] if f else None)
            W[f] = np.clip(x if x is not None else W[f - 1], lo, hi)
        return W

    return run


def clouds_section(args: argparse.Namespace) -> None:
    """Point clouds: 5k points on the 25k-vertex head (the clouds tracker's section)."""
    try:
        import workbench.capture.clouds
    except ModuleNotFoundError:
        print("\n## Point clouds\n\n(workbench.capture.clouds is not there yet: no rows)")
        return
    model = workbench.load_sample("head", resolution="25k")
    T = min(args.frames, 30)
    perf = synthetic_performance(model, T, seed=2, markers=0, landmarks=0, points=5000, noise=0.005, outliers=0.01)
    print(f"\n## Point clouds: 5000 points per frame, {model.n_vertices} vertices, {T} frames\n")
    print("| tracker | frames/s | weight RMSE | rotation error (deg) |")
    print("|---|---|---|---|")
    for name, kw in (("core `track` (clouds), adaptation off", {"adapt": False}),
                     ("core `track` (clouds), adaptation on", {"adapt": True})):
        dt, res = best_of(lambda kw=kw: track(model, perf.clouds, **kw), 1)
        print(f"| {name} | {T / dt:.1f} | {rmse(res.weights, perf.weights):.4f} | "
              f"{rotation_error(res.poses, perf.poses):.3f} |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--markers", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--peer-frames", type=int, default=60, help="frames the slow per-frame peers solve")
    ap.add_argument("--skip-clouds", action="store_true")
    args = ap.parse_args()
    markers_section(args)
    if not args.skip_clouds:
        clouds_section(args)


if __name__ == "__main__":
    main()
