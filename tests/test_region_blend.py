"""Region blending and region sculpting (Joshi et al. 2003 §2, §4)."""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.methods.regions.blend import (
    RegionState,
    RegionWeights,
    damp_drag,
    drag_damping,
    region_blend_displacement,
    region_blend_positions,
    solve_region_drag,
)
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.segmentation import segment_blend_regions
from workbench.model import FaceModel


@pytest.fixture(scope="module")
def head() -> FaceModel:
    m = workbench.load_sample("head")
    m.set_weights({"jawOpen": 0.3, "browInnerUp": 0.5, "mouthSmileRight": 0.2})
    return m


@pytest.fixture(scope="module")
def regions(head: FaceModel) -> Regions:
    return segment_blend_regions(head, 0.25)


def _corner(model: FaceModel) -> int:
    k = model.shape_names.index("mouthSmileLeft")
    return int(np.argmax(np.linalg.norm(model.deltas[k], axis=1)))


def test_global_weights_reproduce_evaluate(head: FaceModel, regions: Regions) -> None:
    for lv in range(regions.n_levels):
        rw = RegionWeights.from_global(head, regions, lv)
        d = region_blend_displacement(head, regions, rw, lv)
        assert d.dtype == np.float32 and d.shape == (head.n_vertices, 3)
        assert not d.any()  # exactly zero: evaluate() + layer == evaluate()
        X = region_blend_positions(head, regions, rw, lv)
        np.testing.assert_allclose(X, head.evaluate(), atol=2e-6)


def test_positions_equal_evaluate_plus_layer(head: FaceModel, regions: Regions) -> None:
    rw = RegionWeights.from_global(head, regions, 1).with_region("mouth_L", {"mouthPucker": 0.8, "jawOpen": 0.0})
    X = region_blend_positions(head, regions, rw)
    np.testing.assert_allclose(X, head.evaluate() + region_blend_displacement(head, regions, rw), atol=2e-6)


def test_asymmetric_smile_from_symmetric_shapes(regions: Regions) -> None:
    m = workbench.load_sample("head")
    lv = 1
    rw = RegionWeights.from_global(m, regions, lv)
    # mouthPucker is one symmetric shape; put it on the left mouth region only
    rw = rw.with_region("mouth_L", {"mouthPucker": 1.0})
    d = region_blend_displacement(m, regions, rw, lv)
    r = regions.region_index(lv, "mouth_L")
    members = regions.members(lv, r)
    moved = np.flatnonzero(np.abs(d).max(axis=1) > 0)
    assert set(moved.tolist()) <= set(members.tolist())
    W = regions.weight_matrix(lv)[:, r].toarray().ravel()
    k = m.shape_names.index("mouthPucker")
    np.testing.assert_allclose(d, W[:, None] * m.deltas[k], atol=1e-7)
    # the right corner does not move, the left one does
    corner_l = _corner(m)
    corner_r = int(np.argmax(np.linalg.norm(m.deltas[m.shape_names.index("mouthSmileRight")], axis=1)))
    assert np.linalg.norm(d[corner_r]) == 0.0
    assert np.linalg.norm(d[corner_l]) > 0.0


def test_partition_of_unity_blend_is_the_weighted_mix(head: FaceModel, regions: Regions) -> None:
    # two regions with different weights: a vertex in their overlap gets the W-weighted mix
    lv = 0
    rw = RegionWeights.from_global(head, regions, lv, weights=np.zeros(len(head.shapes)))
    v = np.flatnonzero(regions.background[lv] == 0)
    W = regions.weights_dense(lv)
    both = v[(W[v, :-1] > 0).sum(axis=1) == 2][0]
    r1, _r2 = np.flatnonzero(W[both, :-1] > 0)
    k = head.shape_names.index("jawOpen")
    rw = rw.with_region(int(r1), {"jawOpen": 1.0})
    m0 = workbench.load_sample("head")  # global weights all 0
    X = region_blend_positions(m0, regions, rw, lv, vertices=[both])[0]
    np.testing.assert_allclose(X - m0.vertices[both], W[both, r1] * m0.deltas[k, both], atol=1e-6)


def test_to_level_finer_inherits_and_round_trips(head: FaceModel, regions: Regions) -> None:
    rw2 = RegionWeights.from_global(head, regions, 2).with_region("mouth_jaw", {"mouthFunnel": 0.7})
    rw0 = rw2.to_level(regions, 0)
    k = head.shape_names.index("mouthFunnel")
    for r in range(regions.n_regions(0)):
        parent = regions.ancestor(0, r, 2)
        assert rw0.values[r, k] == rw2.values[parent, k]
    back = rw0.to_level(regions, 2)
    np.testing.assert_allclose(back.values, rw2.values, atol=1e-6)
    # the blend is the same where no overlap mixes different parents
    d2 = region_blend_displacement(head, regions, rw2, 2)
    d0 = region_blend_displacement(head, regions, rw0, 0)
    core = regions.labels[0] == regions.region_index(0, "mouth_L_1")
    W0 = regions.weights_dense(0)
    deep = core & (W0.max(axis=1) == 1.0)
    np.testing.assert_allclose(d0[deep], d2[deep], atol=1e-6)


