"""Small flat or gently curved grids whose answers can be worked by hand.

Vertex ``(i, j)`` of an ``nx x ny``-vertex grid is ``j * nx + i`` (row-major,
``i`` along x), and every cell is cut along its ``(i, j) - (i + 1, j + 1)``
diagonal into two triangles, counter-clockwise seen from +z.

* :func:`grid_vertices` — the points, optionally over given x/y ranges and
  lifted by a height function;
* :func:`grid_triangles`, :func:`grid_quads` — the faces;
* :func:`grid_polygons` — a flat grid of ``nx x ny`` *cells* as quads
  (:class:`~workbench.core.polygons.Polygons`), what a quad-mesh importer gives;
* :func:`two_bump_grid` — a flat rig with one bump on each half.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from workbench.core.polygons import Polygons
from workbench.model import BlendShape, FaceModel

__all__ = ["grid_polygons", "grid_quads", "grid_triangles", "grid_vertices", "two_bump_grid"]

Height = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]


def grid_vertices(
    nx: int, ny: int | None = None, *, x: tuple[float, float] | None = None, y: tuple[float, float] | None = None,
    height: Height | None = None,
) -> NDArray[np.float64]:
    """``(nx * ny, 3)`` points of an ``nx x ny``-vertex grid, row-major.

    Parameters
    ----------
    nx, ny : int
        Vertices along x and y (``ny`` defaults to ``nx``), at least 2 each.
    x, y : (float, float), optional
        Ranges spanned (default ``(0, nx - 1)``, ``(0, ny - 1)``: unit spacing).
    height : callable, optional
        ``z = height(x, y)`` on arrays; default flat (``z = 0``).
    """
    ny = nx if ny is None else ny
    if nx < 2 or ny < 2:
        raise ValueError(f"a grid needs at least 2 x 2 vertices, got {nx} x {ny}")
    xs = np.linspace(*(x if x is not None else (0.0, nx - 1.0)), nx)
    ys = np.linspace(*(y if y is not None else (0.0, ny - 1.0)), ny)
    X, Y = np.meshgrid(xs, ys)  # (ny, nx): row j, column i
    Z = np.zeros_like(X) if height is None else np.broadcast_to(np.asarray(height(X, Y), np.float64), X.shape)
    return np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)


def _cell_corners(nx: int, ny: int) -> NDArray[np.int64]:
    """``(cells,)`` lower-left vertex of every cell, cells row-major."""
    j, i = np.divmod(np.arange((nx - 1) * (ny - 1)), nx - 1)
    return np.asarray(j * nx + i, np.int64)


def grid_quads(nx: int, ny: int | None = None) -> NDArray[np.int64]:
    """``((nx-1)(ny-1), 4)``: one counter-clockwise quad per cell of an ``nx x ny``-vertex grid."""
    ny = nx if ny is None else ny
    a = _cell_corners(nx, ny)
    return np.stack([a, a + 1, a + nx + 1, a + nx], axis=1)


def grid_triangles(nx: int, ny: int | None = None) -> NDArray[np.int64]:
    """``(2 (nx-1)(ny-1), 3)``: two counter-clockwise triangles per cell of an ``nx x ny``-vertex grid.

    Cell by cell (row-major), each cell's ``(a, a+1, a+nx+1)`` then ``(a, a+nx+1, a+nx)``.
    """
    ny = nx if ny is None else ny
    a = _cell_corners(nx, ny)
    return np.concatenate(
        [np.stack([a, a + 1, a + nx + 1], 1), np.stack([a, a + nx + 1, a + nx], 1)], axis=1
    ).reshape(-1, 3)


def grid_polygons(nx: int, ny: int) -> tuple[NDArray[np.float64], Polygons]:
    """A flat grid of ``nx x ny`` *cells* (``(nx+1)(ny+1)`` vertices, unit spacing) in the z = 0 plane, as quads.

    Quads counter-clockwise seen from +z; vertex ``(i, j)`` is ``j * (nx + 1) + i``.
    """
    V = grid_vertices(nx + 1, ny + 1)
    return V, Polygons.from_lists(grid_quads(nx + 1, ny + 1).tolist())


def two_bump_grid() -> FaceModel:
    """A flat 13 x 13 grid with ``browUpLeft`` bumping its left half and ``browUpRight`` its right half.

    x runs from -6 to 6 (the subject's left is +x), y from 0 to 12; each bump
    is ``exp(-r^2 / 4)`` in z about ``(+-3.5, 6)``. One-sided features a
    segmentation should give one region each.
    """
    n = 13
    V = grid_vertices(n, x=(-6.0, 6.0))

    def bump(cx: float) -> NDArray[np.float32]:
        d = np.zeros((V.shape[0], 3), np.float32)
        d[:, 2] = np.exp(-((V[:, 0] - cx) ** 2 + (V[:, 1] - 6) ** 2) / 4.0)
        return d

    return FaceModel(V, grid_triangles(n), [BlendShape("browUpLeft", bump(3.5)), BlendShape("browUpRight", bump(-3.5))])
