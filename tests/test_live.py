"""Live tracking from camera frames (``workbench.capture.LiveTracker``; issue 30, the kernel side).

The rendered take of ``tests/capture_takes.py`` (the sample head: jawOpen ramp, a
blink, a head turn) is pushed frame by frame as a camera would deliver it. The
input checks run everywhere; the rendered tests need pyvista (``ui``) and
mediapipe (``video``).
"""

from __future__ import annotations

import numpy as np
import pytest
from capture_takes import BLINK, JAW, render_take, zoomed

import workbench
from workbench.capture.facemesh import VideoError
from workbench.capture.live import LiveTracker


def test_bad_frames_and_arguments_are_named() -> None:
    model = workbench.load_sample("head")
    with pytest.raises(VideoError, match="l1"):
        LiveTracker(model, l1=-1.0)
    with pytest.raises(VideoError, match="min_confidence"):
        LiveTracker(model, min_confidence=1.0)
    live = LiveTracker(model)
    with pytest.raises(VideoError, match=r"\(h, w, 3\)"):
        live.push(np.zeros((64, 64), np.uint8), 0.0)
    with pytest.raises(VideoError, match="uint8"):
        live.push(np.zeros((64, 64, 3), np.float32), 0.0)
    with pytest.raises(VideoError, match="no frame"):
        live.take()


@pytest.fixture(scope="module")
def frames():
    pytest.importorskip("pyvista")
    pytest.importorskip("mediapipe")
    model = workbench.load_sample("head")
    return model, render_take(model)


@pytest.mark.ui
def test_pushing_the_take_frame_by_frame_gives_the_offline_tracking(frames) -> None:
    from workbench.capture import LANDMARK_L1
    from workbench.capture.track import DEFAULT_TEMPORAL
    from workbench.capture.video import track_video

    model, F = frames
    offline = track_video(model, F, l1=LANDMARK_L1, temporal=DEFAULT_TEMPORAL)
    with LiveTracker(model, adapt=False) as live:
        got = [live.push(img, f / 30.0) for f, img in enumerate(F)]
    assert all(g.ok for g in got) and got[0].note.startswith("registered")
    take = live.take()
    assert take.n_frames == len(F) and take.info["rate"] == pytest.approx(30.0)
    np.testing.assert_allclose(take.weights, offline.weights, atol=1e-6)
    np.testing.assert_allclose(take.poses, offline.poses, atol=1e-6)
    names = list(model.shape_names)
    jaw = take.weights[:, names.index("jawOpen")]
    assert np.corrcoef(jaw, JAW)[0, 1] > 0.95
    blink = take.weights[:, names.index("eyeBlinkLeft")]
    assert blink[BLINK == 1.0].mean() > blink[BLINK == 0.0].mean() + 0.3
    assert set(got[5].seconds) >= {"landmarks", "solve"}


@pytest.mark.ui
def test_the_live_sparsity_drops_false_readings_and_keeps_the_expressions(frames) -> None:
    """LANDMARK_L1 against the marker tracker's l1 on the rendered take (jaw ramp, blink, head turn): FaceMesh
    misreads the jaw and the turn as a mix of other shapes; the live default keeps far fewer of them, so
    its error beats all-zero weights (the markers' l1 did not: 0.125 against 0.122), and the jaw and
    blink read as well."""
    from workbench.capture import LANDMARK_L1
    from workbench.capture.track import DEFAULT_L1

    model, F = frames
    names = list(model.shape_names)
    truth = np.zeros((len(F), len(names)))
    truth[:, names.index("jawOpen")] = JAW
    truth[:, names.index("eyeBlinkLeft")] = truth[:, names.index("eyeBlinkRight")] = BLINK
    face = np.array([not n.startswith("eyeLook") and n != "tongueOut" for n in names])
    still = face & (truth.max(0) == 0)  # face shapes the take never moves
    got = {}
    for l1 in (DEFAULT_L1, LANDMARK_L1):
        with LiveTracker(model, l1=l1) as live:
            got[l1] = np.array([live.push(img, f / 30.0).weights for f, img in enumerate(F)])
    false = {k: float(W[:, still].sum(1).mean()) for k, W in got.items()}
    rmse = {k: float(np.sqrt(np.mean((W - truth)[:, face] ** 2))) for k, W in got.items()}
    zeros = float(np.sqrt(np.mean(truth[:, face] ** 2)))
    print("false readings", false, "RMSE", rmse, "zeros", zeros)
    assert LANDMARK_L1 > DEFAULT_L1 and false[LANDMARK_L1] < 0.7 * false[DEFAULT_L1]
    assert rmse[LANDMARK_L1] < min(zeros, rmse[DEFAULT_L1])
    W = got[LANDMARK_L1]
    assert np.corrcoef(W[:, names.index("jawOpen")], JAW)[0, 1] > 0.95
    blink = W[:, names.index("eyeBlinkLeft")]
    assert blink[BLINK == 1.0].mean() > blink[BLINK == 0.0].mean() + 0.3


