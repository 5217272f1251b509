"""workbench.capture.track on generated ground truth (Bouaziz et al. 2013, §3.1), bad input, timeline, undo."""

from __future__ import annotations

import numpy as np
import pytest
from capture_takes import marker_visible_shapes, warped_actor
from scipy.spatial.transform import Rotation

from workbench.capture import TrackError, TrackResult, synthetic_performance, track
from workbench.capture.result import FLAG_HELD
from workbench.capture.rig import ExpressionSpace
from workbench.samples import load_sample

FPS = 30.0


@pytest.fixture(scope="module")
def head():
    return load_sample()


@pytest.fixture(scope="module")
def seen(head):
    """The shapes 100 face markers can see (the eyeball and tongue shapes move no skin marker)."""
    return marker_visible_shapes(head)


@pytest.fixture(scope="module")
def take(head, seen):
    """150 frames, 100 markers with 0.5 mm noise, 5 % occluded, the head turning up to 15 degrees."""
    return synthetic_performance(head, 150, fps=FPS, seed=2, noise=0.005, occlusion=0.05, shapes=seen)


def _state(model):
    return (model.version("shapes"), model.version("weights"), model.version("tracks"),
            len(model.history.undo_labels))


def weight_rmse(res, perf):
    return float(np.sqrt(np.mean((res.weights - perf.weights) ** 2)))


def pose_errors(res, perf):
    """Mean rotation error (degrees) and translation error (head sizes)."""
    R = np.einsum("tji,tjk->tik", res.poses[:, :3, :3], perf.poses[:, :3, :3])
    ang = np.degrees(Rotation.from_matrix(R).magnitude())
    tr = np.linalg.norm(res.poses[:, :3, 3] - perf.poses[:, :3, 3], axis=1) / perf.head_size
    return float(ang.mean()), float(tr.mean())


def jitter(W):
    """Mean squared second difference of the weights."""
    return float(np.mean(np.diff(W, 2, axis=0) ** 2))


# ------------------------------------------------------------------ accuracy on ground truth
def test_markers_with_noise_occlusion_and_head_motion(head, take):
    res = track(head, take.markers, vertex_ids=take.marker_ids, fps=FPS)
    assert isinstance(res, TrackResult)
    assert res.weights.shape == (150, len(head.shape_names)) and res.poses.shape == (150, 4, 4)
    assert res.shape_names == tuple(head.shape_names)
    rmse = weight_rmse(res, take)
    ang, tr = pose_errors(res, take)
    print(f"markers: weight RMSE {rmse:.4f}, rotation {ang:.3f} deg, translation {tr:.5f} head sizes")
    assert rmse < 0.05
    assert ang < 0.3 and tr < 0.005
    # the fit error is the noise: 0.5 mm per coordinate is 0.87 mm per marker
    assert np.nanmedian(res.errors) < 2.0 * take.noise * np.sqrt(3)
    assert not any(res.flags[f] == FLAG_HELD for f in range(150))
    # a pose reproduces the markers: R (neutral + Σ w δ) + t at the marker vertices
    space = ExpressionSpace.from_model(head)
    f = 77
    X = space.positions(res.weights[f], take.marker_ids) @ res.poses[f, :3, :3].T + res.poses[f, :3, 3]
    vis = np.isfinite(take.markers[f]).all(1)
    assert np.sqrt(((X[vis] - take.markers[f, vis]) ** 2).sum(1).mean()) == pytest.approx(res.errors[f])


def test_landmarks_on_another_vertex_set(head, take):
    assert not set(take.landmark_ids) & set(take.marker_ids)
    res = track(head, take.landmarks, vertex_ids=take.landmark_ids, fps=FPS)
    rmse = weight_rmse(res, take)
    ang, tr = pose_errors(res, take)
    print(f"landmarks: weight RMSE {rmse:.4f}, rotation {ang:.3f} deg, translation {tr:.5f} head sizes")
    assert rmse < 0.06
    assert ang < 0.5 and tr < 0.01


def test_noise_free_tracking_is_exact_on_the_markers(head, seen):
    perf = synthetic_performance(head, 30, seed=4, shapes=seen)
    res = track(head, perf.markers, vertex_ids=perf.marker_ids, l1=0.0, temporal=0.0, iterations=4)
    assert np.nanmax(res.errors) < 1e-5 * perf.head_size
    ang, tr = pose_errors(res, perf)
    assert ang < 1e-3 and tr < 1e-5


