"""Tiny hand-checkable meshes shared by the core tests: :mod:`workbench.testing.grids`.

Kept as the tests' import point (its own module, not conftest.py: tests/consumers
has a conftest.py too, so ``from conftest import ...`` would depend on which one
pytest imported first).
"""

from __future__ import annotations

from workbench.testing.grids import (
    grid_polygons,
    grid_quads,
    grid_triangles,
    grid_vertices,
    two_bump_grid,
)

__all__ = ["grid_polygons", "grid_quads", "grid_triangles", "grid_vertices", "two_bump_grid"]
