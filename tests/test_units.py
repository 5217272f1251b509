"""Unit inference for files without a unit (workbench/io/units.py), overrides, glTF, ``info``.

The hand-worked cases use boxes whose longest side is chosen by hand; the head
cases use a face the sample has not seen: the sample head converted to metres,
warped smoothly, stretched, re-triangulated along the other diagonals and
written as OBJ in each unit.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.animation.tracks import Timeline
from workbench.cli import format_info, main
from workbench.export import export
from workbench.io.units import HEAD_SIZE, UNITS, decide_units, infer_units, unit_name


def box(x: float, y: float, z: float) -> np.ndarray:
    """The 8 corners of an x by y by z box with a corner at (1, 2, 3) (units of the file)."""
    c = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
    return c * [x, y, z] + [1.0, 2.0, 3.0]


# ---- hand-worked: a head of 0.18 x 0.25 x 0.21 m (longest side 0.25 m) in each unit --------
#   mm: 250       -> 0.25 m; cm would be 2.5 m, in 6.35 m                   -> mm
#   cm: 25        -> 0.25 m; in would be 0.635 m, mm 0.025 m                 -> cm
#   in: 9.843     -> 0.25 m; cm would be 0.098 m (< 0.12), dm 0.98 m         -> in
#   dm: 2.5       -> 0.25 m; in would be 0.0635 m, m 2.5 m                   -> dm
#   m:  0.25      -> 0.25 m; dm would be 0.025 m                             -> m
HEAD_M = (0.18, 0.25, 0.21)


@pytest.mark.parametrize("unit", ["mm", "cm", "in", "dm", "m"])
def test_a_head_in_each_unit_is_inferred(unit: str) -> None:
    f = UNITS[unit]
    d = infer_units(box(*(s / f for s in HEAD_M)))
    assert d.unit == unit and d.how == "inferred" and not d.doubtful
    assert d.size == pytest.approx(0.25 / f)
    assert f"head in {unit}" in d.detail and "0.25 m" in d.detail


def test_the_issue_head_in_centimetres() -> None:
    # the issue: info reported a 25 x 34 x 22 m head; in cm it is 0.34 m long, in inches 0.86 m
    d = infer_units(box(25, 34, 22))
    assert (d.unit, d.how) == ("cm", "inferred")
    assert "34 units, is a 0.34 m head in cm" in d.detail


@pytest.mark.parametrize(
    ("longest", "unit", "other"),
    [
        # 17 units: cm -> 0.17 m (|ln(0.17/0.25)| = 0.386), in -> 0.432 m (0.547): cm
        (17.0, "cm", "in"),
        # 13 units: cm -> 0.13 m (0.654), in -> 0.330 m (0.278): in
        (13.0, "in", "cm"),
        # 4.75 units: in -> 0.121 m (0.728), dm -> 0.475 m (0.642): dm
        (4.75, "dm", "in"),
    ],
)
def test_two_plausible_units_are_ambiguous(longest: float, unit: str, other: str) -> None:
    d = infer_units(box(longest * 0.6, longest, longest * 0.8))
    assert (d.unit, d.how, d.doubtful) == (unit, "ambiguous", True)
    assert f"head in {unit} or a" in d.detail and f"head in {other}" in d.detail
    assert f"pass units={other!r}" in d.detail


@pytest.mark.parametrize(
    ("longest", "why"),
    [
        (0.05, "too small for a head in any of mm, cm, in, dm, m: 5 cm even in metres"),
        (0.0, "too small"),
        (2000.0, "too large for a head in any of mm, cm, in, dm, m: 2 m even in millimetres"),
        (0.8, "between head sizes: 0.8 m in m, 8 cm in dm"),
        (80.0, "between head sizes: 0.8 m in cm, 8 cm in mm"),
    ],
)
def test_tiny_huge_and_in_between_meshes_are_assumed_metres(longest: float, why: str) -> None:
    d = infer_units(box(longest, longest / 2, longest / 3))
    assert (d.unit, d.how, d.doubtful) == ("m", "assumed", True)
    assert why in d.detail and "pass units= to set it" in d.detail


def test_band_edges_are_head_sized() -> None:
    lo, hi = HEAD_SIZE
    assert infer_units(box(lo, lo / 2, lo / 2)).unit == "m"
    assert infer_units(box(hi, hi / 2, hi / 2)).unit == "m"


def test_given_unit_wins_and_stated_unit_is_never_inferred() -> None:
    V = box(25, 34, 22)  # cm by its size
    assert decide_units(V, given="mm").unit == "mm"
    d = decide_units(V, stated="m", given="Inches")
    assert (d.unit, d.how) == ("in", "given") and "the file states m" in d.detail
    stated = decide_units(V, stated="m")
    assert (stated.unit, stated.how, stated.doubtful) == ("m", "file", True)
    assert "not head-sized in m" in stated.detail and "pass units='cm'" in stated.detail
    fine = decide_units(box(0.18, 0.25, 0.2), stated="m")
    assert (fine.unit, fine.doubtful) == ("m", False)


def test_unit_names() -> None:
    assert [unit_name(n) for n in ("Metres", "centimeter", " MM ", "inch", "dm")] == [
        "m",
        "cm",
        "mm",
        "in",
        "dm",
    ]
    with pytest.raises(ValueError, match=r"units: expected one of \['cm', 'dm', 'in', 'm', 'mm'\].*'furlong'"):
        unit_name("furlong")


def test_decisions_are_logged(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="workbench.io"):
        decide_units(box(25, 34, 22), source="face.obj")
        decide_units(box(10, 17, 12), source="odd.obj")
    (info, warning) = caplog.records
    assert info.levelno == logging.INFO
    assert info.getMessage().startswith("face.obj: units: centimetres, inferred")
    assert warning.levelno == logging.WARNING and "ambiguous" in warning.getMessage()


# ---- a face the sample has not seen, through workbench.load and workbench info ------------


def unseen_head() -> tuple[np.ndarray, np.ndarray]:
    """(V in metres, triangles): the sample head warped, stretched and re-triangulated."""
    sample = workbench.load_sample("head")
    V = sample.vertices.astype(np.float64) * sample.metadata.metres_per_unit
    c = V.mean(axis=0)
    x, y, z = (V - c).T
    V = np.stack(
        [
            1.1 * x + 0.004 * np.sin(40 * y),
            0.85 * y + 0.006 * np.cos(25 * x) * np.exp(-((z - 0.05) ** 2) / 0.01),
            1.05 * z + 0.003 * np.sin(30 * x + 20 * y),
        ],
        axis=1,
    )
    P = sample.polygons
    tris = []
    for i in range(len(P)):
        q = P[i].tolist()
        if len(q) == 4:  # the other diagonal than the sample's fan
            tris += [[q[0], q[1], q[3]], [q[1], q[2], q[3]]]
        else:
            tris += [[q[0], q[k], q[k + 1]] for k in range(1, len(q) - 1)]
    return V, np.array(tris)


def write_obj(path: Path, V: np.ndarray, F: np.ndarray) -> Path:
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in V.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F.tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def head() -> tuple[np.ndarray, np.ndarray]:
    return unseen_head()


@pytest.mark.parametrize("unit", ["mm", "cm", "in", "dm", "m"])
def test_load_infers_the_unit_of_an_unseen_head(
    tmp_path: Path, head: tuple[np.ndarray, np.ndarray], unit: str
) -> None:
    V_m, F = head
    longest = float(np.ptp(V_m, axis=0).max())
    assert 0.2 < longest < 0.3  # still a head-sized head after the stretch
    path = write_obj(tmp_path / f"head_{unit}.obj", V_m / UNITS[unit], F)
    model = workbench.load(path)
    assert model.metadata.units == unit
    assert math.isclose(model.metadata.metres_per_unit, UNITS[unit])
    # recorded, not rescaled: the coordinates are the file's
    np.testing.assert_allclose(model.vertices, V_m / UNITS[unit], rtol=1e-8)
    (entry,) = [p for p in model.metadata.provenance if p.get("operation") == "units"]
    assert entry["units"] == unit and entry["how"] == "inferred"


def test_override_wins_on_load(tmp_path: Path, head: tuple[np.ndarray, np.ndarray]) -> None:
    V_m, F = head
    path = write_obj(tmp_path / "head_cm.obj", V_m * 100, F)
    model = workbench.load(path, units="millimetres")
    assert model.metadata.units == "mm"
    np.testing.assert_allclose(model.vertices, V_m * 100, rtol=1e-8)
    with pytest.raises(ValueError, match="units: expected one of"):
        workbench.load(path, units="furlong")


def test_centimetre_head_exports_at_its_real_size(
    tmp_path: Path, head: tuple[np.ndarray, np.ndarray]
) -> None:
    """The issue's symptom: a cm head exported 100x too large. Now the .glb is in metres."""
    V_m, F = head
    model = workbench.load(write_obj(tmp_path / "head_cm.obj", V_m * 100, F))
    (glb,) = export(model, Timeline(), tmp_path / "head.glb")
    back = workbench.load(glb)
    assert back.metadata.units == "m"
    np.testing.assert_allclose(back.vertices, V_m, atol=1e-6)


