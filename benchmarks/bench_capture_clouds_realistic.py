"""Benchmark: point-cloud tracking of a realistic take on a face that is not the template (issue #28).

Run: nice .venv/bin/python benchmarks/bench_capture_clouds_realistic.py [--resolution 25k] [--frames 120] [--points 4000]

The actor is the sample head under a smooth warp (its shapes warped exactly, as
``bench_capture.py``'s adaptation table); it plays :func:`workbench.testing.realistic_weights`
(dense co-articulated weights with a non-zero rest, asymmetric, staggered, phone-like
jitter: ~30 shapes active per frame, weights summing to ~7), observed as ``--points`` points
per frame with 0.5 mm noise, 1 % outliers and the head moving. The tracker fits the
*template* (the unwarped head) and adapts it online (Bouaziz 2013).

``--actor person``: the actor is a MakeHuman person the identity PCA never saw (drawn
with another seed from the sample's identity targets; the template's expressions on its
neutral), warped as above; one more row adapts with the identity PCA
(``adapt={"identity": sample_identity_model(model)}``).

Rows, same take, same run: ``track_clouds`` with its defaults (the identity fitted on the first
frame, then held; ``l1 = 0.005``); the paper's online refinement (``refine=True``: the neutral and
every active shape's correctives updated on each frame, with its stronger ``l1 = 0.02``, the
default until 2026-11-29) and the same at ``l1 = 0.005``; adaptation off (the template as it is:
the baseline); the peer, an oracle: the same tracker on the actor's own rig (nothing to adapt: what
the cloud itself allows), at the default ``l1`` and at 0.02; the λ's around the default (``l1 = 0``,
``l1 = 0.02``, ``temporal = 0.2``); ``refine=True`` with the paper's saturation rule (no shape
stops adapting before the neutral's coverage passes σ̄). Weight RMSE is against the true weights
(all shapes; the eye-look and tongue shapes, which a cloud of the skin cannot see, separately
excluded); frames/s are wall and this process's CPU (the machine is shared).

Measured on the 20k head (2026-11-29, beside another benchmark, so the rates are low): defaults
0.1476 (2nd half 0.1348) at 6.4 frames/s; ``refine=True`` 0.1852 (l1 = 0.005: 0.2062); adaptation
off 0.4328; oracle 0.1132 (at l1 = 0.02: 0.1686). What separates the default from the oracle is
the identity: the take's first frame already carries the actor's rest expression (about 2–4 weight
units of it), which one frame of points cannot tell from the face's shape; with the true neutral
and the transferred shapes the same tracker gets 0.118 on the 5k head. The online refinement
does not close it: on a take with ~30 shapes active at once its correctives trade off against
the weights.

Tried 2026-11-30 and not kept (5k head, three takes): on the first frame, the identity and the
weights solved together (the identity eliminated, the weights' bounded L1 problem solved on what
is left, three rounds of correspondences) instead of the identity alone at zero weights, so a
localised rest expression may go to the weights where the identity's bending prior makes it
costly: 0.128 / 0.143 / 0.142 -> 0.126 / 0.142 / 0.140 (oracle 0.110 on the first); a bending prior
three or ten times stronger moves more of the rest into the weights and is worse on two takes of
three (up to 0.161). A rest expression held through the take is the identity's as much as the
weights' as far as the points can tell.

With ``--actor person --resolution base`` (a MakeHuman person + the warp; the set-up 1.2 s, then
27 frames/s): defaults 0.1777; with the identity PCA 0.1585; ``refine=True`` 0.5797; adaptation
off 0.4683; oracle 0.1184.

``--seeds`` tracks several takes and prints the means. One take says little: on five more
(``--seeds 11 13 17 19 23``, 5k head) the defaults average 0.157 on the warped head (shapes a
cloud sees 0.138) and 0.190 (0.179) on the person, and the oracle 0.134 (0.101) and 0.138
(0.106) — **the oracle itself misses 0.12 over all shapes** on these takes. Most of what it
misses is the eye-look and tongue shapes, which move the eyeballs and the tongue that a cloud of
the skin does not sample (on take 3: tongueOut 0.26, the eye looks 0.08–0.20 each, all of them
read about 0); Bouaziz et al. drive their eye shapes from a separate image-based eye tracker
(§3.3), not from the depth.

Tried 2026-11-30 and not kept (5k head, takes 3, 5, 7 unless said):

* the identity's basis and prior: 50, 100 or 200 eigenvectors with β1 = 0.1 or 1: means
  0.1336–0.1440 against 0.1359 for the default (oracle 0.1181): not what is missing;
* the take with its rest removed (each shape's 2nd percentile subtracted): the defaults come
  within 0.007–0.012 of the oracle (0.108 / 0.121 / 0.122 against 0.101 / 0.109 / 0.113; with
  the rest 0.128 / 0.146 / 0.134 against 0.110 / 0.127 / 0.117), so the rest is what separates them;
* preferring the shapes over the identity is not an answer either: the warp's own offset from
  the template (rigidly aligned) is 14 % explained by the shapes with bounded weights summing to
  4.6 (the eye looks, mouthPress, the brows) — more than the rest expression's 1.4–1.8 — so a
  tracker that gave the shapes what they can explain would read the actor's face as a held
  expression;
* the L1 bias refitted away (the relaxed lasso: a second solve on the weights the first left
  non-zero at half the λ): the same as a smaller λ. ``l1 = 0.0025`` helps the warped head
  (0.157 -> 0.150 over takes 11–23) and costs the person (0.190 -> 0.201); 0.001 is worse on
  both (0.158 / 0.225). The default stays 0.005.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

import workbench
from workbench.capture import adapt as adapt_module
from workbench.capture import synthetic_performance
from workbench.capture.clouds import track_clouds
from workbench.testing import capture_actor_warp, realistic_weights, warped


class _PaperSaturation:
    """Bouaziz §3.2's rule, patched in for one row: shapes saturate only after the neutral does."""

    def __enter__(self) -> None:
        self.orig = orig = adapt_module.AdaptiveModel._update

        def _update(am, AS, cv, xv):  # type: ignore[no-untyped-def]
            out = orig(am, AS, cv, xv)
            if not am.coverage_[0] > am.coverage:
                am.saturated_[:] = False
            return out

        adapt_module.AdaptiveModel._update = _update

    def __exit__(self, *exc: object) -> None:
        adapt_module.AdaptiveModel._update = self.orig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", default="25k")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[3],
                    help="take seeds (realistic_weights); several print the means over the takes. 3: the "
                         "take the defaults were reported on; 11 13 17 19 23: five more")
    ap.add_argument("--actor", choices=("warp", "person"), default="warp",
                    help="warp: the sample head warped; person: a MakeHuman person the identity PCA never "
                         "saw (its own neutral, the template's expressions), then warped")
    args = ap.parse_args()
    model = workbench.load_sample("head", args.resolution)
    warp = capture_actor_warp(model.vertices)
    base = model
    if args.actor == "person":
        from workbench.capture.identity import identity_targets, sample_identities
        from workbench.geometry.subdivision import loop_subdivision

        coarse = workbench.load_sample("head", "base")
        person = sample_identities(identity_targets(), 1, seed=99, neutral=coarse.vertices, centre=False)[0]
        if model.n_vertices != coarse.n_vertices:
            levels = {"25k": 1, "100k": 2, "300k": 3}[args.resolution]
            person = loop_subdivision(coarse.faces, coarse.n_vertices, levels)[0] @ person
        base = workbench.FaceModel(np.asarray(model.vertices) + person, model.faces, list(model.shapes),
                                   component_labels=model.component_labels, component_names=model.component_names,
                                   metadata=model.metadata)
    actor = warped(base, warp, name=model.metadata.name).model
    T = args.frames
    seen = np.array([not n.startswith("eyeLook") and n != "tongueOut" for n in model.shape_names])
    rows: list[tuple[str, Any, dict, bool]] = [
        ("`track_clouds` defaults (the identity fitted at the start, l1 = 0.005)", model, {}, False),
        ("the paper's online refinement (`refine=True`, its l1 = 0.02: the old default)", model,
         {"refine": True}, False),
        ("`refine=True`, l1 = 0.005", model, {"refine": True, "l1": 0.005}, False),
        ("adaptation off (the template: baseline)", model, {"adapt": False}, False),
        ("oracle: the actor's own rig, nothing to adapt (peer)", actor, {"adapt": False}, False),
        ("oracle, l1 = 0.02", actor, {"adapt": False, "l1": 0.02}, False),
        ("l1 = 0", model, {"l1": 0.0}, False),
        ("l1 = 0.02", model, {"l1": 0.02}, False),
        ("temporal = 0.2", model, {"temporal": 0.2}, False),
        ("`refine=True` with the paper's saturation rule", model, {"refine": True}, True),
    ]
    if args.actor == "person":
        from workbench.capture.identity import sample_identity_model

        t0 = time.perf_counter()
        pca = sample_identity_model(model)
        print(f"(identity PCA at {model.n_vertices:,} vertices: {time.perf_counter() - t0:.1f} s)\n")
        rows.insert(1, ("adapting with the identity PCA (50 components, β1 = 0.5 mm²)", model,
                        {"adapt": {"identity": pca}}, False))
    # per row: RMSE, seen-shapes RMSE, 2nd half, wall, cpu, set-up, frame seconds; one entry per take
    runs: list[list[tuple[float, ...]]] = [[] for _ in rows]
    for seed in args.seeds:
        W = realistic_weights(actor, T, seed=seed)
        perf = synthetic_performance(actor, T, seed=seed + 1, markers=0, landmarks=0, points=args.points,
                                     noise=0.005, outliers=0.01, head_motion=0.5, weights=W)
        print(f"take {seed}: {model.n_vertices:,} vertices, {T} frames of {args.points} points; "
              f"{(W > 0.05).sum(1).mean():.1f} shapes active per frame, weights summing to {W.sum(1).mean():.1f}",
              flush=True)
        for i, (_label, rig, kw, paper) in enumerate(rows):
            w0, c0 = time.perf_counter(), time.process_time()
            if paper:
                with _PaperSaturation():
                    res = track_clouds(rig, perf.clouds, fps=perf.fps, **kw)
            else:
                res = track_clouds(rig, perf.clouds, fps=perf.fps, **kw)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            err = res.weights - perf.weights
            runs[i].append((float(np.sqrt(np.mean(err ** 2))), float(np.sqrt(np.mean(err[:, seen] ** 2))),
                            float(np.sqrt(np.mean(err[T // 2:] ** 2))), wall, cpu, res.info["seconds"]["setup"],
                            res.info["seconds"]["frames"]))
    several = len(args.seeds) > 1
    print(f"\n{'means over takes ' + ', '.join(map(str, args.seeds)) if several else 'take ' + str(args.seeds[0])}\n")
    print("| tracker | weight RMSE | shapes a cloud sees | 2nd half | frames/s wall | frames/s CPU | set-up (s) | "
          "frames/s after the set-up |" + (" RMSE per take |" if several else ""))
    print("|---|---|---|---|---|---|---|---|" + ("---|" if several else ""))
    for (label, *_), r in zip(rows, runs, strict=True):
        a = np.array(r)
        n = len(a)
        per = " " + " / ".join(f"{x:.3f}" for x in a[:, 0]) + " |" if several else ""
        print(f"| {label} | {a[:, 0].mean():.4f} | {a[:, 1].mean():.4f} | {a[:, 2].mean():.4f} | "
              f"{n * T / a[:, 3].sum():.1f} | {n * T / a[:, 4].sum():.1f} | {a[:, 5].mean():.1f} | "
              f"{n * T / a[:, 6].sum():.1f} |{per}")


if __name__ == "__main__":
    main()
