"""Autosave and crash recovery."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from workbench.autosave import Autosaver, find_recoverable, recover
from workbench.model import FaceModel


def _wait(pred, timeout: float = 10.0) -> None:
    t0 = time.time()
    while not pred():
        if time.time() - t0 > timeout:
            raise AssertionError("condition not reached")
        time.sleep(0.02)


def test_edits_are_saved_after_a_pause_in_one_save(tiny_model: FaceModel, tmp_path: Path) -> None:
    saver = Autosaver(tiny_model, "session", delay=0.2, folder=tmp_path)
    states: list[str] = []
    saver.changed.connect(states.append)
    for v in np.linspace(0, 1, 10):
        tiny_model.set_weight("up", float(v))
    _wait(lambda: saver.state == "saved")
    assert saver.saves == 1  # debounced
    assert states[0] == "pending" and states[-1] == "saved"
    from workbench import load

    assert load(saver.path).weights["up"] == 1.0
    saver.close(discard=True)
    assert not saver.path.exists()


def test_no_save_while_dragging(tiny_model: FaceModel, tmp_path: Path) -> None:
    saver = Autosaver(tiny_model, "drag", delay=0.05, folder=tmp_path)
    tiny_model.set_weight("up", 0.2)
    with tiny_model.interaction("Drag"):
        tiny_model.set_weight("left", 0.5)
        time.sleep(0.3)
        assert saver.saves == 0
    _wait(lambda: saver.saves >= 1)
    saver.close()


def test_crashed_session_is_recoverable(tmp_path: Path) -> None:
    code = textwrap.dedent(
        f"""
        import os, sys, time
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from grid_meshes import grid_polygons
        import numpy as np
        from workbench.model import BlendShape, FaceModel
        from workbench.autosave import Autosaver
        V, p = grid_polygons(2, 2)
        up = np.zeros((9, 3), np.float32); up[4, 2] = 1
        m = FaceModel(V, None, [BlendShape("up", up)], polygons=p)
        s = Autosaver(m, "crashy", delay=0.05, folder={str(tmp_path)!r})
        m.set_weight("up", 0.75)
        m.timeline.key_weights(1.0)
        while s.state != "saved":
            time.sleep(0.01)
        os._exit(1)   # the kernel dies without closing anything
        """
    )
    subprocess.run([sys.executable, "-c", code], check=False, timeout=120)
    found = find_recoverable(tmp_path)
    assert [r.name for r in found] == ["crashy"]
    assert "9 vertices, 1 shapes, 1 keyed tracks" in found[0].describe()
    m = recover(found[0])
    assert m.weights["up"] == 0.75 and "weights/up" in m.tracks.tracks
    # the recovering session takes the file over at once: nobody else is offered it
    saver = Autosaver(m, "crashy", delay=10.0, folder=tmp_path)
    assert find_recoverable(tmp_path) == []
    saver.close()


def test_live_sessions_are_not_offered(tiny_model: FaceModel, tmp_path: Path) -> None:
    saver = Autosaver(tiny_model, "live", delay=0.0, folder=tmp_path)
    tiny_model.set_weight("up", 0.5)
    _wait(lambda: saver.state == "saved")
    assert find_recoverable(tmp_path) == []
    assert [r.name for r in find_recoverable(tmp_path, include_live=True)] == ["live"]
    saver.close(discard=True)


def test_save_errors_are_reported_not_raised(tiny_model: FaceModel, tmp_path: Path) -> None:
    saver = Autosaver(tiny_model, "err", delay=0.0, folder=tmp_path)
    saver.path.mkdir()  # a folder where the file should go: the rename fails
    tiny_model.set_weight("up", 0.5)
    _wait(lambda: saver.state.startswith("error"))
    assert tiny_model.weights["up"] == 0.5
    saver.close()
    with pytest.raises(ValueError, match="plain file stem"):
        Autosaver(tiny_model, "a/b", folder=tmp_path)


class _ManualScheduler:
    """A scheduler whose timers fire when the test says (as a kernel's loop, on the test's thread)."""

    def __init__(self) -> None:
        self.timers: list[list] = []
        self.delivered: list = []

    def call_later(self, delay, callback):
        entry = [delay, callback, False]
        self.timers.append(entry)

        class _Handle:
            def cancel(self) -> None:
                entry[2] = True

        return _Handle()

    def call_soon_threadsafe(self, callback) -> None:
        self.delivered.append(callback)

    def fire(self) -> None:
        due, self.timers = self.timers, []
        for _delay, callback, cancelled in due:
            if not cancelled:
                callback()

    def run_delivered(self) -> None:
        due, self.delivered = self.delivered, []
        for callback in due:
            callback()


def test_snapshot_is_taken_when_the_timer_fires_and_later_edits_do_not_reach_it(
    tiny_model: FaceModel, tmp_path: Path
) -> None:
    import threading

    from workbench.fileformat import load_model

    sched = _ManualScheduler()
    states: list[tuple[str, threading.Thread]] = []
    saver = Autosaver(tiny_model, "snap", delay=1.0, folder=tmp_path, scheduler=sched)
    saver.changed.connect(lambda st: states.append((st, threading.current_thread())))
    tiny_model.set_weight("up", 0.25)
    tiny_model.set_weight("up", 0.5)
    assert len([t for t in sched.timers if not t[2]]) == 1  # debounced: one live timer
    sched.fire()  # the snapshot is taken here, on this thread
    tiny_model.set_weight("up", 0.9)  # an edit after the snapshot: not in this save
    saver.wait(10)
    assert saver.state == "pending" and saver.saves == 0  # the result is not delivered yet
    sched.run_delivered()  # the writer handed its result back to the scheduler's thread
    assert saver.state == "saved" and saver.saves == 1
    assert all(th is threading.current_thread() for _st, th in states)
    assert load_model(saver.path).weights["up"] == pytest.approx(0.5)
    saver.close()


def test_a_drag_in_progress_postpones_the_snapshot(tiny_model: FaceModel, tmp_path: Path) -> None:
    sched = _ManualScheduler()
    saver = Autosaver(tiny_model, "later", delay=1.0, folder=tmp_path, scheduler=sched)
    tiny_model.set_weight("up", 0.2)
    token = tiny_model.begin_interaction("drag")
    sched.fire()
    assert saver._writing is None and len(sched.timers) == 1  # re-armed, nothing written
    tiny_model.end_interaction(token)
    sched.fire()
    saver.wait(10)
    sched.run_delivered()
    assert saver.state == "saved"
    saver.close()
