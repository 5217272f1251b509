"""workbench.testing.takes: generated takes look like the measured real phone take (the notes' table)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.arkit import mirror_name
from workbench.capture.rig import ExpressionSpace
from workbench.samples import load_sample
from workbench.testing import (
    REAL_TAKE,
    realistic_take,
    realistic_weights,
    renamed_shapes,
    take_statistics,
)


@pytest.fixture(scope="module")
def head():
    return load_sample()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_statistics_in_the_real_takes_ranges(head, seed):
    """335 frames at 30 fps, as the real take: every statistic of the notes' table in its range."""
    W = realistic_weights(head, 335, seed=seed)
    s = take_statistics(W, head.shape_names)
    print(s)
    assert s.outside() == {}
    # the facts spelled out, against the real take's numbers
    k = len(head.shape_names)
    assert 25 <= s.active_share * k <= 38  # real: median 33 of 52 above 0.05
    assert 7 <= s.rest_share * k <= 17  # real: 12 shapes above 0.05 at rest
    assert 2e-4 <= s.jitter <= 2e-3  # real: 6.8e-4
    assert s.asymmetry > 0.3  # real: 0.57; a symmetric take gives 0


def test_deterministic_and_in_the_sliders(head):
    a = realistic_weights(head, 90, seed=3)
    assert np.array_equal(a, realistic_weights(head, 90, seed=3))
    assert not np.array_equal(a, realistic_weights(head, 90, seed=4))
    space = ExpressionSpace.from_model(head)
    assert a.shape == (90, len(head.shape_names))
    assert (a[:, space.plain] >= space.lo - 1e-12).all() and (a[:, space.plain] <= space.hi + 1e-12).all()


def test_pairs_of_any_naming_are_asymmetric(head):
    """Pairs come from mirror_name: ``_L``/``_R`` names pair up as ARKit's Left/Right do."""
    face = renamed_shapes(head, "LR")
    W = realistic_weights(face, 200, seed=0)
    names = list(face.shape_names)
    i = names.index("eyeBlink_L")
    j = names.index(mirror_name("eyeBlink_L"))
    assert np.abs(W[:, i] - W[:, j]).mean() > 0.01
    assert take_statistics(W, names).asymmetry > 0.3


def test_a_clean_generated_take_is_outside_the_ranges(head):
    """The statistics tell a clean sparse take from a real one (the check is not vacuous)."""
    from workbench.capture import synthetic_performance

    perf = synthetic_performance(head, 335, seed=0, markers=10, landmarks=0)
    s = take_statistics(perf.weights, head.shape_names)
    assert {"active_share", "rest_share"} <= set(s.outside(REAL_TAKE))


def test_markers_of_a_realistic_take(head):
    """The markers are the rig playing the weights, posed, with the asked noise (0.5 mm in dm: 0.005)."""
    perf = realistic_take(head, 20, seed=0, markers=40, noise_mm=0.0, max_degrees=10.0)
    assert perf.markers.shape == (20, 40, 3) and perf.landmarks.shape[1] == 0
    space = ExpressionSpace.from_model(head)
    f = 11
    X = space.positions(perf.weights[f], perf.marker_ids) @ perf.poses[f, :3, :3].T + perf.poses[f, :3, 3]
    assert np.allclose(X, perf.markers[f], atol=1e-4)
    angles = np.degrees(np.arccos(np.clip((np.trace(perf.poses[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert angles.max() <= 10.0 * np.sqrt(1 + 0.6**2 + 0.4**2) + 1e-6
    noisy = realistic_take(head, 20, seed=0, markers=40, noise_mm=0.5)
    assert np.std(noisy.markers - perf.markers) == pytest.approx(0.005, rel=0.15)
