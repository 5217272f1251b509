"""Live Link Face CSV for Unreal/MetaHuman: the app's exact layout, any rig, head pose, round trips (issue 15, item 8)."""

from __future__ import annotations

import csv
import dataclasses
import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.animation.curves import (
    HEAD_POSE,
    Key,
    Track,
    head_euler_from_rotation,
    head_rotation_from_euler,
    quaternion_to_matrix,
    weight_track_name,
)
from workbench.animation.importers import (
    AnimationImportError,
    livelink_head_rotation,
    read_animation,
    read_weights_csv,
)
from workbench.animation.tracks import Timeline
from workbench.export import ExportError, export
from workbench.export.csv import timecode
from workbench.model import BlendShape, FaceModel

DATA = Path(__file__).parent / "data"

# Written out by hand from a Live Link Face take's header (not from our constant).
APP_HEADER = (
    "Timecode,BlendShapeCount,EyeBlinkLeft,EyeLookDownLeft,EyeLookInLeft,EyeLookOutLeft,EyeLookUpLeft,"
    "EyeSquintLeft,EyeWideLeft,EyeBlinkRight,EyeLookDownRight,EyeLookInRight,EyeLookOutRight,EyeLookUpRight,"
    "EyeSquintRight,EyeWideRight,JawForward,JawRight,JawLeft,JawOpen,MouthClose,MouthFunnel,MouthPucker,"
    "MouthRight,MouthLeft,MouthSmileLeft,MouthSmileRight,MouthFrownLeft,MouthFrownRight,MouthDimpleLeft,"
    "MouthDimpleRight,MouthStretchLeft,MouthStretchRight,MouthRollLower,MouthRollUpper,MouthShrugLower,"
    "MouthShrugUpper,MouthPressLeft,MouthPressRight,MouthLowerDownLeft,MouthLowerDownRight,MouthUpperUpLeft,"
    "MouthUpperUpRight,BrowDownLeft,BrowDownRight,BrowInnerUp,BrowOuterUpLeft,BrowOuterUpRight,CheekPuff,"
    "CheekSquintLeft,CheekSquintRight,NoseSneerLeft,NoseSneerRight,TongueOut,HeadYaw,HeadPitch,HeadRoll,"
    "LeftEyeYaw,LeftEyePitch,LeftEyeRoll,RightEyeYaw,RightEyePitch,RightEyeRoll"
).split(",")


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


def read_rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def column(path: Path, name: str) -> np.ndarray:
    header, rows = read_rows(path)
    j = header.index(name)
    return np.array([float(r[j]) for r in rows])


def keyed(names_values: dict[str, tuple[float, float, float]], *, fps: float = 30.0, end: float = 2.0,
          head_angles: tuple[tuple[float, float, float], ...] = ((25.0, 8.0, -4.0), (-15.0, -6.0, 10.0), (5.0, 3.0, 1.0)),
          axes: tuple[str, str] = ("+y", "+z")) -> Timeline:
    """Bezier keys at 0, end/2 and end for every named shape and for the head rotation (degrees)."""
    times = (0.0, end / 2, end)
    tl = Timeline(fps=fps, start=0.0, end=end)
    for name, vals in names_values.items():
        for t, v in zip(times, vals, strict=True):
            tl = tl.add_key(weight_track_name(name), t, v)
    for t, (y, p, r) in zip(times, head_angles, strict=True):
        q = head_rotation_from_euler(y, p, r, up_axis=axes[0], front_axis=axes[1])
        tl = tl.add_key(HEAD_POSE, t, np.r_[0.0, 0.0, 0.0, q])
    return tl


def head_angles_rad(tl: Timeline, times: np.ndarray, axes: tuple[str, str] = ("+y", "+z")) -> np.ndarray:
    assert tl.head_pose is not None
    P = tl.head_pose.sample(times)
    return np.radians([head_euler_from_rotation(q, up_axis=axes[0], front_axis=axes[1]) for q in P[:, 3:]])


