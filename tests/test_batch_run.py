"""Batch jobs on a real 2-worker Dask LocalCluster: outputs read by real consumers, caching, failures.

The cluster is what ``workbench batch`` starts: two worker processes with one thread each, every
server on 127.0.0.1, no dashboard.
"""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

pytest.importorskip("distributed")

from batch_consumers import (
    expected_points,
    played_weights,
    three_js,
    usd,
    usdskel_points,
    validate_gltf,
)
from batch_jobs import make_project, small_head, write_marker_take, write_take

import workbench.batch as batch
from workbench.animation.tracks import Timeline
from workbench.batch.cache import memo_stats
from workbench.batch.runner import local_cluster

pytestmark = pytest.mark.slow

RETIME = '[[steps]]\nkind = "retime"\nt0 = 0.25\nt1 = 0.75\ndatabase = ["perf0.csv", "perf1.csv"]\n'


@pytest.fixture(scope="module")
def client():
    from distributed import Client

    cluster = local_cluster(2, dashboard=False, silence_logs=40)
    c = Client(cluster)
    try:
        yield c
    finally:
        c.close()
        cluster.close()


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """2 characters x 3 takes x 2 steps (retime, export glb + usdc) = 12 tasks."""
    root = tmp_path_factory.mktemp("batch")
    head = small_head()
    for i in range(2):
        write_take(head, root / f"perf{i}.csv", seed=10 + i, seconds=3.0)
    job = make_project(root, characters=2, takes=3, formats=("glb", "usdc"))
    text = job.read_text()
    job.write_text(text.replace("[[steps]]", RETIME + "\n[[steps]]", 1))
    return job


def _run(job, client):
    return batch.run(job, client, progress=False)


@pytest.fixture(scope="module")
def first_run(project, client):
    return _run(project, client)


def test_twelve_tasks_complete_on_two_workers(first_run, project, client):
    report = first_run
    assert len(report.outcomes) == 12
    assert report.counts == {"done": 12, "skipped": 0, "failed": 0, "blocked": 0}, report.table()
    assert len({o.worker for o in report.outcomes}) == 2  # both workers took tasks
    servers = [client.scheduler.address, *client.scheduler_info()["workers"]]
    assert all(a.startswith("tcp://127.0.0.1:") for a in servers), servers
    out = project.parent / "out"
    for c in ("char0", "char1"):
        assert sorted(p.name for p in (out / c).iterdir()) == sorted(
            f"take{t}.{ext}" for t in range(3) for ext in ("glb", "usdc"))
    for o in report.outcomes:
        log = open(o.log).read()
        assert o.label in log and "done in" in log
    # heavy set-ups reached each worker once: every rig was loaded at most once per worker
    stats = client.run(memo_stats)
    for worker, built in stats.items():
        assert built and all(n == 1 for n in built.values()), (worker, built)


def _exported_timeline(report, label):
    return Timeline.from_json(report.by_label()[label].timeline)


def test_outputs_are_read_by_real_consumers(first_run, project):
    out = project.parent / "out"
    head = small_head()
    glbs = sorted(out.glob("*/*.glb"))
    assert len(glbs) == 6
    validate_gltf(glbs)
    times = [0.0, 0.3, 0.5, 0.62, 0.9, 1.0]
    for c, t in (("char0", 0), ("char1", 2)):
        tl = _exported_timeline(first_run, f"{c}/take{t}/01-export")
        got = three_js(out / c / f"take{t}.glb", times)
        assert got["targetNames"] == head.shape_names
        np.testing.assert_allclose(got["weights"], played_weights(head, tl, times), atol=1e-6, rtol=0)
    pxr = usd()
    frames = [0, 8, 15, 22, 30]
    for usdc in sorted(out.glob("*/*.usdc")):
        tl = _exported_timeline(first_run, f"{usdc.parent.name}/{usdc.stem}/01-export")
        _, points = usdskel_points(pxr, usdc, frames)
        np.testing.assert_allclose(points, expected_points(head, tl, np.array(frames) / tl.fps), atol=1e-5, rtol=0)
        assert np.abs(points[2] - points[0]).max() > 1e-4  # it animates


