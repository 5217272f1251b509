"""Keying a saved expression whose look comes from region weights reproduces it (Joshi et al. 2003 regions)."""

from __future__ import annotations

import numpy as np

import workbench
from workbench.methods.regions.blend import RegionWeights


def test_a_regional_expression_keys_exactly_as_saved() -> None:
    m = workbench.load_sample("head")
    st = m.segment_regions(0.25)
    # a smile on the left mouth corner only, with every slider at 0
    rw = RegionWeights.from_global(m, st.regions, 0).with_region("mouth_L_2", {"mouthSmileLeft": 1.0})
    m.regions.set_weights(rw)
    saved = m.evaluate().copy()
    assert not any(m.weights.values()) and np.abs(saved - m.vertices).max() > 0.01
    m.expressions.save("smirk")
    m.regions.set_weights(None)  # back to the global blend: the neutral face
    n_shapes = len(m.shape_names)
    m.key_expression(1.0, "smirk")
    assert len(m.shape_names) == n_shapes + 1
    np.testing.assert_allclose(m.evaluate_at(1.0), saved, rtol=0, atol=1e-6)
    np.testing.assert_allclose(m.evaluate_at(1.0, m.tracks), saved, rtol=0, atol=1e-6)
    m.undo()
    assert len(m.shape_names) == n_shapes and not m.tracks.tracks