# ------------------------------------------------------------------------ the layout
def test_header_is_the_apps_61_value_columns_in_its_order(head, tmp_path):
    tl = keyed({"jawOpen": (0.0, 0.8, 0.1)})
    out = export(head, tl, tmp_path / "take.csv", style="livelink")
    header, rows = read_rows(out[0])
    assert header == APP_HEADER
    assert len(header) == 63 and header[:2] == ["Timecode", "BlendShapeCount"]
    assert all(len(r) == 63 and r[1] == "61" for r in rows)
    assert len(rows) == tl.frame_times().size  # 2 s at 30 fps: 61 rows
    # the eyes are written as 0 (the app takes them from ARKit's eye transforms, not from weights)
    for name in APP_HEADER[-6:]:
        assert not column(out[0], name).any()


# ------------------------------------------------------------------------ timecodes
@pytest.mark.parametrize(
    ("t", "fps", "expected"),
    [
        (0.0, 30, "00:00:00:00.000"),
        (59 + 29 / 30, 30, "00:00:59:29.000"),  # last frame of the first minute
        (60.0, 30, "00:01:00:00.000"),
        (3599 + 29 / 30, 30, "00:59:59:29.000"),
        (3600.0, 30, "01:00:00:00.000"),
        (3599 + 59 / 60, 60, "00:59:59:59.000"),
        (3600 + 1 / 60, 60, "01:00:00:01.000"),
        (60 + 2.5 / 60, 60, "00:01:00:02.500"),  # half-way between frames 2 and 3: 500/1000 of a frame
        (1 / 60 + 0.25 / 60, 60, "00:00:00:01.250"),
    ],
)
def test_timecode_hand_worked(t, fps, expected):
    assert timecode(t, fps) == expected


@pytest.mark.parametrize(
    ("fps", "start", "expected"),
    [
        (30, 59.9, ["00:00:59:27.000", "00:00:59:28.000", "00:00:59:29.000", "00:01:00:00.000",
                    "00:01:00:01.000", "00:01:00:02.000", "00:01:00:03.000"]),
        (60, 3599.95, ["00:59:59:57.000", "00:59:59:58.000", "00:59:59:59.000", "01:00:00:00.000",
                       "01:00:00:01.000", "01:00:00:02.000", "01:00:00:03.000"]),
    ],
)
def test_exported_timecodes_cross_a_minute_and_an_hour(head, tmp_path, fps, start, expected):
    track = Track(weight_track_name("jawOpen"), (Key(start, 0.0, "linear"), Key(start + 6 / fps, 0.6, "linear")))
    tl = Timeline(fps=fps, start=start, end=start + 6 / fps, tracks={track.name: track})
    (p,) = export(head, tl, tmp_path / "t.csv", style="livelink")
    _, rows = read_rows(p)
    assert [r[0] for r in rows] == expected
    back = read_weights_csv(p, head.shape_names)  # fps inferred from the frame numbers
    assert back.fps == fps
    assert back.tracks["weights/jawOpen"].times == pytest.approx(np.arange(7) / fps, abs=1e-9)
    assert back.tracks["weights/jawOpen"].values[:, 0] == pytest.approx(np.arange(7) * 0.1, abs=1e-9)


@pytest.mark.parametrize("fps", [29.97, 23.976])
def test_a_non_whole_fps_is_a_clear_error_and_writes_nothing(head, tmp_path, fps):
    tl = keyed({"jawOpen": (0.0, 0.8, 0.1)})
    with pytest.raises(ExportError, match=r"whole frames per second.*fps is " + str(fps)):
        export(head, tl, tmp_path / "t.csv", fps=fps, style="livelink")
    assert not list(tmp_path.iterdir())
    with pytest.raises(ExportError, match="whole"):
        timecode(1.0, fps)


def test_rates_unreal_cannot_infer_are_noted(head, tmp_path, caplog):
    tl = keyed({"jawOpen": (0.0, 0.8, 0.1)})
    with caplog.at_level(logging.WARNING, logger="workbench.export"):
        r = export(head, tl, tmp_path / "t.csv", fps=24, style="livelink")
    assert any("24 fps" in n and "30 or 60" in n for n in r.notes)
    assert "wrong speed" in caplog.text
    assert not export(head, tl, tmp_path / "u.csv", fps=60, style="livelink").notes