def test_retime_changed_the_in_betweens(first_run):
    tl = _exported_timeline(first_run, "char0/take0/01-export")
    keyed = tl.tracks["weights/jawOpen"].times
    inside = keyed[(keyed > 0.25 + 1e-6) & (keyed < 0.75 - 1e-6)]
    assert len(inside) >= 10  # a key per in-between frame (the take had none there)


def test_rerun_does_no_work_and_a_changed_take_reruns_only_its_tasks(first_run, project, client):
    again = _run(project, client)
    assert again.counts == {"done": 0, "skipped": 12, "failed": 0, "blocked": 0}, again.table()
    write_take(small_head(), project.parent / "take1.csv", seed=99)
    changed = _run(project, client)
    done = sorted(o.label for o in changed.outcomes if o.status == "done")
    assert done == [f"char{c}/take1/{s}" for c in range(2) for s in ("00-retime", "01-export")], changed.table()
    assert changed.counts["skipped"] == 8
    # a damaged output is noticed and rewritten
    (project.parent / "out" / "char0" / "take2.glb").write_bytes(b"broken")
    healed = _run(project, client)
    assert [o.label for o in healed.outcomes if o.status == "done"] == ["char0/take2/01-export"]


def test_a_bad_take_fails_alone_with_a_clear_message(tmp_path, client):
    job = make_project(tmp_path, characters=1, takes=3, formats=("glb",))
    (tmp_path / "take1.csv").write_text("time,jawOpen\n0,0.2\n0.5,banana\n")
    report = _run(job, client)
    status = {o.label: o.status for o in report.outcomes}
    assert status == {"char0/take0/00-export": "done", "char0/take1/00-export": "failed",
                      "char0/take2/00-export": "done"}
    (failed,) = report.failures()
    assert "take1.csv" in failed.error and "banana" in failed.error, failed.error
    assert failed.input.endswith("take1.csv")
    assert "Traceback" in open(failed.log).read()
    table = report.table()
    assert "FAILED char0/take1/00-export" in table and "take1.csv" in table
    assert not report.ok
    assert sorted(p.name for p in (tmp_path / "out" / "char0").iterdir()) == ["take0.glb", "take2.glb"]


def test_later_steps_of_a_failed_step_are_blocked(tmp_path, client):
    job = make_project(tmp_path, characters=1, takes=2, formats=("glb",))
    head = small_head()
    for i in range(2):
        write_take(head, tmp_path / f"perf{i}.csv", seed=10 + i, seconds=3.0)
    # take1's weights are the same at t0 and t1: retime has no transition to time
    text = job.read_text().replace("[[steps]]", RETIME + "\n[[steps]]", 1)
    job.write_text(text)
    flat = "".join(f"{i / 30:.5f},0.5\n" for i in range(31))  # jawOpen held at 0.5 for 1 s
    (tmp_path / "take1.csv").write_text("time,jawOpen\n" + flat)
    report = _run(job, client)
    status = {o.label: o.status for o in report.outcomes}
    assert status["char0/take0/01-export"] == "done"
    assert status["char0/take1/00-retime"] == "failed"
    assert status["char0/take1/01-export"] == "blocked"
    assert "same" in report.by_label()["char0/take1/00-retime"].error