@pytest.mark.ui
def test_no_face_holds_the_last_pose_and_the_take_survives_a_stop(frames) -> None:
    model, F = frames
    live = LiveTracker(model)
    blank = np.full_like(F[0], 40)
    first = live.push(blank, 0.0)  # nothing yet: the rest pose, not ok
    assert not first.ok and "no face" in first.note and np.array_equal(first.pose, np.eye(4))
    with pytest.raises(VideoError, match="no face was seen"):
        live.take()
    for f in range(1, 12):
        last = live.push(F[f], f / 30.0)
    assert last.ok
    held = live.push(blank, 12 / 30.0)
    assert not held.ok and "no face" in held.note
    np.testing.assert_array_equal(held.weights, last.weights)
    np.testing.assert_array_equal(held.pose, last.pose)
    with pytest.raises(VideoError, match="timestamp"):
        live.push(F[13], 12 / 30.0)
    with pytest.raises(VideoError, match="like the first"):
        live.push(F[13][:240], 13 / 30.0)
    live.close()  # the camera stops mid-take: what was recorded is kept
    take = live.take()
    assert take.n_frames == 13 and take.held.tolist() == [True] + [False] * 11 + [True]
    np.testing.assert_array_equal(take.weights[0], take.weights[1])  # before the first face: its values
    assert np.isnan(live.landmarks[0]).all() and np.isfinite(live.landmarks[5]).all()


@pytest.mark.ui
def test_two_faces_track_the_larger(frames) -> None:
    from PIL import Image

    model, F = frames
    big = F[0]
    small = np.asarray(Image.fromarray(F[0]).resize((160, 160)))
    scene = np.full((480, 720, 3), 40, np.uint8)
    scene[:, :480] = big
    scene[20:180, 540:700] = small
    with LiveTracker(model, adapt=False) as live:
        got = live.push(scene, 0.0)
    assert got.ok and got.landmarks is not None
    xs = got.landmarks[:, 0] * 720
    assert xs.mean() < 480, "the larger face (left) is tracked"


@pytest.mark.ui
def test_a_take_with_dropped_frames_keys_them_at_their_own_times(frames) -> None:
    model, F = frames
    kept = [0, 1, 2, 5, 6, 9, 10, 11, 15]  # the kernel could not keep up with every camera frame
    with LiveTracker(model, adapt=True, adapt_every=2) as live:
        for f in kept:
            live.push(F[f], 100.0 + f / 30.0)
    take = live.take()
    np.testing.assert_allclose(take.times(), (np.array(kept) - kept[0]) / 30.0)
    tl = take.to_timeline(0.0)
    jaw_keys = [k.time for k in tl.tracks["weights/jawOpen"].keys]
    np.testing.assert_allclose(jaw_keys, (np.array(kept) - kept[0]) / 30.0)
    assert take.info["adapted"] is not None and take.fps == 30.0


