"""Per-marker weights in the marker tracker (``track(..., marker_weights=)``) and FaceMesh's landmark weights.

Identities: unit weights are the unweighted tracker; weights scaled by a constant change
nothing (the fit term is averaged over the total weight, so the λ's keep their meaning); a
marker of weight 0 does not reach the weights however wrong it is. And the one place it is
used: FaceMesh landmarks on features weigh more than those on smooth skin. And the depth axis
(``depth_axis=``: a monocular detector's guessed depth, along the camera's axis, which stays put while
the head turns under it): markers moved along it reach neither the weights nor the λ choice, and a
rig moving only along it reads none.
"""

from __future__ import annotations

import numpy as np
import pytest
from capture_takes import marker_visible_shapes

from workbench.capture import TrackError, synthetic_performance, track
from workbench.capture.landmark_registration import (
    FEATURE_LANDMARKS,
    OTHER_LANDMARK_WEIGHT,
    landmark_weights,
)
from workbench.capture.result import FLAG_HELD
from workbench.samples import load_sample


@pytest.fixture(scope="module")
def head():
    return load_sample()


@pytest.fixture(scope="module")
def take(head):
    """60 frames, 100 markers with 0.5 mm noise, 5 % occluded, the head turning."""
    return synthetic_performance(head, 60, fps=30.0, seed=3, noise=0.005, occlusion=0.05,
                                 shapes=marker_visible_shapes(head))


def _track(head, take, weights=None, markers=None, **kw):
    return track(head, take.markers if markers is None else markers, vertex_ids=take.marker_ids,
                 l1=0.01, temporal=0.25, marker_weights=weights, **kw)


def test_unit_weights_are_the_unweighted_tracker(head, take) -> None:
    plain = _track(head, take)
    ones = _track(head, take, np.ones(take.marker_ids.size))
    np.testing.assert_array_equal(ones.weights, plain.weights)
    np.testing.assert_array_equal(ones.poses, plain.poses)
    np.testing.assert_array_equal(plain.info["marker_weights"], np.ones(take.marker_ids.size))


def test_weights_scaled_by_a_constant_change_nothing(head, take) -> None:
    s = np.random.default_rng(0).uniform(0.2, 1.0, take.marker_ids.size)
    a, b = _track(head, take, s), _track(head, take, 7.0 * s)
    np.testing.assert_allclose(b.weights, a.weights, atol=1e-7)
    # and they matter: the weighted fit is another fit
    assert np.abs(a.weights - _track(head, take).weights).max() > 1e-3


def test_a_marker_of_weight_zero_does_not_reach_the_weights(head, take) -> None:
    # a marker that moves with the face (not one the head pose is fitted on), glued 2 cm off
    res0 = _track(head, take)
    moving = np.setdiff1d(np.arange(take.marker_ids.size), res0.info["rigid_markers"])
    k = int(moving[0])
    w = np.ones(take.marker_ids.size)
    w[k] = 0.0
    bad = take.markers.copy()
    bad[:, k] += np.array([0.2, -0.1, 0.1])  # dm: 2.4 cm
    clean, dirty = _track(head, take, w), _track(head, take, w, markers=bad)
    np.testing.assert_allclose(dirty.weights, clean.weights, atol=1e-9)
    # unweighted, the same marker pulls the weights away
    assert np.abs(_track(head, take, markers=bad).weights - res0.weights).max() > 0.05


def test_weights_keep_the_held_frames_and_the_lambda_choice_working(head, take) -> None:
    Y = take.markers.copy()
    Y[10] = np.nan
    w = np.where(np.arange(take.marker_ids.size) % 2 == 0, 1.0, 0.25)
    res = track(head, Y, vertex_ids=take.marker_ids, marker_weights=w)  # λ's chosen by held-out markers
    assert res.flags[10] == FLAG_HELD
    assert res.info["lambda_choice"] is not None and np.isfinite(res.info["lambda_choice"]["heldout"])
    assert np.sqrt(np.mean((res.weights - take.weights) ** 2)) < 0.08


