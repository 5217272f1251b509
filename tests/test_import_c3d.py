"""C3D markers (workbench.io.c3d.read_markers) on files written by ezc3d's own writer, and a malformed corpus.

The tracks are 24 vertices of the sample head following its keyed animation
(``tests/tools/format_writers.py``), in millimetres (and centimetres, metres),
30 fps, with gaps written both ways a C3D file has them: NaN coordinates
(what ezc3d writes for a NaN point) and a residual of -1 (the C3D standard's
"invalid point"). The reader must give metres, NaN exactly at the gaps, the
labels, rate and unit. The corpus (>= 50 damaged headers, parameter records,
POINT parameters and truncations) is refused before ezc3d sees the file,
naming the file and the header word or parameter; ezc3d itself once crashed
the process on a truncated file, which is why the structure is checked first.
"""

from __future__ import annotations

import struct
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ezc3d = pytest.importorskip("ezc3d", reason="ezc3d is a core dependency (pip install -e .)")

import workbench.io.c3d as c3d_mod  # noqa: E402
from workbench.cli import main  # noqa: E402
from workbench.geometry.mesh_checks import MeshFormatError  # noqa: E402
from workbench.io.c3d import check_c3d, read_markers  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))
import format_writers as fw  # noqa: E402

N_MARKERS = 24
NAN_GAP = (3, slice(5, 9))  # marker 3 is NaN in frames 5-8
RESIDUAL_GAP = (7, 10)  # marker 7 has residual -1 in frame 10
UNIT_SCALE = {"mm": 100.0, "cm": 10.0, "m": 0.1}  # source decimetres -> unit


def truth() -> np.ndarray:
    """(F, m, 3) true marker positions in metres (head vertices following the keyed shapes)."""
    src = fw.face_source()
    ids = np.linspace(0, src.objects[0].vertices.shape[0] - 1, N_MARKERS).astype(int)
    return np.stack([src.points(f)[ids] for f in range(fw.LAST_FRAME + 1)]) * 0.1


def write_c3d(path: Path, unit: str = "mm") -> Path:
    P = truth() / 0.1 * UNIT_SCALE[unit]  # (F, m, 3) in `unit`
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [fw.FPS]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(f"M{j:02d}" for j in range(N_MARKERS))
    c["parameters"]["POINT"]["UNITS"]["value"] = [unit]
    c.add_parameter("POINT", "DESCRIPTIONS", tuple(f"head vertex marker {j}" for j in range(N_MARKERS)))
    pts = np.ones((4, N_MARKERS, P.shape[0]))
    pts[:3] = P.transpose(2, 1, 0)
    j, fr = NAN_GAP
    pts[:3, j, fr] = np.nan
    res = np.zeros((1, N_MARKERS, P.shape[0]))
    j, f = RESIDUAL_GAP
    res[0, j, f] = -1
    c["data"]["points"] = pts
    c["data"]["meta_points"]["residuals"] = res
    c.write(str(path))
    return path


@pytest.fixture(scope="session")
def c3d_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_c3d(tmp_path_factory.mktemp("c3d") / "markers.c3d")


def _expected() -> np.ndarray:
    T = truth()
    j, fr = NAN_GAP
    T[fr, j] = np.nan
    j, f = RESIDUAL_GAP
    T[f, j] = np.nan
    return T


@pytest.mark.parametrize("unit", ["mm", "cm", "m"])
def test_markers_in_metres_with_gaps(unit: str, tmp_path: Path) -> None:
    m = read_markers(write_c3d(tmp_path / f"{unit}.c3d", unit))
    assert m.names == tuple(f"M{j:02d}" for j in range(N_MARKERS))
    assert m.units == unit and m.fps == fw.FPS and m.first_frame == 1
    assert m.positions.shape == (fw.LAST_FRAME + 1, N_MARKERS, 3)
    E = _expected()
    np.testing.assert_array_equal(np.isnan(m.positions), np.isnan(E))
    np.testing.assert_allclose(m.positions, E, atol=1e-7, equal_nan=True)  # float32 in the file
    assert int(m.gaps.sum()) == 5
    np.testing.assert_allclose(m.times, np.arange(m.n_frames) / fw.FPS)
    np.testing.assert_allclose(m.marker("M00"), E[:, 0], equal_nan=True)


def test_same_as_ezc3d_raw_read(c3d_file: Path) -> None:
    raw = ezc3d.c3d(str(c3d_file))["data"]["points"][:3].transpose(2, 1, 0) / 1000.0
    ours = read_markers(c3d_file).positions
    np.testing.assert_array_equal(np.isnan(ours), np.isnan(raw))
    np.testing.assert_allclose(ours, raw, equal_nan=True)


