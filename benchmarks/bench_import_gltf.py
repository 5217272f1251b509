"""Benchmark: loading compressed .glb files (meshopt, Draco) against pygltflib parsing them.

Run: .venv/bin/python benchmarks/bench_import_gltf.py [--resolutions base 25k 100k] [--repeat 5]

The file is the sample head cut into head, teeth and eyes meshes with all 52
ARKit targets and a weights animation (``tests/tools/face_gltf.py``), written
plain and re-written by real tools (``tests/tools``, ``npm ci`` there):
gltfpack ``-cc`` (EXT_meshopt_compression + KHR_mesh_quantization), glTF-Transform
``draco`` (KHR_draco_mesh_compression) and ``sparse``. Per file:

* ``read_gltf``: our reader, everything decoded and checked (positions,
  indices, 52 x 3 morph targets, node transforms) into an ImportedFace;
* ``workbench.load``: the same plus building the FaceModel (triangulation,
  components);
* peer ``pygltflib``: ``GLTF2().load`` — JSON and buffers parsed into its
  dataclasses, *no* accessor decoded (it cannot decode meshopt or Draco at
  all), so it is a lower bound for any loader built on it.

Median of ``--repeat`` runs after one warm-up, one process, 2 shared cores.
"""

from __future__ import annotations

import argparse
import logging
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "tools"))

from face_gltf import build_source_glb, face_source  # noqa: E402
from gltf_writers import node_bin, run  # noqa: E402

import workbench  # noqa: E402
from workbench.arkit import ARKIT_52  # noqa: E402
from workbench.io.gltf import read_gltf  # noqa: E402


def median_time(fn: Callable[[], object], repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--resolutions", nargs="+", default=["base", "25k", "100k"])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    import pygltflib

    # the reader's notes (skipped texture extensions, triangles flattened by quantization) once per file, not per run
    logging.getLogger("workbench.io.gltf").setLevel(logging.ERROR)
    tools = node_bin()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for res in args.resolutions:
            src = face_source(res, shapes=list(ARKIT_52))
            n = len(src.vertices())
            plain = build_source_glb(src, Path(tmp) / f"{res}-plain.glb")
            files = {"plain": plain}
            files["gltfpack -cc"] = Path(tmp) / f"{res}-meshopt.glb"
            run([str(tools / "gltfpack"), "-i", str(plain), "-o", str(files["gltfpack -cc"]), "-cc", "-kn"])
            for cmd in ("draco", "sparse"):
                files[cmd] = Path(tmp) / f"{res}-{cmd}.glb"
                run([str(tools / "gltf-transform"), cmd, str(plain), str(files[cmd])])
            for kind, path in files.items():
                mb = path.stat().st_size / 1e6
                ours = median_time(lambda p=path: read_gltf(p), args.repeat)
                full = median_time(lambda p=path: workbench.load(p), args.repeat)
                peer = median_time(lambda p=path: pygltflib.GLTF2().load(str(p)), args.repeat)
                rows.append((res, n, kind, mb, ours, full, peer))
                print(f"  {res:>5} {kind:<13} {mb:6.2f} MB  read_gltf {ours:.3f} s  load {full:.3f} s  pygltflib {peer:.3f} s", flush=True)
    print()
    print(f"{'model':>6} {'vertices':>9} {'file':<13} {'MB':>6} {'read_gltf (s)':>14} {'workbench.load (s)':>19} {'pygltflib parse (s)':>20}")
    for res, n, kind, mb, ours, full, peer in rows:
        print(f"{res:>6} {n:>9} {kind:<13} {mb:>6.2f} {ours:>14.3f} {full:>19.3f} {peer:>20.3f}")
    print("\npeer: pygltflib GLTF2().load parses JSON + buffers only (no accessor decoding; no meshopt/Draco support)")


if __name__ == "__main__":
    main()