# ------------------------------------------------------------------------ round trips
def test_round_trip_on_the_arkit_sample(head, tmp_path):
    rng = np.random.default_rng(3)
    values = {n: tuple(rng.uniform(0, 1, 3)) for n in head.shape_names}
    for fps in (30, 60):
        tl = keyed(values, fps=fps)
        (p,) = export(head, tl, tmp_path / f"rt{fps}.csv", style="livelink")
        back = read_animation(p, head.shape_names)  # fps inferred: 2 s cross second boundaries
        assert back.fps == fps
        times = tl.frame_times()
        np.testing.assert_allclose(back.weight_matrix(head.shape_names, times),
                                   tl.weight_matrix(head.shape_names, times), atol=1e-6, rtol=0)
        np.testing.assert_allclose(head_angles_rad(back, times), head_angles_rad(tl, times), atol=1e-6, rtol=0)
        # the file holds the normalised angles (degrees / 180) of the model's own yaw/pitch/roll
        assert column(p, "HeadYaw")[0] == pytest.approx(25.0 / 180, abs=1e-9)
        assert column(p, "HeadPitch")[0] == pytest.approx(8.0 / 180, abs=1e-9)
        assert column(p, "HeadRoll")[0] == pytest.approx(-4.0 / 180, abs=1e-9)


def studio_rig(base: FaceModel) -> FaceModel:
    """The sample as another studio ships it: _L/_R names, split halves, one smile, no tongue, extras."""
    x = base.vertices[:, 0]
    left = np.clip(0.5 + x / 0.2, 0.0, 1.0)[:, None].astype(np.float32)
    by = {s.name: s for s in base.shapes}
    shapes = []
    for s in base.shapes:
        n = s.name
        if n in ("tongueOut", "mouthSmileRight"):
            continue
        if n in ("browInnerUp", "cheekPuff", "jawOpen"):
            shapes.append(BlendShape(f"{n}_L", s.delta * left))
            shapes.append(BlendShape(f"{n}_R", s.delta - s.delta * left))
        elif n == "mouthSmileLeft":
            shapes.append(BlendShape("mouthSmile", s.delta + by["mouthSmileRight"].delta))
        elif n == "noseSneerLeft":
            shapes.append(BlendShape("blendShape1.noseSneer_L", s.delta))
        else:
            shapes.append(BlendShape(n.removesuffix("Left") + "_L" if n.endswith("Left")
                                     else n.removesuffix("Right") + "_R" if n.endswith("Right") else n, s.delta))
    shapes.append(BlendShape("browWiggle", by["browInnerUp"].delta * 0.5))
    return FaceModel(base.vertices, base.faces, shapes, polygons=base.polygons,
                     component_labels=base.component_labels, component_names=base.component_names,
                     metadata=base.metadata)


