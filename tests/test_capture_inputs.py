"""Capture input readers (workbench.capture.inputs, issue 17 item 1) on files written here.

Ground truth: a face-sized marker cloud (12 markers on an ellipsoid of
~0.2 m, moving) with occlusions, written as CSV (flat ``_x`` and ``.X`` layouts,
the Vicon Nexus Trajectories layout), NPY/NPZ and C3D (ezc3d's writer); point
clouds written by trimesh (binary/ASCII PLY, with and without normals) and as
NPZ in the three documented layouts; depth images of an analytic plane and
sphere, rendered per pixel by ray intersection and written as 16-bit PNG by
Pillow. Every reader must give the known arrays back in metres, and every
error must name the file, the frame/line and the column/field.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from workbench.capture.inputs import (
    CameraIntrinsics,
    CaptureInputError,
    MarkerSequence,
    PointCloudSequence,
    as_marker_sequence,
    depth_to_points,
    metres_per_unit,
    read_depth_frames,
    read_intrinsics,
    read_marker_csv,
    read_markers,
    read_point_clouds,
    read_vertex_map,
    to_model_units,
)
from workbench.geometry.mesh_checks import MeshFormatError

T, M = 8, 12
NAMES = [f"M{j:02d}" for j in range(M)]
GAPS = [(2, 3), (5, 0), (5, 7)]  # (frame, marker) occluded


def truth() -> np.ndarray:
    """(T, M, 3) marker positions in metres: an ellipsoid of markers, moving, NaN at GAPS."""
    rng = np.random.default_rng(7)
    d = rng.normal(size=(M, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    base = d * [0.08, 0.11, 0.09] + [0.0, 1.6, 0.05]
    P = np.stack([base + np.array([0.002 * t, 0.001 * np.sin(t), 0.0]) for t in range(T)])
    P = np.round(P * 1000.0, 3) / 1000.0  # exactly 3 decimals in mm
    for f, j in GAPS:
        P[f, j] = np.nan
    return P


def fmt(x: float) -> str:
    return "" if np.isnan(x) else f"{x:.12g}"


def write_flat_csv(
    path: Path,
    P_m: np.ndarray,
    *,
    unit: str = "mm",
    sep: str = "_",
    axes: str = "xyz",
    frames: list[int] | None = None,
    fps: float | None = 120.0,
    comment_units: bool = True,
) -> Path:
    scale = 1.0 / metres_per_unit(unit)
    frames = list(range(P_m.shape[0])) if frames is None else frames
    head = ["frame"] + (["time"] if fps else []) + [f"{n}{sep}{a}" for n in NAMES for a in axes]
    lines = [f"# units: {unit}"] if comment_units else []
    lines.append(",".join(head))
    for f, row in zip(frames, P_m, strict=True):
        cells = [str(f)] + ([f"{f / fps:.6f}"] if fps else [])
        cells += [fmt(row[j, "xyz".index(a.lower())] * scale) for j in range(M) for a in axes]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def csv_lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def assert_names(exc: pytest.ExceptionInfo[CaptureInputError], path: Path, *parts: str) -> None:
    msg = str(exc.value)
    assert msg.startswith(path.name + ":"), msg
    for p in parts:
        assert p in msg, (p, msg)


# ---------------------------------------------------------------------------- CSV
def test_flat_csv_round_trip_with_gaps(tmp_path: Path) -> None:
    P = truth()
    seq = read_marker_csv(write_flat_csv(tmp_path / "m.csv", P))
    assert isinstance(seq, MarkerSequence)
    assert seq.names == tuple(NAMES) and seq.units == "mm" and seq.first_frame == 0
    assert seq.fps == 120.0  # from the time column
    np.testing.assert_array_equal(np.isnan(seq.positions), np.isnan(P))
    np.testing.assert_allclose(seq.positions, P, atol=1e-12, equal_nan=True)
    assert sorted(map(tuple, np.argwhere(seq.gaps))) == sorted(GAPS)


def test_dot_layout_any_order_and_units_argument(tmp_path: Path) -> None:
    P = truth()
    f = write_flat_csv(
        tmp_path / "dots.csv", P, unit="cm", sep=".", axes="ZXY", fps=None, comment_units=False
    )
    seq = read_markers(f, units="cm", fps=60.0)
    assert seq.units == "cm" and seq.fps == 60.0
    np.testing.assert_allclose(seq.positions, P, atol=1e-12, equal_nan=True)
    # units= wins over the comment: a file saying mm that is really in cm
    g = write_flat_csv(
        tmp_path / "lies.csv", P / 10.0, unit="mm"
    )  # centimetre numbers, labelled mm
    np.testing.assert_allclose(
        read_marker_csv(g, units="cm").positions, P, atol=1e-12, equal_nan=True
    )


def test_no_fps_anywhere_assumes_30_and_warns(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    f = write_flat_csv(tmp_path / "nofps.csv", truth(), fps=None)
    with caplog.at_level(logging.WARNING, logger="workbench.capture"):
        seq = read_marker_csv(f)
    assert seq.fps == 30.0 and "30 fps assumed" in caplog.text


def test_skipped_frame_numbers_become_occluded_frames(tmp_path: Path) -> None:
    P = truth()[:4]
    f = write_flat_csv(tmp_path / "skip.csv", P, frames=[10, 11, 14, 15], fps=None)
    seq = read_marker_csv(f)
    assert seq.first_frame == 10 and seq.n_frames == 6
    assert np.isnan(seq.positions[2:4]).all()
    np.testing.assert_allclose(seq.positions[[0, 1, 4, 5]], P, atol=1e-12, equal_nan=True)


def test_vicon_trajectories_layout(tmp_path: Path) -> None:
    P = truth()
    names_row = ",," + ",".join(f"Actor:{n},," for n in NAMES)
    axis_row = "Frame,Sub Frame," + ",".join("X,Y,Z" for _ in NAMES)
    unit_row = ",," + ",".join("mm" for _ in range(3 * M))
    rows = [f"{t + 1},0," + ",".join(fmt(x * 1000.0) for x in P[t].ravel()) for t in range(T)]
    text = "\n".join(
        [
            *("Devices", "1000", ",,Force Plate", "Frame,Sub Frame,Fx", ",,N", "1,0,3.5", ""),
            *("Trajectories", "100", names_row, axis_row, unit_row, *rows, ""),
            *("Model Outputs", "100"),
        ]
    )
    f = tmp_path / "nexus.csv"
    f.write_text(text + "\n")
    seq = read_markers(f)
    assert seq.names == tuple(f"Actor:{n}" for n in NAMES)
    assert seq.units == "mm" and seq.fps == 100.0 and seq.first_frame == 1
    np.testing.assert_allclose(seq.positions, P, atol=1e-12, equal_nan=True)


def _flat(tmp_path: Path) -> Path:
    return write_flat_csv(tmp_path / "bad.csv", truth())


def _edit(path: Path, line: int, old: str, new: str) -> None:
    lines = csv_lines(path)
    assert old in lines[line - 1], (old, lines[line - 1])
    lines[line - 1] = lines[line - 1].replace(old, new, 1)
    path.write_text("\n".join(lines) + "\n")


def _set_cell(path: Path, line: int, column: str, value: str) -> None:
    lines = csv_lines(path)
    head = lines[1].split(",")
    cells = lines[line - 1].split(",")
    cells[head.index(column)] = value
    lines[line - 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


# (edit, expected fragments): line 1 is '# units: mm', 2 the header, 3 frame 0, ...
CSV_ERRORS = {
    "not a number": (
        lambda f: _set_cell(f, 6, "M04_y", "abc"),
        ["line 6 (frame 3)", "column 'M04_y'", "not a number"],
    ),
    "infinite": (
        lambda f: _set_cell(f, 4, "M01_z", "inf"),
        ["line 4 (frame 1)", "column 'M01_z'", "infinite"],
    ),
    "partly occluded": (
        lambda f: _set_cell(f, 7, "M02_y", ""),
        ["line 7 (frame 4)", "column 'M02_y'", "not all of x, y, z"],
    ),
    "ragged": (lambda f: _edit(f, 8, ",", ",,1,"), ["line 8", "fields, the header has"]),
    "frame not whole": (
        lambda f: _set_cell(f, 5, "frame", "2.5"),
        ["line 5", "column 'frame'", "whole frame number"],
    ),
    "frames decrease": (
        lambda f: _set_cell(f, 5, "frame", "0"),
        ["line 5", "column 'frame'", "does not come after"],
    ),
    "time decreases": (
        lambda f: _set_cell(f, 9, "time", "0.0"),
        ["line 9 (frame 6)", "column 'time'", "does not come after"],
    ),
    "unknown column": (
        lambda f: _edit(f, 2, "M03_x", "M03_q"),
        ["line 2", "column 'M03_q'", "neither a frame/time column"],
    ),
    "duplicate axis": (
        lambda f: _edit(f, 2, "M05_z", "M06_z"),
        ["line 2", "marker 'M06' has a second z column"],
    ),
    "unknown unit": (lambda f: _edit(f, 1, "mm", "furlongs"), ["units", "unknown unit 'furlongs'"]),
    "no unit": (
        lambda f: _edit(f, 1, "# units: mm", "# made by hand"),
        ["units", "does not state its length unit", "units='mm'"],
    ),
    "wrong unit": (lambda f: _edit(f, 1, "mm", "m"), ["units", "span", "pass units='mm'"]),
}


@pytest.mark.parametrize("case", sorted(CSV_ERRORS))
def test_csv_errors_name_file_line_frame_column(case: str, tmp_path: Path) -> None:
    f = _flat(tmp_path)
    edit, parts = CSV_ERRORS[case]
    edit(f)
    with pytest.raises(CaptureInputError) as exc:
        read_marker_csv(f)
    assert_names(exc, f, *parts)
    assert isinstance(exc.value, MeshFormatError) and isinstance(exc.value, ValueError)


def test_csv_error_attributes(tmp_path: Path) -> None:
    f = _flat(tmp_path)
    _set_cell(f, 6, "M04_y", "abc")
    with pytest.raises(CaptureInputError) as exc:
        read_marker_csv(f)
    e = exc.value
    assert (e.source, e.line, e.frame, e.column, e.field) == (str(f), 6, 3, "M04_y", "M04_y")


def test_csv_missing_axis_column(tmp_path: Path) -> None:
    f = tmp_path / "noz.csv"
    f.write_text("# units: mm\nframe,a_x,a_y,a_z,b_x,b_y\n0,1,2,3,4,5\n")
    with pytest.raises(CaptureInputError) as exc:
        read_marker_csv(f)
    assert_names(exc, f, "line 2", "marker 'b' has no z column", "column 'b_x'")


def test_csv_empty_and_header_only(tmp_path: Path) -> None:
    f = tmp_path / "empty.csv"
    f.write_text("# units: mm\n\n")
    with pytest.raises(CaptureInputError, match=r"empty\.csv: file: no header"):
        read_marker_csv(f)
    f.write_text("# units: mm\nframe,a_x,a_y,a_z\n")
    with pytest.raises(CaptureInputError, match=r"header but no data rows"):
        read_marker_csv(f)


def test_vicon_marker_not_over_xyz(tmp_path: Path) -> None:
    f = tmp_path / "v.csv"
    f.write_text(
        "Trajectories\n100\n,,A,,,B,,\nFrame,Sub Frame,X,Y,Z,X,Y\n,,mm,mm,mm,mm,mm\n1,0,1,2,3,4,5\n"
    )
    with pytest.raises(CaptureInputError) as exc:
        read_marker_csv(f)
    assert_names(exc, f, "line 4", "column 'B'", "X, Y, Z")


# ---------------------------------------------------------------------- arrays, NPZ
def test_npy_and_npz(tmp_path: Path) -> None:
    P = truth()
    np.save(tmp_path / "m.npy", P * 1000.0)
    seq = read_markers(tmp_path / "m.npy", units="mm", fps=25.0)
    assert seq.names == tuple(str(j) for j in range(M)) and seq.fps == 25.0
    np.testing.assert_allclose(seq.positions, P, atol=1e-12, equal_nan=True)
    with pytest.raises(CaptureInputError, match=r"m\.npy: units: the file does not state"):
        read_markers(tmp_path / "m.npy")
    np.savez(
        tmp_path / "m.npz",
        positions=P * 100.0,
        names=np.array(NAMES),
        fps=np.array(50.0),
        units=np.array("cm"),
    )
    seq = read_markers(tmp_path / "m.npz")
    assert seq.names == tuple(NAMES) and seq.fps == 50.0 and seq.units == "cm"
    np.testing.assert_allclose(seq.positions, P, atol=1e-12, equal_nan=True)


def test_npz_refuses_pickles_and_unknown_arrays(tmp_path: Path) -> None:
    P = truth()
    np.savez(
        tmp_path / "obj.npz", positions=P, names=np.array(NAMES, dtype=object), units=np.array("m")
    )
    with pytest.raises(CaptureInputError) as exc:
        read_markers(tmp_path / "obj.npz")
    assert_names(exc, tmp_path / "obj.npz", "array 'names'", "allow_pickle")
    np.savez(tmp_path / "extra.npz", positions=P, units=np.array("m"), weights=np.zeros(3))
    with pytest.raises(CaptureInputError, match=r"extra\.npz: arrays: expected arrays 'positions'"):
        read_markers(tmp_path / "extra.npz")


def test_as_marker_sequence_errors_name_frame_and_marker() -> None:
    P = truth() * 1000.0
    P[4, 6, 1] = np.inf
    with pytest.raises(
        CaptureInputError, match=r"<array>: frame 4, column 'M06': coordinate y is infinite"
    ):
        as_marker_sequence(P, names=NAMES, units="mm")
    P = truth()
    P[3, 2, 0] = np.nan
    with pytest.raises(CaptureInputError, match=r"frame 13, column '2': marker has x missing"):
        as_marker_sequence(P, first_frame=10)
    with pytest.raises(CaptureInputError, match=r"expected a \(frames, markers, 3\) array"):
        as_marker_sequence(np.zeros((4, 3)))
    with pytest.raises(CaptureInputError, match=r"marker name 'a' repeats"):
        as_marker_sequence(np.zeros((1, 2, 3)), names=["a", "a"])


# --------------------------------------------------------------------------- C3D
def write_c3d(path: Path, P_m: np.ndarray, unit: str, scale: float) -> Path:
    """A C3D written by ezc3d's own writer (NaN coordinates are its gaps)."""
    ezc3d = pytest.importorskip("ezc3d", reason="ezc3d is a core dependency (pip install -e .)")
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [200.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(NAMES)
    c["parameters"]["POINT"]["UNITS"]["value"] = [unit]
    pts = np.ones((4, M, P_m.shape[0]))
    pts[:3] = (P_m * scale).transpose(2, 1, 0)
    c["data"]["points"] = pts
    c.write(str(path))
    return path


def test_c3d_by_ezc3d_writer(tmp_path: Path) -> None:
    P = truth()
    seq = read_markers(write_c3d(tmp_path / "take.c3d", P, "mm", 1000.0))
    assert seq.names == tuple(NAMES) and seq.units == "mm" and seq.fps == 200.0
    np.testing.assert_array_equal(np.isnan(seq.positions), np.isnan(P))
    np.testing.assert_allclose(seq.positions, P, atol=1e-6, equal_nan=True)  # float32 in the file


def test_c3d_with_a_wrong_unit(tmp_path: Path) -> None:
    f = write_c3d(tmp_path / "lies.c3d", truth(), "m", 1000.0)  # millimetre numbers, says metres
    with pytest.raises(CaptureInputError) as exc:
        read_markers(f)
    assert_names(exc, f, "units", "pass units='mm'")
    seq = read_markers(f, units="mm")
    assert seq.units == "mm"
    np.testing.assert_allclose(seq.positions, truth(), atol=1e-6, equal_nan=True)


def test_c3d_damaged_names_the_file(tmp_path: Path) -> None:
    f = tmp_path / "junk.c3d"
    f.write_bytes(b"\x02\x51" + bytes(1000))
    with pytest.raises(MeshFormatError, match=r"junk\.c3d: header"):
        read_markers(f)


# ---------------------------------------------------------------------- vertex map
def test_vertex_map_sources_agree(tmp_path: Path) -> None:
    ids = np.arange(M) * 7 + 3
    csv_f = tmp_path / "map.csv"
    csv_f.write_text(
        "# from the rig\nmarker,vertex\n"
        + "".join(f"{n},{v}\n" for n, v in zip(NAMES[::-1], ids[::-1], strict=True))
    )
    json_f = tmp_path / "map.json"
    json_f.write_text(json.dumps({n: int(v) for n, v in zip(NAMES, ids, strict=True)}))
    list_f = tmp_path / "list.json"
    list_f.write_text(
        json.dumps([{"marker": n, "vertex": int(v)} for n, v in zip(NAMES, ids, strict=True)])
    )
    seq = as_marker_sequence(truth(), names=NAMES)
    for src in (csv_f, json_f, list_f, dict(zip(NAMES, ids.tolist(), strict=True)), ids):
        got = read_vertex_map(src, seq, 100)
        assert got.dtype == np.int64 and got.shape == (M,)
        np.testing.assert_array_equal(got, ids)


def test_vertex_map_errors(tmp_path: Path) -> None:
    names = ["nose", "chin", "brow"]
    f = tmp_path / "map.csv"
    f.write_text("marker,vertex\nnose,1\nchin,2\nbrow,3\nnoze,4\n")
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(f, names, 10)
    assert_names(exc, f, "line 5", "['noze']", "not markers of the sequence")
    np.testing.assert_array_equal(read_vertex_map(f, names, 10, allow_extra=True), [1, 2, 3])
    f.write_text("marker,vertex\nnose,1\nbrow,3\n")
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(f, names, 10)
    assert_names(exc, f, "markers", "['chin']", "no vertex")
    f.write_text("marker,vertex\nnose,1\nchin,10\nbrow,3\n")
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(f, names, 10)
    assert_names(exc, f, "line 3", "'chin'", "vertex 10 is out of range", "10 vertices")
    f.write_text("marker,vertex\nnose,1\nchin,2.5\nbrow,3\n")
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(f, names, 10)
    assert_names(exc, f, "line 3", "column 'vertex'", "'2.5' is not a whole vertex index")
    f.write_text("nose,1\nchin,2\nnose,3\n")
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(f, names, 10)
    assert_names(exc, f, "line 3", "column 'marker'", "mapped twice (also line 1)")
    j = tmp_path / "map.json"
    j.write_text('{"nose": 1, "chin": -1, "brow": 2}')
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(j, names, 10)
    assert_names(exc, j, "key 'chin'", "vertex -1 is out of range")
    j.write_text('{"nose": 1, "chin": true, "brow": 2}')
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(j, names, 10)
    assert_names(exc, j, "key 'chin'", "not a whole number")
    j.write_text('{"nose": 1,')
    with pytest.raises(CaptureInputError) as exc:
        read_vertex_map(j, names, 10)
    assert_names(exc, j, "line 1", "not JSON")
    with pytest.raises(CaptureInputError, match=r"<array>: vertex_ids: expected \(3,\) integer"):
        read_vertex_map(np.array([1.0, 2.0, 3.0]), names, 10)


# ---------------------------------------------------------------------- point clouds
def cloud_frames(n_frames: int = 4) -> list[np.ndarray]:
    """Face-sized clouds in metres with different sizes per frame (exact in float32)."""
    rng = np.random.default_rng(3)
    out = []
    for t in range(n_frames):
        P = rng.uniform(-0.1, 0.1, size=(50 + 7 * t, 3))
        out.append(P.astype(np.float32).astype(np.float64))
    return out


def _with_comment(data: bytes, comment: str) -> bytes:
    i = data.index(b"\n", data.index(b"format")) + 1
    return data[:i] + f"comment {comment}\n".encode() + data[i:]


def write_ply_folder(
    folder: Path,
    frames: list[np.ndarray],
    *,
    encoding: str = "binary",
    unit: str | None = None,
    normals: list[np.ndarray] | None = None,
) -> Path:
    import trimesh

    folder.mkdir()
    for t, P in enumerate(frames):
        if normals is None:
            data = trimesh.exchange.ply.export_ply(trimesh.PointCloud(P), encoding=encoding)
        else:  # trimesh writes vertex normals of a mesh (the faces are ignored on reading)
            mesh = trimesh.Trimesh(P, [[0, 1, 2]], vertex_normals=normals[t], process=False)
            data = trimesh.exchange.ply.export_ply(mesh, encoding=encoding, vertex_normal=True)
        if unit is not None:
            data = _with_comment(data, f"units: {unit}")
        (folder / f"frame_{t + 1}.ply").write_bytes(data)  # frame_1 .. frame_10: natural order
    return folder


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_ply_folder_natural_order(encoding: str, tmp_path: Path) -> None:
    frames = cloud_frames(11)
    folder = write_ply_folder(
        tmp_path / "plys", [P * 1000.0 for P in frames], encoding=encoding, unit="mm"
    )
    seq = read_point_clouds(folder, fps=24.0)
    assert isinstance(seq, PointCloudSequence)
    assert (
        seq.labels == tuple(f"frame_{t + 1}.ply" for t in range(11))
        and seq.units == "mm"
        and seq.fps == 24.0
    )
    assert seq.normals is None
    np.testing.assert_array_equal(seq.counts, [P.shape[0] for P in frames])
    for got, P in zip(seq.frames, frames, strict=True):
        np.testing.assert_allclose(got, P, rtol=1e-6, atol=1e-9)


def test_ply_normals(tmp_path: Path) -> None:
    frames = cloud_frames(2)
    rng = np.random.default_rng(5)
    normals = [rng.normal(size=P.shape) for P in frames]
    folder = write_ply_folder(tmp_path / "n", frames, normals=normals)
    seq = read_point_clouds(folder, units="m")
    assert seq.normals is not None
    for got, N in zip(seq.normals, normals, strict=True):
        np.testing.assert_allclose(got, N / np.linalg.norm(N, axis=1, keepdims=True), atol=1e-6)
    # a hand-written ASCII point cloud with nx ny nz and no faces
    f = tmp_path / "one.ply"
    f.write_text(
        "ply\nformat ascii 1.0\ncomment units cm\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n"
        "0 0 0 0 0 2\n10 0 0 0 3 0\n0 10 5 4 0 0\n"
    )
    one = read_point_clouds(f)
    assert one.units == "cm" and one.n_frames == 1
    np.testing.assert_allclose(one.frames[0], [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0.05]])
    assert one.normals is not None
    np.testing.assert_allclose(one.normals[0], [[0, 0, 1], [0, 1, 0], [1, 0, 0]])


