"""ExportPanel (widgets/panels/export.py): the CSV layout choice, the writer's notes, importing back.

Driven from Python (dropdowns set, buttons clicked); the checks are on the files
written and on ``model.timeline`` after an import.
"""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("anywidget")

import ipywidgets as W

import workbench
from widgets.panels import ExportPanel
from workbench.animation.curves import head_euler_from_rotation, head_rotation_from_euler
from workbench.model import FaceModel

pytestmark = pytest.mark.ui

CSV = "CSV weights (.csv)"


def _errors(out: W.Output) -> str:
    return "".join(o.get("text", "") for o in out.outputs)


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _keyed_take(model: FaceModel) -> list[tuple[float, float, float]]:
    """jawOpen and a turning head keyed at 0, 0.5, 1 s (30 fps); the (yaw, pitch, roll) keyed."""
    md = model.metadata
    angles = [(25.0, 8.0, -4.0), (-15.0, -6.0, 10.0), (5.0, 3.0, 1.0)]
    for t, (y, p, r), jaw in zip((0.0, 0.5, 1.0), angles, (0.0, 0.8, 0.2), strict=True):
        model.set_weight("jawOpen", jaw)
        model.timeline.key_weights(t, ["jawOpen"])
        q = head_rotation_from_euler(y, p, r, up_axis=md.up_axis, front_axis=md.front_axis)
        model.timeline.key_head_pose(t, rotation=q)
    return angles


def _head_angles(model: FaceModel, times: np.ndarray) -> np.ndarray:
    md = model.metadata
    P = model.tracks.head_pose.sample(times)
    return np.array(
        [head_euler_from_rotation(q, up_axis=md.up_axis, front_axis=md.front_axis) for q in P[:, 3:]]
    )


@pytest.fixture
def head() -> FaceModel:
    return workbench.load_sample("head")


def test_csv_layout_is_offered_only_for_csv(head, tmp_path) -> None:
    p = ExportPanel(head, path=str(tmp_path / "anim.glb"))
    try:
        assert p.csv_layout.layout.display == "none"  # glb
        assert list(p.csv_layout.options) == [
            ("plain", "plain"),
            ("Live Link Face (Unreal)", "livelink"),
        ]
        p.format.value = CSV
        assert p.path.value.endswith("anim.csv") and p.csv_layout.layout.display == ""
        assert p.csv_layout in p.children and "fwb-export-csv-layout" in p.csv_layout._dom_classes
        p.format.value = "USD crate (.usdc)"
        assert p.csv_layout.layout.display == "none"
    finally:
        p.close()


def test_plain_csv_is_still_the_default(head, tmp_path) -> None:
    _keyed_take(head)
    p = ExportPanel(head, path=str(tmp_path / "plain.csv"))
    try:
        p.format.value = CSV
        (path,) = p.do_export()
        header, rows = _rows(path)
        assert header == ["time", *head.shape_names] and len(rows) == 31
        assert "fwb-export-notes" not in p.result.value
    finally:
        p.close()


def test_livelink_export_from_the_panel_and_import_back_restores_the_head_pose(head, tmp_path) -> None:
    _keyed_take(head)
    times = head.tracks.frame_times()
    want_angles = _head_angles(head, times)
    want_jaw = head.tracks.tracks["weights/jawOpen"].sample(times)[:, 0]
    out = W.Output()
    p = ExportPanel(head, path=str(tmp_path / "take.glb"), errors=out)
    try:
        p.format.value = CSV
        p.csv_layout.value = "livelink"
        p.export_button.click()
        assert _errors(out) == "" and "Export failed" not in p.result.value, p.result.value
        (path,) = p.last_written
        header, rows = _rows(path)
        assert len(header) == 63 and header[:2] == ["Timecode", "BlendShapeCount"]
        assert header[-9:-6] == ["HeadYaw", "HeadPitch", "HeadRoll"]
        assert len(rows) == times.size and all(len(r) == 63 and r[1] == "61" for r in rows)
        assert rows[0][0] == "00:00:00:00.000"

        # a fresh model of the same rig: the panel's import brings the take back
        other = workbench.load_sample("head")
        q = ExportPanel(other, errors=out)
        try:
            q.import_path.value = str(path)
            q.import_button.click()
            assert "Imported" in q.import_result.value and "head pose" in q.import_result.value
            assert other.history.undo_labels[-1] == "Import animation take.csv"
            assert other.tracks.head_pose is not None
            np.testing.assert_allclose(_head_angles(other, times), want_angles, atol=1e-5, rtol=0)
            got_jaw = other.tracks.tracks["weights/jawOpen"].sample(times)[:, 0]
            np.testing.assert_allclose(got_jaw, want_jaw, atol=1e-6, rtol=0)
        finally:
            q.close()
        assert _errors(out) == ""
    finally:
        p.close()


def test_import_reads_head_columns_about_the_models_own_axes(head, tmp_path) -> None:
    """A +z-up, -y-front model: the panel passes its axes to read_animation, so the turn comes back."""
    zup = FaceModel(
        head.vertices,
        head.faces,
        head.shapes,
        polygons=head.polygons,
        metadata=dataclasses.replace(head.metadata, up_axis="+z", front_axis="-y"),
    )
    _keyed_take(zup)
    times = zup.tracks.frame_times()
    want = _head_angles(zup, times)
    p = ExportPanel(zup, path=str(tmp_path / "z.csv"))
    try:
        p.format.value = CSV
        p.csv_layout.value = "livelink"
        (path,) = p.do_export()
        zup.timeline.set(dataclasses.replace(zup.tracks, tracks={}), "Clear keys")
        assert zup.tracks.head_pose is None
        p.import_path.value = str(path)
        assert p.do_import(), p.import_result.value
        np.testing.assert_allclose(_head_angles(zup, times), want, atol=1e-5, rtol=0)
    finally:
        p.close()


def test_the_layouts_notes_show_in_the_result(tiny_model, tmp_path) -> None:
    """A rig with no ARKit shapes: the notes say what was written as 0 and what was left out."""
    m = tiny_model
    m.set_weight("up", 0.5)
    m.timeline.key_weights(0.0)
    m.timeline.key_weights(1.0)
    p = ExportPanel(m, path=str(tmp_path / "tiny.csv"))
    try:
        p.format.value = CSV
        p.csv_layout.value = "livelink"
        (path,) = p.do_export()
        assert len(_rows(path)[0]) == 63
        res = p.result.value
        assert "fwb-export-notes" in res
        assert "no shape for ARKit" in res and "no ARKit meaning" in res and "&#x27;up&#x27;" in res
        # a plain CSV has no notes; the line goes
        p.csv_layout.value = "plain"
        p.do_export()
        assert "fwb-export-notes" not in p.result.value
    finally:
        p.close()


def test_livelink_needs_a_whole_fps_and_says_so(head, tmp_path) -> None:
    _keyed_take(head)
    p = ExportPanel(head, path=str(tmp_path / "odd.csv"))
    try:
        p.format.value = CSV
        p.csv_layout.value = "livelink"
        p.fps.value = 29.97
        assert p.do_export() == []
        assert "Export failed" in p.result.value and "fwb-export-error" in p.result.value
    finally:
        p.close()
