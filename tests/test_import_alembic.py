"""Alembic import (workbench.io.alembic) of a point cache written by Blender, and a malformed corpus.

``face.abc`` is written by Blender's Alembic exporter from the animated source
(``tests/tools/format_writers.py``: two meshes, six keyed shape keys, frames
0-20 at 30 fps): the deformed meshes at every frame. The reader imports it with
Blender's importer: frame 0 is the neutral, each frame's positions equal the
source's evaluated points, the times come from the archive's time sampling,
and the frame shapes + :func:`read_alembic_animation` replay the cache. The
corpus (>= 50 damaged containers: truncations, header, offsets, time samplings)
is refused before Blender runs, naming the file and the field.
"""

from __future__ import annotations

import struct
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ci_env import in_ci

import workbench.io.alembic as abc_mod
from workbench.cli import main
from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io import load
from workbench.io.alembic import read_alembic, read_alembic_animation, read_time_samplings

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))
import format_writers as fw

M = 0.1  # source decimetres -> Blender's metres


@pytest.fixture(scope="session")
def abc_file() -> Path:
    try:
        return fw.blender_files()["abc"]
    except fw.ToolMissing as exc:
        if in_ci():
            pytest.fail(f"{exc} is missing under CI=true", pytrace=False)
        pytest.skip(str(exc))


@pytest.fixture(scope="session")
def face(abc_file: Path):
    return read_alembic(abc_file)


def test_time_sampling_is_the_exported_frame_range(abc_file: Path) -> None:
    ts = read_time_samplings(abc_file)
    anim = max(ts, key=lambda t: t.max_samples)
    assert anim.max_samples == fw.LAST_FRAME + 1
    assert anim.fps == pytest.approx(fw.FPS)
    np.testing.assert_allclose(anim.times(), np.arange(fw.LAST_FRAME + 1) / fw.FPS)


def test_every_frame_matches_the_source(face) -> None:
    src = fw.face_source()
    assert face.group_names == ["Head", "Mouth"] and face.up_axis == "+y" and face.units is None
    fr = face.frames
    assert fr is not None and fr.n_frames == fw.LAST_FRAME + 1 and fr.fps == pytest.approx(fw.FPS)
    np.testing.assert_allclose(fr.times, np.arange(fw.LAST_FRAME + 1) / fw.FPS)
    np.testing.assert_allclose(face.vertices, src.points(0) * M, atol=1e-6, rtol=0)
    for k in range(fr.n_frames):
        np.testing.assert_allclose(fr.positions[k], src.points(k) * M, atol=1e-6, rtol=0, err_msg=f"frame {k}")
    np.testing.assert_array_equal(face.polygons.sizes, np.concatenate([o.counts for o in src.objects]))


def test_frame_shapes_and_timeline_replay_the_cache(abc_file: Path, face) -> None:
    names = [f"frame_{k:04d}" for k in range(1, fw.LAST_FRAME + 1)]
    assert face.shape_names == names
    tl = read_alembic_animation(abc_file, face.shape_names)
    assert tl.fps == pytest.approx(fw.FPS) and tl.end == pytest.approx(fw.LAST_FRAME / fw.FPS)
    D = np.stack([d for _, d in face.shapes])
    for k in (0, 1, 7, 13, fw.LAST_FRAME):
        w = tl.weight_matrix(face.shape_names, [k / fw.FPS])[0]
        np.testing.assert_allclose(face.vertices + np.tensordot(w, D, 1), face.frames.positions[k], atol=1e-6)
    # halfway between frames 4 and 5: the linear blend of the two samples
    w = tl.weight_matrix(face.shape_names, [4.5 / fw.FPS])[0]
    half = 0.5 * (face.frames.positions[4] + face.frames.positions[5])
    np.testing.assert_allclose(face.vertices + np.tensordot(w, D, 1), half, atol=1e-6)


