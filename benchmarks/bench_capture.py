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
    rows = [(f"core `track` (L1 + temporal, fixed l1 = {DEFAULT_L1:g}, temporal = {DEFAULT_TEMPORAL:g})",
             {"l1": DEFAULT_L1, "temporal": DEFAULT_TEMPORAL}),
            ("core `track`, defaults (λ's chosen by held-out markers, the choice timed too; #28)", {}),
            ("core `track`, l1 = 0, temporal = 0 (plain L2)", {"l1": 0.0, "temporal": 0.0})]
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
    """Point clouds: 5k points on the 25k-vertex head (the clouds tracker's section).

    Three tables, every row of one table on the same take in the same run:

    1. The whole tracker (``track`` → ``track_clouds``) with and without adaptation, plain
       bounded L2 (``l1 = temporal = 0``), and the peer: a per-frame ``scipy.optimize.lsq_linear``
       as the weight solver on the same normal equations (bounded L2; it cannot take the L1
       term, and has no warm start). Set-up (sampling, normals, the adaptive model's basis
       and transfer rows) is timed apart from the frames.
    2. The rigid stage alone on the true expression (the stable samples posed by the true
       weights, started from the previous true pose): the core's point-to-plane ICP
       (``clouds._rigid_icp``, 4 steps, a k-d tree built per frame) against trimesh's
       ``registration.icp`` (point-to-point, its own k-d tree per call, 20 iterations).
    3. A face that is not the template (the head under a smooth warp, 8 neutral frames first,
       as the paper's initialisation wants): fit error, posed-vertex error and weight RMSE
       with and without adaptation.

    Measured 2026-11-25 (2 shared cores, load average ~3, 60 frames): without adaptation 36.9
    frames/s (29.0 with the 0.45 s set-up), weight RMSE 0.041, 0.10°; with adaptation 18.2
    frames/s after a 7.8 s set-up (the Laplacian basis and the transfer rows of 52 shapes, once
    per model: pass the same ``AdaptiveModel`` as ``adapt=`` to reuse it), 5.4 frames/s counting
    it; the lsq_linear peer 32.0 frames/s at weight RMSE 0.235 (bounded L2, like the core's own
    L2 row: 0.237) — per frame the correspondences cost more than any weight solver. Rigid stage:
    5.0 ms and 0.10° per frame against trimesh's point-to-point ICP 4.3 ms and 0.33°. On the
    warped actor, adaptation takes the fit error from 1.54 to 0.56 mm, the posed-vertex error
    from 4.61 to 1.12 mm and the weight RMSE from 0.377 to 0.106.
    """
    try:
        from workbench.capture import clouds as cl
    except ModuleNotFoundError:
        print("\n## Point clouds\n\n(workbench.capture.clouds is not there yet: no rows)")
        return
    model = workbench.load_sample("head", resolution="25k")
    T = min(args.frames, args.cloud_frames)
    visible = [n for n in model.shape_names if not n.startswith("eyeLook") and n != "tongueOut"]
    perf = synthetic_performance(model, T, seed=2, markers=0, landmarks=0, points=5000, noise=0.005, outliers=0.01,
                                 shapes=visible)
    print(f"\n## Point clouds: 5000 points per frame, {model.n_vertices} vertices, {T} frames "
          "(sample head 25k, dm; 0.5 mm noise, 1 % outliers, head motion; the eyeball and tongue shapes left still)\n")
    print("| tracker | set-up (s) | frames/s (frames) | frames/s (with set-up) | weight RMSE | "
          "rotation error (deg) | fit error (mm) | active weights per frame |")
    print("|---|---|---|---|---|---|---|---|")
    space = ExpressionSpace.from_model(model)
    rows: list[tuple[str, dict[str, Any]]] = [
        ("core `track` (clouds), adaptation off", {"adapt": False}),
        ("core `track` (clouds), adaptation on", {"adapt": True}),
        ("core `track` (clouds), plain bounded L2 (l1 = temporal = 0), adaptation off",
         {"adapt": False, "l1": 0.0, "temporal": 0.0}),
        ("peer: per-frame `scipy.optimize.lsq_linear` as the weight solver (bounded L2), adaptation off",
         {"adapt": False, "solver": _LsqLinearPeer(space.lo, space.hi)}),
    ]
    for name, kw in rows:
        t0 = time.perf_counter()
        res = track(model, perf.clouds, fps=perf.fps, **kw)
        wall = time.perf_counter() - t0
        sec = res.info["seconds"]
        print(f"| {name} | {sec['setup']:.2f} | {T / sec['frames']:.1f} | {T / wall:.1f} | "
              f"{rmse(res.weights, perf.weights):.4f} | {rotation_error(res.poses, perf.poses):.3f} | "
              f"{100 * np.nanmedian(res.errors):.2f} | {(res.weights > 1e-3).sum(1).mean():.1f} |")
    print(f"| (truth) | | | | | | | {(perf.weights > 1e-3).sum(1).mean():.1f} |")

    _rigid_table(model, perf, cl)
    _adaptation_table(model, args)


