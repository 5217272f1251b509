"""Shared fixtures for the core tests: tiny hand-checkable models."""

from __future__ import annotations

import numpy as np
import pytest
from grid_meshes import grid_polygons

from workbench.model import BlendShape, FaceModel


@pytest.fixture
def tiny_model() -> FaceModel:
    """9 vertices, 4 quads; 'up' lifts the centre vertex by 1, 'left' moves column 0 by -x."""
    V, polys = grid_polygons(2, 2)
    up = np.zeros((9, 3), np.float32)
    up[4, 2] = 1.0
    left = np.zeros((9, 3), np.float32)
    left[[0, 3, 6], 0] = -0.5
    return FaceModel(
        V,
        None,
        [BlendShape("up", up), BlendShape("left", left, slider_min=-1.0, slider_max=2.0)],
        polygons=polys,
    )
