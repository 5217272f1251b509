"""Benchmark: marker replay through the shell against blendshape tracking (Bickel et al. 2008 Fig. 6; issue 29).

Run: .venv/bin/python benchmarks/bench_marker_replay.py [--frames 90] [--markers 120] [--seed 11]

The take: a realistic performance (:func:`workbench.testing.takes.realistic_take`:
dense, co-articulated, asymmetric weights, head motion up to 10°) of the *full*
rig, observed as markers with Gaussian noise. It is put back on a rig that lacks
every other shape (so the take lies partly outside the rig's span):

* **LS** — per-frame least squares on the half rig (no L1, no temporal prior):
  the naive peer;
* **track** — blendshape tracking (Bouaziz 2013, λ's chosen from the take);
* **replay exact** — the markers drive the shell, interpolated exactly
  (``smoothing=0``);
* **smooth** — offsets smoothed over two frames (``denoise=False``);
* **replay** — the default: smoothed, and each marker's offsets shrunk by its
  Wiener gain (noise measured from its own second differences).

Faces: the sample head (5,084 vertices, dm), the same head at 25k, and
:func:`workbench.testing.foreign_face` (remeshed, other proportions, open
mouth and eyes, bust, cm). Error: mean skin-vertex error in millimetres over the
take (head pose removed), and the ratio replay / track (target ≤ 0.75).
Seconds: the whole replay (tracking included), and its frames/s.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import workbench
from workbench.capture import replay, track
from workbench.geometry.masks import skin_or_all_mask
from workbench.model import FaceModel
from workbench.testing import foreign_face
from workbench.testing.takes import realistic_take


def half_rig(m: FaceModel) -> FaceModel:
    return FaceModel(m.vertices, m.faces, m.shapes[::2], polygons=m.polygons, component_labels=m.component_labels,
                     component_names=list(m.component_names), metadata=m.metadata)


def tracked(rig: FaceModel, perf, **kw) -> np.ndarray:
    res = track(rig, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps, **kw)
    tl = res.to_timeline(0.0, head_pose=False)
    return np.stack([rig.evaluation_at(f / perf.fps, tl).mesh for f in range(perf.markers.shape[0])])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=90)
    ap.add_argument("--markers", type=int, default=120)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args()
    head = workbench.load_sample("head")
    faces = [("sample head", head), ("sample head 25k", workbench.load_sample("head", "25k")),
             ("foreign face", foreign_face(head, seed=3).model)]
    print(f"take: {args.frames} frames, {args.markers} markers, realistic weights of the full rig, replayed on a rig "
          "with every other shape; error = mean skin error (mm)")
    print(f"{'face':16s} {'verts':>6s} {'noise':>6s} {'LS':>7s} {'track':>7s} {'exact':>7s} {'smooth':>7s} {'replay':>7s} "
          f"{'replay/track':>12s} {'seconds':>8s} {'frames/s':>8s}")
    for name, face in faces:
        skin = skin_or_all_mask(face)
        mm = 1000.0 * float(face.metadata.metres_per_unit)
        rig = half_rig(face)
        for noise in (0.0, 0.15, 0.5):
            perf = realistic_take(face, args.frames, seed=args.seed, markers=args.markers, noise_mm=noise)
            P = perf.poses
            truth = np.einsum("tji,tnj->tni", P[:, :3, :3], perf.meshes - P[:, None, :3, 3])

            def err(M, truth=truth, skin=skin, mm=mm):
                return mm * float(np.linalg.norm(M - truth, axis=2)[:, skin].mean())

            e_ls = err(tracked(rig, perf, l1=0.0, temporal=0.0))
            e_tr = err(tracked(rig, perf))
            e_ex = err(replay(rig, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps, smoothing=0.0,
                              wrinkles=False).meshes)
            e_sm = err(replay(rig, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps, denoise=False,
                              wrinkles=False).meshes)
            t0 = time.perf_counter()
            rep = replay(rig, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps)
            dt = time.perf_counter() - t0
            e_rp = err(rep.meshes)
            print(f"{name:16s} {face.n_vertices:6d} {noise:6.2f} {e_ls:7.3f} {e_tr:7.3f} {e_ex:7.3f} {e_sm:7.3f} {e_rp:7.3f} "
                  f"{e_rp / e_tr:12.2f} {dt:8.1f} {args.frames / dt:8.1f}", flush=True)


if __name__ == "__main__":
    main()
