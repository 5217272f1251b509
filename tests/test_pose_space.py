"""Pose-space details (Bickel et al. 2008, §5): identities on small meshes and the sample head."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import workbench
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.handles.shell import ShellDeformer
from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor, performance_weights
from workbench.methods.wrinkles.features import (
    FeatureGraph,
    edge_weights,
    extract_details,
    local_frames,
    tangent_neighbours,
    to_world,
    vertex_normals,
)
from workbench.methods.wrinkles.hybrid_deformer import (
    COMPARISON_METHODS,
    HybridDeformer,
    compare_methods,
)
from workbench.methods.wrinkles.pose_space import PoseSpace, fit_pose_space, greedy_fit


def _rot(axis: np.ndarray, deg: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    t = np.radians(deg)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


@pytest.fixture(scope="module")
def head():
    m = workbench.load_sample("head")
    h = default_face_handles(m, per_side=40).vertices
    shell = ShellDeformer(m.vertices, m.faces, h, component_labels=m.component_labels, component_names=m.component_names)
    sculptor = WrinkleSculptor(m)
    examples = np.stack(list(sculptor.examples().values()))
    return m, h, shell, sculptor, examples


@pytest.fixture(scope="module")
def performance(head):
    """40 frames of the procedural performance (detailed meshes)."""
    return head[3].sequence(performance_weights(40))


def test_strain_hand_worked() -> None:
    P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0]])
    g = FeatureGraph(np.array([[0, 1], [0, 2]]), np.array([1.0, 2.0]))
    np.testing.assert_allclose(g.strain(P), [0, 0])
    Q = P * np.array([1.5, 0.5, 1.0])  # x stretched 50 %, y compressed 50 %
    np.testing.assert_allclose(g.strain(Q), [0.5, -0.5])
    R = _rot(np.array([1.0, 2, 3]), 40)
    np.testing.assert_allclose(g.strain(Q @ R.T + 3.0), [0.5, -0.5], atol=1e-12)


def test_feature_graph_from_handles_and_editing() -> None:
    rng = np.random.default_rng(0)
    P = rng.normal(size=(30, 3))
    g = FeatureGraph.from_handles(P, neighbours=4)
    assert 2 * 30 <= len(g) <= 4 * 30
    assert np.all(g.edges[:, 0] < g.edges[:, 1])
    assert len(np.unique(g.edges, axis=0)) == len(g)
    np.testing.assert_allclose(g.rest_lengths, np.linalg.norm(P[g.edges[:, 0]] - P[g.edges[:, 1]], axis=1))
    missing = next((i, j) for i in range(30) for j in range(i + 1, 30) if not np.any((g.edges == [i, j]).all(1)))
    g2 = g.with_edge(*missing, P)
    assert len(g2) == len(g) + 1
    g3 = g2.without_edge(*missing)
    np.testing.assert_array_equal(g3.edges, g.edges)
    with pytest.raises(KeyError):
        g3.without_edge(*missing)


def test_alpha_rows_sum_to_one_with_at_most_16_edges(head) -> None:
    m, h, *_ = head
    V = m.vertices
    g = FeatureGraph.from_handles(V[h])
    a = edge_weights(V, V[h], g)
    np.testing.assert_allclose(np.asarray(a.matrix.sum(1)).ravel(), 1.0, atol=1e-9)
    assert np.diff(a.matrix.indptr).max() <= 16
    assert a.matrix.data.min() > 0
    # on an edge's endpoint-to-endpoint segment the excess is 0: that edge has the largest weight
    i0, i1 = g.edges[0]
    mid = 0.5 * (V[h[i0]] + V[h[i1]])
    one = edge_weights(mid[None], V[h], g, beta=a.beta)
    assert one.matrix[0, 0] == one.matrix.max()


def test_local_frames_are_orthonormal_and_rotate_with_the_mesh(head) -> None:
    m, *_ = head
    nb = tangent_neighbours(m.faces, m.n_vertices)
    R = local_frames(m.vertices, m.faces, nb)
    used = np.zeros(m.n_vertices, bool)
    used[m.faces.ravel()] = True
    gram = np.einsum("nji,njk->nik", R[used], R[used])
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=1e-9)
    Q = _rot(np.array([0.3, 1.0, -0.2]), 70)
    R2 = local_frames(m.vertices @ Q.T + 1.0, m.faces, nb)
    np.testing.assert_allclose(R2[used], Q @ R[used], atol=1e-9)


def test_rotation_invariance_of_details(head) -> None:
    m, h, shell, _sculptor, examples = head
    hd = HybridDeformer(shell)
    hd.fit(examples)
    X = examples[0]
    ds = hd.details_of(X)
    Q = _rot(np.array([1.0, 0.4, 0.2]), 25)
    c = m.vertices.mean(0)
    Xr = (X - c) @ Q.T + c
    # the same pose rigidly rotated: same features; details in frames of the rotated large-scale mesh.
    # (the shell is linear, so it is only rotation-equivariant for the rotated *rest*; compare with
    # frames built on the rotated large-scale mesh of the unrotated pose instead.)
    np.testing.assert_allclose(hd.graph.strain(Xr[h]), ds.features[0], atol=1e-6)
    ls = ds.large_scale[0].astype(np.float64)
    lsr = (ls - c) @ Q.T + c
    nb = hd.neighbours
    d = extract_details(X, ls, local_frames(ls, m.faces, nb))
    dr = extract_details(Xr, lsr, local_frames(lsr, m.faces, nb))
    np.testing.assert_allclose(dr, d, atol=1e-5)  # local details identical
    world = to_world(local_frames(lsr, m.faces, nb), dr)
    np.testing.assert_allclose(world, (X - ls) @ Q.T, atol=1e-5)  # world details rotated


def _conflicts(ps: PoseSpace, values: np.ndarray, tau: float = 1e-2) -> np.ndarray:
    """(P, n): for basis pose j at vertex v, the largest ``‖d_i − d_j‖`` over basis poses i that v's
    metric puts within ``tau`` of its pose-space extent — a difference no fit at v can reproduce."""
    FS = ps.basis_features
    P, n = len(FS), values.shape[1]
    vals = np.concatenate([np.zeros((1, n, 3), np.float32), values[[b for b in ps.basis if b >= 0]]])
    dist = np.empty((P, P, n))
    for i, j in itertools.product(range(P), range(P)):
        sq = (FS[i] - FS[j]) ** 2
        dist[i, j] = np.sqrt(ps.alpha.matrix @ sq) if ps.alpha is not None else np.sqrt(sq.sum())
    near = dist <= tau * dist.max(axis=(0, 1))
    diff = np.linalg.norm(vals[:, None] - vals[None, :], axis=3)  # (P, P, n)
    return np.where(near, diff, 0.0).max(axis=0)


def test_interpolation_reproduces_training_details_exactly(head) -> None:
    _m, h, shell, sculptor, examples = head
    # the sculpted wrinkles (the real fine-scale detail; details also hold the shell's large-scale misfit)
    wrinkle = np.stack([np.abs(sculptor.height(sculptor.blend(w))) for w in EXAMPLE_POSES.values()])
    wrinkle[:, h] = 0.0  # the shell follows the handles, wrinkles included: no detail there
    for weighted in (False, True):
        hd = HybridDeformer(shell, weighted=weighted)
        ds = hd.details_of(examples)
        ps = fit_pose_space(ds.features, ds.details, alpha=hd.alpha, mode="interp")
        wrinkle[:, ~hd.active] = 0.0
        miss = np.linalg.norm(ps.evaluate_many(ds.features) - ds.details, axis=2)  # (T, n)
        scale = np.linalg.norm(ds.details, axis=2).max(axis=1, keepdims=True)
        assert ps.singular is not None
        ok = ~ps.singular
        # exact up to float32 storage of the weights wherever nothing is flagged
        assert np.all(miss[:, ok] <= 2e-4 * scale)
        if not weighted:
            assert not ps.singular.any()  # the global metric tells the six examples apart everywhere
            continue
        face = hd.active
        assert not ps.singular[~face].any()  # no details off the face, nothing to miss
        # WPSD on the 5k head: 46 % of the face region is flagged. There the shell leaks up to 4.5 mm of
        # large-scale motion into the side of the face while no feature edge in the vertex's metric
        # strains (it cannot tell e.g. brow_raise from rest: strain differences at the 1e-6 noise of
        # float32 positions) — a limitation of the local metric, not of the solve (global PSD: none).
        assert ps.singular[face].mean() < 0.5
        # the flag is not eager: every flagged vertex misses some example by more than 1e-4 of its scale
        assert np.all((miss[:, ps.singular] > 1e-4 * scale).any(axis=0))
        # nothing real is hidden: every miss is a difference between two examples the vertex's metric
        # cannot tell apart (within 1 % of its pose-space extent)...
        conflict = _conflicts(ps, ds.details)[1:]
        assert np.all(miss <= conflict + 1e-3 * scale)
        # ...and where a pose is missed, its sculpted wrinkles are at most 0.2 mm (largest: 1.1 mm)
        missed = miss > 2e-4 * scale
        assert missed.any() and wrinkle[missed].max() < 2e-3 < 0.2 * wrinkle.max()


def test_zero_strain_gives_zero_detail_and_handles_are_exact(head) -> None:
    m, h, shell, _sculptor, examples = head
    hd = HybridDeformer(shell)
    ps = hd.fit(examples)
    np.testing.assert_allclose(ps.evaluate(np.zeros(len(hd.graph))), 0.0, atol=1e-6)
    np.testing.assert_allclose(hd.deform(m.vertices[h]), m.vertices, atol=1e-5)
    # handle vertices follow the handles exactly (details there are zero)
    out = hd.deform(examples[3][h])
    np.testing.assert_allclose(out[h], examples[3][h], atol=1e-5)


def test_least_squares_with_all_poses_equals_interpolation(head) -> None:
    _m, _h, shell, _sculptor, examples = head
    hd = HybridDeformer(shell, weighted=False)
    ds = hd.details_of(examples)
    interp = fit_pose_space(ds.features, ds.details, mode="interp")
    lsq, errors = greedy_fit(ds.features, ds.details, mode="lsq", tolerance=0.0)
    assert len(lsq.basis) == len(examples) + 1
    assert errors[-1] < 1e-6
    f = ds.features.mean(0)
    np.testing.assert_allclose(lsq.evaluate(f), interp.evaluate(f), atol=1e-5)
    # and the error decreases as poses are added; a tolerance stops early
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(errors))
    short, _e2 = greedy_fit(ds.features, ds.details, mode="lsq", tolerance=errors[2] * 1.0001)
    assert len(short.basis) == 3


def test_lsq_is_the_rest_constrained_least_squares_optimum() -> None:
    # against a direct KKT solve: min ‖A w − b‖ subject to the rest row, a·w = 0 (per vertex for WPSD)
    rng = np.random.default_rng(1)
    H3, V = rng.normal(size=(12, 3)), rng.normal(size=(40, 3))
    g = FeatureGraph.from_handles(H3, 3)
    Ft = rng.normal(0.0, 0.1, (15, len(g)))
    D = rng.normal(0.0, 1e-2, (15, 40, 3)).astype(np.float32)
    basis = [4, 0, 9, 13]
    rows_F = np.vstack([np.zeros((1, len(g))), Ft])
    rows_D = np.concatenate([np.zeros((1, 40, 3)), D])
    FS = rows_F[[0] + [b + 1 for b in basis]]
    P = len(FS)
    for alpha in (None, edge_weights(V, H3, g)):
        ps = fit_pose_space(Ft, D, alpha=alpha, basis=basis, mode="lsq")
        np.testing.assert_allclose(ps.evaluate(np.zeros(len(g))), 0.0, atol=1e-8)
        for v in range(0, 40, 3):
            sq = (rows_F[:, None, :] - FS[None, :, :]) ** 2  # (R, P, F)
            A = np.sqrt(sq.sum(2) if alpha is None else sq @ alpha.matrix[v].toarray().ravel())
            K = np.block([[A.T @ A, A[:1].T], [A[:1], np.zeros((1, 1))]])
            w = np.linalg.solve(K, np.vstack([A.T @ rows_D[:, v], np.zeros((1, 3))]))[:P]
            got = ps.weights[:, v] if alpha is None else ps.weights[v]
            np.testing.assert_allclose(got, w, rtol=1e-4, atol=1e-6 * np.abs(w).max())


@pytest.mark.parametrize("method", list(COMPARISON_METHODS))
def test_lsq_error_never_rises_as_the_basis_grows(head, performance, method) -> None:
    # every method the comparison fits (blend shapes: full displacements, no shell): the
    # rest-constrained least squares over a larger basis is at least as good (up to float32
    # weights), for the greedy order and for any nested bases; zero strain stays exactly zero
    m, _h, shell, _sculptor, _examples = head
    is_detail, weighted = COMPARISON_METHODS[method]
    hd = HybridDeformer(shell)
    train = performance[:20]
    ds = hd.details_of(train)
    values = ds.details if is_detail else (train - m.vertices[None]).astype(np.float32)
    alpha = hd.alpha if weighted else None
    mask = hd.active
    ps, errors = greedy_fit(ds.features, values, alpha=alpha, mode="lsq", max_basis=8, vertex_mask=mask)
    assert len(errors) == 8
    assert all(b <= a * (1 + 1e-6) for a, b in itertools.pairwise(errors))
    assert errors[-1] < 0.5 * errors[0]
    # two poses: the rest constraint zeroes the second one's weight, the fit equals the rest-only one
    assert errors[1] == pytest.approx(errors[0], rel=1e-6)
    scale = float(np.abs(values).max())
    np.testing.assert_allclose(ps.evaluate(np.zeros(len(hd.graph))), 0.0, atol=1e-6 * scale)
    nested = []
    for k in range(1, 7):
        q = fit_pose_space(ds.features, values, alpha=alpha, basis=[3, 17, 9, 12, 0, 6][:k], mode="lsq")
        err = q.evaluate_many(ds.features)[:, mask] - values[:, mask]
        nested.append(float(np.sqrt(np.mean(np.sum(err.astype(np.float64) ** 2, axis=2)))))
        np.testing.assert_allclose(q.evaluate(np.zeros(len(hd.graph))), 0.0, atol=1e-6 * scale)
    assert all(b <= a * (1 + 1e-6) for a, b in itertools.pairwise(nested))


def test_numba_frame_matches_numpy(head) -> None:
    _m, h, shell, _sculptor, examples = head
    hd = HybridDeformer(shell)
    hd.fit(examples)
    p = examples[2][h]
    np.testing.assert_allclose(hd.frame(p), hd.deform(p), atol=2e-5)
    np.testing.assert_allclose(hd.frame(p, backend="numpy"), hd.deform(p), atol=2e-5)


@pytest.mark.parametrize("poses", [3, 8, 11])
def test_numba_wpsd_matches_numpy_for_any_number_of_poses(head, poses) -> None:
    # the numba kernel sums poses in groups of eight (zero padded): 3, 8 and 11 poses
    # exercise a partial group, an exact one and two groups
    pytest.importorskip("numba")
    from workbench.methods.wrinkles.hybrid_deformer import DetailEvaluator

    m, h, _shell, _sculptor, _examples = head
    V = np.asarray(m.vertices, np.float64)
    g = FeatureGraph.from_handles(V[h])
    rng = np.random.default_rng(poses)
    Ft = rng.normal(0.0, 0.05, (poses, len(g)))
    Ft[0] = 0.0
    D = rng.normal(0.0, 1e-3, (poses, len(V), 3)).astype(np.float32)
    D[0] = 0.0
    ps = fit_pose_space(Ft, D, alpha=edge_weights(V, V[h], g), mode="interp")
    nb = tangent_neighbours(m.faces, len(V))
    f = rng.normal(0.0, 0.05, len(g))
    fast = DetailEvaluator(ps, m.faces, nb, "numba").apply(V, f, 0.7, add_base=False)
    ref = DetailEvaluator(ps, m.faces, nb, "numpy").apply(V, f, 0.7, add_base=False)
    np.testing.assert_allclose(fast, ref, atol=1e-6 + 1e-4 * np.abs(ref).max())
    # exact interpolation at a training pose, through the fast path too
    np.testing.assert_allclose(
        DetailEvaluator(ps, m.faces, nb, "numba").apply(V, Ft[-1], add_base=False),
        DetailEvaluator(ps, m.faces, nb, "numpy").apply(V, Ft[-1], add_base=False),
        atol=1e-6,
    )


@pytest.mark.parametrize("n", [1, 1023, 1024, 2500])
def test_numba_basis_product_matches_numpy(n) -> None:
    # blocks of 1024 rows: sizes below, at and across a block boundary; zero handle rows skipped
    pytest.importorskip("numba")
    from workbench.methods.wrinkles import kernels as _kernels

    rng = np.random.default_rng(n)
    B = np.asfortranarray(rng.normal(size=(n, 7)).astype(np.float32))
    uH = rng.normal(size=(7, 3)).astype(np.float32)
    uH[2] = 0.0
    rest = rng.normal(size=(n, 3)).astype(np.float32)
    out = np.full_like(rest, np.nan)
    _kernels.bmul_add(B, uH, rest, out)
    np.testing.assert_allclose(out, rest + B.astype(np.float64) @ uH, atol=1e-5)


def test_numba_wpsd_skips_vertices_without_details(head) -> None:
    # vertices whose examples have no detail get exactly X (or 0): the fast path
    # only visits vertices with non-zero RBF weights, and must agree with numpy
    pytest.importorskip("numba")
    from workbench.methods.wrinkles.hybrid_deformer import DetailEvaluator

    m, h, _shell, _sculptor, _examples = head
    V = np.asarray(m.vertices, np.float64)
    g = FeatureGraph.from_handles(V[h])
    rng = np.random.default_rng(5)
    Ft = rng.normal(0.0, 0.05, (5, len(g)))
    Ft[0] = 0.0
    D = rng.normal(0.0, 1e-3, (5, len(V), 3)).astype(np.float32)
    D[0] = 0.0
    quiet = V[:, 1] < np.median(V[:, 1])  # the lower half has no details
    D[:, quiet] = 0.0
    ps = fit_pose_space(Ft, D, alpha=edge_weights(V, V[h], g), mode="interp")
    nb = tangent_neighbours(m.faces, len(V))
    fast = DetailEvaluator(ps, m.faces, nb, "numba")
    assert fast.rows.size == np.count_nonzero(~quiet)
    f = rng.normal(0.0, 0.05, len(g))
    X = (V + rng.normal(0.0, 0.01, V.shape)).astype(np.float32)
    ref = DetailEvaluator(ps, m.faces, nb, "numpy").apply(X, f, 0.7)
    out = np.full_like(X, np.nan)
    got = fast.apply(X, f, 0.7, out=out)
    assert got is out
    np.testing.assert_array_equal(got[quiet], X[quiet])
    np.testing.assert_allclose(got, ref, atol=1e-6 + 1e-4 * np.abs(ref - X).max())
    only = fast.apply(X, f, 0.7, add_base=False, out=np.full_like(X, np.nan))
    np.testing.assert_array_equal(only[quiet], 0.0)
    # the public normals() are still those of every vertex
    np.testing.assert_allclose(fast.normals(X), vertex_normals(X, m.faces), atol=1e-5)


def test_editing_one_example_propagates(head) -> None:
    m, _h, shell, _sculptor, examples = head
    hd = HybridDeformer(shell, weighted=False)
    ds = hd.details_of(examples)
    ps = fit_pose_space(ds.features, ds.details, mode="interp")
    j = list(EXAMPLE_POSES).index("brow_raise")
    fore = m.vertices[:, 1] > 7.5
    ps2 = ps.edited(j, mask=fore.astype(float))
    np.testing.assert_allclose(ps2.evaluate(ds.features[j])[fore], 0.0, atol=1e-6)
    np.testing.assert_allclose(ps2.evaluate(ds.features[j])[~fore], ps.evaluate(ds.features[j])[~fore], atol=1e-5)
    # a pose near the brow raise (70 % of it) loses most of its forehead detail too
    f = 0.7 * ds.features[j]
    before = np.abs(ps.evaluate(f)[fore]).max()
    after = np.abs(ps2.evaluate(f)[fore]).max()
    assert after < 0.5 * before
    ps3 = ps.edited(j, scale=2.0)
    np.testing.assert_allclose(ps3.evaluate(ds.features[j]), 2 * ps.evaluate(ds.features[j]), atol=1e-5)


def test_comparison_ordering_on_held_out_frames(head, performance) -> None:
    _m, _h, shell, _sculptor, _examples = head
    seq = performance
    hd = HybridDeformer(shell)
    rows = compare_methods(hd, seq[:20], seq[20:], max_basis=6, modes=("lsq",))
    err = {r["method"]: r["test_rms"] for r in rows if r["basis"] == 6}
    assert err["WPSD"] < err["PSD"] < err["local blend shapes"] < err["global blend shapes"]
    hmax = {r["method"]: r["test_handle_max"] for r in rows if r["basis"] == 6}
    assert hmax["WPSD"] < 1e-5 and hmax["PSD"] < 1e-5
    assert hmax["global blend shapes"] > 1e-3
