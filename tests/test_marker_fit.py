"""Marker fitting with regions and the RBF residual (Joshi et al. 2003 §3)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RBFInterpolator

import workbench
from workbench.geometry.operators import mass_matrix
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.regions.blend import RegionWeights, region_blend_positions
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.marker_fit import (
    RBFResidual,
    SyntheticPerformance,
    fidelity_table,
    fit_markers,
    format_fidelity_table,
    generate_synthetic_marker_performance,
)
from workbench.methods.regions.segmentation import component_roles, segment_blend_regions
from workbench.model import FaceModel


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def regions(head: FaceModel) -> Regions:
    return segment_blend_regions(head, 0.25)


@pytest.fixture(scope="module")
def markers(head: FaceModel) -> np.ndarray:
    return np.asarray(default_face_handles(head).vertices)


@pytest.fixture(scope="module")
def perf(head: FaceModel, markers: np.ndarray) -> SyntheticPerformance:
    return generate_synthetic_marker_performance(head, markers, n_frames=6, seed=3, noise=0.001)


@pytest.mark.parametrize("kernel", ["linear", "thin_plate"])
def test_rbf_matches_scipy(kernel: str) -> None:
    rng = np.random.default_rng(0)
    C = rng.normal(size=(20, 3))
    r = rng.normal(size=(20, 3))
    X = rng.normal(size=(7, 3))
    rbf = RBFResidual(C, kernel)
    ref = RBFInterpolator(C, r, kernel="thin_plate_spline" if kernel == "thin_plate" else "linear", degree=1)
    np.testing.assert_allclose(rbf(X, rbf.coefficients(r)), ref(X), atol=1e-8)


def test_exponential_rbf_interpolates_and_decays() -> None:
    rng = np.random.default_rng(1)
    C = rng.normal(size=(10, 3))
    r = rng.normal(size=(10, 3))
    rbf = RBFResidual(C, "exponential", 0.5)
    np.testing.assert_allclose(rbf(C, rbf.coefficients(r)), r, atol=1e-9)
    assert np.abs(rbf(np.array([[100.0, 0, 0]]), rbf.coefficients(r))).max() < 1e-12


def test_synthetic_performance_is_deterministic_and_in_range(head: FaceModel, markers: np.ndarray) -> None:
    a = generate_synthetic_marker_performance(head, markers, 5, seed=7, noise=0.0)
    b = generate_synthetic_marker_performance(head, markers, 5, seed=7, noise=0.0)
    np.testing.assert_array_equal(a.marker_positions, b.marker_positions)
    assert a.marker_positions.shape == (5, markers.size, 3)
    np.testing.assert_allclose(a.masks.sum(axis=1), 1.0, atol=1e-6)
    assert a.quadrant_weights.min() >= 0 and a.quadrant_weights.max() <= 1
    # noise-free markers are the true positions at the marker vertices
    np.testing.assert_allclose(a.marker_positions[2], a.positions(head, 2)[markers], atol=1e-5)


def test_symmetric_truth_is_recovered_exactly_by_the_global_fit(head: FaceModel, regions: Regions, markers: np.ndarray) -> None:
    # asymmetry 0, no noise: one global weight set explains the markers
    p = generate_synthetic_marker_performance(head, markers, 3, seed=2, noise=0.0, asymmetry=0.0)
    fit = fit_markers(head, regions, markers, p.marker_positions, 2, regularization=0.0, use_regions=False)
    assert fit.marker_error_global.max() < 1e-4


def test_fit_meets_markers_exactly_after_the_residual(head: FaceModel, regions: Regions, perf: SyntheticPerformance) -> None:
    fit = fit_markers(head, regions, perf.markers, perf.marker_positions, 0)
    for t in range(perf.n_frames):
        X = fit.positions(head, regions, t)
        np.testing.assert_allclose(X[perf.markers], perf.marker_positions[t], atol=1e-5)
    # weights stay in the slider ranges; regions without markers follow the global fit
    assert fit.region_weights.min() >= 0 and fit.region_weights.max() <= 1
    tr = fit.tracks()
    assert set(tr) == {*regions.names[0], "background"}
    assert tr["mouth_L_1"].shape == (perf.n_frames, len(head.shapes))
    Wm = regions.weight_matrix(0)[perf.markers].toarray()
    for r in np.flatnonzero(Wm.max(axis=0) == 0):
        np.testing.assert_array_equal(fit.region_weights[:, r], fit.global_weights)
    # residual leaves eyeballs, teeth and tongue alone
    rigid = np.isin(head.component_labels, [head.component_names.index(c) for c in ("eye_left", "teeth_lower")])
    assert not fit.residual_displacement(head, 0)[rigid].any()


def test_weights_at_reproduce_the_fitted_blend(head: FaceModel, regions: Regions, perf: SyntheticPerformance) -> None:
    m = workbench.load_sample("head")
    fit = fit_markers(m, regions, perf.markers, perf.marker_positions, 1)
    m.set_weights(dict(zip(m.shape_names, fit.global_weights[1].tolist(), strict=True)))
    X = region_blend_positions(m, regions, fit.weights_at(1))
    np.testing.assert_allclose(X, fit.positions(m, regions, 1, residual=False), atol=1e-5)
    assert isinstance(fit.weights_at(1), RegionWeights)


def test_region_fit_beats_the_global_fit(head: FaceModel, regions: Regions, perf: SyntheticPerformance) -> None:
    rows = fidelity_table(head, regions, perf, levels=[0])
    glob, reg = rows
    assert glob["method"] == "global" and reg["method"] == "regions L0"
    assert reg["marker_rms"] < 0.7 * glob["marker_rms"]
    assert reg["vertex_rms"] < glob["vertex_rms"]
    assert glob["marker_rms_rbf"] < 1e-6 and reg["marker_rms_rbf"] < 1e-6
    # weight recovery: the same error as fidelity_table's (area-weighted over the moving
    # skin) for the trivial estimate "every weight 0" sets the scale
    roles = component_roles(head)
    maxd = np.linalg.norm(head.deltas, axis=2).max(axis=0)
    ev = np.flatnonzero((roles == 0) & (maxd > 1e-3 * maxd.max()))
    area = mass_matrix(head.vertices, head.faces).diagonal()[ev]
    area /= area.sum()
    zero_rms = np.sqrt(np.mean([area @ np.mean(perf.vertex_weights(t)[ev] ** 2, axis=1) for t in range(perf.n_frames)]))
    # measured: zero estimate 0.168, global 0.1101, regions L0 0.1099 (a 0.15 % gain only:
    # with 71 markers for 52 shapes neither fit pins most weights down)
    assert reg["weight_rms"] < glob["weight_rms"] < 0.75 * zero_rms
    assert reg["weight_rms"] < 0.125
    text = format_fidelity_table(rows)
    assert text.count("\n") == 4 and "regions L0" in text


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"markers": np.array([-1])}, "markers"),
        ({"markers": np.array([1, 1])}, "markers"),
        ({"marker_positions": np.zeros((2, 3, 3))}, "marker_positions"),
        ({"level": 9}, "level"),
        ({"rbf": "cubic"}, "rbf"),
        ({"regularization": np.nan}, "regularization"),
        ({"sweeps": 0}, "sweeps"),
    ],
)
def test_fit_bad_arguments(head: FaceModel, regions: Regions, perf: SyntheticPerformance, kwargs: dict, word: str) -> None:
    args = {"markers": perf.markers, "marker_positions": perf.marker_positions, "level": 0}
    args.update({k: v for k, v in kwargs.items() if k in args})
    extra = {k: v for k, v in kwargs.items() if k not in args}
    with pytest.raises(RegionError, match=word):
        fit_markers(head, regions, args["markers"], args["marker_positions"], args["level"], **extra)


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [({"n_frames": 0}, "n_frames"), ({"noise": -1.0}, "noise"), ({"asymmetry": 2.0}, "asymmetry")],
)
def test_generator_bad_arguments(head: FaceModel, markers: np.ndarray, kwargs: dict, word: str) -> None:
    with pytest.raises(RegionError, match=word):
        generate_synthetic_marker_performance(head, markers, **kwargs)
