"""Benchmark: export 10 s at 30 fps (301 frames) with all 52 shapes keyed, per format.

Run: .venv/bin/python benchmarks/bench_export.py [--resolutions 25k 100k] [--formats glb ...]

Every shape gets an auto-clamped Bézier key every 0.5 s (21 keys, random
values in [0, 1]), so the glTF file has a CUBICSPLINE sampler with 21 merged
key times; per-frame formats evaluate all 301 frames. Prints wall time (s) and
output size (MB, all files of the format). Single run per cell: exports are
seconds long and the machine is shared.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

import workbench
from workbench.animation.curves import Key, Track, weight_track_name
from workbench.animation.tracks import Timeline
from workbench.export import export

FORMATS = {
    "glb": ("face.glb", {}),
    "glb-baked": ("face_baked.glb", {"bake": True}),
    "usdc": ("face.usdc", {}),
    "usda": ("face.usda", {}),
    "pc2": ("face.pc2", {}),
    "mdd": ("face.mdd", {}),
    "csv": ("face.csv", {}),
    "obj-seq": ("seq/face.obj", {}),
    # through Blender (bpy in .venv/blender or $WORKBENCH_BPY_PYTHON); not in the default set
    "fbx": ("face.fbx", {}),
    "abc": ("face.abc", {}),
}
DEFAULT_FORMATS = [f for f in FORMATS if f not in ("fbx", "abc")]


def keyed_timeline(shape_names: list[str], seconds: float = 10.0, fps: float = 30.0) -> Timeline:
    rng = np.random.default_rng(0)
    times = np.arange(0.0, seconds + 1e-9, 0.5)
    tracks = {}
    for s in shape_names:
        name = weight_track_name(s)
        tracks[name] = Track(name, tuple(Key(t, v) for t, v in zip(times, rng.uniform(0, 1, times.size), strict=True)))
    return Timeline(fps=fps, start=0.0, end=seconds, tracks=tracks)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--resolutions", nargs="+", default=["25k", "100k"])
    ap.add_argument("--formats", nargs="+", default=DEFAULT_FORMATS, choices=list(FORMATS),
                    help="fbx and abc need Blender as a Python module (see workbench/export/blender.py)")
    args = ap.parse_args()
    rows = []
    for res in args.resolutions:
        model = workbench.load_sample("head", resolution=res)
        tl = keyed_timeline(model.shape_names)
        for fmt in args.formats:
            name, opts = FORMATS[fmt]
            with tempfile.TemporaryDirectory() as d:
                out = Path(d) / name
                t0 = time.perf_counter()
                paths = export(model, tl, out, **opts)
                dt = time.perf_counter() - t0
                mb = sum(p.stat().st_size for p in paths) / 1e6
                shutil.rmtree(d, ignore_errors=True)
            rows.append((res, model.n_vertices, fmt, len(paths), dt, mb))
            print(f"  {res:>5} {fmt:<10} {dt:7.2f} s {mb:9.1f} MB", flush=True)
    print()
    print(f"{'model':>6} {'vertices':>9} {'format':<10} {'files':>5} {'time (s)':>9} {'size (MB)':>10}")
    for res, n, fmt, nfiles, dt, mb in rows:
        print(f"{res:>6} {n:>9} {fmt:<10} {nfiles:>5} {dt:>9.2f} {mb:>10.1f}")


if __name__ == "__main__":
    main()
