"""The dynamic expression model (Bouaziz et al. 2013 §2, §3.2, appendix): transfer, spectral basis, aggregation.

Every expected value is built here from the definitions, independently of the
code under test: the transfer operator as a dense least-squares problem, the
refinement system of eq. 4 as dense matrices, the batch solution of eq. 6 by
``numpy.linalg.solve``, the sphere's Laplace spectrum ``l (l + 1) / r²``.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from grid_meshes import grid_triangles

import workbench
from workbench.capture.adapt import (
    AdaptiveModel,
    ExpressionTransfer,
    laplacian_basis,
    point_to_plane_rows,
)
from workbench.fileformat import load_model
from workbench.model import BlendShape, FaceModel


# ------------------------------------------------------------------ a small curved face with two shapes
def small_face(n: int = 7) -> FaceModel:
    """An n x n grid on a gentle dome; "bump" lifts a disc, "slide" shears the right half along x."""
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    x, y = xs.ravel() - (n - 1) / 2, ys.ravel() - (n - 1) / 2
    V = np.stack([x, y, 0.05 * (x**2 + y**2) * -1.0 + 0.03 * x * y], axis=1)
    bump = np.zeros_like(V)
    r2 = x**2 + y**2
    bump[:, 2] = np.where(r2 < 2.5, 0.6 * np.exp(-r2 / 2), 0.0)
    bump[:, 0] = np.where(r2 < 2.5, 0.1 * x * np.exp(-r2 / 2), 0.0)
    slide = np.zeros_like(V)
    slide[:, 0] = np.where(x > 0.5, 0.2 * (y + 0.5) * (x - 0.5), 0.0)
    return FaceModel(V, grid_triangles(n), [BlendShape("bump", bump), BlendShape("slide", slide)])


def frame_matrix(X: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(T, 3, 3) Sumner–Popović tetrahedron frames [v1 − v0, v2 − v0, n / sqrt|n|]."""
    e1, e2 = X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]]
    nr = np.cross(e1, e2)
    nr = nr / np.sqrt(np.linalg.norm(nr, axis=1, keepdims=True))
    return np.stack([e1, e2, nr], axis=2)


def dense_transfer(V: np.ndarray, F: np.ndarray, delta: np.ndarray, b0: np.ndarray) -> np.ndarray:
    """``T_i* b0`` from the appendix's definition: least-squares edges ``S_t e(b0)``, unmoved vertices pinned."""
    S = frame_matrix(V + delta, F) @ np.linalg.inv(frame_matrix(V, F))
    edges = [(0, 1), (1, 2), (2, 0)]
    n = V.shape[0]
    G = np.zeros((3 * F.shape[0], n))
    Y = np.zeros((3 * F.shape[0], 3))
    for j, (a, b) in enumerate(edges):
        rows = j * F.shape[0] + np.arange(F.shape[0])
        G[rows, F[:, b]] += 1.0
        G[rows, F[:, a]] -= 1.0
        Y[rows] = np.einsum("tcd,td->tc", S, b0[F[:, b]] - b0[F[:, a]])
    pinned = np.linalg.norm(delta, axis=1) == 0
    free = ~pinned
    out = b0.copy()
    sol, *_ = np.linalg.lstsq(G[:, free], Y - G[:, pinned] @ b0[pinned], rcond=None)
    out[free] = sol
    return out