# ------------------------------------------------------------------ the priors
def _lag(est, truth):
    """The delay (frames, 0.1 steps) that best aligns an estimate with the truth."""
    T = len(truth)
    best, arg = np.inf, 0.0
    for tau in np.arange(0.0, 4.01, 0.1):
        shifted = np.stack([np.interp(np.arange(T) - tau, np.arange(T), truth[:, j]) for j in range(truth.shape[1])], 1)
        e = float(np.mean((est[10:-10] - shifted[10:-10]) ** 2))
        if e < best:
            best, arg = e, tau
    return arg


def _ema(W, a):
    out = np.empty_like(W)
    out[0] = W[0]
    for t in range(1, len(W)):
        out[t] = a * W[t] + (1 - a) * out[t - 1]
    return out


def test_the_temporal_term_lowers_jitter_below_a_per_frame_solve_at_equal_lag(head, seen):
    # 2 mm noise: landmarks from video are this noisy
    perf = synthetic_performance(head, 240, seed=5, noise=0.02, occlusion=0.02, shapes=seen)
    per_frame = track(head, perf.markers, vertex_ids=perf.marker_ids, temporal=0.0).weights
    smooth = track(head, perf.markers, vertex_ids=perf.marker_ids).weights
    lag = _lag(smooth, perf.weights)
    # the per-frame solve smoothed causally (an exponential moving average) until it lags as much
    alphas = np.linspace(1.0, 0.1, 46)
    lags = [_lag(_ema(per_frame, a), perf.weights) for a in alphas]
    a = alphas[int(np.argmin(np.abs(np.array(lags) - lag)))]
    ema = _ema(per_frame, a)
    print(f"lag {lag:.1f} frames; jitter: temporal {jitter(smooth):.2e}, per-frame {jitter(per_frame):.2e}, "
          f"EMA(a={a:.2f}, lag {_lag(ema, perf.weights):.1f}) {jitter(ema):.2e}, truth {jitter(perf.weights):.2e}; "
          f"RMSE {weight_rmse_w(smooth, perf):.4f} / {weight_rmse_w(per_frame, perf):.4f} / {weight_rmse_w(ema, perf):.4f}")
    assert lag <= 1.5
    assert jitter(smooth) < 0.2 * jitter(per_frame)
    assert jitter(smooth) < 0.5 * jitter(ema)
    assert weight_rmse_w(smooth, perf) < weight_rmse_w(ema, perf)


def weight_rmse_w(W, perf):
    return float(np.sqrt(np.mean((W - perf.weights) ** 2)))


def test_l1_is_sparser_than_l2_at_no_worse_error(head, take):
    space = ExpressionSpace.from_model(head)
    out = {}
    for key, l1 in (("l1", None), ("l2", 0.0)):
        res = track(head, take.markers, vertex_ids=take.marker_ids, l1=l1)
        nnz = float((res.weights > 1e-3).sum(1).mean())
        # the error of the tracked face against the true face, over the whole mesh (model frame)
        full = np.mean([np.sqrt(((space.positions(res.weights[f]) - space.positions(take.weights[f])) ** 2).sum(1).mean())
                        for f in range(0, 150, 5)])
        out[key] = (nnz, full, np.nanmean(res.errors))
    print(f"active weights per frame: L1 {out['l1'][0]:.1f}, L2 {out['l2'][0]:.1f}, truth "
          f"{(take.weights > 1e-3).sum(1).mean():.1f}; mesh error {out['l1'][1]:.5f} vs {out['l2'][1]:.5f}")
    assert out["l1"][0] < 0.5 * out["l2"][0]
    assert out["l1"][1] <= out["l2"][1]


