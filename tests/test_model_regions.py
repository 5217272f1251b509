"""Regions stored in the model: segmentation is undoable, region weights act only in their region."""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.model import ModelError
from workbench.region_blend import RegionWeights


def test_region_weights_change_only_their_region_and_undo() -> None:
    m = workbench.load_sample("head")
    with pytest.raises(ModelError, match="segment_regions"):
        m.set_region_level(0)
    st = m.segment_regions(0.25)
    np.testing.assert_array_equal(m.evaluate(), m.blended())  # segmentation alone changes nothing
    r = st.regions.region_index(0, "mouth_L_2")  # the left mouth corner
    rw = RegionWeights.from_global(m, st.regions, 0).with_region(r, {"mouthSmileLeft": 1.0})
    m.set_region_weights(rw)
    moved = np.flatnonzero(np.linalg.norm(m.evaluate() - m.blended(), axis=1) > 1e-7)
    assert moved.size > 0
    assert np.isin(moved, st.regions.members(0, r)).all()
    m.undo()
    np.testing.assert_array_equal(m.evaluate(), m.blended())
    m.undo()
    assert m.regions is None
