"""USD import (workbench.io.usd): UsdSkel blend shapes + SkelAnimation weights from two real writers.

* usd-core (Pixar's library) writes the source head (``tests/tools/format_writers.py``)
  the way the UsdSkel docs lay it out: centimetres, y up, sparse BlendShapes
  (``pointIndices``), one Skeleton whose ``skel:animationSource`` is a
  SkelAnimation with a weights sample per frame;
* Blender 5.0's USD exporter (bpy) writes the same animated head: metres, z up,
  dense offsets, one SkelRoot + Skeleton + SkelAnimation per object.

Both must give the source geometry, deltas, names and the keyed weights, and
agree with each other. The corpus (>= 50 edits of the usda text: truncated
layers, missing/NaN/mistyped attributes, wrong counts, out-of-range and
duplicate indices, bad targets, bad units) is refused naming the file, the prim
path and the attribute.
"""

from __future__ import annotations

import logging
import re
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from ci_env import in_ci

from workbench.animation.importers import AnimationImportError
from workbench.cli import main
from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io import load
from workbench.io.usd import read_usd, read_usd_animation

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))
import format_writers as fw


@pytest.fixture(scope="session")
def pxr_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return fw.write_usdskel(tmp_path_factory.mktemp("usd") / "face.usda")


@pytest.fixture(scope="session")
def blender_usd() -> Path:
    try:
        return fw.blender_files()["usd"]
    except fw.ToolMissing as exc:
        if in_ci():
            pytest.fail(f"{exc} is missing under CI=true", pytrace=False)
        pytest.skip(str(exc))


def _check_face(face, scale: float, atol: float) -> None:
    """Each group equals its source object (scaled from decimetres), shapes included."""
    src = fw.face_source()
    offset = 0
    by_name = {o.name: o for o in src.objects}
    assert sorted(face.group_names) == sorted(by_name)
    shapes = dict(face.shapes)
    assert set(shapes) == set(fw.SHAPES)
    for g in face.group_names:
        o = by_name[g]
        n = o.vertices.shape[0]
        rows = slice(offset, offset + n)
        np.testing.assert_allclose(face.vertices[rows], o.vertices * scale, atol=atol, rtol=0, err_msg=g)
        for s in fw.SHAPES:
            want = o.deltas.get(s, np.zeros_like(o.vertices)) * scale
            np.testing.assert_allclose(shapes[s][rows], want, atol=atol, rtol=0, err_msg=f"{g} {s}")
        offset += n
    assert offset == face.n_vertices


def test_pxr_writer_file(pxr_file: Path) -> None:
    face = read_usd(pxr_file)
    assert face.units == "cm" and face.up_axis == "+y"
    assert face.group_names == ["Head", "Mouth"] and face.shape_names == list(fw.SHAPES)
    _check_face(face, 10.0, 2e-5)


def test_dense_offsets_and_metres(tmp_path: Path, pxr_file: Path) -> None:
    dense = read_usd(fw.write_usdskel(tmp_path / "dense.usda", sparse=False))
    sparse = read_usd(pxr_file)
    for (a, da), (b, db) in zip(dense.shapes, sparse.shapes, strict=True):
        assert a == b
        np.testing.assert_array_equal(da, db)
    metres = read_usd(fw.write_usdskel(tmp_path / "m.usdc", meters_per_unit=1.0))
    assert metres.units == "m"
    _check_face(metres, 0.1, 2e-6)


def test_pxr_weights_at_every_frame(pxr_file: Path) -> None:
    src = fw.face_source()
    tl = read_usd_animation(pxr_file, list(fw.SHAPES))
    assert tl.fps == fw.FPS and tl.end == pytest.approx(fw.LAST_FRAME / fw.FPS)
    for s in fw.SHAPES:
        tr = tl.tracks[f"weights/{s}"]
        assert len(tr) == fw.LAST_FRAME + 1 and set(tr.interpolations) == {"linear"}
        for f in range(fw.LAST_FRAME + 1):
            assert float(tr.evaluate(f / fw.FPS)) == pytest.approx(src.weight(s, f), abs=1e-6)