def test_round_trip_on_a_rig_with_split_suffixed_and_missing_shapes(head, tmp_path, caplog):
    rig = studio_rig(head)
    assert "eyeBlink_L" in rig.shape_names and "tongueOut" not in rig.shape_names
    values = {
        "eyeBlink_L": (0.0, 1.0, 0.2), "mouthFrown_R": (0.3, 0.0, 0.6),
        "jawOpen_L": (0.1, 0.7, 0.0), "jawOpen_R": (0.1, 0.7, 0.0),  # halves keyed alike
        "browInnerUp_L": (0.6, 0.6, 0.6), "browInnerUp_R": (0.2, 0.2, 0.2),  # halves keyed apart
        "mouthSmile": (0.0, 0.9, 0.4), "blendShape1.noseSneer_L": (0.5, 0.25, 0.0),
        "browWiggle": (1.0, 0.0, 1.0),
    }
    tl = keyed(values)
    with caplog.at_level(logging.INFO, logger="workbench.export"):
        result = export(rig, tl, tmp_path / "rig.csv", style="livelink")
    (p,) = result
    notes = " | ".join(result.notes)
    assert "no shape for ARKit ['tongueOut']: written as 0" in notes
    assert "not written: ['browWiggle']" in notes
    assert "browInnerUp is the mean of the split halves ['browInnerUp_L', 'browInnerUp_R']" in notes
    assert "'mouthSmile' fills both mouthSmileLeft and mouthSmileRight" in notes
    assert len(result.notes) == 6 and "browWiggle" in caplog.text  # 3 split pairs, 1 pair, 2 warnings
    header, _ = read_rows(p)
    assert header == APP_HEADER
    times = tl.frame_times()
    played = tl.weight_matrix(list(values), times)
    v = dict(zip(values, played.T, strict=True))
    np.testing.assert_allclose(column(p, "JawOpen"), v["jawOpen_L"], atol=1e-8)
    np.testing.assert_allclose(column(p, "BrowInnerUp"), 0.4, atol=1e-8)  # the halves' mean
    np.testing.assert_allclose(column(p, "MouthSmileLeft"), v["mouthSmile"], atol=1e-8)
    np.testing.assert_allclose(column(p, "MouthSmileRight"), v["mouthSmile"], atol=1e-8)
    np.testing.assert_allclose(column(p, "NoseSneerLeft"), v["blendShape1.noseSneer_L"], atol=1e-8)
    assert not column(p, "TongueOut").any()

    back = read_weights_csv(p, rig.shape_names)  # the all-zero TongueOut column is skipped, not an error
    assert "weights/browWiggle" not in back.tracks
    names = list(values)
    all_w = back.weight_matrix(rig.shape_names, times)
    got = all_w[:, [rig.shape_names.index(n) for n in names]]
    others = [j for j, n in enumerate(rig.shape_names) if n not in values]
    assert not all_w[:, others].any()  # every other shape stays at 0
    expect = played.copy()
    expect[:, names.index("browInnerUp_L")] = expect[:, names.index("browInnerUp_R")] = 0.4
    expect[:, names.index("browWiggle")] = 0.0
    np.testing.assert_allclose(got, expect, atol=1e-6, rtol=0)
    np.testing.assert_allclose(head_angles_rad(back, times), head_angles_rad(tl, times), atol=1e-6, rtol=0)


def test_head_angles_follow_the_models_own_axes(head, tmp_path):
    """The same turn of the head gives the same columns on a +z-up, -y-front model; signs pinned."""
    zup = FaceModel(head.vertices, head.faces, head.shapes, polygons=head.polygons,
                    metadata=dataclasses.replace(head.metadata, up_axis="+z", front_axis="-y"))
    tl = keyed({"jawOpen": (0.0, 0.5, 0.0)}, head_angles=((30.0, 10.0, -5.0),) * 3, axes=("+z", "-y"))
    (p,) = export(zup, tl, tmp_path / "z.csv", style="livelink")
    assert column(p, "HeadYaw") == pytest.approx(30.0 / 180, abs=1e-9)
    assert column(p, "HeadPitch") == pytest.approx(10.0 / 180, abs=1e-9)
    assert column(p, "HeadRoll") == pytest.approx(-5.0 / 180, abs=1e-9)
    back = read_weights_csv(p, zup.shape_names, up_axis="+z", front_axis="-y")
    times = tl.frame_times()
    np.testing.assert_allclose(head_angles_rad(back, times, ("+z", "-y")),
                               head_angles_rad(tl, times, ("+z", "-y")), atol=1e-6, rtol=0)
    # sign convention (+y up, +z front, +x the subject's left): +yaw looks to the subject's left,
    # +pitch nods down, +roll tilts the top of the head to the subject's right
    front, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    assert (quaternion_to_matrix(livelink_head_rotation(1 / 6, 0, 0)) @ front)[0] > 0.4
    assert (quaternion_to_matrix(livelink_head_rotation(0, 1 / 6, 0)) @ front)[1] < -0.4
    assert (quaternion_to_matrix(livelink_head_rotation(0, 0, 1 / 6)) @ up)[0] < -0.4