def test_npz_layouts_agree(tmp_path: Path) -> None:
    frames = cloud_frames(3)
    counts = np.array([P.shape[0] for P in frames])
    allp = np.concatenate(frames)
    np.savez(
        tmp_path / "per.npz",
        **{f"points_{t:04d}": P for t, P in enumerate(frames)},
        **{f"normals_{t:04d}": np.tile([0.0, 3.0, 0.0], (len(P), 1)) for t, P in enumerate(frames)},
        units=np.array("m"),
        fps=np.array(15.0),
    )
    np.savez(tmp_path / "counts.npz", points=allp, counts=counts, units=np.array("m"))
    np.savez(
        tmp_path / "offsets.npz",
        points=allp * 1000,
        offsets=np.concatenate([[0], np.cumsum(counts)]),
    )
    for name, kw in (("per.npz", {}), ("counts.npz", {}), ("offsets.npz", {"units": "mm"})):
        seq = read_point_clouds(tmp_path / name, **kw)
        assert seq.n_frames == 3, name
        for got, P in zip(seq.frames, frames, strict=True):
            np.testing.assert_allclose(got, P, atol=1e-12)
    per = read_point_clouds(tmp_path / "per.npz")
    assert per.fps == 15.0 and per.normals is not None
    np.testing.assert_array_equal(np.concatenate(per.normals), np.tile([0.0, 1.0, 0.0], (len(allp), 1)))
    fixed = np.stack([P[:40] for P in frames])
    N = np.zeros_like(fixed)
    N[..., 2] = 2.0
    np.savez(tmp_path / "fixed.npz", points=fixed, normals=N, units=np.array("m"))
    seq = read_point_clouds(tmp_path / "fixed.npz")
    np.testing.assert_allclose(np.stack(seq.frames), fixed)
    assert seq.normals is not None and np.allclose(np.stack(seq.normals)[..., 2], 1.0)