def dense_operator(V: np.ndarray, F: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``T_i*`` as a (3n, 3n) matrix over ``[x0, y0, z0, x1, ...]`` (it is linear: columns = images of unit vectors)."""
    n = V.shape[0]
    T = np.zeros((3 * n, 3 * n))
    for col in range(3 * n):
        e = np.zeros(3 * n)
        e[col] = 1.0
        T[:, col] = dense_transfer(V, F, delta, e.reshape(n, 3)).reshape(-1)
    return T


# ------------------------------------------------------------------ expression transfer
def test_transfer_of_the_template_neutral_reproduces_the_template_shapes() -> None:
    head = workbench.load_sample("head")
    V = head.vertices
    D = np.asarray(head.effective_deltas, np.float64)
    tr = ExpressionTransfer(V, head.faces, D, skin=np.flatnonzero(head.component_labels == 0))
    out = tr.apply(V)
    assert np.abs(out - D).max() <= 1e-5 * np.abs(D).max()


def test_transfer_matches_the_dense_definition_for_another_neutral() -> None:
    face = small_face()
    V, F = face.vertices, np.asarray(face.faces, np.int64)
    D = np.asarray(face.deltas, np.float64)
    tr = ExpressionTransfer(V, F, D)
    rng = np.random.default_rng(0)
    b0 = V * np.array([1.1, 0.9, 1.3]) + 0.05 * rng.normal(size=V.shape)
    for i in range(2):
        want = dense_transfer(V, F, D[i], b0) - b0
        assert np.allclose(tr.delta(i, b0), want, atol=1e-9)
        # and at the template: exactly the template's shape
        assert np.allclose(tr.delta(i, V), D[i], atol=1e-9)
    # the transfer rows of scalar fields along each axis: (T_i* − I)(f_j axis_d)
    f = rng.normal(size=(V.shape[0], 3))
    rows = np.array([0, 5, 24, 30])
    X = tr.basis_rows(0, f, rows)
    for j in range(3):
        for d in range(3):
            field = np.zeros_like(V)
            field[:, d] = f[:, j]
            want = dense_transfer(V, F, D[0], field) - field
            assert np.allclose(X[:, :, j, d], want[rows], atol=1e-9)


def test_an_untouched_model_is_the_template() -> None:
    face = small_face()
    am = AdaptiveModel(face, n_basis=4, vertex_ids=np.arange(face.n_vertices))
    assert np.allclose(am.neutral_, face.vertices)
    assert np.allclose(am.shapes_, face.deltas, atol=1e-6)
    assert np.allclose(am.deltas_at(), face.deltas[:, am.vertex_ids_], atol=1e-6)


# ------------------------------------------------------------------ the spectral basis
def test_laplacian_basis_of_a_sphere_has_its_spectrum() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=2.0)  # 642 vertices: the sparse shift-invert path
    E, lam = laplacian_basis(sphere.vertices, sphere.faces, 9)
    r2 = 4.0
    assert lam[0] == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(lam[1:4] * r2, 2.0, rtol=0.02)  # l = 1: 2 / r²
    assert np.allclose(lam[4:9] * r2, 6.0, rtol=0.03)  # l = 2: 6 / r²
    assert np.allclose(np.sqrt((E**2).mean(0)), 1.0)  # unit RMS columns
    # the l = 1 eigenvectors span the coordinate functions
    coef, *_ = np.linalg.lstsq(E[:, 1:4], sphere.vertices, rcond=None)
    assert np.abs(E[:, 1:4] @ coef - sphere.vertices).max() < 0.02 * 2.0


# ------------------------------------------------------------------ refinement: Algorithm 1 against eq. 6
def dense_frame(am: AdaptiveModel, T_ops: list[np.ndarray], A: np.ndarray, c: np.ndarray, x: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Ā and c̄ of eq. 4 from dense matrices (module docstring of adapt.py: per-row and head-size normalisation)."""
    face = am.model
    n = face.n_vertices
    E3 = np.kron(am.basis_, np.eye(3))  # (3n, 3K): the offset of coefficients u is ℓ E3 u
    m = A.shape[0]
    xbar = 1.0 - x.sum()
    mix = xbar * np.eye(3 * n) + sum(xi * Ti for xi, Ti in zip(x, T_ops, strict=True))
    blocks = [A @ mix @ E3] + [xi * (A @ E3) for xi in x]
    Abar = np.concatenate(blocks, axis=1) / np.sqrt(m)
    b_template = face.vertices.reshape(-1) + np.tensordot(x, np.asarray(face.deltas, np.float64), 1).reshape(-1)
    cbar = (c - A @ b_template) / (np.sqrt(m) * am.length_scale_)
    return Abar, cbar


def test_online_aggregation_equals_the_batch_solution_of_eq_6() -> None:
    face = small_face()
    n = face.n_vertices
    V, F = face.vertices, np.asarray(face.faces, np.int64)
    D = np.asarray(face.deltas, np.float64)
    gamma, betas = 0.8, (0.3, 0.2, 0.01)
    am = AdaptiveModel(face, n_basis=4, gamma=gamma, betas=betas, coverage=np.inf, sweeps=1,
                       vertex_ids=np.arange(n))
    T_ops = [dense_operator(V, F, D[i]) for i in range(2)]
    rng = np.random.default_rng(1)
    systems = []
    for _ in range(6):
        ids = rng.choice(n, 30, replace=False)
        N = rng.normal(size=(30, 3))
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        A = point_to_plane_rows(ids, N, n)
        x = rng.uniform(0.1, 0.6, 2)
        c = A @ (V + 0.05 * rng.normal(size=V.shape) + np.tensordot(x, D, 1)).reshape(-1)
        am.update(A, c, x)
        systems.append(dense_frame(am, T_ops, A.toarray(), c, x))
    t = len(systems)
    w = gamma ** (t - 1 - np.arange(t))
    w /= w.sum()
    M = sum(wj * Ab.T @ Ab for wj, (Ab, _) in zip(w, systems, strict=True))
    y = sum(wj * Ab.T @ cb for wj, (Ab, cb) in zip(w, systems, strict=True))
    M_online, y_online = am.statistics()
    # (the transfer rows are kept in float32: agreement to ~1e-9 of the largest entry)
    assert np.abs(M_online - M).max() <= 1e-7 * np.abs(M).max()
    assert np.abs(y_online - y).max() <= 1e-7 * np.abs(y).max()
    # D: β (λ / λ_K)² + β3 per coefficient; β1 for the identity, β2 for the correctives
    lam = am.eigenvalues_ / am.eigenvalues_[-1]
    bend = np.repeat(lam**2, 3)
    Dg = np.concatenate([betas[0] * bend + betas[2]] + [betas[1] * bend + betas[2]] * 2)
    assert np.allclose(am.regularization_, Dg)
    u = np.linalg.solve(M + np.diag(Dg), y)
    am.refine(sweeps=2000)
    assert np.abs(am.coefficients_.reshape(-1) - u).max() <= 1e-6 * np.abs(u).max()
    # and the model it describes: neutral and shapes from the coefficients
    U = u.reshape(3, -1)
    b0 = V.reshape(-1) + am.length_scale_ * np.kron(am.basis_, np.eye(3)) @ U[0]
    assert np.allclose(am.neutral_.reshape(-1), b0)
    for i in range(2):
        bi = T_ops[i] @ b0 + am.length_scale_ * np.kron(am.basis_, np.eye(3)) @ U[i + 1]
        assert np.allclose(am.shapes_[i].reshape(-1), bi - b0, atol=1e-8)


def test_frame_system_is_eq_4() -> None:
    face = small_face()
    n = face.n_vertices
    am = AdaptiveModel(face, n_basis=3, vertex_ids=np.arange(n))
    T_ops = [dense_operator(face.vertices, np.asarray(face.faces), np.asarray(face.deltas[i], float)) for i in range(2)]
    rng = np.random.default_rng(2)
    A = rng.normal(size=(12, 3 * n))
    c = rng.normal(size=12)
    x = np.array([0.3, 0.7])
    Ab, cb = am.frame_system(A, c, x)
    Ab2, cb2 = dense_frame(am, T_ops, A, c, x)
    assert np.allclose(Ab, Ab2) and np.allclose(cb, cb2)


def test_fit_neutral_recovers_an_identity_in_the_basis() -> None:
    face = small_face()
    n = face.n_vertices
    am = AdaptiveModel(face, n_basis=5, betas=(1e-10, 1e-10, 1e-10), vertex_ids=np.arange(n))
    rng = np.random.default_rng(3)
    u_true = 0.02 * rng.normal(size=(5, 3))
    actor = face.vertices + am.length_scale_ * am.basis_ @ u_true
    A = np.eye(3 * n)  # a marker at every vertex: three rows each
    am.fit_neutral(A, actor.reshape(-1))
    assert np.allclose(am.coefficients_[0], u_true, atol=1e-7)
    assert np.allclose(am.neutral_, actor, atol=1e-7)
    # the statistics were not touched
    assert am.n_frames_ == 0


def test_coverage_freezes_a_shape_and_the_neutral() -> None:
    face = small_face()
    n = face.n_vertices
    am = AdaptiveModel(face, n_basis=3, coverage=2.0, vertex_ids=np.arange(n))
    rng = np.random.default_rng(4)
    A = np.eye(3 * n)
    for _ in range(3):  # "bump" at 1.0 three times: σ = 3 > 2 after the third frame (x̄ = 0: the neutral is not seen)
        target = face.vertices + 1.0 * face.deltas[0] + 0.05 * rng.normal(size=face.vertices.shape)
        am.update(A, target.reshape(-1), np.array([1.0, 0.0]))
    assert am.coverage_.tolist() == pytest.approx([0.0, 3.0, 0.0])
    assert am.saturated_.tolist() == [False, True, False]
    frozen = am.coefficients_[1].copy()
    target = face.vertices + 0.5 * face.deltas[0] + 0.3 * face.deltas[1] + 0.05 * rng.normal(size=face.vertices.shape)
    am.update(A, target.reshape(-1), np.array([0.5, 0.3]))
    assert np.array_equal(am.coefficients_[1], frozen)
    assert np.abs(am.coefficients_[2]).max() > 0  # "slide" was seen and adapts


def test_bad_frames_name_the_argument() -> None:
    face = small_face()
    n = face.n_vertices
    am = AdaptiveModel(face, n_basis=3, vertex_ids=np.arange(10))
    A = point_to_plane_rows([20], [[0.0, 0.0, 1.0]], n)
    with pytest.raises(ValueError, match="outside vertex_ids_"):
        am.update(A, [0.0], [0.1, 0.0])
    A = point_to_plane_rows([2], [[0.0, 0.0, 1.0]], n)
    with pytest.raises(ValueError, match="x must have one weight per shape"):
        am.update(A, [0.0], [0.1])
    with pytest.raises(ValueError, match="c must have shape"):
        am.update(A, [0.0, 1.0], [0.1, 0.0])
    with pytest.raises(ValueError, match="A must be"):
        am.update(np.zeros((1, 5)), [0.0], [0.1, 0.0])
    with pytest.raises(ValueError, match="rows must index vertex_ids_"):
        am.update_planes([10], [[0.0, 0.0, 1.0]], [0.0], [0.0, 0.0])
    with pytest.raises(ValueError, match="gamma"):
        AdaptiveModel(face, gamma=1.5)
    with pytest.raises(ValueError, match="betas"):
        AdaptiveModel(face, betas=(0.1, -1.0, 0.0))
    with pytest.raises(ValueError, match="n_basis"):
        AdaptiveModel(face, n_basis=0)
    with pytest.raises(TypeError, match="FaceModel"):
        AdaptiveModel(face.vertices)  # type: ignore[arg-type]


def test_the_adapted_rig_is_a_model_that_saves(tmp_path) -> None:
    face = small_face()
    n = face.n_vertices
    am = AdaptiveModel(face, n_basis=4, vertex_ids=np.arange(n))
    rng = np.random.default_rng(5)
    A = np.eye(3 * n)
    actor = face.vertices * 1.05
    for _ in range(4):
        x = rng.uniform(0.0, 0.5, 2)
        am.update(A, (actor + np.tensordot(x, face.deltas, 1)).reshape(-1), x)
    rig = am.to_model(name="actor")
    assert rig.shape_names == face.shape_names
    assert np.allclose(rig.vertices, am.neutral_)
    assert np.allclose(rig.deltas, am.shapes_, atol=1e-6)
    assert not np.allclose(rig.vertices, face.vertices)
    rig.save(tmp_path / "actor.fwb")
    back = load_model(tmp_path / "actor.fwb")
    assert np.allclose(back.vertices, rig.vertices) and np.allclose(back.deltas, rig.deltas)
    assert back.metadata.name == "actor"
    assert back.metadata.provenance[-1]["step"] == "capture.AdaptiveModel"