def test_blender_writer_file_and_agreement_with_ours(blender_usd: Path, pxr_file: Path) -> None:
    face = read_usd(blender_usd)
    assert face.units == "m" and face.up_axis == "+y"  # Blender writes Z up: turned y up
    _check_face(face, 0.1, 2e-6)
    tl = read_usd_animation(blender_usd, face.shape_names)
    src = fw.face_source()
    for s in fw.SHAPES:
        for f, v in fw.KEYS[s]:
            assert float(tl.tracks[f"weights/{s}"].evaluate(f / fw.FPS)) == pytest.approx(v, abs=1e-6)
        for f in range(fw.LAST_FRAME + 1):
            assert float(tl.tracks[f"weights/{s}"].evaluate(f / fw.FPS)) == pytest.approx(src.weight(s, f), abs=1e-6)
    ours = read_usd(pxr_file)
    for g in ("Head", "Mouth"):
        a = ours.vertices[_rows(ours, g)] * 0.01
        b = face.vertices[_rows(face, g)]
        np.testing.assert_allclose(a, b, atol=2e-6)


def _rows(face, g: str) -> np.ndarray:
    labels = np.full(face.n_vertices, -1)
    k = face.group_names.index(g)
    P = face.polygons
    for i in np.flatnonzero(face.face_groups == k):
        labels[P[i]] = k
    return labels == k