@pytest.mark.ui
def test_a_guided_calibration_restores_the_amplitude_and_quiets_the_rest(frames) -> None:
    """A session of a neutral face, the jaw wide open and closed eyes (rendered, the actor's timing and
    reach not exact), then the take: the jaw stays within 15 % of its true 1.0 and the weight error falls.

    Uncalibrated the jaw peaks at 0.96 (0.56 with the inner lips on one vertex and FaceMesh's
    depth in the fit, when the calibration had to restore it)."""
    from workbench.capture.expression_calibration import DEFAULT_PROMPTS
    from workbench.testing import calibration_session

    model, F = frames
    names = list(model.shape_names)
    prompts = list(DEFAULT_PROMPTS[:3])  # relax, jaw, eyes closed
    S = calibration_session(model, prompts, seconds=1.2, fps=10.0, seed=1)
    t = np.arange(S.shape[0]) / 10.0
    session = render_take(model, ({n: S[:, j] for j, n in enumerate(names)}, 0.05 * np.sin(t), 0.03 * np.sin(2 * t)))
    truth = np.zeros((len(F), len(names)))
    truth[:, names.index("jawOpen")] = JAW
    truth[:, names.index("eyeBlinkLeft")] = truth[:, names.index("eyeBlinkRight")] = BLINK
    jaw = names.index("jawOpen")
    takes = {}
    for calibrate in (False, True, "after an open jaw"):
        with LiveTracker(model) as live:
            if calibrate == "after an open jaw":  # the camera started on the open jaw, then the session
                for f, img in enumerate(F[-5:]):
                    live.push(img, -1.0 + f / 10.0)
            if calibrate:
                with pytest.raises(VideoError, match="begin_calibration"):
                    live.end_calibration()
                live.begin_calibration(prompts, seconds=1.2)
            got = [live.push(img, f / 10.0) for f, img in enumerate(session)]
            if calibrate:
                assert got[0].prompt == prompts[0].instruction and got[15].prompt == prompts[1].instruction
                assert [got[0].prompt_index, got[15].prompt_index] == [0, 1]
                assert live.calibrating  # the last prompt's time is not over yet
                # the neutral comes from the relax prompt's later half, as its first frame after it says
                assert got[12].note.startswith("neutral set from the relax prompt: registered"), got[12].note
                assert live.neutral_at_ == (0.6, 1.1)
            after = [live.push(img, 10.0 + f / 30.0) for f, img in enumerate(F)]
        if calibrate:
            assert not live.calibrating and after[0].note.startswith("calibrated: 2 expressions held")
            assert after[1].prompt == "" and after[1].prompt_index == -1 and live.calibration_ is not None
        takes[calibrate] = np.array([g.weights for g in after])
    raw, cal, late = takes[False], takes[True], takes["after an open jaw"]
    err = {k: float(np.sqrt(np.mean((W - truth) ** 2))) for k, W in takes.items()}
    print("jaw peak raw / calibrated", raw[:, jaw].max(), cal[:, jaw].max(), "RMSE", err)
    assert abs(raw[:, jaw].max() - 1.0) <= 0.15 and abs(cal[:, jaw].max() - 1.0) <= 0.15, (raw[:, jaw].max(),
                                                                                           cal[:, jaw].max())
    assert err[True] < 0.85 * err[False], err  # measured 0.068 -> 0.051
    # the session mended the start: as good as calibrated from a relaxed one (measured 0.050)
    assert err["after an open jaw"] < err[True] + 0.02 and abs(late[:, jaw].max() - 1.0) <= 0.15, err
    lo, hi = model.shape("jawOpen").slider_min, model.shape("jawOpen").slider_max
    assert (lo <= cal[:, jaw]).all() and (cal[:, jaw] <= hi).all()


