"""Sign conventions and identities of the discrete operators."""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse as sp
import trimesh
from grid_meshes import grid_triangles

from workbench.geometry.normals import vertex_normals
from workbench.geometry.operators import bilaplacian, cotangent_laplacian, mass_matrix


def _sphere(subdivisions: int = 4) -> tuple[np.ndarray, np.ndarray]:
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return np.asarray(s.vertices), np.asarray(s.faces)


def _plane(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    xs, ys = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    V[:, :2] += rng.uniform(-0.03, 0.03, (V.shape[0], 2))  # irregular but valid triangles
    return V, grid_triangles(n)


def test_laplacian_symmetric_negative_semidefinite_rows_sum_to_zero() -> None:
    V, F = _sphere(2)
    L = cotangent_laplacian(V, F)
    assert abs(L - L.T).max() < 1e-12
    np.testing.assert_allclose(np.asarray(L.sum(axis=1)).ravel(), 0.0, atol=1e-10)
    assert np.all(L.diagonal() < 0)
    eig = np.linalg.eigvalsh(L.toarray())
    assert eig.max() < 1e-9  # negative semi-definite


def test_laplacian_points_inward_on_sphere_with_mean_curvature_two() -> None:
    V, F = _sphere(4)
    L, M = cotangent_laplacian(V, F), mass_matrix(V, F)
    HN = sp.diags(1.0 / M.diagonal()) @ L @ V  # = -2 H n
    radial = np.einsum("ij,ij->i", HN, V)
    assert np.all(radial < 0)  # inward
    np.testing.assert_allclose(np.median(-radial), 2.0, rtol=0.02)


def test_laplacian_is_exact_on_linear_functions_at_interior_vertices() -> None:
    V, F = _plane()
    L = cotangent_laplacian(V, F)
    f = 2.0 * V[:, 0] - 3.0 * V[:, 1] + 0.5
    interior = np.setdiff1d(np.arange(len(V)), igl.boundary_loop(F))
    assert interior.size > 0
    np.testing.assert_allclose((L @ f)[interior], 0.0, atol=1e-12)


def test_mass_trace_is_area() -> None:
    V, F = _plane()
    area = trimesh.Trimesh(V, F, process=False).area
    np.testing.assert_allclose(mass_matrix(V, F).diagonal().sum(), area, rtol=1e-12)


def test_bilaplacian_equals_LT_Minv_L() -> None:
    V, F = _sphere(1)
    L, M = cotangent_laplacian(V, F), mass_matrix(V, F)
    B = bilaplacian(L, M).toarray()
    dense = L.toarray().T @ np.linalg.inv(M.toarray()) @ L.toarray()
    np.testing.assert_allclose(B, dense, atol=1e-10)
    assert np.linalg.eigvalsh(B).min() > -1e-9  # positive semi-definite


def test_normals_outward_for_counter_clockwise_faces() -> None:
    V, F = _sphere(3)
    N = vertex_normals(V, F)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-12)
    assert np.einsum("ij,ij->i", N, V).min() > 0.99
    assert np.einsum("ij,ij->i", vertex_normals(V, F[:, ::-1]), V).max() < -0.99