# ------------------------------------------------------------------ a face that is not the template
def test_markers_of_a_face_that_is_not_the_template(head, seen):
    """The actor is the sample head smoothly warped (other proportions, a longer nose and chin: markers up
    to 9 mm off the rig's neutral); a calibration take of the actor at rest gives ``neutral``."""
    perf = synthetic_performance(head, 120, seed=6, noise=0.005, shapes=seen)
    warp = warped_actor(head)
    centre = 0.5 * (head.vertices.min(0) + head.vertices.max(0))
    space = ExpressionSpace.from_model(head)
    ids = perf.marker_ids
    rng = np.random.default_rng(7)

    def actor(w, pose):  # the actor's markers for weights w, posed
        local = warp(space.positions(w, ids)) - warp(centre[None])[0] + centre
        return local @ pose[:3, :3].T + pose[:3, 3] + rng.normal(0, 0.005, local.shape)

    frames = np.stack([actor(perf.weights[f], perf.poses[f]) for f in range(perf.n_frames)])
    rest = actor(np.zeros(space.k), perf.poses[0])
    plain = track(head, frames, vertex_ids=ids)
    calibrated = track(head, frames, vertex_ids=ids, neutral=rest)
    rmse, rmse_plain = weight_rmse(calibrated, perf), weight_rmse(plain, perf)
    # the pose of another face is defined up to one constant rigid offset: compare motion relative to frame 0
    rel = np.einsum("ij,tjk->tik", calibrated.poses[0, :3, :3].T, calibrated.poses[:, :3, :3])
    rel_true = np.einsum("ij,tjk->tik", perf.poses[0, :3, :3].T, perf.poses[:, :3, :3])
    ang = np.degrees(Rotation.from_matrix(np.einsum("tji,tjk->tik", rel, rel_true)).magnitude()).mean()
    print(f"warped actor: weight RMSE {rmse:.4f} calibrated, {rmse_plain:.4f} not; relative rotation {ang:.3f} deg; "
          f"fit error {np.nanmedian(calibrated.errors):.4f} vs {np.nanmedian(plain.errors):.4f}")
    assert rmse < 0.06
    assert ang < 0.5
    assert np.nanmedian(calibrated.errors) < 0.5 * np.nanmedian(plain.errors)
    assert rmse_plain > 2 * rmse  # uncalibrated, the rig explains the stranger's face with expressions
    np.testing.assert_allclose(calibrated.info["neutral_offsets"].shape, (100, 3))
    with pytest.raises(TrackError, match="neutral must be a frame index or"):
        track(head, frames[:3], vertex_ids=ids, neutral=rest[:5])
    with pytest.raises(TrackError, match="neutral: frame 7 is not in the take"):
        track(head, frames[:3], vertex_ids=ids, neutral=7)
    # a frame of the take at rest works the same as a calibration take
    with_rest = np.concatenate([rest[None], frames[:20]])
    res = track(head, with_rest, vertex_ids=ids, neutral=0)
    np.testing.assert_array_equal(res.info["neutral_offsets"], calibrated.info["neutral_offsets"])


# ------------------------------------------------------------------ bad input
def test_a_nan_frame_and_a_frame_with_too_few_markers_are_held_and_flagged(head, take):
    Y = take.markers.copy()
    Y[40] = np.nan
    Y[41, 3:] = np.nan  # 3 markers left, fewer than min_markers = 4
    res = track(head, Y, vertex_ids=take.marker_ids)
    assert res.flags[40] == FLAG_HELD and res.flags[41] == FLAG_HELD
    assert res.held.sum() == 2
    np.testing.assert_array_equal(res.weights[40], res.weights[39])
    np.testing.assert_array_equal(res.weights[41], res.weights[39])
    np.testing.assert_array_equal(res.poses[41], res.poses[39])
    assert np.isnan(res.errors[40]) and np.isfinite(np.delete(res.errors, [40, 41])).all()
    assert weight_rmse(res, take) < 0.06