def test_empty_frames(tmp_path: Path) -> None:
    frames = cloud_frames(3)
    frames[1] = np.zeros((0, 3))
    np.savez(
        tmp_path / "gap.npz",
        **{f"points_{t}": P for t, P in enumerate(frames)},
        units=np.array("m"),
    )
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(tmp_path / "gap.npz")
    assert_names(exc, tmp_path / "gap.npz", "frame 1", "points", "empty", "allow_empty=True")
    seq = read_point_clouds(tmp_path / "gap.npz", allow_empty=True)
    np.testing.assert_array_equal(seq.empty, [False, True, False])
    # an empty PLY in a folder names that file and frame
    folder = write_ply_folder(tmp_path / "plys", cloud_frames(3), unit="m")
    (folder / "frame_2.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n"
    )
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(folder)
    assert_names(exc, folder / "frame_2.ply", "frame 1", "empty")


def test_point_cloud_errors(tmp_path: Path) -> None:
    frames = cloud_frames(3)
    bad = [P.copy() for P in frames]
    bad[2][17] = np.nan
    np.savez(
        tmp_path / "nan.npz",
        **{f"points_{t:03d}": P for t, P in enumerate(bad)},
        units=np.array("m"),
    )
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(tmp_path / "nan.npz")
    assert_names(
        exc, tmp_path / "nan.npz", "frame 2", "array 'points_002'", "point 17 is not finite"
    )
    np.savez(tmp_path / "hole.npz", points_0=frames[0], points_2=frames[2], units=np.array("m"))
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(tmp_path / "hole.npz")
    assert_names(exc, tmp_path / "hole.npz", "frame 1", "without gaps")
    np.savez(
        tmp_path / "counts.npz",
        points=np.concatenate(frames),
        counts=np.array([50, 57, 60]),
        units=np.array("m"),
    )
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(tmp_path / "counts.npz")
    assert_names(exc, tmp_path / "counts.npz", "array 'counts'", "sum to 167", "171 rows")
    np.savez(tmp_path / "noun.npz", points_0=frames[0])
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(tmp_path / "noun.npz")
    assert_names(exc, tmp_path / "noun.npz", "units", "units='mm'")
    np.savez(
        tmp_path / "mm.npz", points_0=frames[0] * 1000, units=np.array("m")
    )  # mm numbers said m
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(tmp_path / "mm.npz")
    assert_names(exc, tmp_path / "mm.npz", "units", "pass units='mm'")
    # PLY: truncated binary, no 'x' property, units that disagree between frames
    folder = write_ply_folder(tmp_path / "plys", [P * 1000 for P in frames], unit="mm")
    f = folder / "frame_2.ply"
    f.write_bytes(f.read_bytes()[:-100])
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(folder)
    assert_names(exc, f, "frame 1")
    g = tmp_path / "nox.ply"
    g.write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\nend_header\n1 2\n"
    )
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(g, units="m")
    assert_names(exc, g, "frame 0", "element vertex", "no 'x' property")
    folder2 = write_ply_folder(tmp_path / "mixed", [P * 1000 for P in frames], unit="mm")
    (folder2 / "frame_3.ply").write_bytes(
        (folder2 / "frame_3.ply").read_bytes().replace(b"units: mm", b"units: cm")
    )
    with pytest.raises(CaptureInputError) as exc:
        read_point_clouds(folder2)
    assert_names(exc, folder2 / "frame_3.ply", "frame 2", "'cm'", "'mm'")
    assert read_point_clouds(folder2, units="mm").units == "mm"  # the caller's unit settles it


