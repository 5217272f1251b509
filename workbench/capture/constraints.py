"""A frame's constraints on the adaptive rig: rows ``A (b0 + ΔB x) ≈ c`` over the stacked vertex coordinates.

Columns run over ``[x0, y0, z0, x1, ...]`` (``3n`` for ``n`` vertices); the
adaptive rig (:mod:`workbench.capture.adapt`) keeps its transfer rows only at
some *constraint vertices*, so rows are checked to touch only those and cut
down to their ``3p`` columns. Markers are three rows each (the unit axes as
normals); point clouds one point-to-plane row per correspondence.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

__all__ = ["check_vertex_ids", "constraint_rows", "default_constraint_vertices", "plane_rows", "point_to_plane_rows"]


def point_to_plane_rows(vertex_ids: ArrayLike, normals: ArrayLike, n_vertices: int) -> sp.csr_matrix:
    """Constraint rows ``nᵀ v_i`` as a sparse ``(m, 3 n_vertices)`` matrix over ``[x0, y0, z0, x1, ...]``.

    A point-to-plane row: ``nᵀ (v_i − c) = 0`` is ``row · b = nᵀ c``. Markers
    are three rows with the unit axes as normals.

    Parameters
    ----------
    vertex_ids : (m,) int
    normals : (m, 3) float
    n_vertices : int
    """
    ids = np.asarray(vertex_ids, np.int64).reshape(-1)
    N = np.asarray(normals, np.float64)
    if N.shape != (ids.size, 3):
        raise ValueError(f"normals must be ({ids.size}, 3) to match vertex_ids, got {N.shape}")
    if ids.size and (ids.min() < 0 or ids.max() >= n_vertices):
        raise ValueError(f"vertex_ids must be in 0..{n_vertices - 1}")
    m = ids.size
    indptr = np.arange(0, 3 * m + 1, 3)
    cols = (3 * ids[:, None] + np.arange(3)).reshape(-1)
    return sp.csr_matrix((N.reshape(-1), cols, indptr), shape=(m, 3 * n_vertices))


def default_constraint_vertices(D: NDArray[np.float64], skin: NDArray[np.int64], length_scale: float,
                                max_vertices: int) -> NDArray[np.int64]:
    """Up to ``max_vertices`` skin vertices the shapes ``D`` (k, n, 3) move (a fixed random subset when more), sorted."""
    k = D.shape[0]
    moved = np.linalg.norm(D[:, skin], axis=2).max(0) > 1e-3 * length_scale if k else np.ones(skin.size, bool)
    cand = skin[moved] if moved.any() else skin
    if cand.size > max_vertices:
        cand = np.sort(np.random.default_rng(0).choice(cand, max_vertices, replace=False))
    return cand


def check_vertex_ids(vertex_ids: ArrayLike, n_vertices: int) -> NDArray[np.int64]:
    """Constraint vertices given by the caller: (p,) int64, non-empty, in range, no repeats."""
    S = np.asarray(vertex_ids, np.int64).reshape(-1)
    if S.size == 0:
        raise ValueError("vertex_ids is empty")
    if S.min() < 0 or S.max() >= n_vertices:
        raise ValueError(f"vertex_ids must be in 0..{n_vertices - 1}")
    if np.unique(S).size != S.size:
        raise ValueError("vertex_ids has repeated vertices")
    return S


def constraint_rows(A: Any, c: ArrayLike, vertex_ids: NDArray[np.int64], n_vertices: int) -> tuple[
    sp.csr_matrix, NDArray[np.float64]
]:
    """Constraint rows over all vertex coordinates -> their columns at the constraint vertices, checked.

    Parameters
    ----------
    A : (m, 3 n_vertices) sparse or dense
        Rows over ``[x0, y0, z0, x1, ...]``.
    c : (m,) float
        Their targets.
    vertex_ids : (p,) int
        The constraint vertices.
    n_vertices : int

    Returns
    -------
    AS : (m, 3p) sparse CSR
    c : (m,) float64

    Raises
    ------
    ValueError
        Shapes that do not match, values that are not finite, or rows touching other vertices.
    """
    n = n_vertices
    As = sp.csr_matrix(A) if sp.issparse(A) else sp.csr_matrix(np.asarray(A, np.float64))
    if As.ndim != 2 or As.shape[1] != 3 * n:
        raise ValueError(f"A must be (m, {3 * n}) over the stacked vertex coordinates, got {As.shape}")
    m = As.shape[0]
    cv = np.asarray(c, np.float64).reshape(-1)
    if cv.shape != (m,):
        raise ValueError(f"c must have shape ({m},) to match A, got {np.shape(c)}")
    if not (np.isfinite(cv).all() and np.isfinite(As.data).all()):
        raise ValueError("A and c must be finite")
    cols = (3 * np.asarray(vertex_ids, np.int64)[:, None] + np.arange(3)).reshape(-1)
    AS = sp.csr_matrix(As[:, cols])
    total = float(As.multiply(As).sum())
    if abs(float(AS.multiply(AS).sum()) - total) > 1e-9 * max(total, 1e-300):
        raise ValueError("A touches vertices outside vertex_ids_ (pass them as vertex_ids when building the model)")
    return AS, cv


def plane_rows(rows: ArrayLike, normals: ArrayLike, targets: ArrayLike, p: int) -> tuple[
    sp.csr_matrix, NDArray[np.float64]
]:
    """Point-to-plane rows ``nᵀ v = target`` at constraint vertices, as :func:`constraint_rows` returns them.

    Parameters
    ----------
    rows : (m,) int
        Positions among the ``p`` constraint vertices (not vertex ids).
    normals : (m, 3) float
    targets : (m,) float
    p : int
        Number of constraint vertices.
    """
    r = np.asarray(rows, np.int64).reshape(-1)
    if r.size and (r.min() < 0 or r.max() >= p):
        raise ValueError(f"rows must index vertex_ids_ (0..{p - 1})")
    N = np.asarray(normals, np.float64)
    if N.shape != (r.size, 3):
        raise ValueError(f"normals must be ({r.size}, 3) to match rows, got {N.shape}")
    cv = np.asarray(targets, np.float64).reshape(-1)
    if cv.shape != (r.size,):
        raise ValueError(f"targets must be ({r.size},) to match rows, got {np.shape(targets)}")
    if not (np.isfinite(N).all() and np.isfinite(cv).all()):
        raise ValueError("normals and targets must be finite")
    cols = (3 * r[:, None] + np.arange(3)).reshape(-1)
    AS = sp.csr_matrix((N.reshape(-1), cols, np.arange(0, 3 * r.size + 1, 3)), shape=(r.size, 3 * p))
    return AS, cv
