"""Generated ground truth (workbench.capture.synthetic): what it promises about its own data."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.capture import synthetic_performance
from workbench.capture.rig import ExpressionSpace
from workbench.samples import load_sample


@pytest.fixture(scope="module")
def head():
    return load_sample()


@pytest.fixture(scope="module")
def perf(head):
    return synthetic_performance(head, 90, seed=3, noise=0.01, occlusion=0.1, points=500, outliers=0.02)


def test_a_pure_function_of_its_arguments(head, perf):
    again = synthetic_performance(head, 90, seed=3, noise=0.01, occlusion=0.1, points=500, outliers=0.02)
    np.testing.assert_array_equal(again.markers, perf.markers)
    np.testing.assert_array_equal(again.clouds[5], perf.clouds[5])
    other = synthetic_performance(head, 90, seed=4, noise=0.01, occlusion=0.1)
    assert not np.array_equal(other.weights, perf.weights)


def test_weights_are_sparse_smooth_and_in_range(head, perf):
    W = perf.weights
    assert W.shape == (90, len(head.shape_names)) and perf.shape_names == tuple(head.shape_names)
    assert W.min() >= 0.0 and W.max() <= 1.0
    active = (W > 0).sum(1).mean()
    assert 1.0 <= active <= 6.0  # `active` = 3 on average
    assert np.abs(np.diff(W, 2, axis=0)).max() < 0.3  # smooth: bumps of 9 frames or more


def test_meshes_are_the_posed_blend_and_match_model_evaluate(head, perf):
    model = load_sample()
    f = 50
    model.set_weights(dict(zip(model.shape_names, perf.weights[f], strict=True)))
    P = perf.poses[f]
    np.testing.assert_allclose(perf.meshes[f], np.asarray(model.evaluate(), np.float64) @ P[:3, :3].T + P[:3, 3],
                               atol=1e-5)
    R = perf.poses[:, :3, :3]
    np.testing.assert_allclose(np.einsum("tji,tjk->tik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    assert np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1, 1))).max() > 3.0  # it moves


def test_markers_landmarks_noise_and_occlusion(head, perf):
    assert perf.markers.shape == (90, 100, 3) and perf.landmarks.shape == (90, 68, 3)
    assert not set(perf.landmark_ids) & set(perf.marker_ids)
    hidden = np.isnan(perf.markers).any(2)
    assert np.array_equal(hidden, np.isnan(perf.markers).all(2))  # a marker is hidden whole
    assert 0.05 < hidden.mean() < 0.15
    seen = ~hidden
    d = perf.markers[seen] - perf.meshes[:, perf.marker_ids][seen]
    assert d.std() == pytest.approx(0.01, rel=0.1)  # the noise asked for, per coordinate


def test_point_clouds_lie_on_the_posed_surface(head, perf):
    F = np.asarray(head.faces)
    assert len(perf.clouds) == 90
    for f in (0, 45, 89):
        X, tri, bary = perf.clouds[f], perf.cloud_triangles[f], perf.cloud_barycentric[f]
        assert X.shape == (500, 3) and (tri == -1).sum() == 10
        inl = tri >= 0
        on = np.einsum("pc,pcd->pd", bary[inl], perf.meshes[f][F[tri[inl]]].astype(np.float64))
        assert (X[inl] - on).std() == pytest.approx(0.01, rel=0.15)
        np.testing.assert_allclose(bary[inl].sum(1), 1.0)


def test_only_the_chosen_shapes_move_and_derived_shapes_follow(head):
    space = ExpressionSpace.from_model(head)
    perf = synthetic_performance(head, 60, seed=1, shapes=["jawOpen", "mouthSmileLeft"], active=2.0, head_motion=0.0)
    moving = np.flatnonzero(perf.weights.max(0) > 0)
    assert set(moving) <= {head.shape_names.index("jawOpen"), head.shape_names.index("mouthSmileLeft")}
    np.testing.assert_array_equal(perf.poses, np.broadcast_to(np.eye(4), perf.poses.shape))
    assert space.k == len(head.shape_names)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"T": 0}, "T must be"), ({"noise": -1.0}, "noise"), ({"occlusion": 1.0}, "occlusion"),
     ({"markers": 10**6}, "markers: asked for"), ({"landmarks": np.array([[1, 2]])}, "landmarks must be"),
     ({"shapes": ["nope"]}, "nope")],
)
def test_bad_arguments(head, kwargs, match):
    args = {"T": 5, **kwargs}
    with pytest.raises(ValueError, match=match):
        synthetic_performance(head, **args)
