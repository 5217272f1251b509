"""Benchmark: loading FBX, Alembic, USD and C3D files, ours against a peer in the same run.

Run: .venv/bin/python benchmarks/bench_import_formats.py [--repeat 3]

Files (``tests/tools/format_writers.py``, cached): the sample head (5,084
vertices, two meshes, six shape keys, frames 0-20) written by Blender 5.0
(``face.fbx``, ``face.abc`` 21 frames, ``face_blender.usda``) and by usd-core
(UsdSkel, ``.usda`` and ``.usdc``); a C3D take written by ezc3d (71 head
vertices as markers, 3,000 frames at 120 fps, gaps). Rows:

* **FBX / Alembic** — ours: ``read_fbx`` / ``read_alembic`` (checked pre-parse,
  a fresh Blender subprocess, its importer, the npz dump, checks), dump cache
  cleared every run; peer: Blender's importer itself, timed inside Blender
  (``import_scene.fbx``; ``alembic_import`` + evaluating every frame, which any
  reader of the cache must do), and the whole bpy subprocess (start + import);
* **USD** — ours: ``read_usd``; peer: the raw pxr read (``Usd.Stage.Open`` and
  ``Get()`` of points, face counts/indices, blend-shape offsets and indices,
  SkelAnimation weights at every time sample; no checks, no transforms);
* **C3D** — ours: ``read_markers`` (structure check + ezc3d + metres/gaps);
  peer: ``ezc3d.c3d(path)`` alone.

Median of ``--repeat`` runs after one warm-up; one process, 2 shared cores.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "tools"))

import format_writers as fw  # noqa: E402

from workbench.io import blender_bridge  # noqa: E402
from workbench.io.alembic import read_alembic, read_time_samplings  # noqa: E402
from workbench.io.c3d import read_markers  # noqa: E402
from workbench.io.fbx import read_fbx  # noqa: E402
from workbench.io.usd import read_usd  # noqa: E402

PEER_SCRIPT = r"""
import json, sys, time
t0 = time.perf_counter()
import bpy
args = json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
t = time.perf_counter()
if args["kind"] == "fbx":
    bpy.ops.import_scene.fbx(filepath=args["path"], anim_offset=0.0)
else:
    scene.render.fps = args["fps"]
    bpy.ops.wm.alembic_import(filepath=args["path"], set_frame_range=False, as_background_job=False)
    for f in range(args["frames"]):
        scene.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        for ob in scene.objects:
            if ob.type == "MESH":
                ev = ob.evaluated_get(dg)
                me = ev.to_mesh()
                ev.to_mesh_clear()