# ---------------------------------------------------------------------- depth frames
W_, H_ = 64, 48
K_ = (60.0, 62.0, 31.5, 23.25)


def rays() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel grid and the ray of each pixel with z = 1 (OpenCV camera frame)."""
    v, u = np.mgrid[0:H_, 0:W_].astype(np.float64)
    fx, fy, cx, cy = K_
    d = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1)
    return u, v, d


def render_plane(n: np.ndarray, c: float) -> np.ndarray:
    """(H, W) depth z in metres of the plane n·X = c."""
    _, _, d = rays()
    return c / (d @ n)


def render_sphere(C: np.ndarray, R: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) depth (0 = miss) of a sphere and the (H, W, 3) hit points, camera frame."""
    _, _, d = rays()
    a = np.einsum("hwk,hwk->hw", d, d)
    b = d @ C
    disc = b * b - a * (C @ C - R * R)
    hit = disc > 0
    t = np.where(hit, (b - np.sqrt(np.where(hit, disc, 0.0))) / a, 0.0)
    return t, d * t[..., None]


def test_depth_plane_exact_in_float() -> None:
    n = np.array([0.2, -0.1, 1.0])
    z = render_plane(n, 0.6)
    P = depth_to_points(z, K_, depth_scale=1.0, axes="opencv")
    assert P.shape == (H_ * W_, 3)
    _, _, d = rays()
    np.testing.assert_allclose(P, (d * z[..., None]).reshape(-1, 3), atol=1e-12)
    np.testing.assert_allclose(P @ n, 0.6, atol=1e-12)
    # y_up: the same points with y and z negated
    np.testing.assert_allclose(depth_to_points(z, K_, depth_scale=1.0), P * [1, -1, -1], atol=1e-15)


