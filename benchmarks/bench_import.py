"""Benchmark: loading faces from files, per format, with a peer reader in the same run (issue #15).

Run: .venv/bin/python benchmarks/bench_import.py [--files 54] [--grid 163] [--repeat 3] [--no-peers]

Generated into a temporary folder (nothing is downloaded):

* ``local shapes``: a head-sized grid (163 x 164 = 26,732 vertices, quads, in cm)
  written as Blender writes OBJ (``v``/``vt``/``vn`` with 6 decimals, ``f v/vt/vn``),
  a ``neutral.obj`` and 53 shape files. Each shape moves a compact patch of 4-54 % of
  the vertices, as the sample head's ARKit shapes do (mean 22 %); the other
  vertices are written with the same text as in the neutral, as a DCC does.
* ``every vertex moved``: the same mesh, each shape a smooth warp of the whole
  head (the worst case: every ``v`` line differs from the neutral's).
* ``sample head 25k``: the bundled head at 20,051 vertices with its 52 ARKit shapes
  (53 files).

Rows: ``workbench.load`` of the folder (the reader plus building the FaceModel),
the reader alone (``read_obj_folder``; 1 thread and the default pool), and the
peer, ``trimesh.load(path, process=False)`` on every file (vertices and
triangles only: no polygons, groups, line-numbered errors or topology check).
Then one OBJ file (ours vs trimesh) and one .glb with the same 53 morph targets
(``workbench.load`` vs ``pygltflib`` parsing the file and decoding the same
accessors with numpy). Times are the median of ``--repeat`` runs with the files
in the page cache (trimesh: one run), wall clock and CPU time of the process (all
threads; on a shared, loaded machine the CPU time is what the reader costs). The
machine is shared and noisy: compare rows of one run, not across runs. Goal
(issue #15): the 54-file folder in <= 2 s.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import workbench
from workbench.io.obj import read_obj
from workbench.io.obj_folder import read_obj_folder


def head_grid(n: int = 163) -> tuple[np.ndarray, np.ndarray]:
    """(V (n (n + 1), 3) in cm, quads): a closed-around, open-ended ellipsoidal head of quads."""
    theta = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    t = np.linspace(-0.95, 0.95, n + 1)
    T, TH = np.meshgrid(t, theta, indexing="ij")
    r = np.sqrt(1.0 - T**2) * (1.0 + 0.05 * np.sin(3.0 * TH) * np.cos(2.0 * T))
    V = np.stack([9.0 * r * np.cos(TH), 13.0 * T, 11.0 * r * np.sin(TH)], axis=-1).reshape(-1, 3)
    j, i = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = j * n + i
    b = j * n + (i + 1) % n
    return V, np.stack([a, b, b + n, a + n], axis=-1).reshape(-1, 4)


def write_obj(path: Path, V: np.ndarray, quads: np.ndarray) -> None:
    """An OBJ as Blender writes it: v, vt, vn (6 / 4 decimals), s, f v/vt/vn."""
    lines = ["# Blender-style OBJ (generated)", "o head"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in V.tolist()]
    uv = (V[:, :2] - V[:, :2].min(0)) / np.ptp(V[:, :2], axis=0)
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv.tolist()]
    nrm = V / np.linalg.norm(V, axis=1, keepdims=True)
    lines += [f"vn {x:.4f} {y:.4f} {z:.4f}" for x, y, z in nrm.tolist()]
    lines.append("s 1")
    lines += ["f " + " ".join(f"{k}/{k}/{k}" for k in q) for q in (quads + 1).tolist()]
    path.write_text("\n".join(lines) + "\n")


def write_folder(
    root: Path, V: np.ndarray, F: np.ndarray, n_files: int, *, everywhere: bool
) -> Path:
    root.mkdir()
    rng = np.random.default_rng(0)
    write_obj(root / "neutral.obj", V, F)
    fractions = np.linspace(0.04, 0.54, n_files - 1)
    for k, frac in enumerate(fractions):
        if everywhere:
            phase = rng.uniform(0, 2 * np.pi, 3)
            D = 0.3 * np.sin(V / 5.0 + phase)
        else:
            d = np.linalg.norm(V - V[rng.integers(len(V))], axis=1)
            radius = np.quantile(d, frac)
            fall = np.clip(1.0 - (d / radius) ** 2, 0.0, None) ** 2
            D = fall[:, None] * rng.normal(scale=0.6, size=3)
        write_obj(root / f"shape{k:02d}.obj", V + D, F)
    return root


def write_sample_folder(root: Path) -> Path:
    model = workbench.load_sample("head", resolution="25k")
    root.mkdir()
    P = model.polygons
    quads_or_tris = [P[i] for i in range(len(P))]

    def write(path: Path, V: np.ndarray) -> None:
        lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in V.tolist()]
        lines += ["f " + " ".join(str(int(k) + 1) for k in q) for q in quads_or_tris]
        path.write_text("\n".join(lines) + "\n")

    write(root / "neutral.obj", model.vertices)
    for s in model.shapes:
        write(root / f"{s.name}.obj", model.vertices + s.delta.astype(np.float64))
    return root


def median_time(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Median wall time and median CPU time of this process (all threads), in s."""
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu)


