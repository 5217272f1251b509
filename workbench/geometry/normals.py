"""Face and vertex normals of triangle meshes: the one definition every package uses.

Convention (pinned by ``tests/test_geometry_normals.py``):

* A triangle ``(a, b, c)`` has the normal ``(b - a) × (c - a)``: triangles whose
  corners run counter-clockwise seen from outside give outward normals.
  Unnormalised, its length is twice the triangle's area.
* A vertex normal is the **area-weighted** mean of the normals of the triangles
  around it (the sum of their unnormalised normals), scaled to unit length.
* Vertices on no triangle, and vertices whose triangles cancel or are all
  degenerate, get the zero vector (never NaN).

The per-frame numba kernel of the pose-space wrinkles
(:func:`workbench.methods.wrinkles.kernels.vertex_normals`) computes the same
thing in float32 for a subset of the vertices; a test holds it equal to
:func:`vertex_normals`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["face_normals", "triangle_areas", "vertex_normals"]


def _mesh(V: ArrayLike, F: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    v = np.asarray(V, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    return v, f


def face_normals(V: ArrayLike, F: ArrayLike, *, unit: bool = True) -> NDArray[np.float64]:
    """Normals of the triangles.

    Parameters
    ----------
    V : (n, 3) float
        Vertex positions.
    F : (m, 3) int
        Triangles (counter-clockwise seen from outside for outward normals).
    unit : bool
        Unit length (degenerate triangles: zero); else the cross product
        ``(b - a) × (c - a)``, whose length is twice the triangle's area.

    Returns
    -------
    (m, 3) float64
    """
    v, f = _mesh(V, F)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    if not unit:
        return n
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def triangle_areas(V: ArrayLike, F: ArrayLike) -> NDArray[np.float64]:
    """Areas of the triangles, (m,) float64 (``V`` (n, 3) float, ``F`` (m, 3) int)."""
    return 0.5 * np.linalg.norm(face_normals(V, F, unit=False), axis=1)


def vertex_normals(V: ArrayLike, F: ArrayLike, *, unit: bool = True) -> NDArray[np.float64]:
    """Area-weighted vertex normals.

    Parameters
    ----------
    V : (n, 3) float
        Vertex positions.
    F : (m, 3) int
        Triangles. Only the vertices they use get a normal, so passing just
        the triangles around some vertices gives those vertices' full normals
        at the cost of those triangles.
    unit : bool
        Unit length (zero for vertices on no triangle); else the plain sum of
        the unnormalised face normals around each vertex (twice the area-weighted
        sum), which is linear in each triangle's cross product — what a
        first-order model of how normals change needs.

    Returns
    -------
    (n, 3) float64
    """
    v, f = _mesh(V, F)
    fn = face_normals(v, f, unit=False)
    out = np.zeros_like(v)
    n = v.shape[0]
    # bincount per corner and axis: an order of magnitude faster than np.add.at
    for c in range(3):
        for k in range(3):
            out[:, k] += np.bincount(f[:, c], fn[:, k], minlength=n)
    if not unit:
        return out
    ln = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, ln, out=np.zeros_like(out), where=ln > 0)
