"""The tracker's λ's chosen by the take (workbench.capture.lambdas): dense takes want little L1, sparse ones more.

Checked by contrast, not by numbers: the same rig and markers, a realistic dense take
(workbench.testing.realistic_take) and a clean sparse one (synthetic_performance);
explicit λ's are honoured; the result reports the choice; L1 is still sparser than L2
on a sparse take.
"""

from __future__ import annotations

import numpy as np
import pytest
from capture_takes import marker_visible_shapes

from workbench.capture import TrackError, synthetic_performance, track
from workbench.capture.lambdas import L1_GRID, TEMPORAL_GRID, paper_lambdas
from workbench.samples import load_sample
from workbench.testing import realistic_take

T = 90


@pytest.fixture(scope="module")
def head():
    return load_sample()


@pytest.fixture(scope="module")
def dense(head):
    """A realistic take: ~60 % of the shapes active, non-zero rest, 120 markers, 0.5 mm, head up to 10°."""
    return realistic_take(head, T, seed=1, markers=120)


@pytest.fixture(scope="module")
def sparse(head):
    """A clean generated take: 3 shapes active at a time (of those the markers see), the same markers."""
    return synthetic_performance(head, T, seed=1, markers=120, landmarks=0, noise=0.005, head_motion=10 / 15,
                                 shapes=marker_visible_shapes(head))


@pytest.fixture(scope="module")
def dense_default(head, dense):
    """``track`` with its defaults on the dense take (the λ's chosen), shared by the tests that read it."""
    return track(head, dense.markers, vertex_ids=dense.marker_ids)


@pytest.fixture(scope="module")
def sparse_default(head, sparse):
    return track(head, sparse.markers, vertex_ids=sparse.marker_ids)


def _rmse(res, perf):
    return float(np.sqrt(np.mean((res.weights - perf.weights) ** 2)))


def test_dense_takes_choose_less_sparsity_than_sparse_ones(head, dense, sparse, dense_default, sparse_default):
    rd, rs = dense_default, sparse_default
    print("dense", rd.info["l1"], rd.info["temporal"], "sparse", rs.info["l1"], rs.info["temporal"])
    assert rd.info["l1"] < rs.info["l1"]
    assert rd.info["l1"] <= 3e-3  # about 0: the weights are dense
    assert rs.info["l1"] >= 3e-3
    # the choice is worth having on each take: no worse than the other take's choice
    for perf, mine, other in ((dense, rd, rs), (sparse, rs, rd)):
        swapped = track(head, perf.markers, vertex_ids=perf.marker_ids, l1=other.info["l1"],
                        temporal=other.info["temporal"])
        assert _rmse(mine, perf) <= _rmse(swapped, perf) * 1.02


def test_the_result_reports_the_choice(head, dense, dense_default):
    res = dense_default
    ch = res.info["lambda_choice"]
    assert res.info["lambda_auto"] == (True, True)
    assert (ch["l1"], ch["temporal"]) == (res.info["l1"], res.info["temporal"])
    tried = {(a, b) for a, b, _e in ch["grid"]}
    assert (res.info["l1"], res.info["temporal"]) in tried
    assert set(L1_GRID) <= {a for a, _b in tried} and set(TEMPORAL_GRID) <= {b for _a, b in tried}
    assert ch["paper"] in tried  # the search starts at the paper's values
    errs = {(a, b): e for a, b, e in ch["grid"]}
    assert ch["heldout"] == min(errs.values()) == errs[(res.info["l1"], res.info["temporal"])]
    # held-out markers cannot beat the noise: 0.5 mm per coordinate is 0.87 mm per marker (0.0087 dm)
    assert ch["heldout"] > 0.8 * 0.005 * np.sqrt(3)
    assert 0 < ch["frames"] <= T and ch["folds"] >= 2


def test_explicit_values_are_honoured(head, dense, dense_default):
    res = track(head, dense.markers, vertex_ids=dense.marker_ids, l1=0.02, temporal=0.5)
    assert (res.info["l1"], res.info["temporal"]) == (0.02, 0.5)
    assert res.info["lambda_choice"] is None and res.info["lambda_auto"] == (False, False)
    # one given, the other chosen with it fixed
    half = track(head, dense.markers, vertex_ids=dense.marker_ids, l1=0.0)
    assert half.info["l1"] == 0.0 and half.info["lambda_auto"] == (False, True)
    assert {a for a, _b, _e in half.info["lambda_choice"]["grid"]} == {0.0}
    # "auto" spelled out is the default
    auto = track(head, dense.markers, vertex_ids=dense.marker_ids, l1="auto", temporal="auto")
    assert np.array_equal(auto.weights, dense_default.weights)
    with pytest.raises(TrackError, match="l1"):
        track(head, dense.markers, vertex_ids=dense.marker_ids, l1="sparse")


def test_l1_still_sparser_than_l2_on_sparse_takes(head, sparse, sparse_default):
    auto = sparse_default
    l2 = track(head, sparse.markers, vertex_ids=sparse.marker_ids, l1=0.0, temporal=auto.info["temporal"])
    n_auto = (auto.weights > 1e-3).sum(1).mean()
    n_l2 = (l2.weights > 1e-3).sum(1).mean()
    print("active per frame: auto", n_auto, "L2", n_l2, "truth", (sparse.weights > 1e-3).sum(1).mean())
    assert n_auto < n_l2


def test_the_papers_values_scale_with_the_units(head, dense):
    """The paper's λ's are on a fit term in mm²: the same markers in other units give the same relative λ's."""
    from workbench.capture.track import MarkerSetup
    from workbench.testing import in_units

    cm = in_units(head, "cm")
    a = paper_lambdas(MarkerSetup(head, dense.marker_ids, 0.0, 0.0, None), head.metadata.metres_per_unit)
    b = paper_lambdas(MarkerSetup(cm, dense.marker_ids, 0.0, 0.0, None), cm.metadata.metres_per_unit)
    assert a == pytest.approx(b, rel=1e-6)  # float32 vertices
    assert a[0] == pytest.approx(2 * a[1])  # λ₂ = 20, λ₁ = 10