class _LsqLinearPeer:
    """``scipy.optimize.lsq_linear`` per frame on ``||Aw − c||²`` rebuilt from the normal equations ``G, h``.

    ``G = L Lᵀ`` (Cholesky), so ``||Lᵀ w − L⁻¹ h||²`` has the same minimiser; bounded to the sliders.
    No L1 term (a least-squares solver has none) and no warm start.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        self.lo, self.hi = lo, hi

    def solve_gram(self, G: np.ndarray, h: np.ndarray, w_prev: Any = None, w_prev2: Any = None,
                   w0: Any = None) -> np.ndarray:
        from scipy.linalg import solve_triangular

        k = G.shape[0]
        L = np.linalg.cholesky(G + 1e-12 * max(float(np.trace(G)) / k, 1e-300) * np.eye(k))
        return np.asarray(lsq_linear(L.T, solve_triangular(L, h, lower=True), bounds=(self.lo, self.hi)).x)


def _rigid_table(model: Any, perf: Any, cl: Any) -> None:
    from scipy.spatial import cKDTree

    try:
        import trimesh.registration as treg
    except ImportError:  # pragma: no cover - trimesh is a core dependency
        treg = None
    ids, stable = cl.sample_vertices(model)
    sid = ids[stable]
    space = ExpressionSpace.from_model(model)
    D = np.asarray(space.deltas[:, sid], np.float64)
    V = space.neutral[sid]
    # the stable samples' normals, as the tracker computes them
    setup = cl._setup(model, ids, stable, 0.0, 0.0)
    N0 = setup.N0[stable]
    T = perf.n_frames
    thr = 0.03 * space.size
    core_err, peer_err = [], []
    t_core = t_peer = 0.0
    for f in range(1, T):
        X = V + np.tensordot(perf.weights[f], D, 1)
        P = perf.clouds[f]
        start = perf.poses[f - 1]
        t0 = time.perf_counter()
        tree = cKDTree(P)
        M, _ = cl._rigid_icp(X, N0, tree, P, cl._CloudNormals(P, tree), start, thr, np.cos(np.radians(60.0)), 4, 6)
        t_core += time.perf_counter() - t0
        core_err.append(M)
        if treg is not None:
            t0 = time.perf_counter()
            Mp, _, _ = treg.icp(X, P, initial=start, threshold=1e-7, max_iterations=20)
            t_peer += time.perf_counter() - t0
            peer_err.append(Mp)
    print(f"\n## The rigid stage alone ({len(sid)} stable samples, {T - 1} frames, true expression, "
          "started from the previous true pose)\n")
    print("| rigid ICP | ms per frame | rotation error (deg) | translation error (mm) |")
    print("|---|---|---|---|")
    truth = perf.poses[1:]
    for name, Ms, t in (("core point-to-plane ICP (`clouds._rigid_icp`, 4 steps, Huber)", core_err, t_core),
                        ("peer `trimesh.registration.icp` (point-to-point, 20 iterations)", peer_err, t_peer)):
        if not Ms:
            continue
        P_ = np.stack(Ms)
        tr = np.linalg.norm(P_[:, :3, 3] - truth[:, :3, 3], axis=1).mean()
        print(f"| {name} | {1000 * t / len(Ms):.1f} | {rotation_error(P_, truth):.3f} | {100 * tr:.2f} |")


def _adaptation_table(model: Any, args: argparse.Namespace) -> None:
    from workbench.capture.clouds import track_clouds
    from workbench.testing import capture_actor_warp, warped

    V = model.vertices
    D = np.asarray(model.effective_deltas, np.float64)
    warp = capture_actor_warp(V)
    actor = warped(model, warp, name=model.metadata.name).model  # the same mesh, its shapes warped exactly
    Va = actor.vertices
    visible = [n for n in model.shape_names if not n.startswith("eyeLook") and n != "tongueOut"]
    T = min(args.frames, args.cloud_frames)
    lead = 8
    perf = synthetic_performance(actor, T, seed=4, markers=0, landmarks=0, points=5000, noise=0.005, outliers=0.01,
                                 head_motion=0.5, shapes=visible)
    rest = synthetic_performance(actor, lead, seed=5, markers=0, landmarks=0, points=5000, noise=0.005,
                                 outliers=0.01, head_motion=0.0, active=0.0)
    R0, t0 = perf.poses[0, :3, :3], perf.poses[0, :3, 3]
    clouds = [c @ R0.T + t0 for c in rest.clouds] + list(perf.clouds)  # the neutral frames at the take's first pose
    truth_w = np.concatenate([np.zeros((lead, len(model.shape_names))), perf.weights])
    meshes = np.concatenate([np.repeat((Va @ R0.T + t0)[None], lead, 0), perf.meshes])
    n = len(clouds)
    late = slice(n // 2, n)
    off = (np.linalg.norm(Va - V, axis=1)).mean() / perf.head_size
    print(f"\n## Adaptation: a face that is not the template (the 25k head under a smooth warp, mean offset "
          f"{100 * off:.1f} % of the head size; {lead} neutral frames, then {T})\n")
    print("| tracker | frames/s (frames) | set-up (s) | fit error, 2nd half (mm) | posed-vertex error, last 10 "
          "frames (mm) | weight RMSE |")
    print("|---|---|---|---|---|---|")
    for name, kw in (("template rig, adaptation off", {"adapt": False}),
                     ("adaptation on (defaults: the identity from the neutral start)", {}),
                     ("adaptation with the online refinement (`refine=True`)", {"refine": True})):
        res = track_clouds(model, clouds, **kw)
        am = res.info["adapted"]
        b0, DS = (am.neutral_, am.shapes_) if am is not None else (V, D)
        ids = res.info["vertex_ids"]
        err = []
        for f in range(n - 10, n):
            X = (b0[ids] + np.tensordot(res.weights[f], DS[:, ids], 1)) @ res.poses[f, :3, :3].T + res.poses[f, :3, 3]
            err.append(np.linalg.norm(X - meshes[f][ids], axis=1).mean())
        sec = res.info["seconds"]
        print(f"| {name} | {n / sec['frames']:.1f} | {sec['setup']:.2f} | {100 * np.nanmean(res.errors[late]):.2f} | "
              f"{100 * np.mean(err):.2f} | {rmse(res.weights, truth_w):.4f} |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--markers", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--peer-frames", type=int, default=60, help="frames the slow per-frame peers solve")
    ap.add_argument("--skip-clouds", action="store_true")
    ap.add_argument("--cloud-frames", type=int, default=60, help="frames of the point-cloud takes")
    args = ap.parse_args()
    markers_section(args)
    if not args.skip_clouds:
        clouds_section(args)


if __name__ == "__main__":
    main()
