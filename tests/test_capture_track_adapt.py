"""workbench.capture.track with ``adapt``: the dynamic expression model (Bouaziz 2013 §4) driven by markers."""

from __future__ import annotations

import numpy as np
import pytest
from capture_takes import marker_visible_shapes, warped_actor

from workbench.capture import AdaptiveModel, TrackError, synthetic_performance, track
from workbench.capture.rig import ExpressionSpace
from workbench.samples import load_sample

#: a small spectral basis keeps the test fast (the default is 50)
OPTIONS = {"n_basis": 30}


@pytest.fixture(scope="module")
def head():
    return load_sample()


@pytest.fixture(scope="module")
def actor_take(head):
    """60 frames of 100 markers on the sample head smoothly warped (markers up to 9 mm off the rig's neutral)."""
    space = ExpressionSpace.from_model(head)
    seen = marker_visible_shapes(head)
    perf = synthetic_performance(head, 60, seed=6, noise=0.005, shapes=seen)
    warp = warped_actor(head)
    centre = 0.5 * (head.vertices.min(0) + head.vertices.max(0))
    ids = perf.marker_ids
    rng = np.random.default_rng(7)

    def actor(w, pose):
        local = warp(space.positions(w, ids)) - warp(centre[None])[0] + centre
        return local @ pose[:3, :3].T + pose[:3, 3] + rng.normal(0, 0.005, local.shape)

    frames = np.stack([actor(perf.weights[f], perf.poses[f]) for f in range(perf.n_frames)])
    rest = actor(np.zeros(space.k), perf.poses[0])
    return perf, frames, rest


def weight_rmse(res, perf):
    return float(np.sqrt(np.mean((res.weights - perf.weights) ** 2)))


def test_adapting_to_a_face_that_is_not_the_template_lowers_fit_error_and_weight_error(head, actor_take):
    perf, frames, _ = actor_take
    ids = perf.marker_ids
    plain = track(head, frames, vertex_ids=ids)
    adapted = track(head, frames, vertex_ids=ids, adapt=OPTIONS)
    err, err_plain = np.nanmedian(adapted.errors), np.nanmedian(plain.errors)
    rmse, rmse_plain = weight_rmse(adapted, perf), weight_rmse(plain, perf)
    print(f"markers, warped actor: fit error {err:.4f} adapted vs {err_plain:.4f}; "
          f"weight RMSE {rmse:.4f} vs {rmse_plain:.4f}")
    assert err < 0.5 * err_plain
    assert rmse < 0.9 * rmse_plain
    am = adapted.info["adapted"]
    assert isinstance(am, AdaptiveModel) and am.n_frames_ == perf.n_frames
    assert plain.info["adapted"] is None
    # the adapted rig moves its neutral at the markers towards the actor's
    assert np.abs(am.neutral_[ids] - head.vertices[ids]).max() > 0.001 * plain.head_size


def test_neutral_start_fits_the_identity_first(head, actor_take):
    perf, frames, rest = actor_take
    ids = perf.marker_ids
    res = track(head, frames[:15], vertex_ids=ids, adapt=OPTIONS, neutral=rest)
    plain = track(head, frames[:15], vertex_ids=ids)
    assert np.nanmedian(res.errors) < 0.5 * np.nanmedian(plain.errors)
    assert res.info["neutral_offsets"].shape == (100, 3)


def test_without_adapt_the_result_is_the_plain_tracker(head, actor_take):
    perf, frames, _ = actor_take
    ref = track(head, frames[:10], vertex_ids=perf.marker_ids)
    for off in (None, False):
        res = track(head, frames[:10], vertex_ids=perf.marker_ids, adapt=off)
        np.testing.assert_array_equal(res.weights, ref.weights)
        np.testing.assert_array_equal(res.poses, ref.poses)
        np.testing.assert_array_equal(res.errors, ref.errors)
        assert res.info["adapted"] is None


def test_a_given_adaptive_model_is_updated_in_place_and_must_hold_the_markers(head, actor_take):
    perf, frames, _ = actor_take
    ids = perf.marker_ids
    am = AdaptiveModel(head, vertex_ids=np.unique(ids), n_basis=10)
    res = track(head, frames[:4], vertex_ids=ids, adapt=am)
    assert res.info["adapted"] is am and am.n_frames_ == 4
    few = AdaptiveModel(head, vertex_ids=np.unique(ids)[:50], n_basis=10)
    with pytest.raises(TrackError, match="adapt: the AdaptiveModel's vertex_ids_ miss 50 of the marker"):
        track(head, frames[:4], vertex_ids=ids, adapt=few)


@pytest.mark.parametrize(
    ("adapt", "match"),
    [
        ("yes", "adapt must be None, a bool"),
        (1, "adapt must be None, a bool"),
        ({"n_basis": 0}, "adapt: n_basis must be"),
        ({"nonsense": 1}, "adapt: .*nonsense"),
        ({"vertex_ids": [0, 1]}, "adapt: the tracker sets vertex_ids"),
    ],
)
def test_bad_adapt_is_named(head, actor_take, adapt, match):
    perf, frames, _ = actor_take
    with pytest.raises(TrackError, match=match):
        track(head, frames[:3], vertex_ids=perf.marker_ids, adapt=adapt)


def test_markers_off_their_vertices_stay_offsets_the_rig_does_not_chase(head):
    """A neutral start with adaptation keeps what the identity leaves as per-marker offsets.

    Markers glued 3 mm off their vertices in random directions (what FaceMesh landmarks are to
    the registered vertices) on the rig's own face: no identity explains that, so the rest
    calibration keeps the residual as offsets through every adoption and out of the rig's
    updates. When it was dropped, the correctives chased it and the weight error tripled
    (0.043, against 0.022 now; the plain tracker with the same calibration: 0.0014).
    """
    space = ExpressionSpace.from_model(head)
    perf = synthetic_performance(head, 40, seed=3, noise=0.0, shapes=marker_visible_shapes(head))
    ids = perf.marker_ids
    rng = np.random.default_rng(11)
    glue = rng.normal(size=(ids.size, 3))
    glue *= 0.003 * space.size / np.linalg.norm(glue, axis=1, keepdims=True)
    rest = space.positions(np.zeros(space.k), ids) + glue
    frames = perf.markers + np.einsum("tij,mj->tmi", perf.poses[:, :3, :3], glue)
    plain = track(head, frames, vertex_ids=ids, neutral=rest)
    adapted = track(head, frames, vertex_ids=ids, neutral=rest, adapt=OPTIONS)
    rmse, rmse_plain = weight_rmse(adapted, perf), weight_rmse(plain, perf)
    print(f"glued markers: weight RMSE adapted {rmse:.4f}, plain {rmse_plain:.4f}")
    assert rmse_plain < 0.005 and rmse < 0.03