def test_depth_sphere_16bit_png(tmp_path: Path) -> None:
    from PIL import Image

    C, R = np.array([0.02, -0.01, 0.5]), 0.12
    z, X = render_sphere(C, R)
    D = np.round(z * 1000.0).astype(np.uint16)  # millimetre depth, 0 = miss
    folder = tmp_path / "depth"
    folder.mkdir()
    for t in (0, 1, 10):  # natural order 0, 1, 10
        Image.fromarray(D).save(folder / f"depth_{t}.png")
    fx, fy, cx, cy = K_
    (tmp_path / "cam.json").write_text(
        json.dumps(
            {"width": W_, "height": H_, "intrinsic_matrix": [fx, 0, 0, 0, fy, 0, cx, cy, 1]}
        )  # Open3D
    )
    seq = read_depth_frames(folder, tmp_path / "cam.json", axes="opencv", fps=30.0)
    assert seq.labels == ("depth_0.png", "depth_1.png", "depth_10.png") and seq.units == "mm"
    hit = D > 0
    assert np.all(seq.counts == int(hit.sum())) and hit.sum() > 500
    P = seq.frames[0]
    # the known hit points, to within the millimetre quantisation along each ray
    _, _, d = rays()
    err = np.linalg.norm(P - X[hit], axis=1)
    assert np.all(err <= 0.5e-3 * np.linalg.norm(d[hit], axis=1) + 1e-12)
    assert abs(np.linalg.norm(P - C, axis=1) - R).max() < 1e-3
    np.testing.assert_allclose(P, depth_to_points(D, K_, axes="opencv"), atol=0)