@pytest.mark.ui
def test_a_start_mid_expression_is_mended_by_set_neutral(frames) -> None:
    """The camera starts on the open jaw (the take's last frames), then plays the take: read against
    the open jaw, the take's jaw is lost; ``set_neutral`` before its first (relaxed) frame reads it as
    a tracker started relaxed does (the rendered whole take: ``bench_live.py`` table 8)."""
    model, F = frames
    names = list(model.shape_names)
    jaw = names.index("jawOpen")
    truth = np.zeros((len(F), len(names)))
    truth[:, jaw] = JAW
    truth[:, names.index("eyeBlinkLeft")] = truth[:, names.index("eyeBlinkRight")] = BLINK
    with LiveTracker(model) as relaxed:
        want = np.array([relaxed.push(img, f / 30.0).weights for f, img in enumerate(F)])
    got = {}
    for press in (False, True):
        with LiveTracker(model) as live:
            first = [live.push(img, f / 30.0) for f, img in enumerate(F[-5:])]
            assert first[0].note.startswith("registered") and live.neutral_at_ == (0.0, 0.0)
            if press:
                live.set_neutral()
            after = [live.push(img, 1.0 + f / 30.0) for f, img in enumerate(F)]
        if press:
            assert after[0].note.startswith("neutral set on this frame: registered")
            assert live.neutral_at_ == (1.0, 1.0) and not after[1].note
        got[press] = np.array([a.weights for a in after])
    err = {k: float(np.sqrt(np.mean((W - truth) ** 2))) for k, W in got.items()}
    relaxed_err = float(np.sqrt(np.mean((want - truth) ** 2)))
    print("RMSE started on the open jaw / then set_neutral / started relaxed", err, relaxed_err)
    assert got[False][:, jaw].max() < 0.5 and np.corrcoef(got[True][:, jaw], JAW)[0, 1] > 0.95
    # measured 0.241 -> 0.084, started relaxed 0.073 (FaceMesh's tracking mode remembers the open jaw
    # a few frames, so the frames are not the relaxed start's one for one)
    assert err[True] < 0.5 * err[False] and err[True] < relaxed_err + 0.03, (err, relaxed_err)