def test_info(c3d_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(c3d_file)]) == 0
    out = capsys.readouterr().out
    assert "markers     24 (C3D, units mm" in out and "21 at 30 fps" in out and "5 marker-frames missing" in out


# ---------------------------------------------------------------- the malformed corpus
def _records(d: bytes) -> dict[str, dict[str, int]]:
    """``"GROUP:NAME"`` / ``"GROUP"`` -> byte positions of a record's fields (Intel files)."""
    p0 = (d[0] - 1) * 512 + 4
    q = p0
    groups: dict[int, str] = {}
    raw: list[tuple[int, str, dict[str, int]]] = []
    while True:
        nlen = abs(struct.unpack("b", d[q : q + 1])[0])
        gid = struct.unpack("b", d[q + 1 : q + 2])[0]
        if nlen == 0:
            break
        name = d[q + 2 : q + 2 + nlen].decode()
        op = q + 2 + nlen
        nxt = struct.unpack_from("<H", d, op)[0]
        info = {"at": q, "name": q + 2, "gid": q + 1, "next": op}
        if gid < 0:
            groups[-gid] = name
            raw.append((0, name, info))
        else:
            r = op + 2
            nd = d[r + 1]
            info.update(type=r, ndims=r + 1, dims=r + 2, data=r + 2 + nd)
            raw.append((gid, name, info))
        if nxt == 0:
            break
        q = op + nxt
    return {(f"{groups[g]}:{n}" if g else n): i for g, n, i in raw}


def _at(key: str, field: str, delta: int = 0) -> Callable[[bytes], int]:
    return lambda d: _records(d)[key][field] + delta


def _patch(at: int | Callable[[bytes], int], raw: bytes) -> Callable[[bytes], bytes]:
    def make(d: bytes) -> bytes:
        a = at(d) if callable(at) else at
        return d[:a] + raw + d[a + len(raw) :]

    return make


def _f32(x: float) -> bytes:
    return struct.pack("<f", x)


def _i16(x: int) -> bytes:
    return struct.pack("<h", x)


def _param_block(d: bytes) -> int:
    return (d[0] - 1) * 512


def _data_end(d: bytes) -> int:
    """Where the last frame's points end (ezc3d pads the file to whole blocks after it)."""
    start = struct.unpack_from("<h", d, _records(d)["POINT:DATA_START"]["data"])[0]
    return (start - 1) * 512 + (fw.LAST_FRAME + 1) * N_MARKERS * 4 * 4