def test_depth_options() -> None:
    D = np.full((H_, W_), 1000, np.uint16)
    D[10, 20] = 0  # no measurement
    D[30, 40] = 3000
    assert depth_to_points(D, K_).shape == (H_ * W_ - 1, 3)
    assert depth_to_points(D, K_, max_depth=2.0).shape == (H_ * W_ - 2, 3)
    P = depth_to_points(D, K_, stride=4, roi=(8, 4, 24, 16), axes="opencv")
    u = (P[:, 0] / P[:, 2]) * K_[0] + K_[2]
    v = (P[:, 1] / P[:, 2]) * K_[1] + K_[3]
    np.testing.assert_allclose(np.unique(np.round(u)), [8, 12, 16, 20])
    np.testing.assert_allclose(np.unique(np.round(v)), [4, 8, 12])
    K = np.array([[K_[0], 0, K_[2]], [0, K_[1], K_[3]], [0, 0, 1]])
    np.testing.assert_array_equal(depth_to_points(D, K), depth_to_points(D, CameraIntrinsics(*K_)))
    with pytest.raises(ValueError, match=r"expected an \(H, W\) image"):
        depth_to_points(np.zeros((2, 2, 3)), K_)
    with pytest.raises(ValueError, match=r"negative value -1 at row 1, column 0"):
        depth_to_points(np.array([[1.0, 2.0], [-1.0, 0.0]]), K_, depth_scale=1.0)
    with pytest.raises(CaptureInputError, match=r"Open3D's units per metre: use 0.001"):
        depth_to_points(D, K_, depth_scale=1000.0)
    with pytest.raises(ValueError, match=r"stride"):
        depth_to_points(D, K_, stride=0)
    with pytest.raises(ValueError, match=r"roi"):
        depth_to_points(D, K_, roi=(10, 0, 5, 5))