def test_gltf_is_never_rescaled_or_inferred(
    tmp_path: Path, head: tuple[np.ndarray, np.ndarray], caplog: pytest.LogCaptureFixture
) -> None:
    V_m, F = head
    # an exporter that wrote centimetres into a glTF (metres by the spec): a 25 m head
    model = workbench.load(write_obj(tmp_path / "head_cm.obj", V_m * 100, F), units="m")
    (glb,) = export(model, Timeline(), tmp_path / "big.glb")
    with caplog.at_level(logging.INFO, logger="workbench.io"):
        back = workbench.load(glb)
    assert back.metadata.units == "m"
    np.testing.assert_allclose(back.vertices, V_m * 100, rtol=1e-6)  # as in the file
    (entry,) = [p for p in back.metadata.provenance if p.get("operation") == "units"]
    assert entry["how"] == "file"
    assert "pass units='cm'" in entry["detail"]
    assert any(r.levelno == logging.WARNING and "not head-sized in m" in r.getMessage() for r in caplog.records)
    # a correct glTF: metres, no warning
    (ok,) = export(workbench.load(write_obj(tmp_path / "h.obj", V_m, F)), Timeline(), tmp_path / "ok.glb")
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="workbench.io"):
        assert workbench.load(ok).metadata.units == "m"
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    # an explicit override is still honoured
    assert workbench.load(glb, units="cm").metadata.units == "cm"


def test_info_says_how_the_unit_was_found(
    tmp_path: Path, head: tuple[np.ndarray, np.ndarray], capsys: pytest.CaptureFixture[str]
) -> None:
    V_m, F = head
    path = write_obj(tmp_path / "head_cm.obj", V_m * 100, F)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "units       cm (0.01 m per unit)" in out
    assert "units from  inferred: centimetres, inferred from the size" in out
    size = next(line for line in out.splitlines() if line.startswith("  size"))
    assert size.endswith(" m)") and " cm (0." in size
    assert "operation=units" not in out  # shown once, under units


def test_inches_survive_save_and_load(tmp_path: Path, head: tuple[np.ndarray, np.ndarray]) -> None:
    V_m, F = head
    model = workbench.load(write_obj(tmp_path / "head_in.obj", V_m / 0.0254, F))
    assert model.metadata.units == "in"
    model.save(tmp_path / "h.fwb")
    back = workbench.load(tmp_path / "h.fwb")
    assert back.metadata.units == "in" and back.metadata.metres_per_unit == 0.0254
    assert "units from  inferred: inches" in format_info(back, "h.fwb")
