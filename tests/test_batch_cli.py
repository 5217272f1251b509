"""``workbench batch JOBS.toml [--scheduler ADDRESS] [--workers N]`` through the console script."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from batch_jobs import make_project

from workbench.batch.runner import local_cluster

pytestmark = pytest.mark.slow

WORKBENCH = Path(sys.executable).parent / "workbench"  # [project.scripts] workbench = "workbench.cli:main"


def _batch(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(WORKBENCH), "batch", *args], capture_output=True, text=True, timeout=timeout)


def test_local_cluster_run_then_rerun(tmp_path):
    job = make_project(tmp_path, characters=1, takes=2, formats=("glb", "csv"))
    first = _batch(str(job), "--workers", "2", "--no-dashboard")
    assert first.returncode == 0, first.stdout + first.stderr
    assert "2 tasks (1 characters x 2 takes x 1 steps) on 2 workers at tcp://127.0.0.1:" in first.stdout
    assert "100% Completed" in first.stdout  # dask.distributed's text progress bar
    assert "2 tasks: 2 done, 0 skipped, 0 failed, 0 blocked" in first.stdout
    assert "char0/take1/00-export  done" in first.stdout and "char0/take1.glb, char0/take1.csv" in first.stdout
    assert sorted(p.name for p in (tmp_path / "out" / "char0").iterdir()) == [
        "take0.csv", "take0.glb", "take1.csv", "take1.glb"]
    again = _batch(str(job), "--workers", "1", "--no-dashboard")
    assert again.returncode == 0, again.stderr
    assert "2 tasks: 0 done, 2 skipped" in again.stdout


def test_an_existing_scheduler_and_a_failing_take(tmp_path):
    from distributed import Client

    job = make_project(tmp_path, characters=1, takes=2, formats=("glb",))
    (tmp_path / "take0.csv").write_text("time,noSuchShape\n0,1\n")
    cluster = local_cluster(1, dashboard=False, silence_logs=40)
    try:
        with Client(cluster):
            proc = _batch(str(job), "--scheduler", cluster.scheduler_address)
    finally:
        cluster.close()
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert f"on 1 workers at {cluster.scheduler_address}" in proc.stdout
    assert "1 done, 0 skipped, 1 failed" in proc.stdout
    assert "FAILED char0/take0/00-export" in proc.stdout and "take0.csv" in proc.stdout


def test_a_malformed_job_file_fails_before_anything_runs(tmp_path):
    job = make_project(tmp_path, characters=1, takes=1, formats=("glb",))
    job.write_text(job.read_text().replace('kind = "export"', 'kind = "exprot"'))
    proc = _batch(str(job), "--workers", "1", timeout=120)
    assert proc.returncode == 2
    line = job.read_text().splitlines().index('kind = "exprot"') + 1
    assert proc.stderr.startswith(f'workbench batch: jobs.toml line {line}: [[steps]] kind = "exprot": expected one of '), proc.stderr
    assert proc.stdout == "" and not (tmp_path / "out").exists()