def test_track_and_transfer_rig_steps(tmp_path, client):
    from rig_faces import Actor

    head = small_head()
    head.save(tmp_path / "head.fwb")
    Actor(head).model.save(tmp_path / "actor.fwb")
    write_marker_take(head, tmp_path / "m0.csv", tmp_path / "m0.json", seed=3)
    job = tmp_path / "jobs.toml"
    job.write_text(
        'output = "out"\n[[characters]]\nname = "head"\nrig = "head.fwb"\n'
        '[[takes]]\nname = "m0"\npath = "m0.csv"\nvertex_map = "m0.json"\n'
        '[[steps]]\nkind = "track"\n[[steps]]\nkind = "export"\nformats = ["glb"]\n')
    report = _run(job, client)
    assert report.ok, report.table()
    tl = Timeline.from_json(report.by_label()["head/m0/01-export"].timeline)
    assert "head_pose" in tl.tracks and sum(k.startswith("weights/") for k in tl.tracks) > 10
    write_take(head, tmp_path / "t.csv", seed=1)
    job.write_text(
        'output = "out"\n[[characters]]\nname = "actor"\nrig = "actor.fwb"\n'
        '[[takes]]\nname = "t"\npath = "t.csv"\n'
        '[[steps]]\nkind = "transfer_rig"\ntemplate = "head"\n[[steps]]\nkind = "export"\nformats = ["glb"]\n')
    report = _run(job, client)
    assert report.ok, report.table()
    glb = tmp_path / "out" / "actor" / "t.glb"
    validate_gltf([glb, tmp_path / "out" / "head" / "m0.glb"])
    got = three_js(glb, [0.0, 0.5])
    assert got["targetNames"] == head.shape_names  # the template's shapes, on the actor's mesh
    assert np.ptp(got["weights"][:, head.shape_names.index("jawOpen")]) > 0.01


def _one_pc2_step(tmp_path, client, step: str, kind: str):
    """Run export (glb) then ``step`` on one character and take; the step's PC2 header, frames and report."""
    from workbench.export.pointcache import PC2_HEADER

    job = make_project(tmp_path, characters=1, takes=1, formats=("glb",), extra_steps=step)
    report = _run(job, client)
    outcome = report.by_label()[f"char0/take0/01-{kind}"]
    assert outcome.status == "done", outcome.error
    (pc2,) = outcome.outputs
    assert pc2.endswith(f"char0/take0.{kind}d.pc2")  # enhanced, cloned
    header = np.fromfile(pc2, PC2_HEADER, count=1)[0]
    got = np.fromfile(pc2, "<f4", offset=32).reshape(header["samples"], header["points"], 3)
    return header, got, report


def test_enhance_step(tmp_path, client):
    """A database one Loop subdivision finer than the character: the frames come out at its resolution."""
    from workbench.enhance import Correspondence, PerformanceDatabase

    head = small_head()
    corr = Correspondence.loop(head.faces, head.n_vertices, 1)
    frames = corr(np.stack([head.evaluate_at(0.0) + 0.001 * i for i in range(3)]).astype(np.float64))
    fine_faces = np.asarray(workbench_loop_faces(head), np.int64)
    PerformanceDatabase.from_frames(frames[0], fine_faces, frames,
                                    metres_per_unit=head.metadata.metres_per_unit).save(tmp_path / "db.npz")
    header, got, report = _one_pc2_step(tmp_path, client, '[[steps]]\nkind = "enhance"\ndatabase = "db.npz"\n',
                                        "enhance")
    n_fine = frames.shape[1]
    assert (header["signature"], header["points"], header["samples"]) == (b"POINTCACHE2", n_fine, 31)
    # the same as calling the database directly on the take's frames (metres in the file)
    tl = Timeline.from_json(report.by_label()["char0/take0/00-export"].timeline)
    takes = np.stack([head.evaluate_at(float(t), tl) for t in tl.frame_times()]).astype(np.float64)
    database = PerformanceDatabase.load(tmp_path / "db.npz")
    want = database.enhance(takes, correspondence=corr) * head.metadata.metres_per_unit
    np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)  # 10 µm: BLAS threads differ (worker: 1)