def test_drag_moves_the_point_and_only_its_region(head: FaceModel, regions: Regions) -> None:
    lv = 1
    rw = RegionWeights.from_global(head, regions, lv)
    v = _corner(head)
    x0 = region_blend_positions(head, regions, rw, lv, vertices=[v])[0]
    target = x0 + np.array([0.04, 0.03, 0.0])
    new = solve_region_drag(head, regions, lv, rw, {v: target})
    x1 = region_blend_positions(head, regions, new, lv, vertices=[v])[0]
    assert np.linalg.norm(x1 - target) < 0.1 * np.linalg.norm(x0 - target)
    changed = np.flatnonzero(np.abs(new.values - rw.values).max(axis=1) > 0)
    assert set(changed.tolist()) <= set(regions.regions_at(lv, v))
    assert len(changed) >= 1
    lo = np.array([s.slider_min for s in head.shapes])
    hi = np.array([s.slider_max for s in head.shapes])
    assert (new.values >= lo - 1e-6).all() and (new.values <= hi + 1e-6).all()


def test_drag_with_a_held_point_keeps_it(head: FaceModel, regions: Regions) -> None:
    lv = 2
    rw = RegionWeights.from_global(head, regions, lv)
    v = _corner(head)
    r = regions.region_index(lv, "mouth_jaw")
    held = int(regions.core(lv, r)[len(regions.core(lv, r)) // 2])
    X = region_blend_positions(head, regions, rw, lv, vertices=[v, held])
    new = solve_region_drag(head, regions, lv, rw, {v: X[0] + [0.0, 0.04, 0.0], held: X[1]})
    Y = region_blend_positions(head, regions, new, lv, vertices=[v, held])
    assert np.linalg.norm(Y[1] - X[1]) < 0.25 * np.linalg.norm(Y[0] - X[0])


def test_drag_with_zero_motion_changes_nothing(head: FaceModel, regions: Regions) -> None:
    rw = RegionWeights.from_global(head, regions, 0)
    v = _corner(head)
    x0 = region_blend_positions(head, regions, rw, 0, vertices=[v])[0]
    new = solve_region_drag(head, regions, 0, rw, {v: x0})
    np.testing.assert_allclose(new.values, rw.values, atol=1e-6)


def test_drag_in_the_background_is_refused(head: FaceModel, regions: Regions) -> None:
    rw = RegionWeights.from_global(head, regions, 0)
    v = int(np.flatnonzero(regions.background[0] == 1.0)[0])
    with pytest.raises(RegionError, match="background"):
        solve_region_drag(head, regions, 0, rw, {v: head.vertices[v]})


@pytest.mark.parametrize(
    ("pinned", "kwargs", "word"),
    [
        ({}, {}, "pinned"),
        ({10**7: [0, 0, 0]}, {}, "pinned"),
        ({0: [0, 0]}, {}, "pinned"),
        ({0: [0, 0, 0]}, {"regularization": -1.0}, "regularization"),
    ],
)
def test_drag_bad_arguments(head: FaceModel, regions: Regions, pinned: dict, kwargs: dict, word: str) -> None:
    rw = RegionWeights.from_global(head, regions, 0)
    with pytest.raises(RegionError, match=word):
        solve_region_drag(head, regions, 0, rw, pinned, **kwargs)


def test_region_weights_validation(head: FaceModel, regions: Regions) -> None:
    with pytest.raises(RegionError, match="values"):
        RegionWeights(0, tuple(head.shape_names), regions.names[0], np.zeros((2, 2)))
    rw = RegionWeights.from_global(head, regions, 0)
    with pytest.raises(RegionError, match="shape"):
        rw.with_region(0, {"nope": 1.0})
    with pytest.raises(RegionError, match="region"):
        rw.region("nope")
    with pytest.raises(ValueError):
        rw.values[0, 0] = 1.0


def test_damping_is_small_where_shapes_barely_move(head: FaceModel) -> None:
    f = drag_damping(head)
    assert f.max() == 1.0 and f.min() >= 0.0
    corner = _corner(head)
    back = int(np.argmax(-head.vertices[:, 2]))  # back of the head: nothing moves it
    assert f[back] == 0.0 and f[corner] > 0.3
    np.testing.assert_allclose(damp_drag(head, corner, [1.0, 0.0, 0.0]), [f[corner], 0, 0])


def test_region_layer_in_a_model(regions: Regions) -> None:
    m = workbench.load_sample("head")
    assert m.layer_displacement("regions").any() == False  # noqa: E712 - no regions: zero
    rw = RegionWeights.from_global(m, regions, 1).with_region("mouth_L", {"mouthPucker": 1.0})
    m.set_slot("regions", RegionState(regions, 1, rw), "Region weights")
    expected = region_blend_positions(m, regions, rw)
    np.testing.assert_allclose(m.evaluate(), expected, atol=2e-6)
    # a state on another level converts the weights
    st = RegionState(regions, 0, rw)
    assert st.weights is not None and st.weights.level == 0


def test_bounded_lsq_matches_bvls_on_random_boxes() -> None:
    from scipy.optimize import lsq_linear

    from workbench.methods.regions.blend import bounded_lsq

    rng = np.random.default_rng(0)
    for _ in range(60):
        m, u = int(rng.integers(3, 40)), int(rng.integers(1, 30))
        A = rng.normal(size=(m, u))
        b = 3 * rng.normal(size=m)
        lo, hi = -rng.uniform(0, 1, u), rng.uniform(0, 1, u)
        x = bounded_lsq(A, b, lo, hi, 1e-3)
        lam = 1e-3 * np.mean((A**2).sum(0))
        AA = np.vstack([A, np.sqrt(lam) * np.eye(u)])
        bb = np.r_[b, np.zeros(u)]
        ref = lsq_linear(AA, bb, bounds=(lo, hi), method="bvls").x
        fx, fref = (float(np.sum((AA @ z - bb) ** 2)) for z in (x, ref))
        assert fx <= fref + 1e-9 * (1 + fref)
        assert (x >= lo - 1e-12).all() and (x <= hi + 1e-12).all()
