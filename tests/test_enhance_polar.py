"""Polar parts of detail gradients (Bermano 2014's shape space): hand-worked cases and identities."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from workbench.enhance import polar
from workbench.enhance.polar import from_polar, to_polar


def _rz(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _random_polar(m: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    Q = Rotation.random(m, random_state=seed).as_matrix()
    A = rng.normal(size=(m, 3, 3))
    S = A @ A.transpose(0, 2, 1) / 3 + 0.2 * np.eye(3)  # symmetric positive definite
    return Q, S, Q @ S


def test_a_rotation_about_z_is_its_angle_on_z_and_no_stretch() -> None:
    P = to_polar(_rz(0.7)[None])[0]
    np.testing.assert_allclose(P[:3], [0.0, 0.0, 0.7], atol=1e-12)
    np.testing.assert_allclose(P[3:], [1, 0, 0, 1, 0, 1], atol=1e-12)  # S = I, upper triangle row by row


def test_a_pure_stretch_has_no_rotation() -> None:
    S = np.array([[1.2, 0.1, 0.0], [0.1, 0.9, -0.05], [0.0, -0.05, 1.1]])
    P = to_polar(S[None])[0]
    np.testing.assert_allclose(P[:3], 0.0, atol=1e-12)
    np.testing.assert_allclose(P[3:], [1.2, 0.1, 0.0, 0.9, -0.05, 1.1], atol=1e-12)


@pytest.mark.parametrize("numpy_path", [False, True])
def test_parts_give_the_matrix_back_and_the_rotation_is_the_polar_factor(numpy_path: bool) -> None:
    Q, S, H = _random_polar(3000, seed=1)
    # the hard angles: none, tiny, just below π, exactly π about each axis
    for i, r in enumerate([[0, 0, 0], [1e-9, 0, 0], [0, 0, np.pi - 1e-6], [np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi]]):
        Q[i] = Rotation.from_rotvec(r).as_matrix()
        H[i] = Q[i] @ S[i]
    P = polar._to_polar_numpy(H) if numpy_path else to_polar(H)
    np.testing.assert_allclose(from_polar(P), H, atol=1e-10)
    np.testing.assert_allclose(polar._from_polar_numpy(P), H, atol=1e-10)
    np.testing.assert_allclose(np.linalg.norm(P[:, :3], axis=1),
                               np.linalg.norm(Rotation.from_matrix(Q).as_rotvec(), axis=1), atol=1e-9)
    iu = np.triu_indices(3)
    np.testing.assert_allclose(P[:, 3:], S[:, iu[0], iu[1]], atol=1e-10)


def test_blending_two_turns_keeps_the_size_where_matrices_shrink() -> None:
    theta = 0.6
    P = to_polar(np.stack([_rz(theta), _rz(-theta)]))
    mean = from_polar(0.5 * (P[:1] + P[1:]))[0]
    np.testing.assert_allclose(mean, np.eye(3), atol=1e-12)  # the mean of ±θ is no turn, full size
    matrices = 0.5 * (_rz(theta) + _rz(-theta))
    assert np.linalg.det(matrices[:2, :2]) == pytest.approx(np.cos(theta) ** 2)  # the matrix mean shrinks


def test_blending_turns_about_one_axis_blends_their_angles() -> None:
    P = to_polar(np.stack([_rz(0.2), _rz(1.4)]))
    np.testing.assert_allclose(from_polar(0.3 * P[:1] + 0.7 * P[1:])[0], _rz(0.3 * 0.2 + 0.7 * 1.4), atol=1e-12)


def test_a_reflection_gets_the_closest_rotation() -> None:
    H = np.diag([1.0, 1.0, -0.5])[None]
    P = to_polar(H)
    Q = from_polar(np.concatenate([P[:, :3], [[1, 0, 0, 1, 0, 1]]], axis=1))[0]
    assert np.linalg.det(Q) == pytest.approx(1.0)
    np.testing.assert_allclose(from_polar(P), H, atol=1e-12)


def test_bad_shapes_name_the_argument() -> None:
    with pytest.raises(ValueError, match=r"H must be \(m, 3, 3\)"):
        to_polar(np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"P must be \(m, 9\)"):
        from_polar(np.zeros((4, 3, 3)))