def _variants(size: int) -> dict[str, tuple[Callable[[bytes], bytes], str]]:
    v: dict[str, tuple[Callable[[bytes], bytes], str]] = {}
    for k, frac in enumerate(np.linspace(0.02, 0.995, 20)):
        v[f"truncated_{k:02d}"] = ((lambda c: lambda d: d[:c])(int(size * frac)), "truncated" if frac > 0.2 else ": ")
    v["empty"] = (lambda d: b"", "512-byte C3D header")
    v["short_header"] = (lambda d: d[:300], "512-byte C3D header")
    v["not_c3d_key"] = (_patch(1, b"\x51"), "not the C3D key 0x50")
    v["param_block_0"] = (_patch(0, b"\x00"), "header word 1")
    v["param_block_1"] = (_patch(0, b"\x01"), "header word 1")
    v["param_block_beyond_file"] = (_patch(0, b"\xc8"), "beyond the end of the file")
    v["processor_unknown"] = (lambda d: _patch(_param_block(d) + 3, b"\x00")(d), "processor type 0")
    v["param_blocks_zero"] = (lambda d: _patch(_param_block(d) + 2, b"\x00")(d), "0 blocks")
    v["param_blocks_beyond_file"] = (lambda d: _patch(_param_block(d) + 2, b"\xfa")(d), "truncated")
    v["param_name_not_ascii"] = (_patch(_at("POINT:USED", "name"), b"\xff"), "not ASCII")
    v["param_name_invalid"] = (_patch(_at("POINT:USED", "name"), b"*"), "not a valid C3D name")
    v["param_type_3"] = (_patch(_at("POINT:RATE", "type"), b"\x03"), "data type 3")
    v["param_dims_huge"] = (_patch(_at("POINT:LABELS", "dims"), b"\xff\xff"), "run past the end of the parameter section")
    v["param_next_overlaps"] = (_patch(_at("POINT:LABELS", "next"), struct.pack("<H", 6)), "overlap the next record")
    v["param_undefined_group"] = (_patch(_at("POINT:RATE", "gid"), b"\x63"), "group id 99")
    v["no_point_group"] = (_patch(_at("POINT", "name", 4), b"X"), "no POINT group")
    v["used_not_header"] = (_patch(_at("POINT:USED", "data"), _i16(N_MARKERS - 1)), "POINT:USED")
    v["header_points_not_used"] = (_patch(2, struct.pack("<H", N_MARKERS + 2)), "POINT:USED")
    v["scale_zero"] = (_patch(_at("POINT:SCALE", "data"), _f32(0.0)), "POINT:SCALE: is 0")
    v["scale_nan"] = (_patch(_at("POINT:SCALE", "data"), _f32(float("nan"))), "POINT:SCALE: not finite")
    v["rate_zero"] = (_patch(_at("POINT:RATE", "data"), _f32(0.0)), "POINT:RATE: must be > 0")
    v["rate_negative"] = (_patch(_at("POINT:RATE", "data"), _f32(-30.0)), "POINT:RATE: must be > 0")
    v["rate_nan"] = (_patch(_at("POINT:RATE", "data"), _f32(float("nan"))), "POINT:RATE: not finite")
    v["rate_inf"] = (_patch(_at("POINT:RATE", "data"), _f32(float("inf"))), "POINT:RATE: not finite")
    v["data_start_0"] = (_patch(_at("POINT:DATA_START", "data"), _i16(0)), "POINT:DATA_START")
    v["data_start_1"] = (_patch(_at("POINT:DATA_START", "data"), _i16(1)), "POINT:DATA_START")
    v["data_start_beyond_file"] = (_patch(_at("POINT:DATA_START", "data"), _i16(900)), "truncated")
    v["frames_reversed"] = (_patch(6, struct.pack("<HH", 20, 3)), "no frames")
    v["first_frame_0"] = (_patch(6, struct.pack("<H", 0)), "header word 4")
    v["frames_param_exceeds_header"] = (_patch(_at("POINT:FRAMES", "data"), _i16(500)), "POINT:FRAMES")
    v["labels_fewer"] = (_patch(_at("POINT:LABELS", "dims", 1), bytes([N_MARKERS - 4])), "labels for")
    v["labels_numeric"] = (_patch(_at("POINT:LABELS", "type"), b"\x01"), "expected text labels")
    v["units_unknown"] = (_patch(_at("POINT:UNITS", "data"), b"ft"), "unknown unit 'ft'")
    v["units_numeric"] = (_patch(_at("POINT:UNITS", "type"), b"\x01"), "expected text")
    v["rate_as_text"] = (_patch(_at("POINT:RATE", "type"), b"\xff"), "expected a number")
    v["data_cut"] = (lambda d: d[: _data_end(d) - 40], "truncated")
    v["data_cut_one_byte"] = (lambda d: d[: _data_end(d) - 1], "truncated")
    return v


@pytest.fixture(scope="session")
def c3d_bytes(c3d_file: Path) -> bytes:
    return c3d_file.read_bytes()


VARIANTS = sorted(_variants(10_000))


def test_corpus_is_large_enough() -> None:
    assert len(VARIANTS) >= 50


def check_c3d_bytes(data: bytes) -> c3d_mod.C3dLayout:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "x.c3d"
        p.write_bytes(data)
        return check_c3d(p)


def test_the_locator_finds_the_point_parameters(c3d_bytes: bytes) -> None:
    recs = _records(c3d_bytes)
    for key in ("POINT", "POINT:USED", "POINT:RATE", "POINT:UNITS", "POINT:LABELS", "POINT:DATA_START", "POINT:FRAMES", "POINT:SCALE"):
        assert key in recs
    layout = check_c3d_bytes(c3d_bytes)
    assert layout.n_points == N_MARKERS and layout.n_frames == fw.LAST_FRAME + 1 and layout.processor == "Intel"


@pytest.mark.parametrize("name", VARIANTS)
def test_malformed_variant_is_refused_before_ezc3d(
    name: str, c3d_bytes: bytes, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    make, expected = _variants(len(c3d_bytes))[name]
    p = tmp_path / f"{name}.c3d"
    p.write_bytes(make(c3d_bytes))

    class NoEzc3d:
        def c3d(self, *a: Any, **k: Any) -> Any:
            raise AssertionError("ezc3d read a malformed file")

    monkeypatch.setitem(sys.modules, "ezc3d", NoEzc3d())
    with pytest.raises(MeshFormatError) as ei:
        read_markers(p)
    msg = str(ei.value)
    assert msg.startswith(f"{p.name}: "), msg
    assert expected in msg, msg
    assert ei.value.field, msg
