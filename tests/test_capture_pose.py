"""Robust rigid pose (workbench.capture.pose): exact recovery, outliers, NaN points, degenerate input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from workbench.capture.pose import PoseError, fit_rigid, fit_rigid_robust


def _scene(seed: int, n: int = 30):
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 3)) * [1.0, 1.5, 0.7]
    R = Rotation.random(random_state=seed).as_matrix()
    t = rng.normal(size=3) * 5
    return P, R, t


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_exact_recovery_of_a_known_pose(seed):
    P, R, t = _scene(seed)
    Q = P @ R.T + t
    M = fit_rigid(P, Q)
    np.testing.assert_allclose(M[:3, :3], R, atol=1e-12)
    np.testing.assert_allclose(M[:3, 3], t, atol=1e-11)
    np.testing.assert_allclose(M[3], [0, 0, 0, 1])
    pose = fit_rigid_robust(P, Q)
    np.testing.assert_allclose(pose.matrix, M, atol=1e-11)
    assert pose.rms < 1e-10 and pose.scale == 1.0


def test_scale_is_recovered_when_asked_and_not_invented_otherwise():
    P, R, t = _scene(3)
    Q = 2.5 * P @ R.T + t
    M = fit_rigid(P, Q, scale=True)
    np.testing.assert_allclose(M[:3, :3], 2.5 * R, atol=1e-11)
    np.testing.assert_allclose(M[:3, 3], t, atol=1e-10)
    rigid = fit_rigid(P, Q)
    assert np.linalg.det(rigid[:3, :3]) == pytest.approx(1.0)  # a rotation, whatever the data


def test_a_mirrored_cloud_still_gives_a_rotation():
    P, _, _ = _scene(4)
    Q = P * [-1.0, 1.0, 1.0]
    M = fit_rigid(P, Q)
    assert np.linalg.det(M[:3, :3]) == pytest.approx(1.0)


def test_weights_zero_ignore_a_point_and_nan_points_are_ignored():
    P, R, t = _scene(5)
    Q = P @ R.T + t
    Q[0] += 10.0
    w = np.ones(len(P))
    w[0] = 0.0
    np.testing.assert_allclose(fit_rigid(P, Q, w), fit_rigid(P[1:], Q[1:]), atol=1e-12)
    Q2 = Q.copy()
    Q2[0] = np.nan
    np.testing.assert_allclose(fit_rigid(P, Q2), fit_rigid(P[1:], Q[1:]), atol=1e-12)
    pose = fit_rigid_robust(P, Q2)
    assert pose.weights[0] == 0.0


@pytest.mark.parametrize("loss", ["tukey", "huber"])
def test_outliers_are_rejected(loss):
    P, R, t = _scene(6, n=40)
    rng = np.random.default_rng(7)
    Q = P @ R.T + t + rng.normal(0, 0.01, P.shape)
    bad = np.arange(6)
    Q[bad] += rng.normal(0, 2.0, (6, 3))  # 15 % gross outliers (swapped or ghost markers)
    plain = fit_rigid(P, Q)
    pose = fit_rigid_robust(P, Q, loss=loss)
    err = lambda M: np.degrees(Rotation.from_matrix(M[:3, :3] @ R.T).magnitude())  # noqa: E731
    oracle = fit_rigid(P[6:], Q[6:])  # least squares knowing which points are bad
    assert err(plain) > 1.0  # the least-squares pose is pulled away
    assert err(pose.matrix) < 1.5 * err(oracle) + 0.01  # degrees: as good as the oracle, at the noise floor
    assert np.linalg.norm(pose.translation - t) < 1.5 * np.linalg.norm(oracle[:3, 3] - t) + 0.005
    if loss == "tukey":
        assert np.all(pose.weights[bad] == 0.0) and np.all(pose.weights[6:] > 0.5)
    else:
        assert pose.weights[bad].max() < pose.weights[6:].min()


def test_degenerate_input_is_a_clear_error():
    P, R, t = _scene(8)
    Q = P @ R.T + t
    with pytest.raises(PoseError, match="at least 3 points"):
        fit_rigid(P[:2], Q[:2])
    Qn = Q.copy()
    Qn[2:] = np.nan
    with pytest.raises(PoseError, match="at least 3 points"):
        fit_rigid_robust(P, Qn)
    line = np.outer(np.linspace(0, 1, 10), [1.0, 2.0, 3.0])
    with pytest.raises(PoseError, match="collinear"):
        fit_rigid(line, line + 1.0)
    with pytest.raises(PoseError, match="collinear"):
        fit_rigid_robust(np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(PoseError, match="P must be"):
        fit_rigid(P[:, :2], Q[:, :2])
    with pytest.raises(PoseError, match="Q must have the shape"):
        fit_rigid(P, Q[:-1])
    with pytest.raises(PoseError, match="weights"):
        fit_rigid(P, Q, -np.ones(len(P)))
    with pytest.raises(PoseError, match="loss"):
        fit_rigid_robust(P, Q, loss="cauchy")  # type: ignore[arg-type]


def test_apply_reproduces_the_points():
    P, R, t = _scene(9)
    Q = P @ R.T + t
    pose = fit_rigid_robust(P, Q)
    np.testing.assert_allclose(pose.apply(P), Q, atol=1e-10)


def test_one_closed_form_behind_every_rigid_fit() -> None:
    """fit_rigid, fit_similarity and rigid_align are procrustes; a hand-made pose comes back exactly."""
    from workbench.enhance.gradients import rigid_align
    from workbench.geometry.similarity import fit_similarity, procrustes

    rng = np.random.default_rng(4)
    P = rng.normal(size=(30, 3))
    a = 0.7
    R0 = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    t0, s0 = np.array([0.3, -1.0, 2.0]), 1.7
    w = rng.uniform(0.5, 2.0, 30)
    Q = s0 * P @ R0.T + t0
    R, t, s, sv = procrustes(P, Q, w, scale=True)
    np.testing.assert_allclose(R, R0, atol=1e-12)
    np.testing.assert_allclose(t, t0, atol=1e-12)
    assert abs(s - s0) < 1e-12 and np.all(np.diff(sv) <= 0)
    M = fit_rigid(P, Q, w, scale=True)
    np.testing.assert_allclose(M[:3, :3], s0 * R0, atol=1e-12)
    sim = fit_similarity(P, Q, w)
    np.testing.assert_allclose(sim(P), Q, atol=1e-12)
    Rr, tr = rigid_align(P, Q / s0, w)
    np.testing.assert_allclose(Rr, R0, atol=1e-12)
    np.testing.assert_allclose(tr, t0 / s0, atol=1e-12)
    # a mirror image is not a rotation: the closest rotation, det +1
    Rm, _, _, _ = procrustes(P, P * np.array([1.0, 1.0, -1.0]))
    assert np.linalg.det(Rm) > 0.999999
