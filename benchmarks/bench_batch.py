"""Benchmark: batch throughput on 1 vs 2 Dask workers, and the per-task overhead.

Run: .venv/bin/python benchmarks/bench_batch.py [--takes 8] [--resolution 25k] [--formats glb usda]

One character (the sample head at ``--resolution``, 20,051 vertices for 25k, 52 shapes) ×
``--takes`` takes of 4 s at 30 fps (6 shapes keyed, 5 keys each), one ``export`` step writing
``--formats``: CPU-bound tasks of a second or so. Each cluster (processes, one thread each,
127.0.0.1, no dashboard) is started and warmed up (each worker loads the rig once: the
per-worker memo) before the timed run; every timed run writes a fresh output folder, so no
task is skipped. Prints:

* throughput (tasks/s) with 1 and 2 workers and the speed-up;
* per-task overhead: the same export called directly in this process, the batch task function
  in this process (no Dask), one batch task (1 worker, wall time / tasks), an empty Dask task (submit + result of a no-op), and a
  skipped task (a re-run of a finished job: hashing inputs and checking the task records).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))


def _noop(x: int) -> int:
    return x


def _peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kB


def _job(root: Path, takes: int, resolution: str, formats: tuple[str, ...], output: str) -> Path:
    from batch_jobs import make_project

    job = make_project(root, characters=1, takes=takes, formats=formats, resolution=resolution, seconds=4.0)
    job.write_text(job.read_text().replace('output = "out"', f'output = "{output}"'))
    return job


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--takes", type=int, default=12)
    ap.add_argument("--resolution", default="25k")
    ap.add_argument("--formats", nargs="+", default=["glb", "usda"])
    args = ap.parse_args()

    from distributed import Client

    import workbench
    from workbench.batch import load_jobs, plan, run
    from workbench.batch.runner import local_cluster
    from workbench.export import export
    from workbench.io.animation import read_file_animation

    formats = tuple(args.formats)
    tmp = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    job = _job(tmp, args.takes, args.resolution, formats, "warm")
    n_vertices = workbench.load(tmp / "char0.fwb").n_vertices

    # the direct call: the same work in this process, rig loaded once, one BLAS thread as a worker has
    from threadpoolctl import threadpool_limits

    model = workbench.load(tmp / "char0.fwb")
    with threadpool_limits(1):
        t0 = time.perf_counter()
        for t in range(args.takes):
            tl = read_file_animation(tmp / f"take{t}.csv", model.shape_names)
            for f in formats:
                export(model, tl, tmp / "direct" / f"take{t}.{f}")
        direct = (time.perf_counter() - t0) / args.takes
        # the same tasks through workbench.batch's task function, in this process (no Dask)
        from workbench.batch.tasks import execute

        chains = plan(load_jobs(_job(tmp, args.takes, args.resolution, formats, "inprocess")))
        execute(chains[0][0])  # loads the rig into this process's memo
        t0 = time.perf_counter()
        for chain in chains[1:]:
            execute(chain[0])
        in_process = (time.perf_counter() - t0) / max(1, len(chains) - 1)
    load_before = os.getloadavg()[0]

    rows = {}
    for workers in (1, 2):
        cluster = local_cluster(workers, dashboard=False, silence_logs=50)
        with Client(cluster) as client:
            run(job, client, progress=False)  # warm-up: every worker loads the rig (once)
            timed = load_jobs(_job(tmp, args.takes, args.resolution, formats, f"out{workers}"))
            t0 = time.perf_counter()
            report = run(timed, client, progress=False)
            wall = time.perf_counter() - t0
            assert report.counts["done"] == args.takes, report.table()
            t0 = time.perf_counter()
            again = run(timed, client, progress=False)
            skipped = (time.perf_counter() - t0) / args.takes
            assert again.counts["skipped"] == args.takes
            n = 200
            t0 = time.perf_counter()
            client.gather([client.submit(_noop, i, pure=False) for i in range(n)])
            empty = (time.perf_counter() - t0) / n
            rss = client.run(_peak_rss_mb)
            rows[workers] = (wall, report, skipped, empty, max(rss.values()))
        cluster.close()

    w1 = rows[1][0]
    print(f"load average before the runs {load_before:.2f} (2 cores; other work slows the 2-worker run)")
    print(f"batch: 1 character ({n_vertices:,} vertices, 52 shapes) x {args.takes} takes x export "
          f"{'+'.join(formats)}; {args.takes} tasks")
    print()
    print("| workers | wall (s) | tasks/s | speed-up |")
    print("|---|---|---|---|")
    for workers in (1, 2):
        wall = rows[workers][0]
        print(f"| {workers} | {wall:.2f} | {args.takes / wall:.2f} | {w1 / wall:.2f}x |")
    print()
    task_1 = w1 / args.takes
    print("| per task | seconds |")
    print("|---|---|")
    print(f"| direct call in this process (read take + export) | {direct:.3f} |")
    print(f"| the task function in this process, no Dask (record, log, digests) | {in_process:.3f} |")
    print(f"| batch task, 1 worker (wall / tasks, incl. planning and hashing inputs) | {task_1:.3f} |")
    print(f"| overhead of a batch task (1 worker - direct) | {task_1 - direct:.3f} |")
    print(f"| empty Dask task (submit + gather a no-op, 2 workers) | {rows[2][3]:.4f} |")
    print(f"| skipped task (re-run of a finished job, 1 worker) | {rows[1][2]:.3f} |")
    print()
    import json

    sizes = [len(json.dumps(o.timeline)) for o in rows[1][1].outcomes]
    print(f"peak worker memory (RSS): {rows[1][4]:.0f} MB (1 worker), {rows[2][4]:.0f} MB (2 workers); "
          f"timeline JSON handed on per take: {np.mean(sizes) / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