def trimesh_folder(folder: Path) -> None:
    import trimesh

    for p in sorted(folder.glob("*.obj")):
        trimesh.load(p, process=False)


def pygltflib_load(path: Path) -> None:
    """Parse the .glb and decode POSITION and every morph target's POSITION with numpy (dense or sparse)."""
    import pygltflib

    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()

    def view(index: int, offset: int | None, dtype: type, count: int) -> np.ndarray:
        start = (g.bufferViews[index].byteOffset or 0) + (offset or 0)
        return np.frombuffer(blob, dtype, count, start)

    def read(index: int) -> np.ndarray:
        acc = g.accessors[index]
        out = (
            np.zeros((acc.count, 3), np.float32)
            if acc.bufferView is None
            else view(acc.bufferView, acc.byteOffset, np.float32, acc.count * 3).reshape(-1, 3).copy()
        )
        if acc.sparse is not None:  # our writer stores morph targets as sparse accessors
            sp = acc.sparse
            itype = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}[sp.indices.componentType]
            idx = view(sp.indices.bufferView, sp.indices.byteOffset, itype, sp.count)
            out[idx] = view(sp.values.bufferView, sp.values.byteOffset, np.float32, sp.count * 3).reshape(-1, 3)
        return out

    for mesh in g.meshes:
        for prim in mesh.primitives:
            read(prim.attributes.POSITION)
            for target in prim.targets or []:
                read(target["POSITION"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--files", type=int, default=54, help="OBJ files per folder (neutral + shapes)")
    ap.add_argument("--grid", type=int, default=163, help="grid size: n (n + 1) vertices")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-peers", action="store_true", help="skip trimesh / pygltflib")
    args = ap.parse_args()

    Timing = tuple[float, float]
    rows: list[tuple[str, str, Timing, Timing | None]] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        V, F = head_grid(args.grid)
        folders = {
            "local shapes": write_folder(root / "local", V, F, args.files, everywhere=False),
            "every vertex moved": write_folder(root / "all", V, F, args.files, everywhere=True),
            "sample head 25k": write_sample_folder(root / "sample"),
        }
        for label, folder in folders.items():
            n_files = len(list(folder.glob("*.obj")))
            n_v = read_obj(folder / "neutral.obj").n_vertices
            what = f"{label}: {n_files} OBJ x {n_v:,} v"
            peer = None if args.no_peers else median_time(lambda f=folder: trimesh_folder(f), 1)
            rows.append((what, "workbench.load", median_time(lambda f=folder: workbench.load(f), args.repeat), peer))
            rows.append((what, "read_obj_folder", median_time(lambda f=folder: read_obj_folder(f), args.repeat), peer))
            rows.append(
                (what, "read_obj_folder, 1 thread", median_time(lambda f=folder: read_obj_folder(f, workers=1), args.repeat), peer)
            )
            print(f"  {what}: load {rows[-3][2][0]:.2f} s, trimesh {'-' if peer is None else f'{peer[0]:.2f}'} s", flush=True)

        one = folders["local shapes"] / "neutral.obj"
        peer = None
        if not args.no_peers:
            import trimesh

            peer = median_time(lambda: trimesh.load(one, process=False), args.repeat)
        rows.append((f"one OBJ x {V.shape[0]:,} v", "read_obj", median_time(lambda: read_obj(one), args.repeat), peer))

        from workbench.animation.tracks import Timeline
        from workbench.export import export

        model = workbench.load(folders["local shapes"])
        glb = root / "face.glb"
        export(model, Timeline(), glb)
        peer = None if args.no_peers else median_time(lambda: pygltflib_load(glb), args.repeat)
        t = median_time(lambda: workbench.load(glb), args.repeat)
        rows.append((f".glb, {len(model.shapes)} morph targets x {model.n_vertices:,} v", "workbench.load", t, peer))

    print()
    print(
        f"{'input':<40} {'ours':<26} {'wall (s)':>9} {'CPU (s)':>8} {'peer wall':>10} {'peer CPU':>9} "
        f"{'peer/ours wall':>15} {'CPU':>6}"
    )
    for what, how, (w, c), peer in rows:
        if peer is None:
            tail = f"{'-':>10} {'-':>9} {'-':>15} {'-':>6}"
        else:
            tail = f"{peer[0]:>10.3f} {peer[1]:>9.3f} {peer[0] / w:>14.1f}x {peer[1] / c:>5.1f}x"
        print(f"{what:<40} {how:<26} {w:>9.3f} {c:>8.3f} {tail}")
    print("peers: trimesh.load(path, process=False) per OBJ file; pygltflib load + numpy decode for .glb")


if __name__ == "__main__":
    main()
