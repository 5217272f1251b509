"""OBJ reader and folder-of-OBJs reader: tiny fixtures written in tmp_path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io import obj as obj_module
from workbench.io import obj_folder as folder_module
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
    p = write(tmp_path / "face.ply", "nope")
    with pytest.raises(MeshFormatError) as exc:
        read_any(p)
    msg = str(exc.value)
    assert "face.ply: not a supported face input" in msg
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


# ---- the fast (vectorised) parser reads exactly what the line parser reads ---------------

def blender_obj(V: np.ndarray, quads: list[list[int]], fmt: str = "{:.6f}", eol: str = "\n") -> str:
    """An OBJ as Blender writes it: o, v, vt, vn, s, usemtl, f v/vt/vn."""
    lines = ["# Blender v4.2 OBJ File", "mtllib face.mtl", "o Head"]
    lines += ["v " + " ".join(fmt.format(c) for c in row) for row in V.tolist()]
    lines += [f"vt {i / len(V):.6f} 0.500000" for i in range(len(V))]
    lines += ["vn 0.0000 0.0000 1.0000"]
    lines += ["s 0", "usemtl skin"]
    lines += ["f " + " ".join(f"{k + 1}/{k + 1}/1" for k in q) for q in quads]
    return eol.join(lines) + eol


def grid(n: int = 6, seed: int = 0) -> tuple[np.ndarray, list[list[int]]]:
    rng = np.random.default_rng(seed)
    jj, ii = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    V = np.stack([ii.ravel(), jj.ravel(), rng.normal(size=n * n) * 0.1], axis=1) * 1.5 - 3.0
    quads = [
        [j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i]
        for j in range(n - 1)
        for i in range(n - 1)
    ]
    return V, quads


def assert_same_face(a, b) -> None:
    np.testing.assert_array_equal(a.vertices, b.vertices)
    assert np.array_equal(np.signbit(a.vertices), np.signbit(b.vertices))
    assert a.polygons.equals(b.polygons)
    assert a.group_names == b.group_names
    if a.face_groups is None:
        assert b.face_groups is None
    else:
        np.testing.assert_array_equal(a.face_groups, b.face_groups)


def line_parser(data: bytes, source: str = "x.obj"):
    return obj_module._parse_lines(obj_module._decode(data), source)


V6, Q6 = grid()
FAST_CASES = {
    "blender": blender_obj(V6, Q6),
    "repr floats with exponents": blender_obj(V6 * 1e-5, Q6, fmt="{!r}"),
    "mixed decimals": obj_text(np.round(V6, 3), Q6),
    "crlf": blender_obj(V6, Q6, eol="\r\n"),
    "signs, .5 and 5.": "v +1.5 .5 -0.0\nv 2. -.25 +0\nv 0 1 0.\nf 1 2 3\n",
    "tabs and trailing blanks": "v\t0 0 0 \t\nv 1\t0\t0\nv 0 1 0   \nf\t1 2\t3  \n",
    "w and colours": "v 0 0 0 1\nv 1 0 0 0.5 0.5 0.5\nv 0 1 0 1 0.2 0.2 0.2\nf 1 2 3\n",
    "v//vn and v/vt": "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nf 1//1 2//1 4//1\nf 1/1 4/1 3/1\n",
    "relative indices, groups again, comments": (
        "# a\n\nv 0 0 0\nv 1 0 0\nv 0 1 0\ng a b\nf -3 -2 -1\no eye\n#x\nv 0 0 1\nv 1 0 1\n"
        "v 0 1 1\nf -3 -2 -1\ng a b\nf 1 2 6\ng\nf 4 5 3"
    ),
    "utf-8 group name": "v 0 0 0\nv 1 0 0\nv 0 1 0\ng Zähne\nf 1 2 3\n",
    "vt at the end of a file": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nvt",
}


@pytest.mark.parametrize("name", list(FAST_CASES))
def test_fast_parser_agrees_with_the_line_parser(name: str) -> None:
    data = FAST_CASES[name].encode()
    fast, template = obj_module._parse(data, "x.obj")
    assert template is not None, "expected the vectorised parser to read this file"
    assert_same_face(fast, line_parser(data))


@pytest.mark.parametrize(
    "text",
    [
        "  v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",  # an indented statement
        "v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\r",  # old Mac line ends
        "v 0 0 0\nv 1 0 0\nv 0 1 0\x0cf 1 2 3\n",  # a form feed ends a line for str.splitlines
        "v 0 0 0\nv 1 0 0\nv 0 1 0\ng caf\xe9\nf 1 2 3\n",  # Latin-1
    ],
)
def test_unusual_files_are_read_by_the_line_parser(text: str) -> None:
    data = text.encode("latin-1")
    face, template = obj_module._parse(data, "x.obj")
    assert_same_face(face, line_parser(data))
    if "\xe9" not in text:
        assert template is None


ALPHABET = b"0123456789.-+/ \t\r\nvftne#g"


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_fuzz_fast_parser_gives_the_line_parsers_result_or_error(data: st.DataObject) -> None:
    base = FAST_CASES[data.draw(st.sampled_from(list(FAST_CASES)))].encode()
    raw = bytearray(base)
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        op = data.draw(st.sampled_from(["set", "insert", "delete"]))
        byte = data.draw(st.sampled_from(list(ALPHABET)))
        if op == "set" and raw:
            raw[pos] = byte
        elif op == "insert":
            raw[pos:pos] = bytes([byte])
        elif op == "delete" and raw:
            del raw[pos : pos + data.draw(st.integers(1, 4))]
    blob = bytes(raw)
    try:
        expected = line_parser(blob)
    except MeshFormatError as exc:
        with pytest.raises(MeshFormatError) as got:
            obj_module.parse_obj_bytes(blob, "x.obj")
        assert (str(got.value), got.value.field) == (str(exc), exc.field)
        return
    assert_same_face(obj_module.parse_obj_bytes(blob, "x.obj"), expected)


# ---- folder: faces parsed once, v lines that did not move not converted again ------------


def blender_folder(root: Path, n_shapes: int = 4, n: int = 8) -> tuple[Path, np.ndarray, dict]:
    """neutral.obj + shapes moving a patch (other v lines written as in the neutral)."""
    root.mkdir()
    V, Q = grid(n, seed=1)
    (root / "neutral.obj").write_text(blender_obj(V, Q))
    rng = np.random.default_rng(2)
    shapes = {}
    for k in range(n_shapes):
        S = V.copy()
        moved = rng.choice(len(V), size=len(V) // (k + 2), replace=False)
        S[moved, 2] += rng.normal(size=moved.size) * 0.05
        # a same-length rewrite: -0.5 -> -0.4 keeps the line length
        S[0, 0] = V[0, 0] + (0.1 if k == 1 else 0.0)
        shapes[f"shape{k}"] = S
        (root / f"shape{k}.obj").write_text(blender_obj(S, Q))
    return root, V, shapes


def reference_folder(folder: Path) -> dict[str, np.ndarray]:
    """Deltas as the line parser reads each file (the reader's meaning, file by file)."""
    base = line_parser((folder / "neutral.obj").read_bytes()).vertices
    return {
        p.stem: (line_parser(p.read_bytes()).vertices - base).astype(np.float32)
        for p in sorted(folder.glob("*.obj"))
        if p.stem != "neutral"
    }


def test_folder_fast_path_matches_the_line_parser(tmp_path: Path, monkeypatch) -> None:
    folder, _, _ = blender_folder(tmp_path / "f")
    calls: list[Path] = []
    full = folder_module._read_full
    monkeypatch.setattr(folder_module, "_read_full", lambda p, *a: calls.append(p) or full(p, *a))
    ref = reference_folder(folder)
    for workers in (1, 3):
        face = read_obj_folder(folder, workers=workers)
        assert calls == []  # every shape file took the fast path
        assert face.shape_names == list(ref)
        for name, delta in face.shapes:
            np.testing.assert_array_equal(delta, ref[name])


def test_folder_shapes_written_differently_are_parsed_in_full(tmp_path: Path) -> None:
    folder, V, _ = blender_folder(tmp_path / "f", n_shapes=1)
    _, Q = grid(8, seed=1)
    S = V + 0.25
    (folder / "other_writer.obj").write_text(obj_text(S, Q))  # f a b c d, no vt/vn, repr floats
    face = read_obj_folder(folder)
    np.testing.assert_array_equal(dict(face.shapes)["other_writer"], reference_folder(folder)["other_writer"])
    np.testing.assert_allclose(dict(face.shapes)["other_writer"], 0.25, atol=1e-6)


def test_folder_same_face_lines_but_other_relative_indices_differ(tmp_path: Path) -> None:
    folder = tmp_path / "f"
    folder.mkdir()
    write(folder / "neutral.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 2 0 0\nv 3 0 0\nv 2 1 0\nf -3 -2 -1\n")
    write(folder / "jawOpen.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv 3 0 0\nv 2 1 0\nf -3 -2 -1\nf -3 -2 -1\n")
    with pytest.raises(MeshFormatError, match=r"jawOpen.obj: line 8: face 1 \[3, 4, 5\] duplicates face 0"):
        read_obj_folder(folder)


def test_folder_collapsed_face_in_a_shape_is_an_error(tmp_path: Path) -> None:
    folder, V, _ = blender_folder(tmp_path / "f", n_shapes=1)
    _, Q = grid(8, seed=1)
    S = V.copy()
    S[Q[3][1]] = S[Q[3][0]]  # two corners of quad 3 on top of each other ...
    S[Q[3][2]] = S[Q[3][0]]  # ... and a third: zero area
    (folder / "blink.obj").write_text(blender_obj(S, Q))
    with pytest.raises(MeshFormatError, match=r"^blink.obj: line \d+: face 3 .* has zero area"):
        read_obj_folder(folder)


@pytest.mark.parametrize("workers", [1, 4])
def test_folder_reports_the_first_bad_file_by_name(tmp_path: Path, workers: int) -> None:
    folder = blender_folder(tmp_path / "f", n_shapes=6)[0]
    for name in ("shape4.obj", "shape2.obj"):
        text = (folder / name).read_text().replace("v ", "v nan ", 1)
        (folder / name).write_text(text)
    with pytest.raises(MeshFormatError, match=r"^shape2.obj: line 4: row 0 is not finite"):
        read_obj_folder(folder, workers=workers)
