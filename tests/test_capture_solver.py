"""WeightSolver (Bouaziz et al. 2013, §3.1): optimality, peers, a hand-worked case, sparsity, warm starts."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from workbench.capture.solver import NUMBA, WeightSolver, objective
from workbench.samples import load_sample


@pytest.fixture(scope="module")
def sample_head():
    return load_sample()


def _problem(seed: int, r: int = 60, k: int = 12):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(r, k)) @ np.diag(rng.uniform(0.2, 2.0, k))  # columns of different sizes
    w_true = rng.normal(0.3, 1.0, k)  # some beyond [-1, 1]: the box matters
    c = A @ w_true + 0.05 * rng.normal(size=r)
    return A, c


def _kkt_violation(A, c, w, lo, hi, l1, temporal, p):
    """Largest violation of the optimality conditions of the (absolute-λ) problem at w."""
    g = 2.0 * A.T @ (A @ w - c) + (2.0 * temporal * (w - p) if p is not None else 0.0)
    viol = np.zeros_like(w)
    for j in range(w.size):
        at_lo, at_hi = w[j] <= lo[j] + 1e-12, w[j] >= hi[j] - 1e-12
        # the subgradient of l1·|w| at w: l1·sign(w), or [-l1, l1] at 0
        if w[j] > 1e-12:
            lo_g = hi_g = g[j] + l1
        elif w[j] < -1e-12:
            lo_g = hi_g = g[j] - l1
        else:
            lo_g, hi_g = g[j] - l1, g[j] + l1
        if at_lo and at_hi:
            continue
        if at_lo:  # need some subgradient ≥ 0
            viol[j] = max(0.0, -hi_g)
        elif at_hi:  # need some subgradient ≤ 0
            viol[j] = max(0.0, lo_g)
        else:  # need 0 in [lo_g, hi_g]
            viol[j] = max(0.0, lo_g, -hi_g)
    return float(np.abs(viol).max())


@pytest.mark.parametrize("newton", [True, False])
@pytest.mark.parametrize("lo", [0.0, -1.0])
@pytest.mark.parametrize(("l1", "temporal"), [(0.0, 0.0), (0.5, 0.0), (0.0, 2.0), (1.0, 3.0)])
def test_kkt_conditions_hold_at_the_solution(lo, l1, temporal, newton):
    A, c = _problem(1)
    k = A.shape[1]
    rng = np.random.default_rng(2)
    w1, w2 = rng.uniform(0, 1, k), rng.uniform(0, 1, k)
    los, his = np.full(k, lo), np.ones(k)
    s = WeightSolver(los, his, l1=l1, temporal=temporal, relative=False, tol=1e-13, max_iter=100000, newton=newton)
    w = s.solve(A, c, w_prev=w1, w_prev2=w2)
    assert np.all(w >= los) and np.all(w <= his)
    p = 2 * w1 - w2 if temporal else None
    scale = float(np.abs(A.T @ c).max())
    assert _kkt_violation(A, c, w, los, his, l1, temporal, p) < 1e-8 * scale
    # and the bounds are really active somewhere (the test is not of an unconstrained solve)
    assert np.any((w <= los + 1e-12) | (w >= his - 1e-12))


def test_relative_lambdas_are_absolute_ones_times_the_mean_squared_column():
    A, c = _problem(3)
    s_rel = WeightSolver(l1=0.2, temporal=0.5, tol=1e-13, max_iter=100000)
    w1 = np.full(A.shape[1], 0.3)
    w_rel = s_rel.solve(A, c, w_prev=w1)
    scale = float(np.trace(A.T @ A)) / A.shape[1]
    assert s_rel.scale_ == pytest.approx(scale)
    s_abs = WeightSolver(l1=0.2 * scale, temporal=0.5 * scale, relative=False, tol=1e-13, max_iter=100000)
    np.testing.assert_allclose(s_abs.solve(A, c, w_prev=w1), w_rel, atol=1e-10)
    # unit-free: markers in other units (A and c scaled alike) give the same weights
    np.testing.assert_allclose(s_rel.solve(1000.0 * A, 1000.0 * c, w_prev=w1), w_rel, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_plain_l2_equals_scipy_lsq_linear(seed):
    A, c = _problem(seed, r=90, k=20)
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-0.5, 0.0, A.shape[1])
    hi = rng.uniform(0.3, 1.0, A.shape[1])
    w = WeightSolver(lo, hi, tol=1e-14, max_iter=100000).solve(A, c)
    ref = lsq_linear(A, c, bounds=(lo, hi), tol=1e-14, lsmr_tol="auto").x
    np.testing.assert_allclose(w, ref, atol=1e-8)
    assert objective(A.T @ A, A.T @ c, w) <= objective(A.T @ A, A.T @ c, ref) + 1e-10


def test_hand_worked_two_by_two():
    # A = [[1, 1], [0, 1]], c = (1, 2): unconstrained w = (-1, 2); on [0, 1]²: w2 = 1 (upper bound),
    # then min_w1 (w1 + 1 - 1)² + (1 - 2)² gives w1 = 0; the gradient 2(Gw - h) = (0, -2) confirms it.
    A = np.array([[1.0, 1.0], [0.0, 1.0]])
    c = np.array([1.0, 2.0])
    s = WeightSolver(relative=False, tol=1e-14)
    np.testing.assert_allclose(s.solve(A, c), [0.0, 1.0], atol=1e-12)
    # A = I, c = (0.4, 0.2), the previous two frames both at p = (0.6, 0.2), temporal 1, l1 0.2:
    # per coordinate (w - c)² + (w - p)² + 0.2 w  →  w = (c + p - 0.1) / 2 = (0.45, 0.15)
    s = WeightSolver(l1=0.2, temporal=1.0, relative=False, tol=1e-14)
    w = s.solve(np.eye(2), [0.4, 0.2], w_prev=[0.6, 0.2], w_prev2=[0.6, 0.2])
    np.testing.assert_allclose(w, [0.45, 0.15], atol=1e-12)
    # constant velocity: frames 0.2 then 0.4 predict 0.6; with c = 0.6 the answer is 0.6 whatever temporal is
    s = WeightSolver(temporal=5.0, relative=False, tol=1e-14)
    np.testing.assert_allclose(s.solve(np.eye(1), [0.6], w_prev=[0.4], w_prev2=[0.2]), [0.6], atol=1e-12)


def test_gram_form_equals_the_row_form():
    A, c = _problem(4)
    s = WeightSolver(l1=0.1, temporal=0.3, tol=1e-13, max_iter=100000)
    wp = np.full(A.shape[1], 0.5)
    np.testing.assert_allclose(s.solve(A, c, wp), s.solve_gram(A.T @ A, A.T @ c, wp), atol=1e-12)


@pytest.mark.skipif(not NUMBA, reason="numba is not installed")
def test_numba_and_python_give_identical_results():
    A, c = _problem(5)
    wp = np.full(A.shape[1], 0.2)
    for newton in (True, False):
        a = WeightSolver(l1=0.05, temporal=0.4, newton=newton, backend="numba").solve(A, c, wp)
        b = WeightSolver(l1=0.05, temporal=0.4, newton=newton, backend="numpy").solve(A, c, wp)
        np.testing.assert_array_equal(a, b)


def test_a_shape_that_moves_nothing_stays_at_rest():
    A, c = _problem(6)
    A[:, 3] = 0.0
    w = WeightSolver(tol=1e-12).solve(A, c)
    assert np.isfinite(w).all() and w[3] == 0.0


def test_l1_is_sparser_than_l2_at_no_worse_error_on_face_frames(sample_head):
    """The paper's Fig. 4 claim on ground truth: face frames of 3 shapes each, seen by 100 noisy markers."""
    from workbench.capture.rig import ExpressionSpace
    from workbench.capture.synthetic import face_vertices

    model = sample_head
    space = ExpressionSpace.from_model(model)
    rng = np.random.default_rng(0)
    ids = np.sort(rng.choice(face_vertices(model), 100, replace=False))
    X0, D = space.marker_basis(ids)
    A = D.reshape(-1, space.k)
    seen = np.flatnonzero(np.linalg.norm(D, axis=1).max(0) > 0.005 * space.size)  # shapes the markers see
    nnz, err = {"l1": [], "l2": []}, {"l1": [], "l2": []}
    for _ in range(8):
        truth = np.zeros(space.k)
        truth[rng.choice(seen, 3, replace=False)] = rng.uniform(0.3, 1.0, 3)
        Y = X0 + D @ truth + rng.normal(0, 0.005, X0.shape)  # 0.5 mm on a 3.9 dm head
        c = (Y - X0).reshape(-1)
        for key, l1 in (("l1", 0.02), ("l2", 0.0)):
            w = WeightSolver(l1=l1, tol=1e-12, max_iter=100000).solve(A, c)
            nnz[key].append(int((w > 1e-4).sum()))
            # error against the truth over the whole mesh (not the noisy markers the L2 fit chases)
            err[key].append(np.sqrt(((space.positions(w) - space.positions(truth)) ** 2).sum(1).mean()))
    assert np.mean(nnz["l1"]) < 0.5 * np.mean(nnz["l2"])
    assert np.mean(err["l1"]) <= np.mean(err["l2"])


