"""OBJ reader and folder-of-OBJs reader: tiny fixtures written in tmp_path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.obj import parse_obj_text, read_obj
from workbench.io.obj_folder import read_obj_folder
from workbench.io.registry import read_any, supported_inputs

# 2x1 quads in the z=0 plane, plus a separate triangle in group "eye"
QUAD_OBJ = """\
# tiny test mesh
mtllib tiny.mtl
o head
v 0 0 0
v 1 0 0
v 2 0 0
v 0 1 0
v 1 1 0
v 2 1 0
vt 0 0
vn 0 0 1
g skin
usemtl mat
s 1
f 1/1/1 2/1/1 5/1/1 4/1/1
f 2//1 3//1 6//1 5//1
g eye
v 0 0 1
v 1 0 1
v 0 1 1
f -3 -2 -1
"""

QUAD_V = np.array(
    [
        [0, 0, 0],
        [1, 0, 0],
        [2, 0, 0],
        [0, 1, 0],
        [1, 1, 0],
        [2, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [0, 1, 1],
    ],
    dtype=float,
)


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def obj_text(V: np.ndarray, faces: list[list[int]]) -> str:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    return "\n".join(lines) + "\n"


def test_reads_vertices_polygons_groups(tmp_path: Path) -> None:
    face = read_obj(write(tmp_path / "tiny.obj", QUAD_OBJ))
    np.testing.assert_array_equal(face.vertices, QUAD_V)
    assert face.vertices.dtype == np.float64
    assert [face.polygons[i].tolist() for i in range(3)] == [[0, 1, 4, 3], [1, 2, 5, 4], [6, 7, 8]]
    assert face.group_names == ["head", "skin", "eye"]
    assert face.face_groups is not None and face.face_groups.tolist() == [1, 1, 2]
    assert face.shapes == [] and face.units is None and face.up_axis is None
    assert face.source_files == [str(tmp_path / "tiny.obj")]
    labels, names = face.components()
    assert names == ["skin", "eye"]
    assert labels.tolist() == [0] * 6 + [1] * 3


def test_no_groups_gives_none(tmp_path: Path) -> None:
    face = read_obj(write(tmp_path / "a.obj", obj_text(QUAD_V[:6], [[0, 1, 4, 3]])))
    assert face.face_groups is None and face.group_names == []


def test_faces_before_first_group_are_ungrouped() -> None:
    face = parse_obj_text(obj_text(QUAD_V[:6], [[0, 1, 4, 3]]) + "g right\nf 2 3 6 5\n")
    assert face.face_groups is not None and face.face_groups.tolist() == [-1, 0]


def test_vertex_w_and_colour_columns_are_accepted() -> None:
    text = "v 0 0 0 1\nv 1 0 0 0.5 0.5 0.5\nv 0 1 0\nf 1 2 3\n"
    np.testing.assert_array_equal(parse_obj_text(text).vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_crlf_and_no_trailing_newline() -> None:
    face = parse_obj_text("v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3")
    assert len(face.polygons) == 1


def test_large_file_round_trip(tmp_path: Path) -> None:
    # 100x100 grid of quads: values survive repr() exactly
    rng = np.random.default_rng(0)
    n = 100
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    V = np.stack([ii.ravel(), jj.ravel(), rng.normal(size=n * n) * 0.01], axis=1).astype(float)
    faces = [
        [i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1]
        for i in range(n - 1)
        for j in range(n - 1)
    ]
    face = read_obj(write(tmp_path / "grid.obj", obj_text(V, faces)))
    np.testing.assert_array_equal(face.vertices, V)
    assert face.polygons.equals(type(face.polygons).from_lists(faces))


# ---- bad input: every error names the file, the line and the problem -----------------

BAD_OBJ = [
    ("", "file", r"bad.obj: empty file"),
    ("# only a comment\n\n", "v", r"bad.obj: no vertices"),
    ("g lonely\n", "v", r"bad.obj: no vertices"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "f", r"bad.obj: no faces"),
    ("v 0 0 0\nv 1 0 0\nv 0 1\n", "v", r"bad.obj: line 3: vertex needs 3 coordinates.*got 2"),
    (
        "v 0 0 0\nv 1 0 x\nv 0 1 0\nf 1 2 3\n",
        "v",
        r"bad.obj: line 2: vertex coordinate is not a number",
    ),
    (
        "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n",
        "v",
        r"bad.obj: line 2: row 1 is not finite \(1.0, 0.0, nan\)",
    ),
    ("v 0 0 0\nv 1 0 0\nv inf 1 0\nf 1 2 3\n", "v", r"bad.obj: line 3: row 2 is not finite"),
    (
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9001\n",
        "f",
        r"bad.obj: line 4: face index 9001 out of range \(file has 3 vertices\)",
    ),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", "f", r"bad.obj: line 4: face index -4 out of range"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "f", r"bad.obj: line 4: face index 0"),
    # a face line cut mid-way (truncated download)
    (
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2",
        "f",
        r"bad.obj: line 4: face needs at least 3 corners, got 2",
    ),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/", "f", r"bad.obj: line 4: bad face corner '3/'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/1/1/1\n", "f", r"line 4: bad face corner"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", "f", r"line 4: bad face corner 'a'"),
    (
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2\n",
        "f",
        r"bad.obj: line 4: face 0 uses vertex 1 more than once",
    ),
    (
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
        "f",
        r"bad.obj: line 4: face 0 \[0, 1, 2\] has zero area",
    ),
    (
        "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3\nf 3 1 2\n",
        "f",
        r"bad.obj: line 6: face 1 \[2, 0, 1\] duplicates face 0",
    ),
    ("v 0 0 0\nvx 1 0 0\n", "line", r"bad.obj: line 2: unknown statement 'vx'"),
    ("v 0 0 0\ncstype bspline\n", "cstype", r"line 2: free-form geometry"),
]


@pytest.mark.parametrize(("text", "field", "pattern"), BAD_OBJ)
def test_bad_obj_errors(tmp_path: Path, text: str, field: str, pattern: str) -> None:
    path = write(tmp_path / "bad.obj", text)
    with pytest.raises(MeshFormatError, match=pattern) as exc:
        read_obj(path)
    assert exc.value.source == str(path)
    assert exc.value.field == field


def test_binary_garbage_is_a_format_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.obj"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe")
    with pytest.raises(MeshFormatError, match=r"bad.obj: line 1: unknown statement"):
        read_obj(path)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_fuzz_corrupted_obj_loads_or_raises_format_error(
    tmp_path: Path, data: st.DataObject
) -> None:
    raw = bytearray(QUAD_OBJ.encode())
    n_edits = data.draw(st.integers(1, 6))
    for _ in range(n_edits):
        op = data.draw(st.sampled_from(["set", "insert", "delete", "truncate"]))
        pos = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if op == "set" and raw:
            raw[pos] = data.draw(st.integers(0, 255))
        elif op == "insert":
            raw[pos:pos] = data.draw(st.binary(min_size=1, max_size=8))
        elif op == "delete" and raw:
            del raw[pos : pos + data.draw(st.integers(1, 8))]
        elif op == "truncate":
            del raw[pos:]
    path = tmp_path / "fuzz.obj"
    path.write_bytes(bytes(raw))
    try:
        face = read_obj(path)
    except MeshFormatError as exc:
        assert exc.source == str(path)
        return
    assert face.vertices.shape[1] == 3 and np.isfinite(face.vertices).all()
    assert face.polygons.indices.max() < face.n_vertices


# ---- folder of OBJs ---------------------------------------------------------------

QUADS = [[0, 1, 4, 3], [1, 2, 5, 4]]


def make_folder(
    root: Path, shapes: dict[str, np.ndarray], neutral_name: str = "neutral.obj"
) -> Path:
    root.mkdir(exist_ok=True)
    write(root / neutral_name, obj_text(QUAD_V[:6], QUADS))
    for fname, V in shapes.items():
        write(root / fname, obj_text(V, QUADS))
    return root


def test_folder_gives_deltas(tmp_path: Path) -> None:
    smile = QUAD_V[:6].copy()
    smile[4, 1] += 0.25
    blink = QUAD_V[:6].copy()
    blink[0, 2] -= 0.5
    folder = make_folder(tmp_path / "f", {"mouthSmileLeft.obj": smile, "eyeBlink_L.obj": blink})
    face = read_obj_folder(folder)
    assert face.shape_names == ["eyeBlink_L", "mouthSmileLeft"]
    d = dict(face.shapes)
    assert d["mouthSmileLeft"].dtype == np.float32
    expected = np.zeros((6, 3), np.float32)
    expected[4, 1] = 0.25
    np.testing.assert_array_equal(d["mouthSmileLeft"], expected)
    assert d["eyeBlink_L"][0, 2] == -0.5 and np.count_nonzero(d["eyeBlink_L"]) == 1
    assert face.source_files[0].endswith("neutral.obj")
    # read_any picks the folder reader
    assert read_any(folder).shape_names == face.shape_names


def test_folder_base_obj_and_explicit_neutral(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "f", {"jawOpen.obj": QUAD_V[:6] + 1}, neutral_name="Base.OBJ")
    assert read_obj_folder(folder).shape_names == ["jawOpen"]
    other = make_folder(
        tmp_path / "g", {"rest.obj": QUAD_V[:6], "jawOpen.obj": QUAD_V[:6] + 1}, "x.obj"
    )
    face = read_obj_folder(other, neutral="rest.obj")
    assert sorted(face.shape_names) == ["jawOpen", "x"]
    np.testing.assert_array_equal(dict(face.shapes)["jawOpen"], np.ones((6, 3), np.float32))


def test_folder_without_neutral_lists_candidates(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "f", {"a.obj": QUAD_V[:6]}, neutral_name="b.obj")
    with pytest.raises(MeshFormatError, match=r"no neutral mesh.*candidates: a.obj, b.obj") as exc:
        read_obj_folder(folder)
    assert exc.value.field == "neutral"
    with pytest.raises(MeshFormatError, match=r"neutral 'zz.obj' not found"):
        read_obj_folder(folder, neutral="zz.obj")


def test_folder_ambiguous_neutral(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "f", {"base.obj": QUAD_V[:6]})
    with pytest.raises(MeshFormatError, match=r"ambiguous neutral: base.obj, neutral.obj"):
        read_obj_folder(folder)


def test_folder_shape_with_other_vertex_count(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "f", {})
    write(folder / "jawOpen.obj", obj_text(QUAD_V[:6], QUADS) + "v 5 5 5\n")
    with pytest.raises(
        MeshFormatError, match=r"jawOpen.obj: has 7 vertices but the neutral neutral.obj has 6"
    ) as exc:
        read_obj_folder(folder)
    assert exc.value.source == str(folder / "jawOpen.obj") and exc.value.field == "v"


def test_folder_shape_with_other_faces(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "f", {})
    write(folder / "jawOpen.obj", obj_text(QUAD_V[:6], [[0, 1, 4, 3], [1, 2, 5]]))
    with pytest.raises(
        MeshFormatError,
        match=r"jawOpen.obj: faces differ from the neutral neutral.obj \(face 1 is \[1, 2, 5\] vs \[1, 2, 5, 4\]\)",
    ):
        read_obj_folder(folder)


@pytest.mark.parametrize(
    ("a", "b", "why"),
    [
        ("Smile.obj", "smile.OBJ", "same name ignoring case"),
        ("eyeBlinkLeft.obj", "EyeBlink_L.obj", "both are ARKit 'eyeBlinkLeft'"),
    ],
)
def test_folder_duplicate_shape_names(tmp_path: Path, a: str, b: str, why: str) -> None:
    folder = make_folder(tmp_path / "f", {a: QUAD_V[:6], b: QUAD_V[:6]})
    if len(list(folder.iterdir())) < 3:
        pytest.skip("case-insensitive file system")
    with pytest.raises(MeshFormatError, match=f"duplicate shape name: .*{why}") as exc:
        read_obj_folder(folder)
    assert exc.value.field == "shape names"


def test_folder_bad_shape_file_names_that_file(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "f", {})
    write(
        folder / "jawOpen.obj",
        obj_text(QUAD_V[:6], QUADS).replace("v 1.0 1.0 0.0", "v 1.0 1.0 nan"),
    )
    with pytest.raises(MeshFormatError, match=r"^jawOpen.obj: line 5: row 4 is not finite"):
        read_obj_folder(folder)


def test_read_any_unsupported_lists_inputs(tmp_path: Path) -> None:
    p = write(tmp_path / "face.fbx", "nope")
    with pytest.raises(MeshFormatError) as exc:
        read_any(p)
    msg = str(exc.value)
    assert "face.fbx: not a supported face input" in msg
    for line in supported_inputs():
        assert line in msg
    assert any(".glb" in s for s in supported_inputs()) and any(
        ".target" in s for s in supported_inputs()
    )
    with pytest.raises(FileNotFoundError):
        read_any(tmp_path / "missing.obj")


def test_registry_custom_reader_wins_by_name(tmp_path: Path) -> None:
    from workbench.io import registry

    calls: list[Path] = []

    def fake_read(p: Path) -> registry.ImportedFace:
        calls.append(p)
        return read_obj(tmp_path / "q.obj")

    write(tmp_path / "q.obj", QUAD_OBJ)
    p = write(tmp_path / "x.myfmt", "")
    saved = list(registry._READERS)
    try:
        registry.register_reader(
            "myfmt", lambda p: p.suffix == ".myfmt", fake_read, "a .myfmt file"
        )
        assert read_any(p).n_vertices == 9
        assert calls == [p]
        assert "myfmt: a .myfmt file" in supported_inputs()
    finally:
        registry._READERS[:] = saved
