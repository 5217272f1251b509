"""The live tracker's guided expression calibration (``workbench.capture.expression_calibration``; issue 30).

The numerics by identities and hand-worked cases; the session's schedule; a tracker
reading that is a known linear misreading of the truth (the jaw read half-way, the
parting lips read partly as ``mouthShrugLower``) corrected by a session of generated
prompts; and, with a rendered camera, the whole path through ``LiveTracker``.
"""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.capture.expression_calibration import (
    DEFAULT_PROMPTS,
    CalibrationPrompt,
    ExpressionCalibration,
    fit_weight_map,
    held_frames,
)
from workbench.testing import calibration_head_motion, calibration_session, renamed_shapes


def test_the_map_of_a_reading_that_is_already_right_is_the_identity() -> None:
    rng = np.random.default_rng(0)
    R = rng.uniform(0, 1, (40, 6))
    for ridge in (0.0, 0.01, 10.0):
        np.testing.assert_allclose(fit_weight_map(R, R, ridge=ridge), np.eye(6), atol=1e-10)


def test_without_a_ridge_a_linear_misreading_is_inverted_exactly() -> None:
    rng = np.random.default_rng(1)
    truth = rng.uniform(0, 1, (50, 5))
    M = np.eye(5) * 0.5 + 0.1 * rng.normal(size=(5, 5))  # what the tracker reads: truth @ M
    C = fit_weight_map(truth @ M, truth, ridge=0.0)
    np.testing.assert_allclose(C, np.linalg.inv(M), atol=1e-9)


def test_a_large_ridge_keeps_the_reading_and_a_small_one_follows_the_data() -> None:
    rng = np.random.default_rng(2)
    R = rng.uniform(0, 1, (30, 4))
    Y = 2.0 * R
    assert np.abs(fit_weight_map(R, Y, ridge=1e6) - np.eye(4)).max() < 1e-4
    np.testing.assert_allclose(fit_weight_map(R, Y, ridge=1e-9), 2.0 * np.eye(4), atol=1e-6)


