"""Benchmark: rig any face — set-up and transfer of all 52 shapes (issue 16, items 1-2).

Run: .venv/bin/python benchmarks/bench_rig_transfer.py [--template 25k] [--rings 75] [--repeat 3]

The template is the sample head at the "25k" resolution (20,051 vertices, 52
ARKit shapes). The target is a face the template has never seen: the base
head re-triangulated so that no vertex sits where one was (every triangle
split in four through random edge points, old vertices slid along an edge,
a third of the inner edges flipped; :func:`workbench.testing.split_remesh`),
given a bust below the neck (``--rings`` rings of the neck loop flaring into
shoulders), warped by three Gaussian bumps, an anisotropic scale and a
rotation, in centimetres — about 27k vertices.

Measured (goal: all 52 shapes transferred in <= 2 s after <= 10 s set-up):

* **set-up** — ``RigTransfer(template, target)``: checks, rigid alignment,
  non-rigid fit of the template skin onto the target (CHOLMOD refactored per
  ICP step), correspondence, parts, the Poisson matrix factored once and the
  sparse map from template deltas to its right-hand sides; per stage from the
  progress callback.
* **transfer** — ``.run()``: right-hand sides of all shapes (one sparse
  product), one multi-column back-substitution (156 columns), parts, masks,
  the quality report and the new ``FaceModel``; and the solve alone.
* **peer, same run**: the same system solved per shape without a
  prefactorisation (``scipy.sparse.linalg.spsolve`` on each shape's three
  columns, as a transfer without a kept factor would), on the same right-hand
  sides; its result is checked against ours.
* **self-intersections** (part of the report, :mod:`workbench.rigging.intersections`):
  the rest check plus the new self-intersecting triangles of all 52 shapes on
  the target skin (in ``run``) and on the template skin (in set-up), numba on
  all of numba's threads and on one. Peers in the same run: the module's
  numpy path (scipy cKDTree broad phase, vectorised separating-axis test) on a
  few shapes, answers checked equal; and libigl's
  ``tri_tri_overlap_test_3d`` called per candidate pair of one shape (the
  narrow phase only; the Python bindings have no broad phase), answers
  checked against the vectorised test. trimesh's collision manager needs
  python-fcl (not installed) and compares two meshes, not one with itself.

The machine is shared and noisy: compare rows of one run, not across runs.
Measured 2026-11-25 (2 cores, load average ~2 from other jobs): set-up 4.1 s
(non-rigid fit 3.1 s: 27 ICP steps, 16 factorisations), transfer 0.33 s (RHS +
solve 0.12 s), peer 5.1 s (44x the RHS + solve); under load average 6 the
same run gave 8.6 s / 0.77 s.

Self-intersections, measured 2026-11-26 (2 cores, load average ~1): on the
target skin (24,163 vertices, 48,232 triangles; 52 % of them move in a shape,
12 % are tested) the rest check and clearance take 83 ms and the 52 shapes
0.20 s, 0.29 s in all (1 thread 0.42 s), in ``run``; on the template skin
(17,263 vertices, in set-up) 48 ms + 0.17 s. So the report costs ~0.5 s more
in all, plus ~0.8 s once per process to import numba and load the cached
kernels (compiling them the first time on a machine takes ~6 s). Peers: the
numpy path 0.50 s per shape (~26 s for 52, same triangles); libigl's pair
test 2.6 µs per pair, 0.10 s for the narrow phase alone of one shape's 37k
candidate pairs (the vectorised test 0.6 µs per pair). Under load average 4
(another job on one core) the check took 2.0 s + 1.0 s before the clearance
pruning, which cut it ~2x.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import subprocess
import sys
import time

import igl
import numpy as np
import scipy.sparse.linalg as spla

import workbench
from workbench.geometry.sparse_cholesky import cholmod_available
from workbench.model import FaceModel
from workbench.rigging import RigTransfer
from workbench.rigging import intersections as ix
from workbench.testing import remeshed, sample_head_warp, with_bust


def build_target(rings: int) -> FaceModel:
    base = workbench.load_sample("head")
    face = remeshed(base, seed=1, warp=sample_head_warp(), name="warped remesh with a bust")
    return with_bust(face, rings=rings, drop=0.6, flare=2.2).model


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--template", default="25k", help="sample resolution of the template (base, 25k, 100k)")
    ap.add_argument("--rings", type=int, default=75, help="rings of the bust below the target's neck")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    template = workbench.load_sample("head", resolution=args.template)
    target = build_target(args.rings)
    print(f"template: {template.n_vertices} vertices, {len(template.faces)} triangles, {len(template.shapes)} shapes")
    print(f"target:   {target.n_vertices} vertices, {len(target.faces)} triangles (cm, bust, new topology)")
    print(f"CHOLMOD: {'yes' if cholmod_available() else 'no (SuperLU)'}")

    setups, stages = [], []
    rt = None
    for _ in range(args.repeat):
        marks: list[tuple[float, str]] = []
        t0 = time.perf_counter()
        rt = RigTransfer(template, target, progress=lambda f, m, t0=t0, marks=marks: marks.append((time.perf_counter() - t0, m)))
        setups.append(time.perf_counter() - t0)
        stages.append(marks)
    assert rt is not None
    # stage times: from the first message of a stage to the first of the next
    names = {"rigid alignment": "rigid alignment", "non-rigid fit": "non-rigid fit", "correspondence": "correspondence",
             "parts": "parts", "factoring the Poisson system": "factor + RHS map + template quality"}
    print(f"\nset-up: median {statistics.median(setups):.2f} s (min {min(setups):.2f}) over {args.repeat}; goal <= 10 s")
    marks = stages[int(np.argsort(setups)[len(setups) // 2])]
    firsts = [(t, m) for t, m in marks if m in names] + [(marks[-1][0], "end")]
    for (t, m), (t2, _) in itertools.pairwise(firsts):
        print(f"  {names[m]:<38} {t2 - t:6.2f} s")
    print(f"  fit: {rt.fit.iterations} ICP steps, {rt.fit.factorizations} factorisations, coverage {rt.registration['coverage']:.1%}, "
          f"median residual {rt.registration['median_residual'] * 10:.2f} mm")

    runs, solves, peers = [], [], []
    result = None
    deltas = np.stack([s.delta for s in template.shapes]).astype(np.float64)
    k = deltas.shape[0]
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        result = rt.run()
        runs.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        rhs = rt.right_hand_sides(deltas)
        ours = rt._system.solve(rhs)
        solves.append(time.perf_counter() - t0)
    assert result is not None
    # the peer: no kept factor, one sparse solve per shape (its x, y, z columns)
    A = rt.matrix.tocsc()
    for _ in range(max(1, args.repeat - 1)):
        t0 = time.perf_counter()
        peer = np.zeros_like(rhs)
        for i in range(k):
            cols = [i, k + i, 2 * k + i]
            peer[:, cols] = spla.spsolve(A, rhs[:, cols])
        peers.append(time.perf_counter() - t0)
    diff = float(np.abs(peer - ours).max() / max(np.abs(ours).max(), 1e-300))
    print(f"\ntransfer of all {k} shapes (run: RHS, solve, parts, masks, report, model): "
          f"median {statistics.median(runs):.3f} s (min {min(runs):.3f}); goal <= 2 s")
    print(f"  RHS + one multi-column solve ({3 * k} columns, {A.shape[0]} unknowns): "
          f"median {statistics.median(solves):.3f} s")
    print(f"  peer: spsolve per shape, no prefactorisation:           median {statistics.median(peers):.3f} s "
          f"({statistics.median(peers) / statistics.median(solves):.0f}x ours); max relative difference {diff:.1e}")
    worst = result.report.worst
    if worst is not None:
        print(f"\nreport: worst stretch {worst.max_stretch:.2f} ({worst.name}, template {worst.source_max_stretch:.2f}); "
              f"flipped triangles in all shapes {sum(q.flipped for q in result.report.shapes)} "
              f"(template {sum(q.source_flipped for q in result.report.shapes)} of {len(template.faces)} triangles); "
              f"warnings: {list(result.report.warnings) or 'none'}")
        crossing = [q for q in result.report.shapes if q.intersecting]
        print(f"  new self-intersections: {len(crossing)} shapes, {sum(q.intersecting for q in crossing)} triangles "
              f"(template {sum(q.source_intersecting for q in result.report.shapes)}); flagged: "
              f"{[q.name for q in result.report.flagged] or 'none'}")
    work = ours.reshape(rhs.shape[0], 3, k).transpose(2, 0, 1)  # (k, n_skin, 3) as in run()
    bench_intersections(rt, template, work, args.repeat)


def bench_intersections(rt: RigTransfer, template: FaceModel, work: np.ndarray, repeat: int) -> None:
    """The report's self-intersection check on both skins, and its peers (see the module docstring)."""
    if not ix.NUMBA:
        print("\nself-intersections: numba is not installed; the transfer's report skips them")
        return
    import numba

    t_F = rt.tgt.skin_faces[rt._t_good]
    lin = rt.src.frame.scale * rt.src.frame.R
    s_D = np.stack([s.delta[rt.src.skin_ids].astype(np.float64) @ lin.T for s in template.shapes])
    sides = {"target": (rt.tgt.skin_X, t_F, work), "template": (rt.src.skin_X, rt.src.skin_faces, s_D)}
    # a fresh process: loading the cached kernels (compiling them, the first time on a machine: ~6 s)
    first = subprocess.run(
        [sys.executable, "-c", "import time; t = time.perf_counter(); import numpy as np; "
         "from workbench.rigging import intersections as ix; "
         "ix.SelfIntersections(np.eye(3), np.array([[0, 1, 2]])).new(np.eye(3)); print(time.perf_counter() - t)"],
        capture_output=True, text=True, check=True).stdout.strip()
    threads = numba.get_num_threads()
    print(f"\nself-intersections (new at weight 1, vs the rest pose), numba {threads} threads "
          f"(import + kernels in a fresh process {float(first):.2f} s):")
    counts = {}
    for name, (X, F, D) in sides.items():
        times, ones = [], []
        for nt in (threads, 1):
            numba.set_num_threads(nt)
            for _ in range(repeat):
                t0 = time.perf_counter()
                si = ix.SelfIntersections(X, F)
                rest = time.perf_counter() - t0
                c = [si.count_new(d) for d in D]
                (times if nt == threads else ones).append((time.perf_counter() - t0, rest))
        numba.set_num_threads(threads)
        counts[name] = c
        tot, rest = min(times)
        step = [np.sqrt(np.einsum("ij,ij->i", d, d))[F].max(1) for d in D]
        moving = np.mean([(x > si.tol).mean() for x in step])
        tested = np.mean([((x > si.tol) & (x >= si.clearance / 2)).mean() for x in step])
        print(f"  {name:<8} {X.shape[0]} vertices, {F.shape[0]} triangles ({moving:.0%} move per shape, {tested:.0%} "
              f"tested):\n    rest check + clearance {rest * 1e3:.0f} ms, {len(D)} shapes {(tot - rest) * 1e3:.0f} ms, "
              f"in all {tot:.3f} s (min of {repeat}; 1 thread {min(ones)[0]:.3f} s); "
              f"found in {sum(x > 0 for x in c)} shapes, {sum(c)} triangles")
    # peer 1: the numpy path on the shapes that move the most
    X, F, D = sides["target"]
    si_np, si_nb = ix.SelfIntersections(X, F, backend="numpy"), ix.SelfIntersections(X, F)
    pick = np.argsort([-(np.abs(d).max(1) > 0).sum() for d in D])[:4]
    t0 = time.perf_counter()
    same = all((si_np.new(D[i]) == si_nb.new(D[i])).all() for i in pick)
    per = (time.perf_counter() - t0) / len(pick)
    print(f"  peer: numpy path (cKDTree + vectorised SAT), target: {per:.3f} s per shape "
          f"(~{per * len(D):.0f} s for {len(D)}); same triangles: {same}")
    # peer 2: libigl's pair test on one shape's candidate pairs (narrow phase only)
    i_shape = int(np.argmax(counts["target"]))
    V1 = X + D[i_shape]
    query = (np.einsum("ij,ij->i", D[i_shape], D[i_shape]) > si_nb.tol**2)[F].any(1)
    i, j = ix._candidate_pairs(V1, F, query)
    T = V1[F]
    sample = np.random.default_rng(0).choice(i.size, min(i.size, 20000), replace=False)
    t0 = time.perf_counter()
    theirs = np.array([igl.tri_tri_overlap_test_3d(T[a, :1], T[a, 1:2], T[a, 2:], T[b, :1], T[b, 1:2], T[b, 2:])
                       for a, b in zip(i[sample], j[sample], strict=True)])
    igl_per = (time.perf_counter() - t0) / sample.size
    t0 = time.perf_counter()
    vec = ix.triangles_intersect(T[i], T[j])
    vec_per = (time.perf_counter() - t0) / i.size
    print(f"  peer: libigl tri_tri_overlap_test_3d per pair, {template.shape_names[i_shape]}'s {i.size} candidate "
          f"pairs: {igl_per * 1e6:.2f} us/pair ({igl_per * i.size:.3f} s for the shape's narrow phase alone; "
          f"vectorised SAT {vec_per * 1e6:.2f} us/pair); answers equal on {sample.size} pairs: "
          f"{bool((theirs == vec[sample]).all())}")


if __name__ == "__main__":
    main()
