"""The head pose as a similarity (``track(..., fit_scale=True)``, ``LiveTracker(fit_scale=)``).

A camera's landmarks scale with the actor's distance; a rigid head pose reads the change as
expressions. Identities on exact markers: a rig scaled frame by frame, turned and moved, gives its
weights back and the scales it was given; at scale 1 the similarity is the rigid pose.
The rendered case (FaceMesh, the actor leaning in) is in ``tests/test_live.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from capture_takes import marker_visible_shapes

import workbench
from workbench.capture import track
from workbench.samples import load_sample


@pytest.fixture(scope="module")
def rig():
    """The head with five of the shapes that move its skin, 150 of its vertices as markers, 12 frames of weights."""
    head = load_sample()
    model = workbench.FaceModel(head.vertices, head.faces, [
        workbench.BlendShape(head.shapes[i].name, np.asarray(head.shapes[i].delta))
        for i in marker_visible_shapes(head)[:5]])
    ids = np.arange(0, head.n_vertices, max(head.n_vertices // 150, 1))
    W = np.random.default_rng(2).uniform(0.0, 0.6, (12, len(model.shapes)))
    X = np.asarray(model.vertices)[ids][None] + np.einsum("tk,knc->tnc", W, np.stack(
        [np.asarray(sh.delta)[ids] for sh in model.shapes]))
    return model, ids, W, X


def _turn(deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def test_a_rig_scaled_frame_by_frame_gives_its_weights_and_scales_back(rig) -> None:
    model, ids, W, X = rig
    T = len(W)
    scales = np.linspace(0.85, 1.2, T)
    Rs = [_turn(a) for a in np.linspace(-15.0, 15.0, T)]
    t = np.array([0.3, -0.2, 1.5])
    Y = np.stack([s * X[f] @ R.T + t for f, (s, R) in enumerate(zip(scales, Rs, strict=True))])
    kw = dict(vertex_ids=ids, l1=0.0, temporal=0.0, iterations=4)
    res = track(model, Y, fit_scale=True, **kw)
    np.testing.assert_allclose(res.weights, W, atol=2e-3)
    np.testing.assert_allclose(res.info["scales"], scales, rtol=1e-3)
    # the pose stays rigid: the rotation it was given, the scale is not in it
    for f in range(T):
        np.testing.assert_allclose(res.poses[f][:3, :3], Rs[f], atol=1e-3)
        np.testing.assert_allclose(res.poses[f][:3, 3], t, atol=1e-3)
    rigid = track(model, Y, **kw)
    assert rigid.info["scales"] is None
    assert np.abs(rigid.weights - W).max() > 0.1  # a rigid pose reads the scale as expressions


def test_at_scale_one_the_similarity_is_the_rigid_pose(rig) -> None:
    model, ids, _, X = rig
    Y = np.stack([x @ _turn(a).T for x, a in zip(X, np.linspace(-10.0, 10.0, len(X)), strict=True)])
    kw = dict(vertex_ids=ids, l1=0.01, temporal=0.2, iterations=2)
    a, b = track(model, Y, fit_scale=True, **kw), track(model, Y, **kw)
    np.testing.assert_allclose(a.info["scales"], 1.0, atol=1e-6)
    np.testing.assert_allclose(a.weights, b.weights, atol=1e-5)
    np.testing.assert_allclose(a.poses, b.poses, atol=1e-6)