@pytest.mark.ui
def test_leaning_toward_the_camera_is_not_read_as_expressions(frames) -> None:
    """The take with the actor coming 15 % closer over its first half (the face 15 % larger in the frame):
    with a rigid head pose the larger face reads as every shape that widens it; the similarity pose
    (``fit_scale``, the default) reads the take as at a fixed distance, and its scale is the actor's
    (the whole take: ``bench_live.py`` table 9)."""
    model, F = frames
    T = len(F)
    zoom = np.r_[np.linspace(1.0, 1.15, T // 2), np.full(T - T // 2, 1.15)]
    Z = [zoomed(img, s) for img, s in zip(F, zoom, strict=True)]
    names = list(model.shape_names)
    truth = np.zeros((T, len(names)))
    truth[:, names.index("jawOpen")] = JAW
    truth[:, names.index("eyeBlinkLeft")] = truth[:, names.index("eyeBlinkRight")] = BLINK

    def rmse(frames_, **kw):
        with LiveTracker(model, **kw) as live:
            W = np.array([live.push(img, f / 30.0).weights for f, img in enumerate(frames_)])
        return float(np.sqrt(np.mean((W - truth) ** 2))), live.take()

    still, _ = rmse(F)
    leaning, take = rmse(Z)
    rigid, rigid_take = rmse(Z, fit_scale=False)
    print("RMSE at a fixed distance / leaning in / leaning in with a rigid pose", still, leaning, rigid)
    assert leaning < still + 0.02 and rigid > 2.0 * leaning, (still, leaning, rigid)
    scales = take.info["scales"]
    assert scales[0] == 1.0 and rigid_take.info["scales"] is None
    np.testing.assert_allclose(scales[-10:], 1.15, rtol=0.03)  # FaceMesh's own size wobbles ±2 %


@pytest.mark.ui
def test_a_saved_take_re_tracks_offline_as_it_was_tracked_live(frames, tmp_path) -> None:
    """Save take → ``track_video(model, "take.npz")``: the same landmarks, so the same weights with the same λ's."""
    from workbench.capture import LANDMARK_L1
    from workbench.capture.facemesh import LandmarkSequence
    from workbench.capture.track import DEFAULT_TEMPORAL
    from workbench.capture.video import track_video

    model, F = frames
    with LiveTracker(model) as live:
        for f, img in enumerate(F[:12]):
            live.push(img, 5.0 + f / 24.0)
    path = live.save_take(tmp_path / "take.npz")
    seq = LandmarkSequence.load_take(path)
    assert seq.n_frames == 12 and seq.fps == pytest.approx(24.0) and seq.image_size == live.image_size
    np.testing.assert_array_equal(seq.landmarks, live.landmarks)
    offline = track_video(model, str(path), l1=LANDMARK_L1, temporal=DEFAULT_TEMPORAL)
    np.testing.assert_allclose(offline.weights, live.take().weights, atol=1e-6)
    # by default the sparsity is the live tracker's too (landmarks cannot choose it: see track_video)
    assert track_video(model, str(path)).info["l1"] == LANDMARK_L1 == live.take().info["l1"]


@pytest.mark.ui
def test_a_saved_take_re_tracks_offline_from_the_neutral_the_session_took(frames, tmp_path) -> None:
    """Started on the open jaw, then ``set_neutral``: the saved take keeps that frame, and
    ``track_video`` registers on it unless told another ``rest_frame``."""
    from workbench.capture.facemesh import LandmarkSequence
    from workbench.capture.track import DEFAULT_TEMPORAL
    from workbench.capture.video import track_video

    model, F = frames
    jaw = list(model.shape_names).index("jawOpen")
    with LiveTracker(model) as live:
        for f, img in enumerate(F[-5:]):
            live.push(img, f / 30.0)
        live.set_neutral()
        for f, img in enumerate(F):
            live.push(img, 1.0 + f / 30.0)
    path = live.save_take(tmp_path / "take.npz")
    assert LandmarkSequence.load_take(path).rest_frame == 5  # the take's first frame after the press
    offline = track_video(model, str(path), temporal=DEFAULT_TEMPORAL)  # the live tracker's λ's
    live_w = live.take().weights
    assert np.corrcoef(offline.weights[5:, jaw], JAW)[0, 1] > 0.95
    # the same registration: after the first frames the two runs agree (the temporal prior's start differs)
    np.testing.assert_allclose(offline.weights[15:], live_w[15:], atol=0.05)
    assert track_video(model, str(path), rest_frame=0).weights[5:, jaw].max() < 0.5  # the open jaw as the neutral


def test_a_file_that_is_not_a_saved_take_is_named(tmp_path) -> None:
    from workbench.capture.facemesh import LandmarkSequence

    bad = tmp_path / "other.npz"
    np.savez(bad, landmarks=np.zeros((2, 478, 3)))
    with pytest.raises(VideoError, match=r"other\.npz: a saved live take has .*missing \['image_size', 'timestamps'\]"):
        LandmarkSequence.load_take(bad)
    np.savez(bad, landmarks=np.zeros((2, 478, 3)), timestamps=[1.0, 1.0], image_size=[640, 480])
    with pytest.raises(VideoError, match="timestamps must be increasing"):
        LandmarkSequence.load_take(bad)
    np.savez(bad, landmarks=np.zeros((2, 10, 3)), timestamps=[0.0, 0.1], image_size=[640, 480])
    with pytest.raises(VideoError, match=r"other\.npz: LandmarkSequence: landmarks must be"):
        LandmarkSequence.load_take(bad)
    np.savez(bad, landmarks=np.zeros((2, 478, 3)), timestamps=[0.0, 0.1], image_size=[640, 480])
    assert LandmarkSequence.load_take(bad).rest_frame is None  # a take saved before neutral_frame was written
    np.savez(bad, landmarks=np.zeros((2, 478, 3)), timestamps=[0.0, 0.1], image_size=[640, 480], neutral_frame=[0, 1])
    with pytest.raises(VideoError, match=r"other\.npz: neutral_frame must be one frame index"):
        LandmarkSequence.load_take(bad)
    np.savez(bad, landmarks=np.zeros((2, 478, 3)), timestamps=[0.0, 0.1], image_size=[640, 480], neutral_frame=2)
    with pytest.raises(VideoError, match=r"other\.npz: LandmarkSequence: rest_frame must be a frame with a face"):
        LandmarkSequence.load_take(bad)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(VideoError, match=r"junk\.npz: not a saved live take"):
        LandmarkSequence.load_take(tmp_path / "junk.npz")