def test_inbetweens_are_ignored_with_a_note(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from pxr import Usd, UsdSkel, Vt

    p = fw.write_usdskel(tmp_path / "inb.usda")
    stage = Usd.Stage.Open(str(p))
    bs = UsdSkel.BlendShape(stage.GetPrimAtPath("/Face/Head/jawOpen"))
    n = len(bs.GetPointIndicesAttr().Get())
    bs.CreateInbetween("half").SetOffsets(Vt.Vec3fArray.FromNumpy(np.zeros((n, 3), np.float32)))
    bs.GetInbetween("half").SetWeight(0.5)
    stage.GetRootLayer().Save()
    with caplog.at_level(logging.INFO, logger="workbench.io"):
        face = read_usd(p)
    assert face.shape_names == list(fw.SHAPES)
    assert any("in-between" in r.getMessage() and "/Face/Head/jawOpen" in r.getMessage() for r in caplog.records)


def test_load_and_info(pxr_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = load(pxr_file)
    assert model.metadata.units == "cm"
    assert main(["info", str(pxr_file)]) == 0
    out = capsys.readouterr().out
    assert "units       cm (0.01 m per unit)" in out and "tongueOut" in out


# ---------------------------------------------------------------- the malformed corpus
Edit = Callable[[str], str]


def sub(pattern: str, repl: str, after: str = "") -> Edit:
    """Replace the first match of ``pattern`` (after the first ``after``)."""

    def edit(text: str) -> str:
        i = text.index(after) if after else 0
        head, tail = text[:i], text[i:]
        new, n = re.subn(pattern, repl, tail, count=1)
        assert n == 1, f"pattern {pattern!r} not found"
        return head + new

    return edit


HEAD = 'def Mesh "Head"'
JAW = 'def BlendShape "jawOpen"'
ANIM = 'def SkelAnimation "Anim"'


def _mesh_variants() -> dict[str, tuple[Edit, str]]:
    v: dict[str, tuple[Edit, str]] = {}
    for k, frac in enumerate(np.linspace(0.03, 0.97, 15)):
        v[f"truncated_{k:02d}"] = ((lambda f: lambda t: t[: int(len(t) * f)])(frac), "does not parse")
    v["empty"] = (lambda t: "", "does not parse")
    v["bad_header"] = (lambda t: t.replace("#usda 1.0", "#usda 9.9", 1), "does not parse")
    v["not_usd_text"] = (lambda t: "hello world {\n", "does not parse")
    v["points_nan"] = (sub(r"points = \[\([^)]*\)", "points = [(nan, 0, 0)", HEAD), "/Face/Head.points: element 0 is not finite")
    v["points_inf"] = (sub(r"points = \[\([^)]*\),", "points = [(1, 2, 3), (inf, 0, 0),", HEAD), "element 1 is not finite")
    v["points_scalar_floats"] = (sub(r"point3f\[\] points = \[[^\]]*\]", "float[] points = [1, 2, 3]", HEAD), "expected 3-vectors")
    v["points_missing"] = (sub(r"point3f\[\] points = \[[^\]]*\]", "", HEAD), "/Face/Head.points: missing")
    v["points_empty"] = (sub(r"point3f\[\] points = \[[^\]]*\]", "point3f[] points = []", HEAD), "/Face/Head.points: empty")
    v["counts_sum"] = (sub(r"faceVertexCounts = \[4,", "faceVertexCounts = [5,", HEAD), "add up to")
    v["counts_two"] = (sub(r"faceVertexCounts = \[4,", "faceVertexCounts = [2, 2,", HEAD), "at least 3")
    v["index_out_of_range"] = (sub(r"faceVertexIndices = \[\d+,", "faceVertexIndices = [999999,", HEAD), "out of range")
    v["index_negative"] = (sub(r"faceVertexIndices = \[\d+,", "faceVertexIndices = [-5,", HEAD), "out of range")
    v["indices_missing"] = (sub(r"int\[\] faceVertexIndices = \[[^\]]*\]", "", HEAD), "faceVertexIndices: missing")
    v["counts_missing"] = (sub(r"int\[\] faceVertexCounts = \[[^\]]*\]", "", HEAD), "faceVertexCounts: missing")
    v["indices_floats"] = (sub(r"int\[\] faceVertexIndices", "float[] faceVertexIndices", HEAD), "expected integers")
    v["indices_empty"] = (sub(r"int\[\] faceVertexIndices = \[[^\]]*\]", "int[] faceVertexIndices = []", HEAD), "add up to")
    v["counts_empty"] = (sub(r"int\[\] faceVertexCounts = \[[^\]]*\]", "int[] faceVertexCounts = []", HEAD), "no faces")
    v["shape_names_fewer"] = (sub(r', "cheekPuff"\]', "]", HEAD), "skel:blendShapeTargets has 5 targets")
    v["shape_targets_fewer"] = (sub(r"\s*</Face/Head/cheekPuff>,?", "", HEAD), "4 targets")
    v["target_missing_prim"] = (sub(r"</Face/Head/jawOpen>", "</Face/Head/nothing>", HEAD), "is not a prim of the stage")
    v["target_is_mesh"] = (sub(r"</Face/Head/jawOpen>", "</Face/Mouth>", HEAD), "not a BlendShape")
    v["shape_name_twice"] = (sub(r'"eyeBlinkLeft"', '"jawOpen"', HEAD), "names shape 'jawOpen' twice")
    v["shape_name_empty"] = (sub(r'"eyeBlinkLeft"', '""', HEAD), "a shape name is empty")
    v["offsets_missing"] = (sub(r"uniform vector3f\[\] offsets = \[[^\]]*\]", "", JAW), "jawOpen.offsets: missing")
    v["offsets_nan"] = (sub(r"offsets = \[\([^)]*\)", "offsets = [(nan, 0, 0)", JAW), "jawOpen.offsets: element 0 is not finite")
    v["offsets_fewer_than_indices"] = (sub(r"offsets = \[\([^)]*\), ", "offsets = [", JAW), "indices for")
    v["point_index_out_of_range"] = (sub(r"pointIndices = \[\d+", "pointIndices = [999999", JAW), "out of range")
    v["point_index_negative"] = (sub(r"pointIndices = \[\d+", "pointIndices = [-1", JAW), "out of range")
    v["point_index_duplicate"] = (sub(r"pointIndices = \[(\d+), \d+", r"pointIndices = [\1, \1", JAW), "more than once")
    v["dense_offsets_wrong_count"] = (sub(r"uniform int\[\] pointIndices = \[[^\]]*\]", "", JAW), "without pointIndices")
    v["offsets_wrong_type"] = (sub(r"uniform vector3f\[\] offsets = \[[^\]]*\]", "uniform float[] offsets = [1, 2]", JAW), "expected 3-vectors")
    v["meters_per_unit_zero"] = (sub(r"metersPerUnit = [0-9.]+", "metersPerUnit = 0"), "metersPerUnit: must be a positive")
    v["meters_per_unit_negative"] = (sub(r"metersPerUnit = [0-9.]+", "metersPerUnit = -1"), "metersPerUnit: must be a positive")
    v["up_axis_x"] = (sub(r'upAxis = "Y"', 'upAxis = "X"'), 'upAxis: must be "Y" or "Z"')
    v["zero_scale"] = (
        sub(r'(def Mesh "Head"[^{]*\{)', r'\1\n        float3 xformOp:scale = (0, 0, 0)\n        uniform token[] xformOpOrder = ["xformOp:scale"]'),
        "singular",
    )
    v["nan_translate"] = (
        sub(r'(def Mesh "Head"[^{]*\{)', r'\1\n        double3 xformOp:translate = (nan, 0, 0)\n        uniform token[] xformOpOrder = ["xformOp:translate"]'),
        "not finite",
    )
    v["orientation_unknown"] = (sub(r'(def Mesh "Head"[^{]*\{)', r'\1\n        uniform token orientation = "sideways"'), "must be rightHanded or leftHanded")
    v["no_meshes"] = (lambda t: t.replace("def Mesh", "def Xform"), "no Mesh prim")
    v["all_invisible"] = (lambda t: re.sub(r'(def Mesh "\w+"[^{]*\{)', r'\1\n        token visibility = "invisible"', t), "no Mesh prim")
    return v


def _anim_variants() -> dict[str, tuple[Edit, str]]:
    return {
        "weights_short": (sub(r"0: \[0, 0, 0.5, 0, 0.2, 0\]", "0: [0, 0, 0.5, 0, 0.2]"), "has 5 weights, blendShapes names 6"),
        "weights_nan": (sub(r"0: \[0, 0, 0.5", "0: [nan, 0, 0.5"), "weight 0 ('jawOpen') is not finite"),
        "anim_tokens_missing": (sub(r"uniform token\[\] blendShapes = \[[^\]]*\]", "", ANIM), "blendShapes: missing"),
        "anim_tokens_twice": (sub(r'"eyeBlinkLeft"', '"jawOpen"', ANIM), "names a shape twice"),
        "time_codes_zero": (sub(r"timeCodesPerSecond = 30", "timeCodesPerSecond = 0"), "timeCodesPerSecond: must be > 0"),
        "source_not_anim": (sub(r"skel:animationSource = </Face/Skel/Anim>", "skel:animationSource = </Face/Head>"), "is not a SkelAnimation"),
        "no_animation": (lambda t: t.replace(ANIM, 'def Scope "Anim"').replace("rel skel:animationSource = </Face/Skel/Anim>", ""), "no SkelAnimation"),
    }


@pytest.fixture(scope="session")
def usda_text(pxr_file: Path) -> str:
    return pxr_file.read_text()


MESH_VARIANTS = sorted(_mesh_variants())
ANIM_VARIANTS = sorted(_anim_variants())


def test_corpus_is_large_enough() -> None:
    assert len(MESH_VARIANTS) + len(ANIM_VARIANTS) >= 50


@pytest.mark.parametrize("name", MESH_VARIANTS)
def test_malformed_stage_is_refused(name: str, usda_text: str, tmp_path: Path) -> None:
    edit, expected = _mesh_variants()[name]
    p = tmp_path / f"{name}.usda"
    p.write_text(edit(usda_text))
    with pytest.raises(MeshFormatError) as ei:
        read_usd(p)
    msg = str(ei.value)
    assert msg.startswith(f"{p.name}: "), msg
    assert expected in msg, msg


@pytest.mark.parametrize("name", ANIM_VARIANTS)
def test_malformed_animation_is_refused(name: str, usda_text: str, tmp_path: Path) -> None:
    edit, expected = _anim_variants()[name]
    p = tmp_path / f"{name}.usda"
    p.write_text(edit(usda_text))
    read_usd(p)  # the geometry itself is fine
    with pytest.raises(AnimationImportError) as ei:
        read_usd_animation(p, list(fw.SHAPES))
    msg = str(ei.value)
    assert msg.startswith(f"{p.name}: "), msg
    assert expected in msg, msg