def test_a_warm_start_converges_in_fewer_sweeps(sample_head):
    """Consecutive frames of a face performance, solved as the tracker does (with the temporal term):
    started from the previous frame's weights (the default) or from rest."""
    from workbench.capture.rig import ExpressionSpace
    from workbench.capture.synthetic import synthetic_performance

    # a busy face (10 shapes active at a time): rest is far from the answer, the previous frame is not
    perf = synthetic_performance(sample_head, 40, seed=3, markers=100, head_motion=0.0, noise=0.002, active=10.0)
    space = ExpressionSpace.from_model(sample_head)
    X0, D = space.marker_basis(perf.marker_ids)
    A = D.reshape(-1, space.k)
    s = WeightSolver(l1=0.01, temporal=0.25, tol=1e-6, max_iter=100000)
    exact = WeightSolver(l1=0.01, temporal=0.25, tol=1e-13, max_iter=100000)
    plain = WeightSolver(l1=0.01, temporal=0.25, tol=1e-6, max_iter=100000, newton=False)
    cold, warm, plain_warm = [], [], []
    history = [s.solve(A, (perf.markers[0] - X0).reshape(-1))]
    for f in range(1, 40):
        c = (perf.markers[f] - X0).reshape(-1)
        prev = history[-1], (history[-2] if len(history) > 1 else None)
        s.solve(A, c, *prev, w0=np.zeros(space.k))
        cold.append(s.n_iter_)
        w = s.solve(A, c, *prev)
        warm.append(s.n_iter_)
        ref = exact.solve(A, c, *prev)
        np.testing.assert_allclose(w, ref, atol=1e-5)
        # the paper's plain shooting reaches the same minimum, in more sweeps
        np.testing.assert_allclose(plain.solve(A, c, *prev), ref, atol=1e-4)
        plain_warm.append(plain.n_iter_)
        history.append(w)
    assert sum(warm) < 0.8 * sum(cold)
    assert sum(warm) < 0.5 * sum(plain_warm)


@pytest.mark.parametrize(
    ("kwargs", "call", "match"),
    [
        ({"lo": 1.0, "hi": 0.0}, {}, "lo must be ≤ hi"),
        ({"l1": -1.0}, {}, "l1"),
        ({"temporal": float("nan")}, {}, "temporal"),
        ({"lo": np.zeros(3)}, {}, "lo must be"),
        ({"max_iter": 0}, {}, "max_iter"),
        ({"backend": "gpu"}, {}, "backend"),
        ({}, {"w_prev": np.zeros(3)}, "w_prev must have shape"),
        ({}, {"w_prev2": np.zeros(5)}, "w_prev2 needs w_prev"),
    ],
)
def test_bad_arguments_are_named(kwargs, call, match):
    A, c = _problem(9, k=5)
    with pytest.raises(ValueError, match=match):
        WeightSolver(**kwargs).solve(A, c, **call)


def test_nan_rows_are_refused():
    A, c = _problem(10, k=5)
    c[3] = np.nan
    with pytest.raises(ValueError, match="occluded"):
        WeightSolver().solve(A, c)
    with pytest.raises(ValueError, match="c must have shape"):
        WeightSolver().solve(A, c[:-1])