def test_load_infers_metres_and_info(abc_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = load(abc_file)
    assert model.metadata.units == "m"
    assert main(["info", str(abc_file)]) == 0
    out = capsys.readouterr().out
    assert "frame_0020" in out and "inferred" in out


# ---------------------------------------------------------------- the malformed corpus
def _root(d: bytes) -> tuple[int, list[int]]:
    r = struct.unpack_from("<Q", d, 8)[0]
    n = struct.unpack_from("<Q", d, r)[0]
    return r, list(struct.unpack_from(f"<{n}Q", d, r + 8))


def _patch(at: int | Callable[[bytes], int], raw: bytes) -> Callable[[bytes], bytes]:
    def make(d: bytes) -> bytes:
        a = at(d) if callable(at) else at
        return d[:a] + raw + d[a + len(raw) :]

    return make


def _child_ref(k: int) -> Callable[[bytes], int]:
    return lambda d: _root(d)[0] + 8 + 8 * k


def _data_off(k: int) -> Callable[[bytes], int]:
    return lambda d: _root(d)[1][k] & ~(1 << 63)


def _repoint(k: int, payload: bytes) -> Callable[[bytes], bytes]:
    """Append a data block with ``payload`` and make root child ``k`` refer to it."""

    def make(d: bytes) -> bytes:
        off = len(d)
        d = d + struct.pack("<Q", len(payload)) + payload
        at = _child_ref(k)(d)
        return d[:at] + struct.pack("<Q", off | (1 << 63)) + d[at + 8 :]

    return make


def _ts(*samplings: tuple[int, float, list[float]]) -> bytes:
    out = b""
    for m, tpc, times in samplings:
        out += struct.pack("<IdI", m, tpc, len(times)) + struct.pack(f"<{len(times)}d", *times)
    return out


IDENT = (1, 1.0, [0.0])
ACYCLIC = 1.7976931348623157e308 / 32.0


def _first_object_child(d: bytes) -> int:
    objs = _root(d)[1][2]
    n = struct.unpack_from("<Q", d, objs)[0]
    kids = struct.unpack_from(f"<{n}Q", d, objs + 8)
    return next(c for c in kids if c and not c & (1 << 63))


def _variants(size: int) -> dict[str, tuple[Callable[[bytes], bytes], str]]:
    v: dict[str, tuple[Callable[[bytes], bytes], str]] = {}
    for k, frac in enumerate(np.linspace(0.02, 0.995, 22)):
        cut = int(size * frac)
        v[f"truncated_{k:02d}"] = ((lambda c: lambda d: d[:c])(cut), "end of the file")
    v["empty"] = (lambda d: b"", "fewer than Ogawa's 16-byte header")
    v["header_only_10_bytes"] = (lambda d: d[:10], "16-byte header")
    v["not_ogawa"] = (_patch(0, b"Ogowa"), "not an Alembic (Ogawa) file")
    v["hdf5"] = (lambda d: b"\x89HDF\r\n\x1a\n" + d[8:], "HDF5")
    v["unfinished"] = (_patch(5, b"\x00"), "never finished by its writer")
    v["version_2"] = (_patch(6, b"\x00\x02"), "Ogawa version 2")
    v["root_zero"] = (_patch(8, struct.pack("<Q", 0)), "is not a group")
    v["root_is_data"] = (lambda d: d[:8] + struct.pack("<Q", struct.unpack_from("<Q", d, 8)[0] | (1 << 63)) + d[16:], "is not a group")
    v["root_beyond_end"] = (lambda d: d[:8] + struct.pack("<Q", len(d) + 64) + d[16:], "beyond the end of the file")
    v["root_three_children"] = (_patch(lambda d: _root(d)[0], struct.pack("<Q", 3)), "6 expected")
    v["root_children_overflow"] = (_patch(lambda d: _root(d)[0], struct.pack("<Q", 1 << 40)), "run past the end")
    v["archive_version_size"] = (_patch(_data_off(0), struct.pack("<Q", 2)), "expected a 4-byte integer")
    v["archive_version_huge"] = (_patch(_data_off(0), struct.pack("<Q", 1 << 50)), "run past the end")
    v["archive_version_is_group"] = (lambda d: _patch(_child_ref(0), struct.pack("<Q", _root(d)[1][2]))(d), "found a group")
    v["objects_beyond_end"] = (lambda d: _patch(_child_ref(2), struct.pack("<Q", len(d) + 1000))(d), "beyond the end of the file")
    v["object_group_overflow"] = (_patch(_first_object_child, struct.pack("<Q", 1 << 45)), "run past the end")
    v["object_group_child_beyond_end"] = (
        lambda d: _patch(lambda e: _first_object_child(e) + 8, struct.pack("<Q", len(d) * 4))(d), "beyond the end of the file"
    )
    v["metadata_beyond_end"] = (lambda d: _patch(_child_ref(3), struct.pack("<Q", (len(d) + 99) | (1 << 63)))(d), "archive metadata")
    v["indexed_metadata_huge"] = (_patch(_data_off(5), struct.pack("<Q", 1 << 52)), "indexed metadata")
    v["time_samplings_size_huge"] = (_patch(_data_off(4), struct.pack("<Q", 1 << 33)), "time samplings")
    v["ts_tpc_zero"] = (_repoint(4, _ts(IDENT, (21, 0.0, [0.0]))), "timePerCycle")
    v["ts_tpc_negative"] = (_repoint(4, _ts(IDENT, (21, -1 / 30, [0.0]))), "timePerCycle")
    v["ts_tpc_nan"] = (_repoint(4, _ts(IDENT, (21, float("nan"), [0.0]))), "timePerCycle")
    v["ts_tpc_inf"] = (_repoint(4, _ts(IDENT, (21, float("inf"), [0.0]))), "timePerCycle")
    v["ts_no_times"] = (_repoint(4, _ts(IDENT, (21, 1 / 30, []))), "has no sample time")
    v["ts_time_nan"] = (_repoint(4, _ts(IDENT, (21, 1 / 30, [float("nan")]))), "not finite")
    v["ts_times_decreasing"] = (_repoint(4, _ts(IDENT, (21, 1.0, [0.5, 0.25]))), "strictly increasing")
    v["ts_cycle_too_short"] = (_repoint(4, _ts(IDENT, (21, 0.1, [0.0, 0.2]))), "cannot hold times")
    v["ts_acyclic_short"] = (_repoint(4, _ts(IDENT, (21, ACYCLIC, [0.0, 0.1, 0.2]))), "acyclic times")
    v["ts_cut_header"] = (_repoint(4, _ts(IDENT) + b"\x01\x02\x03"), "cut off")
    v["ts_cut_times"] = (_repoint(4, _ts(IDENT) + struct.pack("<IdI", 21, 1 / 30, 5) + b"\0" * 16), "only 2 follow")
    v["ts_none"] = (_repoint(4, b""), "none")
    v["ts_too_many_frames"] = (_repoint(4, _ts(IDENT, (10**6, 1 / 30, [0.0]))), "more than")
    v["ts_fps_unusable"] = (_repoint(4, _ts(IDENT, (21, 1e-300, [0.0]))), "frame rate")
    return v


@pytest.fixture(scope="session")
def abc_bytes(abc_file: Path) -> bytes:
    return abc_file.read_bytes()


VARIANTS = sorted(_variants(100_000))


def test_corpus_is_large_enough() -> None:
    assert len(VARIANTS) >= 50


@pytest.mark.parametrize("name", VARIANTS)
def test_malformed_variant_is_refused_before_blender(
    name: str, abc_bytes: bytes, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    make, expected = _variants(len(abc_bytes))[name]
    p = tmp_path / f"{name}.abc"
    p.write_bytes(make(abc_bytes))

    def no_blender(*a: Any, **k: Any) -> Any:
        raise AssertionError("Blender ran on a malformed file")

    monkeypatch.setattr(abc_mod, "run_dump", no_blender)
    with pytest.raises(MeshFormatError) as ei:
        read_alembic(p)
    msg = str(ei.value)
    assert msg.startswith(f"{p.name}: "), msg
    assert expected in msg, msg
    assert ei.value.field, msg
