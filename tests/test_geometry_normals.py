"""The one normals function (``workbench.geometry.normals``): its convention, pinned by hand-worked cases."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from grid_meshes import grid_triangles

from workbench.geometry.frames import triangle_frames
from workbench.geometry.normals import face_normals, triangle_areas, vertex_normals
from workbench.geometry.surface import SurfaceQuery, boundary_edge_flags, boundary_vertices
from workbench.methods.wrinkles import kernels


def _sphere(subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64)


def _bumpy(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 12 x 12 grid with random heights: triangles of many sizes and tilts."""
    rng = np.random.default_rng(seed)
    n = 12
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    V = np.stack([xs.ravel(), ys.ravel(), rng.normal(0.0, 0.4, n * n)], axis=1)
    V[:, :2] += rng.normal(0.0, 0.15, (n * n, 2))
    return V, grid_triangles(n)


def test_face_normal_of_a_right_triangle_by_hand() -> None:
    V = [[0, 0, 0], [2, 0, 0], [0, 3, 0]]
    F = [[0, 1, 2]]
    np.testing.assert_array_equal(face_normals(V, F), [[0, 0, 1]])
    # unnormalised: (2, 0, 0) x (0, 3, 0) = (0, 0, 6), twice the area 3
    np.testing.assert_array_equal(face_normals(V, F, unit=False), [[0, 0, 6]])
    np.testing.assert_array_equal(triangle_areas(V, F), [3.0])
    # clockwise seen from +z: the normal points down
    np.testing.assert_array_equal(face_normals(V, [[0, 2, 1]]), [[0, 0, -1]])


def test_vertex_normals_are_area_weighted_not_angle_weighted() -> None:
    # vertex 0 is the right-angle corner of a triangle in the xy plane (area 2, normal +z)
    # and of one in the yz plane (area 1, normal +x). Both corner angles are 90°, so angle
    # weighting would give (1, 0, 1)/√2; area weighting gives (1, 0, 2)/√5.
    V = [[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 1]]
    F = [[0, 1, 2], [0, 2, 3]]
    np.testing.assert_allclose(face_normals(V, F), [[0, 0, 1], [1, 0, 0]])
    N = vertex_normals(V, F)
    np.testing.assert_allclose(N[0], np.array([1.0, 0.0, 2.0]) / np.sqrt(5.0), atol=1e-15)
    np.testing.assert_allclose(N[1], [0, 0, 1])  # on the first triangle only
    np.testing.assert_allclose(N[3], [1, 0, 0])  # on the second only
    # unnormalised: the sum of the cross products around each vertex
    np.testing.assert_allclose(vertex_normals(V, F, unit=False)[0], [2, 0, 4])


def test_isolated_and_degenerate_vertices_get_zero_not_nan() -> None:
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [7, 0, 0], [8, 0, 0], [9, 0, 0]]
    F = [[0, 1, 2], [4, 5, 6]]  # the second triangle has zero area; vertex 3 is on none
    N = vertex_normals(V, F)
    assert np.isfinite(N).all()
    np.testing.assert_array_equal(N[3:], 0.0)
    np.testing.assert_array_equal(face_normals(V, F)[1], 0.0)
    np.testing.assert_allclose(np.linalg.norm(N[:3], axis=1), 1.0)


def test_sphere_normals_point_outward_and_flip_with_the_winding() -> None:
    V, F = _sphere()
    N = vertex_normals(V, F)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-12)
    assert np.einsum("ij,ij->i", N, V).min() > 0.99
    np.testing.assert_allclose(vertex_normals(V, F[:, ::-1]), -N, atol=1e-15)


def test_normals_turn_with_the_mesh_and_ignore_scale_and_translation() -> None:
    V, F = _bumpy()
    N = vertex_normals(V, F)
    q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))  # a rotation
    np.testing.assert_allclose(vertex_normals(3.5 * V @ R.T + [1.0, -2.0, 0.5], F), N @ R.T, atol=1e-12)
    np.testing.assert_allclose(face_normals(V @ R.T, F), face_normals(V, F) @ R.T, atol=1e-12)


def test_the_triangles_around_some_vertices_give_their_full_normals() -> None:
    V, F = _bumpy()
    ids = np.array([13, 40, 77, 100])
    around = F[np.isin(F, ids).any(1)]
    np.testing.assert_allclose(vertex_normals(V, around, unit=False)[ids], vertex_normals(V, F, unit=False)[ids])
    np.testing.assert_allclose(vertex_normals(V, around)[ids], vertex_normals(V, F)[ids])


def test_surface_query_normal_at_a_vertex_is_its_vertex_normal() -> None:
    V, F = _bumpy()
    q = SurfaceQuery(V, F)
    faces = np.arange(F.shape[0])
    for corner in range(3):
        bary = np.zeros((faces.size, 3))
        bary[:, corner] = 1.0
        np.testing.assert_allclose(q.normals_at(faces, bary), vertex_normals(V, F)[F[:, corner]], atol=1e-12)
    # on a convex surface the vertex normal lies in each vertex's normal cone:
    # a step out along it has the vertex as its closest point
    S, G = _sphere(2)
    d, _, C, _ = SurfaceQuery(S, G).closest(S + 0.01 * vertex_normals(S, G))
    np.testing.assert_allclose(C, S, atol=1e-9)
    np.testing.assert_allclose(d, 0.01, rtol=1e-6)


def test_boundary_of_a_grid_is_its_outer_ring() -> None:
    n = 5
    F = grid_triangles(n)
    j, i = np.divmod(np.arange(n * n), n)
    outer = (i == 0) | (j == 0) | (i == n - 1) | (j == n - 1)
    np.testing.assert_array_equal(boundary_vertices(F, n * n), outer)
    flags = boundary_edge_flags(F, n * n)
    assert flags.sum() == 4 * (n - 1)  # each border edge once
    # a border edge's two corners are on the outer ring
    for k in range(3):
        on = flags[:, k]
        assert outer[F[on, k]].all() and outer[F[on, (k + 1) % 3]].all()


def test_triangle_frames_by_hand() -> None:
    V = [[0, 0, 0], [2, 0, 0], [0, 2, 0]]
    M = triangle_frames(V, [[0, 1, 2]])[0]
    # columns: the two edges and the normal scaled by 1/sqrt(|n|) (|n| = 4)
    np.testing.assert_allclose(M, [[2, 0, 0], [0, 2, 0], [0, 0, 2]])


@pytest.mark.parametrize("subset", [False, True])
def test_numba_kernel_equals_the_numpy_normals(subset: bool) -> None:
    """The wrinkles' per-frame kernel computes the same normals (float32) as the one numpy function."""
    V, F = _bumpy(2)
    n = V.shape[0]
    X = V.astype(np.float32)
    faces = np.ascontiguousarray(F, np.int32)
    ptr, idx = kernels.vertex_face_csr(faces, n)
    rows = np.arange(0, n, 3, dtype=np.int32) if subset else np.arange(n, dtype=np.int32)
    touched = np.zeros(n, bool)
    touched[rows] = True
    face_rows = np.flatnonzero(touched[F].any(1)).astype(np.int32)
    out = np.full((n, 3), 7.0, np.float32)
    kernels.vertex_normals(X, faces, ptr, idx, face_rows, rows, np.empty((F.shape[0], 3), np.float32), out)
    np.testing.assert_allclose(out[rows], vertex_normals(V, F)[rows], atol=2e-6)
    others = np.setdiff1d(np.arange(n), rows)
    np.testing.assert_array_equal(out[others], 7.0)  # rows not asked for are left as they were