def test_bad_arguments_are_named() -> None:
    with pytest.raises(ValueError, match="raw and target"):
        fit_weight_map(np.zeros((3, 2)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        fit_weight_map(np.full((3, 2), np.nan), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="ridge"):
        fit_weight_map(np.zeros((3, 2)), np.zeros((3, 2)), ridge=-1.0)
    with pytest.raises(ValueError, match="seconds"):
        ExpressionCalibration(["jawOpen"], seconds=0.0)
    with pytest.raises(ValueError, match=r"CalibrationPrompt.head: expected one of"):
        CalibrationPrompt("spin", head="roll")
    with pytest.raises(ValueError, match="none of the prompted shapes"):
        ExpressionCalibration(["smirk", "wince"])
    cal = ExpressionCalibration(["jawOpen", "eyeBlinkLeft"])
    with pytest.raises(ValueError, match=r"\(2,\)"):
        cal.add(0.0, np.zeros(3))
    with pytest.raises(ValueError, match="neutral"):
        cal.fit()


def test_the_hold_is_where_the_prompted_shapes_are_near_their_peak() -> None:
    R = np.zeros((6, 3))
    R[:, 1] = [0.0, 0.2, 0.9, 1.0, 0.85, 0.1]
    R[:, 2] = [0.0, 0.2, 0.7, 0.6, 0.65, 0.1]
    assert held_frames(R, [1]).tolist() == [False, False, True, True, True, False]
    # two shapes: their mean (0, .2, .8, .8, .75, .1) against 0.8 × 0.8
    assert held_frames(R, [1, 2]).tolist() == [False, False, True, True, True, False]
    assert held_frames(R, []).all()  # the neutral prompt: every frame
    assert not held_frames(np.zeros((4, 3)), [0]).any()  # never shown


def test_the_schedule_follows_the_frames_clock_and_any_spelling_of_the_names() -> None:
    names = ["jaw_open", "EyeBlink_L", "eyeBlink_R", "smirk"]  # no smile, brows, pucker, funnel
    cal = ExpressionCalibration(names, seconds=1.5)
    # relax, jaw, eyes closed, then the relaxed face turning and nodding (any rig can)
    assert [p.instruction for p in cal.prompts_] == [DEFAULT_PROMPTS[i].instruction for i in (0, 1, 2, 8, 9)]
    assert cal.columns_ == ((), (0,), (1, 2), (), ()) and cal.duration == pytest.approx(7.5)
    assert [p.head for p in cal.prompts_] == ["still", "still", "still", "turn", "nod"]
    assert cal.prompt_index(0.0) == 0  # before the first frame
    assert cal.add(10.0, np.zeros(4)) == 0  # the session starts at its first frame
    assert cal.prompt_index(11.49) == 0 and cal.prompt_index(11.5) == 1 and cal.prompt_index(14.49) == 2
    assert cal.prompt_index(14.5) == 3 and cal.prompt_index(17.49) == 4
    assert cal.prompt_index(17.5) is None and cal.done(17.5) and not cal.done(17.0)
    assert cal.add(18.0, np.ones(4)) is None  # after the session: not recorded


def test_the_neutral_window_is_the_still_relax_prompt_and_its_frames_can_be_read_again() -> None:
    names = ["jawOpen", "eyeBlinkLeft"]
    cal = ExpressionCalibration(names, seconds=2.0)
    assert cal.neutral_window() is None  # before the session's first frame
    cal.add(5.0, [0.3, 0.0])  # read against a start that was not relaxed
    cal.add(6.0, [0.4, 0.1])
    cal.add(7.5, [0.9, 0.0])  # the jaw prompt
    assert cal.neutral_window() == (5.0, 7.0)
    cal.reread(0, np.zeros((3, 2)))  # the relax prompt's frames read again against the new neutral
    cal.fit()
    assert cal.held_ is not None and list(cal.held_[:2]) == [3, 1]
    np.testing.assert_allclose(cal.apply([0.0, 0.0]), [0.0, 0.0])
    with pytest.raises(ValueError, match="index must be a prompt"):
        cal.reread(9, np.zeros((1, 2)))
    # a session that does not begin with a still neutral face has no window
    moving = ExpressionCalibration(names, [CalibrationPrompt("Open your jaw", ("jawOpen",)),
                                           CalibrationPrompt("Relax", ())])
    moving.add(0.0, [0.0, 0.0])
    assert moving.neutral_window() is None
    turning = ExpressionCalibration(names, [CalibrationPrompt("Relax and turn", head="turn"),
                                            CalibrationPrompt("Open your jaw", ("jawOpen",))])
    turning.add(0.0, [0.0, 0.0])
    assert turning.neutral_window() is None


def _misread(truth: np.ndarray, names: list[str], rng) -> np.ndarray:
    """A tracker's reading: the jaw at half, a third of it read as mouthShrugLower, blinks at 70 %, noise."""
    j, s, bl, br = (names.index(n) for n in ("jawOpen", "mouthShrugLower", "eyeBlinkLeft", "eyeBlinkRight"))
    M = np.eye(len(names))
    M[j, j], M[j, s] = 0.5, 0.35
    M[bl, bl] = M[br, br] = 0.7
    return np.clip(truth @ M + rng.normal(0.0, 0.01, truth.shape), 0.0, 1.0)


def test_a_session_corrects_a_systematic_misreading_on_a_take_it_did_not_see() -> None:
    from workbench.testing import realistic_weights

    model = workbench.load_sample("head")
    names = list(model.shape_names)
    rng = np.random.default_rng(3)
    fps = 15.0
    S = calibration_session(model, fps=fps, seed=4)
    cal = ExpressionCalibration(names)
    for f, w in enumerate(_misread(S, names, rng)):
        cal.add(100.0 + f / fps, w)
    assert cal.done(100.0 + len(S) / fps)
    cal.fit()
    assert cal.held_ is not None and (cal.held_[1:] >= 5).all()  # each expression held for a while
    # a take of the jaw, the blinks and other shapes the session never prompted
    take = 0.5 * realistic_weights(model, 90, seed=5)
    take[:, names.index("jawOpen")] = np.linspace(0.0, 1.0, 90)
    raw = _misread(take, names, rng)
    fixed = np.clip(cal.apply(raw), 0.0, 1.0)
    err_raw = np.sqrt(np.mean((raw - take) ** 2))
    err_fixed = np.sqrt(np.mean((fixed - take) ** 2))
    assert err_fixed < 0.6 * err_raw, (err_raw, err_fixed)
    jaw = names.index("jawOpen")
    assert abs(fixed[-1, jaw] - 1.0) < 0.15 and raw[-1, jaw] < 0.7
    # a shape no prompt showed and the misreading leaves alone keeps its reading
    k = names.index("cheekPuff")
    assert np.abs(fixed[:, k] - raw[:, k]).max() < 0.05


def _misread_as_the_head_turns(W, yaw, names):
    """A tracker that reads a brow and a dimple on one side as the head turns (measured on video:
    browDownLeft correlates +0.69 with yaw on a neutral face), and a true frown as it is."""
    R = np.array(W, np.float64)
    left, right = np.clip(yaw, 0.0, None), np.clip(-yaw, 0.0, None)
    for name, side, gain in (("browDownLeft", left, 2.0), ("mouthDimpleRight", left, 1.5),
                             ("browDownRight", right, 2.0), ("mouthDimpleLeft", right, 1.5)):
        R[:, names.index(name)] += gain * side
    return np.clip(R, 0.0, 1.0)


def test_the_turning_and_nodding_prompts_teach_what_a_turned_head_misreads() -> None:
    model = workbench.load_sample("head")
    names = list(model.shape_names)
    fps = 15.0
    S = calibration_session(model, fps=fps, seed=2)
    yaw, pitch = calibration_head_motion(model, fps=fps, seed=2)
    assert yaw.shape == pitch.shape == (len(S),)
    n = round(2.0 * fps)
    assert np.rad2deg(np.abs(yaw[-2 * n : -n])).max() > 12.0  # it turns
    assert np.rad2deg(np.abs(pitch[-n:])).max() > 6.0  # it nods
    assert np.rad2deg(np.abs(yaw[: -2 * n])).max() <= 3.0 + 1e-9  # and otherwise holds about still
    # a take: the head turning ±12° throughout, a frown in its middle, nothing else
    T = 120
    take_yaw = np.deg2rad(12.0) * np.sin(np.linspace(0, 4 * np.pi, T))
    take = np.zeros((T, len(names)))
    frown = np.sin(np.linspace(0, np.pi, 40)) ** 2
    for side in ("browDownLeft", "browDownRight"):
        take[40:80, names.index(side)] = frown
    raw = _misread_as_the_head_turns(take, take_yaw, names)
    errors = {}
    for label, prompts in (("with", DEFAULT_PROMPTS), ("without", [p for p in DEFAULT_PROMPTS if p.head == "still"])):
        cal = ExpressionCalibration(names, prompts)
        m = len(cal.prompts_) * n
        for f, w in enumerate(_misread_as_the_head_turns(S[:m], yaw[:m], names)):
            cal.add(f / fps, w)
        cal.fit()
        fixed = np.clip(cal.apply(raw), 0.0, 1.0)
        errors[label] = float(np.sqrt(np.mean((fixed - take) ** 2)))
    err_raw = float(np.sqrt(np.mean((raw - take) ** 2)))
    # measured 0.029 with, 0.046 without, 0.051 as read: a weights-only map cancels the part of the
    # turned head's pattern that no expression shares
    assert errors["with"] < 0.75 * errors["without"] and errors["with"] < 0.65 * err_raw, (errors, err_raw)


def test_a_rig_with_other_names_and_prompts_of_its_own() -> None:
    model = renamed_shapes(workbench.load_sample("head"), "snake")
    prompts = [CalibrationPrompt("neutral"), CalibrationPrompt("jaw", ("jawOpen",)),
               CalibrationPrompt("fly", ("notAShape",))]
    cal = ExpressionCalibration(list(model.shape_names), prompts)
    assert [p.instruction for p in cal.prompts_] == ["neutral", "jaw"]
    S = calibration_session(model, prompts, seconds=1.0, fps=10.0, seed=0)
    assert S.shape == (20, len(model.shape_names))
    j = cal.columns_[1][0]
    assert S[:10].max() == 0.0 and 0.75 < S[10:, j].max() <= 1.0


def test_the_tracker_starts_ends_and_cancels_a_session() -> None:
    from workbench.capture.facemesh import VideoError
    from workbench.capture.live import LiveTracker

    live = LiveTracker(workbench.load_sample("head"))
    assert not live.calibrating and live.calibration_ is None
    with pytest.raises(VideoError, match="begin_calibration first"):
        live.end_calibration()
    cal = live.begin_calibration(seconds=1.0)
    assert live.calibrating and cal.duration == pytest.approx(len(DEFAULT_PROMPTS))
    with pytest.raises(VideoError, match="neutral face"):  # no frame was tracked
        live.end_calibration()
    assert not live.calibrating and live.calibration_ is None  # nothing half-kept
    live.begin_calibration()
    live.cancel_calibration()
    assert not live.calibrating and live.calibration_ is None


def test_the_summary_names_the_expressions_the_tracker_barely_read() -> None:
    """Hand-made readings: the jaw read at 0.6 while prompted, the eyes at 0.5, the pucker at only 0.05
    and the 'oo' never: the readings are those levels over each hold, and the summary names the two."""
    from workbench.capture.expression_calibration import WEAK_READING

    names = ["jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthPucker", "mouthFunnel"]
    by_shape = {p.shapes: p for p in DEFAULT_PROMPTS}
    prompts = [DEFAULT_PROMPTS[0], by_shape[("jawOpen",)], by_shape[("eyeBlinkLeft", "eyeBlinkRight")],
               by_shape[("mouthPucker",)], by_shape[("mouthFunnel",)]]
    level = {"jawOpen": 0.6, "eyeBlinkLeft": 0.5, "eyeBlinkRight": 0.5, "mouthPucker": 0.05, "mouthFunnel": 0.0}
    cal = ExpressionCalibration(names, prompts, seconds=1.0)
    for f in range(50):  # 10 frames a prompt: half reaction, half held
        i = f // 10
        w = np.zeros(len(names))
        if f % 10 >= 5:
            for s in prompts[i].shapes:
                w[names.index(s)] = level[s]
        cal.add(f / 10.0, w)
    with pytest.raises(ValueError, match="no frame of the neutral face"):
        ExpressionCalibration(names, prompts).fit()
    assert ExpressionCalibration(names, prompts).summary() == "not calibrated yet"
    cal.fit()
    assert cal.readings_ is not None and np.isnan(cal.readings_[0])  # the neutral face shows no shape
    np.testing.assert_allclose(cal.readings_[1:], [0.6, 0.5, 0.05, 0.0])
    assert cal.weak_prompts() == [3, 4] and WEAK_READING > 0.05
    s = cal.summary()
    assert s.startswith("calibrated: 3 expressions held") and s.endswith("read weakly: mouthPucker 0.05, mouthFunnel 0.00")
