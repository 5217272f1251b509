"""Tiny hand-checkable meshes shared by the core tests.

Its own module, not conftest.py: tests/consumers has a conftest.py too, so
``from conftest import ...`` would depend on which one pytest imported first.
"""

from __future__ import annotations

import numpy as np

from workbench.core.polygons import Polygons
from workbench.model import BlendShape, FaceModel


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


def grid_triangles(n: int) -> np.ndarray:
    """(2 (n-1)², 3) int: two counter-clockwise triangles per cell of a row-major n x n vertex grid."""
    j, i = np.divmod(np.arange((n - 1) * (n - 1)), n - 1)
    a = j * n + i
    return np.concatenate(
        [np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)], axis=1
    ).reshape(-1, 3)


def two_bump_grid() -> FaceModel:
    """A flat 13 x 13 grid with ``browUpLeft`` bumping its left half and ``browUpRight`` its right half.

    One-sided features a segmentation should give one region each.
    """
    n = 13
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    V = np.stack([xs.ravel() - 6, ys.ravel(), np.zeros(xs.size)], axis=1)

    def bump(cx: float) -> np.ndarray:
        d = np.zeros((V.shape[0], 3), np.float32)
        d[:, 2] = np.exp(-((V[:, 0] - cx) ** 2 + (V[:, 1] - 6) ** 2) / 4.0)
        return d

    return FaceModel(V, grid_triangles(n), [BlendShape("browUpLeft", bump(3.5)), BlendShape("browUpRight", bump(-3.5))])
