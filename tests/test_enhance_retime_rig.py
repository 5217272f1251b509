"""Point caches retimed in the rig's weights (Bermano et al. 2014 §6: matching in a compressed space).

Ground truth: caches the rig itself made from known weights. Their projection
(:class:`workbench.enhance.RigBasis`) gives those weights back, and retiming the
caches gives the timing that retiming the weights gives; the in-betweens are
still the mesh keys' (``start + s (end − start)`` in vertices).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_triangular
from scipy.optimize import lsq_linear

import workbench
from workbench.core.shapes import ModelError
from workbench.enhance import RigBasis, retime
from workbench.testing import realistic_weights
from workbench.testing.takes import _transitions as held_out


@pytest.fixture(scope="module")
def head():
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def basis(head) -> RigBasis:
    return RigBasis.from_model(head)


@pytest.fixture(scope="module")
def take(head) -> np.ndarray:
    return realistic_weights(head, 200, seed=7, repeat=0.5)


def _cache(basis: RigBasis, W: np.ndarray) -> np.ndarray:
    return basis.neutral + np.einsum("...k,kvc->...vc", W, basis.deltas)


def test_projection_gives_back_the_weights_the_rig_made(basis, take) -> None:
    assert (basis.n_shapes, basis.n_vertices) == (52, 5084)
    truth = take.copy()
    truth[::10, 0] = 1.0
    assert (truth == 0.0).sum() > 100 and (truth == 1.0).sum() > 10  # weights on both bounds: the box is exercised
    W, rms = basis.fit(_cache(basis, truth))
    np.testing.assert_allclose(W, truth, atol=1e-6)
    scale = float(np.abs(basis.deltas).max())
    assert rms < 1e-6 * scale
    np.testing.assert_allclose(basis.project(_cache(basis, take[3])), take[3], atol=1e-6)  # one frame: (k,)


def test_bounded_projection_is_the_box_constrained_least_squares(basis, take) -> None:
    """Noisy frames leave the box unconstrained; the batched active set agrees with BVLS frame by frame."""
    rng = np.random.default_rng(1)
    X = _cache(basis, take[:40]) + rng.normal(0.0, 0.01, (40, basis.n_vertices, 3))
    W = basis.project(X)
    assert W.min() >= 0.0 and W.max() <= 1.0
    D = basis.deltas.reshape(basis.n_shapes, -1)
    G = D @ D.T
    L = np.linalg.cholesky(G)
    C = solve_triangular(L, ((X.reshape(40, -1) - basis.neutral.reshape(-1)) @ D.T).T, lower=True).T
    ref = np.array([lsq_linear(L.T, c, bounds=(basis.lower, basis.upper), method="bvls").x for c in C])
    unconstrained = np.linalg.solve(G, (C @ L.T).T).T
    assert ((unconstrained < 0) | (unconstrained > 1)).any(axis=1).sum() > 20  # most frames hit the box
    np.testing.assert_allclose(W, ref, atol=1e-6)


def test_other_bounds_and_a_pair_basis() -> None:
    rng = np.random.default_rng(2)
    D, N = rng.normal(size=(6, 40, 3)), rng.normal(size=(40, 3)) + 50.0
    b = RigBasis(D, N, lower=[-1, 0, 0, 0, 0, 0.2], upper=[1, 1, 2, 1, 1, 0.2])
    w = np.array([-0.5, 0.3, 1.7, 1.0, 0.0, 0.2])
    np.testing.assert_allclose(b.project(N + np.einsum("k,kvc->vc", w, D)), w, atol=1e-8)
    over = b.project(N + np.einsum("k,kvc->vc", w * 3.0, D))  # far outside: every weight within its slider
    assert np.all(over >= b.lower - 1e-12) and np.all(over <= b.upper + 1e-12)
    assert over[5] == pytest.approx(0.2)


def test_a_cache_retimes_like_the_weights_that_made_it(basis, take) -> None:
    X = _cache(basis, take)
    cases = [(a, b) for a, b in held_out(take, np.percentile(take, 5, axis=0)) if b - a + 1 >= 4]
    assert len(cases) >= 4
    for a, b in cases[:6]:
        n = b - a + 1
        db_w = [x for x in (take[:a], take[b + 1 :]) if len(x) >= 2]
        db_x = [x for x in (X[:a], X[b + 1 :]) if len(x) >= 2]
        for method in ("auto", "closest"):
            rw = retime(db_w, take[a], take[b], n, method=method)
            rx = retime(db_x, X[a], X[b], n, method=method, basis=basis)
            assert rx.space == "rig" and rw.space == "weights"
            assert rx.choice == rw.choice and rx.matched == rw.matched
            np.testing.assert_allclose(rx.s, rw.s, atol=1e-6)
            # the in-betweens are the mesh keys' with that timing; the keys untouched
            np.testing.assert_array_equal(rx.frames[0], X[a])
            np.testing.assert_array_equal(rx.frames[-1], X[b])
            np.testing.assert_allclose(rx.frames, X[a][None] + rx.s[:, None, None] * (X[b] - X[a])[None], atol=1e-9)
        assert "matched in the rig's weights" in rx.describe()
        assert rx.fit_rms < 1e-5


def test_space_mesh_is_the_raw_vertices(basis, take) -> None:
    X = _cache(basis, take[:120])
    db, a, b = [X[:60], X[90:]], X[60], X[89]
    plain = retime(db, a, b, 30)
    mesh = retime(db, a, b, 30, basis=basis, space="mesh")
    assert plain.space == mesh.space == "mesh" and np.isnan(mesh.fit_rms)
    np.testing.assert_array_equal(plain.s, mesh.s)
    assert "matched in mesh space" in mesh.describe()
    # a (deltas, neutral) pair is a basis bounded to [0, 1], like the head's sliders
    pair = retime(db, a, b, 30, basis=(basis.deltas, basis.neutral), space="weights")
    np.testing.assert_allclose(pair.s, retime(db, a, b, 30, basis=basis).s, atol=1e-9)


def test_keys_the_rig_cannot_tell_apart_fall_back_to_the_mesh() -> None:
    rng = np.random.default_rng(3)
    D = np.zeros((2, 20, 3))
    D[0, :10, 0] = 1.0
    D[1, :10, 1] = 1.0
    N = rng.normal(size=(20, 3))
    b = RigBasis(D, N)
    off = np.zeros((20, 3))
    off[15:, 2] = 1.0  # moves vertices no shape reaches
    u = np.linspace(0.0, 1.0, 30) ** 2
    take = N[None] + u[:, None, None] * off[None]
    r = retime([take], N, N + off, 10, basis=b)
    assert r.space == "mesh"
    with pytest.raises(ValueError, match=r'end.*space="mesh"'):
        retime([take], N, N + off, 10, basis=b, space="weights")


def test_bad_input_names_the_argument(basis, take) -> None:
    X = _cache(basis, take[:30])
    a, b = X[0], X[-1]
    other = np.zeros((30, 100, 3))
    with pytest.raises(ValueError, match=r"database\[1\]"):
        retime([X, other], a, b, 10, basis=basis)  # a cache on another mesh
    small = RigBasis(np.ones((2, 100, 3)), np.zeros((100, 3)))
    with pytest.raises(ValueError, match="basis is on a mesh of 100 vertices"):
        retime([X], a, b, 10, basis=small)
    with pytest.raises(ValueError, match="basis"):
        retime([X], a, b, 10, space="weights")
    with pytest.raises(ValueError, match="basis"):
        retime([take], take[0], take[-1], 10, basis=basis)  # weight keys: nothing to project
    with pytest.raises(ValueError, match="basis"):
        retime([X], a, b, 10, basis="head")
    with pytest.raises(ValueError, match="basis: deltas"):
        retime([X], a, b, 10, basis=(np.ones((2, 7, 3)), basis.neutral))
    with pytest.raises(ValueError, match="space"):
        retime([X], a, b, 10, basis=basis, space="vertices")
    with pytest.raises(ValueError, match=r"frames must be \(T, 5084, 3\)"):
        basis.project(np.zeros((3, 10, 3)))
    with pytest.raises(ValueError, match="neutral"):
        RigBasis(np.ones((2, 4, 3)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="deltas"):
        RigBasis(np.ones((2, 5, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="lower"):
        RigBasis(np.ones((2, 4, 3)), np.zeros((4, 3)), lower=1.0, upper=0.0)


def test_the_facet_matches_point_caches_in_the_models_weights(basis, take) -> None:
    model = workbench.load_sample("head")
    names = list(model.shape_names)
    j = names.index("jawOpen")
    W = np.zeros((40, len(names)))
    W[:, j] = 0.9 * np.clip((np.arange(40) - 5) / 25.0, 0.0, 1.0) ** 3
    caches = [_cache(basis, W), _cache(basis, take[:50])]
    for t, w in ((0.0, 0.0), (1.0, 0.9)):
        model.set_weights({"jawOpen": w})
        model.timeline.key_weights(t, ["jawOpen"])
    res = model.enhance.retime(0.0, 1.0, caches)
    assert res.space == "rig" and "rig's weights" in res.describe()
    model.undo()
    by_mesh = model.enhance.retime(0.0, 1.0, caches, space="mesh")
    assert by_mesh.space == "mesh"
    model.undo()
    with pytest.raises(ModelError, match=r"database\[1\] must be \(50, 5084, 3\) on the model's mesh"):
        model.enhance.retime(0.0, 1.0, [caches[0], caches[1][:, :100]])
    with pytest.raises(ModelError, match="space"):
        model.enhance.retime(0.0, 1.0, [W], space="vertex")
