"""MakeHuman .target reader on a tiny base OBJ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.makehuman_target import parse_target, read_targets
from workbench.io.registry import read_any

BASE_OBJ = """\
v 0 0 0
v 1 0 0
v 2 0 0
v 0 1 0
v 1 1 0
v 2 1 0
g skin
f 1 2 5 4
f 2 3 6 5
"""


def make_base(root: Path, targets: dict[str, str]) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "head.obj").write_text(BASE_OBJ)
    (root / "targets").mkdir(exist_ok=True)
    for name, text in targets.items():
        (root / "targets" / name).write_text(text)
    return root / "head.obj"


def test_reads_sparse_deltas(tmp_path: Path) -> None:
    obj = make_base(
        tmp_path / "m",
        {
            "jawOpen.target": "# comment\n4 0 -.25 0.5\n0 .125 0 0\n",
            "eyeBlinkLeft.target": "5 0 0 -1\n\n",
        },
    )
    face = read_targets(obj)
    assert face.shape_names == ["eyeBlinkLeft", "jawOpen"]  # folder order: sorted
    d = dict(face.shapes)
    expected = np.zeros((6, 3), np.float32)
    expected[4] = [0, -0.25, 0.5]
    expected[0] = [0.125, 0, 0]
    np.testing.assert_array_equal(d["jawOpen"], expected)
    assert d["jawOpen"].dtype == np.float32
    assert face.units == "dm" and face.up_axis == "+y"
    assert face.group_names == ["skin"]
    assert face.source_files[0] == str(obj) and len(face.source_files) == 3
    # the folder holding head.obj + targets/ is recognised by read_any
    assert read_any(tmp_path / "m").shape_names == face.shape_names


def test_explicit_target_list_keeps_order(tmp_path: Path) -> None:
    obj = make_base(tmp_path, {"b.target": "1 0 0 1\n", "a.target": "2 0 0 1\n"})
    face = read_targets(obj, [tmp_path / "targets" / "b.target", tmp_path / "targets" / "a.target"])
    assert face.shape_names == ["b", "a"]


BAD_TARGETS = [
    ("", "file", r"bad.target: empty target"),
    ("# just a header\n", "file", r"bad.target: empty target"),
    ("1 0 0\n", "delta", r"bad.target: line 1: expected 'vertex_index dx dy dz', got '1 0 0'"),
    ("1 0 0 0\n2 0 0 0 0\n", "delta", r"bad.target: line 2: expected 'vertex_index dx dy dz'"),
    ("1 0 0 0\n1.5 0 0 0\n", "index", r"bad.target: line 2: vertex index '1.5' is not an integer"),
    (
        "1 0 0 0\n6 0 0 0\n",
        "index",
        r"bad.target: line 2: vertex index 6 out of range \(base mesh has 6 vertices\)",
    ),
    ("-1 0 0 0\n", "index", r"line 1: vertex index -1 out of range"),
    (
        "3 0 0 0\n# c\n1 1 1 1\n3 0 0 1\n",
        "index",
        r"bad.target: line 4: vertex index 3 already given on line 1",
    ),
    ("1 0 x 0\n", "delta", r"bad.target: line 1: delta is not a number: '0 x 0'"),
    ("0 0 0 0\n1 0 nan 0\n", "delta", r"bad.target: line 2: row 1 is not finite"),
    ("1 0 0 inf\n", "delta", r"bad.target: line 1: row 0 is not finite"),
]


@pytest.mark.parametrize(("text", "field", "pattern"), BAD_TARGETS)
def test_bad_target(tmp_path: Path, text: str, field: str, pattern: str) -> None:
    p = tmp_path / "bad.target"
    p.write_text(text)
    with pytest.raises(MeshFormatError, match=pattern) as exc:
        parse_target(p, 6)
    assert exc.value.source == str(p) and exc.value.field == field


def test_bad_target_inside_read_targets_names_the_target(tmp_path: Path) -> None:
    obj = make_base(tmp_path, {"jawOpen.target": "1 0 0 0\n9 0 0 0\n"})
    with pytest.raises(
        MeshFormatError, match=r"^jawOpen.target: line 2: vertex index 9 out of range"
    ):
        read_targets(obj)


def test_duplicate_shape_names(tmp_path: Path) -> None:
    obj = make_base(
        tmp_path, {"mouthSmile_L.target": "1 0 0 1\n", "MouthSmileLeft.target": "1 0 0 1\n"}
    )
    with pytest.raises(
        MeshFormatError, match=r"duplicate shape name: .*both are ARKit 'mouthSmileLeft'"
    ):
        read_targets(obj)


def test_missing_targets_folder(tmp_path: Path) -> None:
    (tmp_path / "head.obj").write_text(BASE_OBJ)
    with pytest.raises(MeshFormatError, match=r"targets: targets folder not found"):
        read_targets(tmp_path / "head.obj")
    (tmp_path / "targets").mkdir()
    with pytest.raises(MeshFormatError, match=r"targets: no .target files in folder"):
        read_targets(tmp_path / "head.obj")


def test_bad_base_obj_is_reported(tmp_path: Path) -> None:
    obj = make_base(tmp_path, {"a.target": "1 0 0 1\n"})
    obj.write_text(BASE_OBJ.replace("f 2 3 6 5", "f 2 3 60 5"))
    with pytest.raises(MeshFormatError, match=r"^head.obj: line 9: face index 60 out of range"):
        read_targets(obj)