def test_leading_frames_without_markers_take_the_first_tracked_frame(head, take):
    Y = take.markers[:20].copy()
    Y[:3] = np.nan
    res = track(head, Y, vertex_ids=take.marker_ids)
    assert res.flags[:3] == (FLAG_HELD,) * 3
    np.testing.assert_array_equal(res.weights[0], res.weights[3])


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda Y, ids: (np.full_like(Y, np.nan), ids), "frames: no frame has at least"),
        (lambda Y, ids: (Y * 1000.0, ids), r"frames: the markers spread 1e\+03× .* another unit .* by about 0.001"),
        (lambda Y, ids: (Y / 1000.0, ids), "frames: the markers spread 0.001×"),
        (lambda Y, ids: (Y[..., :2], ids), r"frames must be \(T, m, 3\)"),
        (lambda Y, ids: (Y, ids[:-1]), "vertex_ids has 99 ids but frames have 100 markers"),
        (lambda Y, ids: (Y, ids[:, None]), "vertex_ids must be a 1-D array"),
        (lambda Y, ids: (Y, ids + 100000), r"vertex_ids\[0\] = .* is not a vertex of the model"),
        (lambda Y, ids: (Y, ids - ids.max() - 1), r"vertex_ids\[0\] = -"),
        (lambda Y, ids: (Y, ids + 0.5), "vertex_ids must be integers"),
        (lambda Y, ids: (np.where(np.arange(Y.shape[0])[:, None, None] == 3, np.inf, Y), ids), r"frames\[3, 0\] is infinite"),
    ],
)
def test_bad_input_is_a_clear_error_naming_the_argument(head, take, change, match):
    Y, ids = change(take.markers[:10], take.marker_ids)
    before = _state(head)
    with pytest.raises(TrackError, match=match):
        track(head, Y, vertex_ids=ids)
    assert _state(head) == before  # nothing changed


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"l1": -1.0}, "l1 must be"),
        ({"temporal": float("nan")}, "temporal must be"),
        ({"fps": 0.0}, "fps must be"),
        ({"adapt": "yes"}, "adapt must be None, a bool"),
        ({"adapt": {"n_basis": 0}}, "adapt: n_basis must be"),
        ({"iterations": 0}, "iterations"),
        ({"min_markers": 2}, "min_markers"),
        ({"rigid": [0, 1]}, "rigid: need at least 3"),
    ],
)
def test_bad_options_are_named(head, take, kwargs, match):
    with pytest.raises(TrackError, match=match):
        track(head, take.markers[:5], vertex_ids=take.marker_ids, **kwargs)


def test_the_still_markers_carry_the_pose(head, take):
    res = track(head, take.markers[:5], vertex_ids=take.marker_ids)
    rigid = res.info["rigid_markers"]
    space = ExpressionSpace.from_model(head)
    motion = space.motion(take.marker_ids) / space.size
    assert 4 <= len(rigid) < 100 and motion[rigid].max() <= 0.01
    # given explicitly (here: every marker), they are used
    res_all = track(head, take.markers[:5], vertex_ids=take.marker_ids, rigid=np.ones(100, bool))
    assert len(res_all.info["rigid_markers"]) == 100


def test_progress_is_reported(head, take):
    calls = []
    track(head, take.markers[:30], vertex_ids=take.marker_ids, progress=lambda f, msg: calls.append((f, msg)))
    fractions = [f for f, _ in calls]
    assert fractions == sorted(fractions) and fractions[0] == 0.0 and fractions[-1] == 1.0
    assert all(isinstance(m, str) and m for _, m in calls)


# ------------------------------------------------------------------ derived shapes follow their drivers
def test_a_corrective_follows_its_drivers(seen):
    model = load_sample()
    names = model.shape_names
    a, b = "jawOpen", "mouthSmileLeft"
    model.shape_tools.add_corrective(None, [a, b], delta=0.3 * np.asarray(model.shape("mouthPucker").delta))
    perf = synthetic_performance(model, 60, seed=8, noise=0.002, shapes=[names.index(a), names.index(b)],
                                 active=1.5)
    k = names.index("mouthPucker")
    res = track(model, perf.markers, vertex_ids=perf.marker_ids)
    j = model.shape_names.index("jawOpen_mouthSmileLeft")
    assert "jawOpen_mouthSmileLeft" in res.derived
    np.testing.assert_allclose(res.weights[:, j], res.weights[:, names.index(a)] * res.weights[:, names.index(b)],
                               atol=1e-12)
    assert weight_rmse(res, perf) < 0.05
    assert res.weights[:, k].max() < 0.1  # the corrective's shape is not explained by mouthPucker
    tl = res.to_timeline(0.01)
    assert "weights/jawOpen_mouthSmileLeft" not in tl.tracks


