"""A save killed mid-write leaves the previous file intact, and its partial temporary is cleaned up."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import workbench
from workbench.fileformat import remove_stale_temporaries

KILLED_SAVE = r"""
import os, signal, sys
import workbench
m = workbench.load_sample("head")
m.set_weight("jawOpen", 0.9)
os.fsync = lambda fd: os.kill(os.getpid(), signal.SIGKILL)   # die after writing, before the rename
m.save(sys.argv[1])
"""


def leftovers(path: Path) -> list[Path]:
    return sorted(path.parent.glob(f".{path.name}.*.tmp"))


def test_killed_save_keeps_the_old_file_and_the_next_load_cleans_up(tmp_path: Path) -> None:
    path = tmp_path / "face.fwb"
    workbench.load_sample("head").save(path)
    before = path.read_bytes()
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-c", KILLED_SAVE, str(path)], capture_output=True, timeout=120)
        assert proc.returncode == -9, proc.stderr.decode()[-2000:]
    assert path.read_bytes() == before  # the previous save is intact
    stale = leftovers(path)  # the second killed save already removed the first one's
    assert len(stale) == 1 and stale[0].stat().st_size > 1_000_000
    m = workbench.load(path)
    assert leftovers(path) == [] and m.weights["jawOpen"] == 0.0
    # and a save cleans up too
    subprocess.run([sys.executable, "-c", KILLED_SAVE, str(path)], capture_output=True, timeout=120)
    assert len(leftovers(path)) == 1
    m.save(path)
    assert leftovers(path) == []


def test_a_save_in_progress_and_other_files_are_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "face.fwb"
    live = tmp_path / f".face.fwb.{os.getpid()}.abcd1234.tmp"  # this process is alive: a save in progress
    other = tmp_path / ".other.fwb.1.abcd.tmp"
    old_style = tmp_path / ".face.fwb.k3j4h5.tmp"  # no pid: judged by age
    for p in (live, other, old_style):
        p.write_bytes(b"partial")
    assert remove_stale_temporaries(path) == []
    hour_ago = time.time() - 3600
    os.utime(old_style, (hour_ago, hour_ago))
    assert remove_stale_temporaries(path) == [old_style]
    assert live.exists() and other.exists()
    dead = tmp_path / ".face.fwb.999999999.zz.tmp"  # no such process
    dead.write_bytes(b"partial")
    assert remove_stale_temporaries(path) == [dead]
    np.testing.assert_equal(live.read_bytes(), b"partial")