def test_head_translation_is_noted_and_no_head_pose_writes_zeros(head, tmp_path):
    tl = Timeline(fps=30, start=0.0, end=1.0).add_key(weight_track_name("jawOpen"), 0.0, 0.3)
    (p,) = export(head, tl, tmp_path / "nohead.csv", style="livelink")
    for name in ("HeadYaw", "HeadPitch", "HeadRoll"):
        assert not column(p, name).any()
    assert read_weights_csv(p, head.shape_names).head_pose is None  # all-zero head columns: no track
    moved = tl.add_key(HEAD_POSE, 0.0, np.r_[0.0, 0.01, 0.0, 0.0, 0.0, 0.0, 1.0])
    r = export(head, moved, tmp_path / "moved.csv", style="livelink")
    assert any("head translation is not written" in n for n in r.notes)


# ------------------------------------------------------------------ a take from the app
def test_a_live_link_face_take_imports(head):
    path = DATA / "livelink_take.csv"
    header, rows = read_rows(path)
    assert header == APP_HEADER and len(rows) == 5
    tl = read_weights_csv(path, head.shape_names)
    assert tl.fps == 60  # frame numbers up to 59
    # 14:03:52:57.512 ... 14:03:53:01.518: fractional frames at 60 fps, relative to the first row
    frames = np.array([57.512, 58.513, 59.515, 60.516, 61.518])
    jaw = tl.tracks["weights/jawOpen"]
    assert jaw.times == pytest.approx((frames - frames[0]) / 60, abs=1e-12)
    assert jaw.values[:, 0] == pytest.approx(column(path, "JawOpen"))
    assert len(tl.weight_tracks) == 52
    assert tl.tracks["weights/jawLeft"].values[:, 0] == pytest.approx(column(path, "JawLeft"))
    expect = np.stack([column(path, c) for c in ("HeadYaw", "HeadPitch", "HeadRoll")], axis=1) * np.pi
    np.testing.assert_allclose(head_angles_rad(tl, jaw.times), expect, atol=1e-9)


def test_a_take_onto_a_rig_without_a_tongue(head):
    rig = studio_rig(head)
    path = DATA / "livelink_take.csv"
    with pytest.raises(AnimationImportError, match=r"\['TongueOut'\] have non-zero weights.*on_unknown='ignore'"):
        read_weights_csv(path, rig.shape_names)
    tl = read_weights_csv(path, rig.shape_names, on_unknown="ignore")
    brow = column(path, "BrowInnerUp")
    assert tl.tracks["weights/browInnerUp_L"].values[:, 0] == pytest.approx(brow)
    assert tl.tracks["weights/browInnerUp_R"].values[:, 0] == pytest.approx(brow)
    smile = (column(path, "MouthSmileLeft") + column(path, "MouthSmileRight")) / 2
    assert tl.tracks["weights/mouthSmile"].values[:, 0] == pytest.approx(smile)


# ------------------------------------------------------------------------ the command
def test_cli_export_style_livelink(head, tmp_path):
    model = workbench.load_sample("head")
    model.key_expression(0.0, "jawOpen")
    model.key_expression(1.5, "mouthSmileLeft")
    saved = tmp_path / "anim.fwb"
    model.save(saved)
    out = tmp_path / "anim.csv"
    cmd = [sys.executable, "-m", "workbench.cli", "export", str(saved), str(out)]
    r = subprocess.run([*cmd, "--style", "livelink"], capture_output=True, text=True, check=False)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(out)
    header, rows = read_rows(out)
    assert header == APP_HEADER and len(rows) == 46  # 1.5 s at 30 fps
    r = subprocess.run([*cmd[:-1], str(tmp_path / "anim.glb"), "--style", "livelink"],
                       capture_output=True, text=True, check=False)
    assert r.returncode == 2 and "is a CSV layout" in r.stderr