def test_clone_step_plays_the_take_on_another_face(tmp_path, client):
    """A warped, renumbered face of other triangles: the PC2 holds what ExpressionCloner gives directly."""
    from workbench.rigging import ExpressionCloner
    from workbench.testing import random_warp, renumbered, warped

    head = small_head()
    other = renumbered(warped(head, random_warp(head.vertices, seed=3), shapes=False, retriangulate=True), seed=2)
    other.model.save(tmp_path / "other.fwb")
    header, got, report = _one_pc2_step(tmp_path, client, '[[steps]]\nkind = "clone"\nonto = "other.fwb"\n',
                                        "clone")
    assert (header["points"], header["samples"]) == (other.model.n_vertices, 31)
    tl = Timeline.from_json(report.by_label()["char0/take0/00-export"].timeline)
    frames = np.stack([head.evaluate_at(float(t), tl) for t in tl.frame_times()]).astype(np.float64)
    want = ExpressionCloner(head, other.model).clone(frames) * other.model.metadata.metres_per_unit
    np.testing.assert_allclose(got, want, atol=1e-5 * np.abs(want).max(), rtol=0)
    assert np.abs(got - got[0]).max() > 1e-4  # the face moves


def workbench_loop_faces(model):
    from workbench.geometry.subdivision import loop_subdivision

    return loop_subdivision(model.faces, model.n_vertices, 1)[1]


def test_a_killed_worker_loses_nothing(tmp_path):
    """Kill a worker process while it runs a task: Dask re-runs it elsewhere; every output is complete."""
    import signal
    import threading
    import time

    from distributed import Client

    job = make_project(tmp_path, characters=2, takes=3, formats=("glb", "usda"), resolution="25k")
    cluster = local_cluster(2, dashboard=False, silence_logs=50)
    client = Client(cluster)
    try:
        result = {}
        runner = threading.Thread(target=lambda: result.setdefault("report", _run(job, client)))
        runner.start()
        killed = None
        deadline = time.time() + 120
        while killed is None and time.time() < deadline and runner.is_alive():
            busy = [w for w, keys in client.processing().items() if keys]
            if busy:
                pids = client.run(os.getpid, workers=[busy[0]])
                os.kill(pids[busy[0]], signal.SIGKILL)
                killed = busy[0]
            time.sleep(0.05)
        runner.join(600)
        assert killed is not None, "no task was seen running"
        report = result["report"]
    finally:
        client.close()
        cluster.close()
    assert report.counts["done"] == 6 and report.ok, report.table()
    out = tmp_path / "out"
    for c in ("char0", "char1"):
        assert sorted(p.name for p in (out / c).iterdir()) == sorted(
            f"take{t}.{ext}" for t in range(3) for ext in ("glb", "usda"))
    validate_gltf(sorted(out.glob("*/*.glb")))
    pxr = usd()
    for usda in sorted(out.glob("*/*.usda")):
        stage = pxr.Usd.Stage.Open(str(usda))
        assert stage.GetPrimAtPath("/Face/Mesh"), usda
    shutil.rmtree(out)


def test_a_bad_rig_fails_its_character_alone(tmp_path, client):
    job = make_project(tmp_path, characters=2, takes=1, formats=("glb",))
    (tmp_path / "char1.fwb").write_bytes(b"PK\x03\x04 not a workbench file")
    report = _run(job, client)
    assert {o.label: o.status for o in report.outcomes} == {"char0/take0/00-export": "done",
                                                           "char1/take0/00-export": "failed"}
    (failed,) = report.failures()
    assert failed.input.endswith("char1.fwb") and "char1.fwb" in failed.error, failed.error


def test_the_dashboard_link_serves_on_localhost_only():
    import urllib.request

    from distributed import Client

    cluster = local_cluster(1, silence_logs=50)
    try:
        with Client(cluster) as c:
            link = c.dashboard_link
            assert link.startswith("http://127.0.0.1:"), link
            assert urllib.request.urlopen(link, timeout=60).status == 200  # bokeh serves it (the batch extra)
    finally:
        cluster.close()
