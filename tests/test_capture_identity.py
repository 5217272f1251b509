"""The identity PCA (Bouaziz et al. 2013, §2) from MakeHuman's modelling targets, and the DEM using it."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import workbench
from workbench.capture import AdaptiveModel, IdentityModel, sample_identity_model
from workbench.capture.identity import identity_targets, sample_identities


@pytest.fixture(scope="module")
def head() -> workbench.FaceModel:
    return workbench.load_sample("head", "base")


@pytest.fixture(scope="module")
def pca(head: workbench.FaceModel) -> IdentityModel:
    return sample_identity_model(head, n_components=20, n_samples=200)


def _point_rows(ids: np.ndarray, n: int) -> sp.csr_matrix:
    cols = (3 * ids[:, None] + np.arange(3)).ravel()
    return sp.csr_matrix((np.ones(cols.size), (np.arange(cols.size), cols)), shape=(cols.size, 3 * n))


def test_the_sample_carries_real_identity_targets() -> None:
    T = identity_targets()
    macro = [n for n in T if n.split("-")[0] in ("african", "asian", "caucasian")]
    assert len(macro) == 12  # 3 ethnicities x 2 genders x young/old
    assert {"head-oval", "nose-scale-horiz-incr", "nose-scale-horiz-decr", "chin-prominent-incr"} <= set(T)
    # they change the face by millimetres to centimetres, not by nothing
    assert 0.01 < np.abs(T["head-scale-horiz-incr"]).max() < 0.5  # decimetres


def test_sampled_people_are_centred_and_rigidly_aligned(head: workbench.FaceModel) -> None:
    V = np.asarray(head.vertices, np.float64)
    X = sample_identities(identity_targets(), 60, seed=3, neutral=V)
    np.testing.assert_allclose(X.mean(axis=0), 0.0, atol=1e-12)
    # no sampled face is a rigid motion away from where it could be: re-aligning changes nothing
    from workbench.capture.pose import fit_rigid

    M = fit_rigid(V + X[5], V)
    np.testing.assert_allclose(M, np.eye(4), atol=1e-8)
    # deterministic given the seed
    np.testing.assert_array_equal(X, sample_identities(identity_targets(), 60, seed=3, neutral=V))


def test_one_person_drawn_to_test_on_is_a_face_not_zeros(head: workbench.FaceModel) -> None:
    V = np.asarray(head.vertices, np.float64)
    one = sample_identities(identity_targets(), 1, seed=99, neutral=V, centre=False)[0]
    assert np.linalg.norm(one, axis=1).mean() > 0.01  # millimetres to centimetres, in dm
    # the same person as in an uncentred population drawn with that seed (the first one drawn)
    many = sample_identities(identity_targets(), 3, seed=99, neutral=V, centre=False)
    np.testing.assert_allclose(many[0], one, atol=1e-12)
    # centring a single sample leaves nothing: why the benchmarks draw test people uncentred
    np.testing.assert_array_equal(sample_identities(identity_targets(), 1, seed=99, neutral=V), 0.0)


def test_the_basis_is_orthonormal_and_ordered(pca: IdentityModel, head: workbench.FaceModel) -> None:
    P = pca.basis.reshape(pca.n_components, -1)
    np.testing.assert_allclose(P @ P.T, np.eye(pca.n_components), atol=1e-9)
    assert np.all(np.diff(pca.std) <= 0) and pca.std[-1] > 0
    np.testing.assert_array_equal(pca.mean, head.vertices)
    y = np.linspace(-1, 1, pca.n_components) * pca.std
    np.testing.assert_allclose(pca.project(pca.face(y)), y, atol=1e-9)
    assert pca.truncated(5).n_components == 5 and pca.truncated(0).face([]).shape == pca.mean.shape


def test_a_face_in_the_span_is_recovered_from_points(pca: IdentityModel, head: workbench.FaceModel) -> None:
    y = np.random.default_rng(0).normal(size=pca.n_components) * pca.std
    truth = pca.face(y)
    ids = np.arange(0, head.n_vertices, 7)
    A = _point_rows(ids, head.n_vertices)
    # noise-free points and a vanishing prior: the exact coefficients
    np.testing.assert_allclose(pca.fit(A, truth[ids].reshape(-1), beta1=1e-12), y, rtol=1e-6, atol=1e-9)
    # the prior pulls towards the mean, more for a larger β1
    small = np.linalg.norm(pca.fit(A, truth[ids].reshape(-1), beta1=1e3))
    large = np.linalg.norm(pca.fit(A, truth[ids].reshape(-1), beta1=1e7))
    assert large < small < np.linalg.norm(y) * 1.0001


def test_the_adaptive_model_solves_identity_and_correctives_together(
    pca: IdentityModel, head: workbench.FaceModel
) -> None:
    am = AdaptiveModel(head, n_basis=10, identity=pca)
    S = am.vertex_ids_
    A = _point_rows(S, head.n_vertices)
    V = np.asarray(head.vertices, np.float64)
    # the template fits itself: no identity, no corrective
    am.fit_neutral(A, V[S].reshape(-1))
    np.testing.assert_allclose(am.identity_coefficients_, 0.0, atol=1e-9)
    np.testing.assert_allclose(am.neutral_, V, atol=1e-9)
    # a person of the PCA's population, seen at the constraint vertices only: the whole skin follows
    y = np.random.default_rng(1).normal(size=pca.n_components) * pca.std
    truth = pca.face(y)
    am.fit_neutral(A, truth[S].reshape(-1))
    plain = AdaptiveModel(head, n_basis=10, vertex_ids=S)
    plain.fit_neutral(A, truth[S].reshape(-1))
    err = np.sqrt(((am.neutral_ - truth) ** 2).sum(1).mean())
    err_plain = np.sqrt(((plain.neutral_ - truth) ** 2).sum(1).mean())
    assert err < 0.2 * err_plain, (err, err_plain)
    # the shapes follow the new neutral: the tracked deltas at the constraints are its transfer
    D = am.shapes_
    np.testing.assert_allclose(am.deltas_at(), D[:, S], atol=1e-9)
    np.testing.assert_allclose(am.neutral_at(), am.neutral_[S], atol=1e-12)
    # reset goes back to the template
    am.reset()
    np.testing.assert_allclose(am.neutral_, V, atol=1e-12)


def test_the_pca_follows_the_sample_at_other_resolutions(head: workbench.FaceModel) -> None:
    fine = workbench.load_sample("head", "25k")
    pca = sample_identity_model(fine, n_components=5, n_samples=50)
    assert pca.basis.shape == (5, fine.n_vertices, 3)
    P = pca.basis.reshape(5, -1)
    np.testing.assert_allclose(P @ P.T, np.eye(5), atol=1e-9)
    coarse = sample_identity_model(head, n_components=5, n_samples=50)
    # a subdivided component is the subdivision of the coarse one, up to its norm
    from workbench.geometry.subdivision import loop_subdivision

    S, _ = loop_subdivision(head.faces, head.n_vertices, 1)
    sub = S @ coarse.basis[0]
    cos = abs(np.sum(sub * pca.basis[0])) / np.linalg.norm(sub)
    assert cos > 1 - 1e-9


def test_bad_input_gives_clear_errors(pca: IdentityModel, head: workbench.FaceModel) -> None:
    with pytest.raises(ValueError, match="y must have one coefficient per component \\(20,\\)"):
        pca.face(np.zeros(3))
    with pytest.raises(ValueError, match="n_components must be in \\[0, 20\\]"):
        pca.truncated(21)
    grid = workbench.FaceModel(np.random.default_rng(0).normal(size=(10, 3)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="model has 10 vertices, not a Loop level of the sample head"):
        sample_identity_model(grid)
    with pytest.raises(ValueError, match="identity: its mean has 5084 vertices, the model 10"):
        AdaptiveModel(grid, n_basis=1, identity=pca)
    with pytest.raises(TypeError, match="identity must be an IdentityModel"):
        AdaptiveModel(head, n_basis=5, identity="pca")  # type: ignore[arg-type]


def test_the_pca_spans_the_way_from_the_template_to_the_average_person(pca: IdentityModel,
                                                                       head: workbench.FaceModel) -> None:
    """The PCA's m is the template, so its components are of the offsets from it, not from the people's mean."""
    V = np.asarray(head.vertices, np.float64)
    people = sample_identities(identity_targets(), 200, seed=7, neutral=V, centre=False)
    mean = people.mean(axis=0)
    assert np.sqrt((mean**2).sum(1).mean()) > 0.03  # the average person is not the template (> 3 mm, in dm)
    back = np.tensordot(pca.project(V + mean), pca.basis, axes=(0, 0))
    # a PCA of centred offsets leaves most of it out; of offsets from m, nearly nothing
    assert np.linalg.norm(back - mean) < 0.1 * np.linalg.norm(mean)
