"""Shared fixtures for the core tests: tiny hand-checkable models."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.model import BlendShape, FaceModel
from workbench.polygons import Polygons


def grid_polygons(nx: int, ny: int) -> tuple[np.ndarray, Polygons]:
    """A flat (nx x ny)-quad grid in the z=0 plane, quads counter-clockwise seen from +z."""
    xs, ys = np.meshgrid(np.arange(nx + 1, dtype=float), np.arange(ny + 1, dtype=float))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    quads = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            quads.append([a, a + 1, a + nx + 2, a + nx + 1])
    return V, Polygons.from_lists(quads)


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
