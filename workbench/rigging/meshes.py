"""Small mesh tools the rig transfer shares: frames, closest points, similarity fits, checks.

Closest points use libigl's AABB tree; everything else is numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Similarity",
    "SurfaceQuery",
    "axis_vector",
    "boundary_vertices",
    "face_normals",
    "fit_similarity",
    "triangle_frames",
    "vertex_normals",
]

_AXES = {"x": 0, "y": 1, "z": 2}


def axis_vector(spec: str) -> NDArray[np.float64]:
    """``"+y"`` -> (0, 1, 0), ``"-z"`` -> (0, 0, -1)."""
    s = spec.strip().lower()
    v = np.zeros(3)
    v[_AXES[s[-1]]] = -1.0 if s.startswith("-") else 1.0
    return v


def face_normals(V: NDArray[np.float64], F: NDArray[np.int64], *, unit: bool = True) -> NDArray[np.float64]:
    """(m, 3) normals (area-weighted cross products when ``unit`` is False)."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if not unit:
        return n
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1.0)


def vertex_normals(V: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.float64]:
    """(n, 3) area-weighted unit normals (zero for vertices on no face)."""
    fn = face_normals(V, F, unit=False)
    out = np.zeros_like(V)
    for k in range(3):
        np.add.at(out, F[:, k], fn)
    ln = np.linalg.norm(out, axis=1, keepdims=True)
    return out / np.where(ln > 0, ln, 1.0)


def triangle_frames(V: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.float64]:
    """(m, 3, 3) Sumner & Popovic frames: columns ``v2 - v1``, ``v3 - v1``, ``n / sqrt(|n|)``."""
    e1 = V[F[:, 1]] - V[F[:, 0]]
    e2 = V[F[:, 2]] - V[F[:, 0]]
    n = np.cross(e1, e2)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = n / np.sqrt(np.where(ln > 0, ln, 1.0))
    return np.stack([e1, e2, n], axis=2)


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


@dataclass(frozen=True)
class Similarity:
    """``p -> scale * p @ R.T + t`` (``R`` a rotation)."""

    scale: float
    R: NDArray[np.float64]
    t: NDArray[np.float64]

    def __call__(self, P: ArrayLike) -> NDArray[np.float64]:
        return self.scale * (np.asarray(P, np.float64) @ self.R.T) + self.t

    def linear(self, D: ArrayLike) -> NDArray[np.float64]:
        """Apply to vectors (displacements): ``scale * R d``."""
        return self.scale * (np.asarray(D, np.float64) @ self.R.T)

    def inverse_linear(self, D: ArrayLike) -> NDArray[np.float64]:
        """Vectors back: ``R^T d / scale``."""
        return (np.asarray(D, np.float64) @ self.R) / self.scale

    def then(self, other: Similarity) -> Similarity:
        """``other(self(p))``."""
        return Similarity(self.scale * other.scale, other.R @ self.R, other.scale * (self.t @ other.R.T) + other.t)

    @staticmethod
    def identity() -> Similarity:
        return Similarity(1.0, np.eye(3), np.zeros(3))


def fit_similarity(
    X: ArrayLike, Y: ArrayLike, w: ArrayLike | None = None, *, scale: bool = True
) -> Similarity:
    """Least-squares similarity ``Y ~ s R X + t`` (Umeyama 1991), optionally weighted.

    Parameters
    ----------
    X, Y : (p, 3) float
        Corresponding points (p >= 3, not collinear, for a unique rotation).
    w : (p,) float, optional
    scale : bool
        Fit the scale (else 1).
    """
    X = np.asarray(X, np.float64)
    Y = np.asarray(Y, np.float64)
    w = np.ones(X.shape[0]) if w is None else np.asarray(w, np.float64)
    ws = w.sum()
    if ws <= 0:
        raise ValueError("fit_similarity: all weights are zero")
    mx = (w[:, None] * X).sum(0) / ws
    my = (w[:, None] * Y).sum(0) / ws
    Xc, Yc = X - mx, Y - my
    C = (w[:, None] * Yc).T @ Xc / ws
    U, S, Vt = np.linalg.svd(C)
    D = np.eye(3)
    if np.linalg.det(U @ Vt) < 0:
        D[2, 2] = -1.0
    R = U @ D @ Vt
    var = float((w * (Xc**2).sum(1)).sum() / ws)
    s = float(np.trace(np.diag(S) @ D) / var) if scale and var > 0 else 1.0
    return Similarity(s, R, my - s * (mx @ R.T))