@pytest.mark.parametrize(
    ("weights", "match"),
    [
        (np.ones(5), r"marker_weights must have one weight per marker \(100,\), got shape \(5,\)"),
        (-np.ones(100), "marker_weights must be finite, ≥ 0 and not all 0"),
        (np.zeros(100), "marker_weights must be finite, ≥ 0 and not all 0"),
        (np.full(100, np.nan), "marker_weights must be finite"),
    ],
)
def test_bad_weights_are_named(head, take, weights, match) -> None:
    with pytest.raises(TrackError, match=match):
        _track(head, take, weights, markers=take.markers[:5])


def test_facemesh_feature_landmarks_weigh_one_and_the_rest_less() -> None:
    w = landmark_weights()
    assert w.shape == (478,) and len(set(FEATURE_LANDMARKS)) == len(FEATURE_LANDMARKS) == 116
    assert (w[list(FEATURE_LANDMARKS)] == 1.0).all()
    assert np.count_nonzero(w == OTHER_LANDMARK_WEIGHT) == 478 - 116
    assert (landmark_weights(1.0) == 1.0).all()
    with pytest.raises(Exception, match=r"other: a landmark weight in \[0, 1\]"):
        landmark_weights(2.0)


def test_the_feature_landmarks_are_mediapipes_contours() -> None:
    connections = pytest.importorskip("mediapipe.python.solutions.face_mesh_connections")
    sets = (connections.FACEMESH_LIPS, connections.FACEMESH_LEFT_EYE, connections.FACEMESH_RIGHT_EYE,
            connections.FACEMESH_LEFT_EYEBROW, connections.FACEMESH_RIGHT_EYEBROW, connections.FACEMESH_NOSE)
    ids = {i for s in sets for pair in s for i in pair}
    assert ids == set(FEATURE_LANDMARKS)


def test_moving_markers_along_the_depth_axis_does_not_reach_the_weights(head, take) -> None:
    # a monocular detector's depth: markers shifted along the camera's axis (fixed in the frames'
    # coordinates while the head turns under it), by a different amount per marker and frame, fit
    # the same weights across that axis
    axis = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    clean = _track(head, take, depth_axis=axis)
    moving = np.setdiff1d(np.arange(take.marker_ids.size), clean.info["rigid_markers"])
    shift = np.random.default_rng(1).uniform(-0.1, 0.1, (take.markers.shape[0], moving.size))  # dm: ±1 cm
    bad = take.markers.copy()
    bad[:, moving] += shift[..., None] * axis
    dirty = _track(head, take, markers=bad, depth_axis=axis)
    np.testing.assert_allclose(dirty.weights, clean.weights, atol=1e-4)  # the solver's tolerance (measured 5e-6)
    np.testing.assert_allclose(clean.info["depth_axis"], axis)
    # the λ's keep their scale (an average shape's motion in all three coordinates)
    assert clean.info["lambda_scale"] == _track(head, take).info["lambda_scale"]
    # without the axis the same shifts pull the weights away
    assert np.abs(_track(head, take, markers=bad).weights - _track(head, take).weights).max() > 0.05


def test_the_lambda_choice_does_not_see_the_depth_axis(head, take) -> None:
    # the held-out markers score the λ's across the axis, as the tracker fits: shifts along it change nothing
    axis = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    kw = dict(vertex_ids=take.marker_ids, l1="auto", temporal="auto", depth_axis=axis)
    clean = track(head, take.markers, **kw)
    moving = np.setdiff1d(np.arange(take.marker_ids.size), clean.info["rigid_markers"])
    bad = take.markers.copy()
    bad[:, moving] += np.random.default_rng(4).uniform(-0.1, 0.1, (bad.shape[0], moving.size))[..., None] * axis
    dirty = track(head, bad, **kw)
    a, b = clean.info["lambda_choice"], dirty.info["lambda_choice"]
    assert (dirty.info["l1"], dirty.info["temporal"]) == (clean.info["l1"], clean.info["temporal"])
    np.testing.assert_allclose(np.array(b["grid"])[:, 2], np.array(a["grid"])[:, 2], rtol=1e-5)
    # without the axis the same shifts are held-out error
    plain = track(head, bad, **{**kw, "depth_axis": None}).info["lambda_choice"]
    assert plain["heldout"] > 1.5 * a["heldout"]


