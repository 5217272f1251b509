"""Closest points on a triangle mesh and its border: what registration and landmark fitting ask a surface.

:class:`SurfaceQuery` builds libigl's AABB tree once and answers closest
points (distance, triangle, point, barycentric coordinates), the interpolated
normal there and whether the point lies on the mesh's border. The border
itself (:func:`boundary_vertices`, :func:`boundary_edge_flags`) is the set of
edges used by one triangle only.
"""

from __future__ import annotations

import igl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.normals import face_normals, vertex_normals

__all__ = ["SurfaceQuery", "boundary_edge_flags", "boundary_vertices"]


def boundary_vertices(F: NDArray[np.int64], n: int) -> NDArray[np.bool_]:
    """(n,) bool: vertices on an edge used by one face only."""
    he = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    key = he[:, 0] * n + he[:, 1]
    uniq, counts = np.unique(key, return_counts=True)
    b = uniq[counts == 1]
    out = np.zeros(n, bool)
    out[b // n] = True
    out[b % n] = True
    return out


def boundary_edge_flags(F: NDArray[np.int64], n: int) -> NDArray[np.bool_]:
    """(m, 3) bool: edge ``(F[:, k], F[:, k+1])`` is a boundary edge (one face only)."""
    he = np.sort(np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1), axis=2)  # (m, 3, 2)
    key = he[..., 0] * n + he[..., 1]
    _, inv, counts = np.unique(key.ravel(), return_inverse=True, return_counts=True)
    return (counts[inv] == 1).reshape(F.shape[0], 3)


class SurfaceQuery:
    """Closest points on a triangle mesh (libigl AABB tree, built once).

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    """

    def __init__(self, V: ArrayLike, F: ArrayLike) -> None:
        self.V = np.ascontiguousarray(V, dtype=np.float64)
        self.F = np.ascontiguousarray(F, dtype=np.int64)
        self._tree = igl.AABB()
        self._tree.init(self.V, self.F)
        self.face_normals = face_normals(self.V, self.F)
        self.vertex_normals = vertex_normals(self.V, self.F)
        self._boundary_edge = boundary_edge_flags(self.F, self.V.shape[0])

    def closest(self, P: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Closest points: (distance (p,), face (p,), point (p, 3), barycentric (p, 3))."""
        P = np.ascontiguousarray(P, dtype=np.float64)
        d2, face, C = self._tree.squared_distance(self.V, self.F, P)
        face = np.asarray(face, np.int64)
        T = self.V[self.F[face]]
        bary = igl.barycentric_coordinates(np.ascontiguousarray(C), np.ascontiguousarray(T[:, 0]),
                                           np.ascontiguousarray(T[:, 1]), np.ascontiguousarray(T[:, 2]))
        bary = np.clip(np.nan_to_num(np.asarray(bary), nan=1.0 / 3.0), 0.0, 1.0)
        bary /= np.maximum(bary.sum(1, keepdims=True), 1e-300)
        return np.sqrt(np.maximum(d2, 0.0)), face, np.asarray(C), bary

    def normals_at(self, face: NDArray[np.int64], bary: NDArray[np.float64]) -> NDArray[np.float64]:
        """Interpolated unit vertex normals at barycentric points."""
        n = (self.vertex_normals[self.F[face]] * bary[:, :, None]).sum(1)
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        fallback = self.face_normals[face]
        return np.where(ln > 1e-9, n / np.where(ln > 1e-9, ln, 1.0), fallback)

    def on_boundary(self, face: NDArray[np.int64], bary: NDArray[np.float64], tol: float = 1e-3) -> NDArray[np.bool_]:
        """Whether each closest point lies on a boundary edge of the mesh (a hole or the open border)."""
        # edge (k, k+1) is opposite corner k+2: the point is on it when that coordinate is ~0
        out = np.zeros(face.shape[0], bool)
        for k in range(3):
            out |= self._boundary_edge[face, k] & (bary[:, (k + 2) % 3] < tol)
        return out
