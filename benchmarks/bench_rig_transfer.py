"""Benchmark: rig any face — set-up and transfer of all 52 shapes (issue 16, items 1-2).

Run: .venv/bin/python benchmarks/bench_rig_transfer.py [--template 25k] [--rings 75] [--repeat 3]

The template is the sample head at the "25k" resolution (20,051 vertices, 52
ARKit shapes). The target is a face the template has never seen: the base
head re-triangulated so that no vertex sits where one was (every triangle
split in four through random edge points, old vertices slid along an edge,
a third of the inner edges flipped; :func:`workbench.rigging.synthetic.split_remesh`),
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

The machine is shared and noisy: compare rows of one run, not across runs.
Measured 2026-11-25 (2 cores, load average ~2 from other jobs): set-up 4.1 s
(non-rigid fit 3.1 s: 27 ICP steps, 16 factorisations), transfer 0.33 s (RHS +
solve 0.12 s), peer 5.1 s (44x the RHS + solve); under load average 6 the
same run gave 8.6 s / 0.77 s.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time

import igl
import numpy as np
import scipy.sparse.linalg as spla

import workbench
from workbench.geometry.sparse_cholesky import cholmod_available
from workbench.model import FaceModel, ModelMetadata
from workbench.rigging import RigTransfer
from workbench.rigging import synthetic as syn

WARP = syn.SmoothWarp(
    centres=np.array([[0.4, 7.3, 1.2], [-0.3, 6.4, 1.3], [0.0, 8.0, 0.5]]),
    radii=np.array([0.35, 0.4, 0.6]),
    amplitudes=np.array([[0.05, 0.04, 0.08], [-0.04, 0.0, 0.06], [0.0, 0.08, 0.05]]),
    scale=np.array([1.08, 0.95, 1.04]),
    rotation=syn.SmoothWarp.rotation_xyz([8, 15, -5]),
    unit=10.0,
    translation=np.array([3.0, -60.0, 5.0]),
)


def build_target(rings: int) -> FaceModel:
    base = workbench.load_sample("head")
    V2, F2, W = syn.split_remesh(base.vertices, base.faces, seed=1)
    lab = base.component_labels[np.asarray(W.argmax(axis=1)).ravel()]
    loop = max(igl.boundary_loop_all(F2[lab[F2[:, 0]] == 0]), key=len)
    V3, F3 = syn.add_bust(V2, F2, loop, rings=rings, drop=0.6, flare=2.2)
    lab3 = np.concatenate([lab, np.zeros(V3.shape[0] - V2.shape[0], lab.dtype)])
    return FaceModel(WARP(V3), F3, component_labels=lab3, component_names=base.component_names,
                     metadata=ModelMetadata(name="warped remesh with a bust", units="cm"))


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


if __name__ == "__main__":
    main()