def test_depth_frame_errors(tmp_path: Path) -> None:
    from PIL import Image

    D = np.full((H_, W_), 800, np.uint16)
    folder = tmp_path / "d"
    folder.mkdir()
    Image.fromarray(D).save(folder / "f1.png")
    Image.fromarray((D // 8).astype(np.uint8)).save(folder / "f2.png")
    with pytest.raises(CaptureInputError) as exc:
        read_depth_frames(folder, K_)
    assert_names(exc, folder / "f2.png", "frame 1", "image mode", "16-bit single-channel", "'L'")
    Image.fromarray(D[:, :40]).save(folder / "f2.png")
    with pytest.raises(CaptureInputError) as exc:
        read_depth_frames(folder, K_)
    assert_names(exc, folder / "f2.png", "frame 1", "image size", "40x48", "64x48")
    Image.fromarray(np.zeros_like(D)).save(folder / "f2.png")
    with pytest.raises(CaptureInputError) as exc:
        read_depth_frames(folder, K_)
    assert_names(exc, folder / "f2.png", "frame 1", "no pixel has a valid depth")
    seq = read_depth_frames(folder, K_, allow_empty=True)
    np.testing.assert_array_equal(seq.empty, [False, True])
    with pytest.raises(CaptureInputError) as exc:
        read_depth_frames(
            folder, K_, depth_scale=1.0, allow_empty=True
        )  # millimetres read as metres
    assert_names(exc, folder / "f1.png", "frame 0", "depth_scale", "800 m")
    cam = tmp_path / "cam.json"
    cam.write_text(
        json.dumps({"fx": 60, "fy": 62, "cx": 31.5, "cy": 23.25, "width": 640, "height": 480})
    )
    with pytest.raises(CaptureInputError) as exc:
        read_depth_frames(folder, cam, allow_empty=True)
    assert_names(exc, folder / "f1.png", "frame 0", "image size", "intrinsics are for 640x480")


def test_intrinsics_errors(tmp_path: Path) -> None:
    cam = tmp_path / "cam.json"
    for obj, parts in (
        ({"fx": 60, "fy": 62, "cx": 31.5}, ["intrinsics:", "expected fx, fy, cx, cy"]),
        ({"fx": -60, "fy": 62, "cx": 31.5, "cy": 2}, ["intrinsics 'fx'", "positive"]),
        ({"fx": "60", "fy": 62, "cx": 31.5, "cy": 2}, ["intrinsics 'fx'", "expected a number"]),
        ({"K": [[60, 1, 3], [0, 60, 2], [0, 0, 1]]}, ["intrinsics 'K'", "not a pinhole"]),
        (
            {"fx": 60, "fy": 62, "cx": 31.5, "cy": 2, "depth_scale": 1000},
            ["intrinsics 'depth_scale'", "use 0.001"],
        ),
    ):
        cam.write_text(json.dumps(obj))
        with pytest.raises(CaptureInputError) as exc:
            read_intrinsics(cam)
        assert_names(exc, cam, *parts)
    cam.write_text(
        json.dumps({"K": [[60, 0, 3], [0, 61, 2], [0, 0, 1]], "depth_scale": 0.0001, "fps": 90})
    )
    k = read_intrinsics(cam)
    assert (k.fx, k.fy, k.cx, k.cy, k.depth_scale, k.fps) == (60, 61, 3, 2, 0.0001, 90)


# ---------------------------------------------------------------------------- units
def test_to_model_units() -> None:
    from workbench.core.shapes import ModelMetadata

    class _Model:
        metadata = ModelMetadata(units="dm")

    seq = as_marker_sequence(truth())
    np.testing.assert_allclose(to_model_units(seq, _Model()), truth() * 10.0, equal_nan=True)
    np.testing.assert_allclose(to_model_units(seq, "mm"), truth() * 1000.0, equal_nan=True)
    clouds = PointCloudSequence(tuple(cloud_frames(2)), 30.0, "m")
    out = to_model_units(clouds, "cm")
    assert isinstance(out, list) and len(out) == 2
    np.testing.assert_allclose(out[1], cloud_frames(2)[1] * 100.0)
    with pytest.raises(ValueError, match=r"units: expected one of"):
        to_model_units(seq, "furlong")