def test_a_rig_moving_only_along_the_depth_axis_reads_no_weights(head) -> None:
    import workbench

    flat = workbench.FaceModel(head.vertices, head.faces, [
        workbench.BlendShape(s.name, np.asarray(s.delta) * np.array([0.0, 0.0, 1.0])) for s in head.shapes[:5]])
    # the head still: the camera's axis is the rig's z in every frame
    still = synthetic_performance(head, 30, fps=30.0, seed=3, noise=0.005, head_motion=0.0,
                                  shapes=marker_visible_shapes(head))
    res = track(flat, still.markers, vertex_ids=still.marker_ids, l1=0.01, temporal=0.25, depth_axis=(0, 0, 2.0))
    assert np.abs(res.weights).max() < 1e-9
    assert np.abs(track(flat, still.markers, vertex_ids=still.marker_ids, l1=0.01, temporal=0.25).weights).max() > 0.05


def test_the_depth_axis_stays_with_the_camera_as_the_head_turns(head) -> None:
    # a rig seen from a camera looking along z, its head turned 30° about y: markers moved along the
    # camera's z do not reach the weights; along the rig's own z (which the turn has moved off the
    # camera's axis) they do, by what the turn brings into the image plane
    model = workbench_model(head)
    ids = np.arange(0, head.n_vertices, max(head.n_vertices // 150, 1))
    k = len(model.shapes)
    W = np.random.default_rng(2).uniform(0.0, 0.6, (12, k))
    c, s = np.cos(np.deg2rad(30.0)), np.sin(np.deg2rad(30.0))
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    X = np.asarray(head.vertices)[ids][None] + np.einsum("tk,knc->tnc", W, np.stack(
        [np.asarray(sh.delta)[ids] for sh in model.shapes]))
    Y = X @ R.T
    kw = dict(vertex_ids=ids, l1=0.0, temporal=0.0, iterations=4)
    exact = track(model, Y, depth_axis=(0, 0, 1), **kw)
    along = np.random.default_rng(3).uniform(-0.1, 0.1, Y.shape[:2])[..., None]
    along[:, exact.info["rigid_markers"]] = 0.0  # the head pose's markers stay put
    camera = track(model, Y + along * np.array([0.0, 0.0, 1.0]), depth_axis=(0, 0, 1), **kw)
    rig_z = track(model, Y + along * (R @ np.array([0.0, 0.0, 1.0])), depth_axis=(0, 0, 1), **kw)
    np.testing.assert_allclose(exact.weights, W, atol=2e-3)
    np.testing.assert_allclose(camera.weights, exact.weights, atol=1e-8)  # measured 5e-13
    assert np.abs(rig_z.weights - exact.weights).max() > 0.02


def workbench_model(head):
    """The head with five of the shapes that move its skin (the eyeball and tongue shapes move none)."""
    import workbench

    return workbench.FaceModel(head.vertices, head.faces, [
        workbench.BlendShape(head.shapes[i].name, np.asarray(head.shapes[i].delta))
        for i in marker_visible_shapes(head)[:5]])


@pytest.mark.parametrize("axis", [(0.0, 0.0, 0.0), (1.0, 2.0), (np.nan, 0.0, 1.0), "z"])
def test_a_bad_depth_axis_is_named(head, take, axis) -> None:
    with pytest.raises(TrackError, match="depth_axis must be a"):
        _track(head, take, markers=take.markers[:5], depth_axis=axis)
