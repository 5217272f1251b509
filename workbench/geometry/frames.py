"""Per-triangle frames for deformation gradients (Sumner & Popović 2004, §3).

A triangle ``(v1, v2, v3)`` gets the 3×3 frame whose columns are its two edges
``v2 − v1``, ``v3 − v1`` and its normal scaled to ``n / √|n|`` (so the third
column has the length of an edge). ``M' M⁻¹`` of a deformed and a rest frame is
the triangle's deformation gradient; the rig transfer and the capture's
expression transfer both build on it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["triangle_frames"]


def triangle_frames(V: ArrayLike, F: ArrayLike) -> NDArray[np.float64]:
    """Sumner & Popović frames of the triangles.

    Parameters
    ----------
    V : (n, 3) float
        Vertex positions.
    F : (m, 3) int
        Triangles.

    Returns
    -------
    (m, 3, 3) float64
        Columns ``v2 − v1``, ``v3 − v1``, ``n / √|n|`` (``n`` their cross
        product; zero for a degenerate triangle).
    """
    v = np.asarray(V, np.float64)
    f = np.asarray(F, np.int64)
    e1 = v[f[:, 1]] - v[f[:, 0]]
    e2 = v[f[:, 2]] - v[f[:, 0]]
    n = np.cross(e1, e2)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = n / np.sqrt(np.where(ln > 0, ln, 1.0))
    return np.stack([e1, e2, n], axis=2)