print("PEER", json.dumps({"import": time.perf_counter() - t, "startup": t - t0}))
"""


def median_time(fn: Callable[[], object], repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def bpy_peer(path: Path, kind: str, repeat: int, fps: float = 30.0, frames: int = 0) -> tuple[float, float]:
    """(median import time inside Blender, median wall time of the subprocess)."""
    py = blender_bridge.blender_python()
    assert py is not None, "no Python with bpy (WORKBENCH_BPY_PYTHON)"
    inside, wall = [], []
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "peer.py"
        script.write_text(PEER_SCRIPT)
        arg = json.dumps({"path": str(path), "kind": kind, "fps": round(fps), "frames": frames})
        for k in range(repeat + 1):
            t = time.perf_counter()
            out = subprocess.run([str(py), str(script), arg], capture_output=True, text=True, check=True).stdout
            w = time.perf_counter() - t
            if k:
                line = next(ln for ln in out.splitlines() if ln.startswith("PEER"))
                inside.append(json.loads(line[5:])["import"])
                wall.append(w)
    return statistics.median(inside), statistics.median(wall)


def ours_blender(fn: Callable[[Path], object], path: Path) -> Callable[[], object]:
    def run() -> object:
        blender_bridge._CACHE.clear()  # a cold read: Blender runs every time
        return fn(path)

    return run


def pxr_raw(path: Path) -> None:
    from pxr import Usd, UsdGeom, UsdSkel

    stage = Usd.Stage.Open(str(path))
    t = Usd.TimeCode.EarliestTime()
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            m = UsdGeom.Mesh(prim)
            np.asarray(m.GetPointsAttr().Get(t))
            np.asarray(m.GetFaceVertexCountsAttr().Get(t))
            np.asarray(m.GetFaceVertexIndicesAttr().Get(t))
            for target in UsdSkel.BindingAPI(prim).GetBlendShapeTargetsRel().GetTargets():
                bs = UsdSkel.BlendShape(stage.GetPrimAtPath(target))
                np.asarray(bs.GetOffsetsAttr().Get())
                ix = bs.GetPointIndicesAttr().Get()
                if ix is not None:
                    np.asarray(ix)
        elif prim.IsA(UsdSkel.Animation):
            w = UsdSkel.Animation(prim).GetBlendShapeWeightsAttr()
            for tc in w.GetTimeSamples():
                np.asarray(w.Get(tc))


def write_take(path: Path, n_frames: int = 3000, fps: int = 120) -> Path:
    """A 3,000-frame C3D take written by ezc3d: 71 head vertices moving, a few gaps."""
    import ezc3d

    src = fw.face_source()
    V = src.objects[0].vertices
    ids = np.linspace(0, V.shape[0] - 1, 71).astype(int)
    t = np.arange(n_frames) / fps
    rng = np.random.default_rng(0)
    P = V[ids][None] * 100.0 + 3.0 * np.sin(2 * np.pi * 0.7 * t)[:, None, None] * rng.normal(size=(1, ids.size, 3))
    pts = np.ones((4, ids.size, n_frames))
    pts[:3] = P.transpose(2, 1, 0)
    pts[:3, 5, 100:140] = np.nan
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [fps]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(f"M{j:02d}" for j in range(ids.size))
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c["data"]["points"] = pts
    c.write(str(path))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    import ezc3d

    files = fw.blender_files()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        usda = fw.write_usdskel(Path(tmp) / "face.usda")
        usdc = fw.write_usdskel(Path(tmp) / "face.usdc")
        take = write_take(Path(tmp) / "take.c3d")
        n = read_fbx(files["fbx"]).n_vertices

        ours = median_time(ours_blender(read_fbx, files["fbx"]), args.repeat)
        inside, wall = bpy_peer(files["fbx"], "fbx", args.repeat)
        rows.append(("FBX (Blender)", files["fbx"], n, ours, f"bpy import_scene.fbx {inside:.3f} s (subprocess {wall:.3f} s)"))

        ts = max(read_time_samplings(files["abc"]), key=lambda s: s.max_samples)
        ours = median_time(ours_blender(read_alembic, files["abc"]), args.repeat)
        inside, wall = bpy_peer(files["abc"], "abc", args.repeat, ts.fps, ts.max_samples)
        rows.append((f"Alembic ({ts.max_samples} frames)", files["abc"], n, ours, f"bpy alembic_import + frames {inside:.3f} s (subprocess {wall:.3f} s)"))

        for label, p in (("USD usd-core .usda", usda), ("USD usd-core .usdc", usdc), ("USD Blender .usda", files["usd"])):
            ours = median_time(lambda p=p: read_usd(p), args.repeat)
            peer = median_time(lambda p=p: pxr_raw(p), args.repeat)
            rows.append((label, p, n, ours, f"pxr Stage.Open + Get {peer:.3f} s"))

        ours = median_time(lambda: read_markers(take), args.repeat)
        peer = median_time(lambda: ezc3d.c3d(str(take)), args.repeat)
        rows.append(("C3D 71 markers x 3000", take, 71, ours, f"ezc3d.c3d {peer:.3f} s"))

        print(f"{'file':<26} {'MB':>6} {'vertices':>9} {'ours (s)':>9}  peer")
        for label, p, nv, t, peer_s in rows:
            print(f"{label:<26} {p.stat().st_size / 1e6:>6.2f} {nv:>9} {t:>9.3f}  {peer_s}")


if __name__ == "__main__":
    main()
