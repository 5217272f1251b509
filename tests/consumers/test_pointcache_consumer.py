"""PC2 / MDD / OBJ-sequence exports read back by minimal parsers written here from the specs.

The parsers deliberately use ``struct`` (not the numpy dtypes of the writer),
following the published layouts:

* PC2: ``<12s i i f f i`` header (signature "POINTCACHE2\\0", version 1,
  points, start frame, sample rate, samples), then float32 little-endian xyz.
* MDD: big-endian ``>i i`` (frames, points), ``frames`` float32 times, then
  float32 xyz per point per frame.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from consumer_timelines import expected_points, expression_timeline, with_head_pose

from workbench.export import export


def read_pc2(data: bytes):
    sig, version, points, start, rate, samples = struct.unpack_from("<12siiffi", data, 0)
    assert len(data) == 32 + samples * points * 12
    flat = struct.unpack_from(f"<{samples * points * 3}f", data, 32)
    return sig, version, start, rate, np.array(flat).reshape(samples, points, 3)


def read_mdd(data: bytes):
    frames, points = struct.unpack_from(">ii", data, 0)
    times = struct.unpack_from(f">{frames}f", data, 8)
    off = 8 + 4 * frames
    assert len(data) == off + frames * points * 12
    flat = struct.unpack_from(f">{frames * points * 3}f", data, off)
    return np.array(times), np.array(flat).reshape(frames, points, 3)


@pytest.fixture(scope="module")
def short_anim(head):
    # 0.5 s at 30 fps keeps the struct parsers fast (16 frames x 5k vertices)
    tl = with_head_pose(expression_timeline("cubic")).replace(start=0.5, end=1.0)
    return tl, expected_points(head, tl, tl.frame_times())


def test_pc2_layout(head, short_anim, tmp_path):
    tl, ours = short_anim
    (p,) = export(head, tl, tmp_path / "a.pc2")
    sig, version, start, rate, pts = read_pc2(p.read_bytes())
    assert (sig, version, start, rate) == (b"POINTCACHE2\0", 1, 15.0, 1.0)
    np.testing.assert_allclose(pts, ours, atol=1e-6)


def test_mdd_layout(head, short_anim, tmp_path):
    tl, ours = short_anim
    (p,) = export(head, tl, tmp_path / "a.mdd")
    times, pts = read_mdd(p.read_bytes())
    np.testing.assert_allclose(times, tl.frame_times(), atol=1e-6)
    np.testing.assert_allclose(pts, ours, atol=1e-6)


def test_obj_sequence(head, short_anim, tmp_path):
    tl, ours = short_anim
    paths = export(head, tl.replace(end=0.6), tmp_path / "face.obj")
    assert [p.name for p in paths] == ["face_0015.obj", "face_0016.obj", "face_0017.obj", "face_0018.obj"]
    for i, p in enumerate(paths):
        v, f = [], []
        for line in p.read_text().splitlines():
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:]])
            elif line.startswith("f "):
                f.append([int(x) for x in line.split()[1:]])
        np.testing.assert_allclose(np.array(v), ours[i], atol=1e-6)
        assert len(f) == len(head.polygons)  # original quads, not triangles
        assert f[0] == (head.polygons[0] + 1).tolist()