# ------------------------------------------------------------------ timeline and undo
def test_to_timeline_round_trip_within_the_tolerance(head, take):
    res = track(head, take.markers, vertex_ids=take.marker_ids)
    for tol in (0.0, 0.01, 0.05):
        tl = res.to_timeline(tol, start=2.0)
        times = res.times(2.0)
        W = tl.weight_matrix(head.shape_names, times)
        assert np.abs(W - res.weights).max() <= tol + 1e-9
        n_keys = sum(len(t.keys) for n, t in tl.tracks.items() if n.startswith("weights/"))
        if tol == 0.0:
            assert n_keys == 150 * len(head.shape_names)
        elif tol == 0.05:
            assert n_keys < 0.25 * 150 * len(head.shape_names)
        pose = tl.head_pose.sample(times)
        np.testing.assert_allclose(pose[:, :3], res.poses[:, :3, 3], atol=1e-3 * res.head_size + 1e-12)
        R = np.stack([Rotation.from_quat(q).as_matrix() for q in pose[:, 3:]])
        ang = np.degrees(Rotation.from_matrix(np.einsum("tji,tjk->tik", R, res.poses[:, :3, :3])).magnitude())
        assert ang.max() < 0.15
    assert tl.fps == FPS and tl.start == 2.0 and tl.end == pytest.approx(2.0 + 149 / FPS)


def test_apply_is_one_undo_step_and_reproduces_the_take(take):
    model = load_sample()
    model.timeline.key_weights(0.0, ["browInnerUp"])  # something already there
    model.timeline.add_key("weights/cheekPuff", 10.0, 0.5)
    before = model.timeline.value
    res = model.capture.track(take.markers, vertex_ids=take.marker_ids, fps=FPS)
    n_undo = len(model.history.undo_labels)
    tl = model.capture.apply(res, tolerance=0.005)
    assert model.timeline.value is tl
    assert tl.tracks["weights/cheekPuff"] is not before.tracks["weights/cheekPuff"]  # replaced by the take
    assert tl.end >= 10.0 - 1e-9 or tl.end == pytest.approx(149 / FPS)
    # the evaluated model at frame f reproduces the markers within the noise and the reduction tolerance
    for f in (0, 60, 149):
        mesh = model.evaluate_at(f / FPS)
        X = np.asarray(mesh, np.float64)[take.marker_ids]
        vis = np.isfinite(take.markers[f]).all(1)
        rms = np.sqrt(((X[vis] - take.markers[f, vis]) ** 2).sum(1).mean())
        assert rms < res.errors[f] + 0.005 * take.head_size
    assert len(model.history.undo_labels) == n_undo + 1
    assert model.history.undo_labels[-1].startswith("Apply capture (150 frames")
    model.undo()
    assert model.timeline.value is before
    model.redo()
    assert model.timeline.value is tl


def test_apply_refuses_a_result_for_other_shapes_and_changes_nothing(take):
    from workbench.core.shapes import ModelError

    model = load_sample()
    res = track(model, take.markers[:10], vertex_ids=take.marker_ids)
    model.remove_shape("tongueOut")
    before, state = model.timeline.value, _state(model)
    with pytest.raises(ModelError, match="track again"):
        model.capture.apply(res)
    assert model.timeline.value is before and _state(model) == state
    with pytest.raises(ModelError, match="TrackResult"):
        model.capture.apply("not a result")  # type: ignore[arg-type]


def test_track_result_checks_its_arrays_and_leaves_the_callers_alone(head):
    names = tuple(head.shape_names)
    W = np.zeros((4, len(names)))
    res = TrackResult(W, np.tile(np.eye(4), (4, 1, 1)), np.zeros(4), ("",) * 4, 30.0, names)
    assert W.flags.writeable and not res.weights.flags.writeable
    W[0, 0] = 1.0
    assert res.weights[0, 0] == 0.0
    with pytest.raises(ValueError, match="weights must be"):
        TrackResult(np.zeros(3), np.zeros((3, 4, 4)), np.zeros(3), ("",) * 3, 30.0, names)
    with pytest.raises(ValueError, match="poses must be"):
        TrackResult(W, np.zeros((3, 4, 4)), np.zeros(4), ("",) * 4, 30.0, names)
    with pytest.raises(ValueError, match="flags must have 4"):
        TrackResult(W, np.tile(np.eye(4), (4, 1, 1)), np.zeros(4), ("",), 30.0, names)
    with pytest.raises(ValueError, match="tolerance"):
        res.to_timeline(-1.0)
