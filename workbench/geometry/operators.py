"""Discrete differential operators on triangle meshes (thin wrappers over libigl).

Sign conventions (pinned by ``tests/test_operators.py``):

* ``cotangent_laplacian`` returns libigl's ``L``: symmetric, **negative
  semi-definite**, rows summing to zero, ``(L x)_i = sum_j w_ij (x_j - x_i)``
  with ``w_ij = (cot a_ij + cot b_ij) / 2``. On a closed surface with outward
  normals ``M^{-1} L V = -2 H n``: it points *inward* on a sphere (``H > 0``).
* ``mass_matrix`` is the diagonal Voronoi-hybrid mass; its trace is the surface area.
* ``bilaplacian`` is ``L^T M^{-1} L`` (symmetric positive semi-definite), the
  operator of the thin-shell bending energy used by the shell deformer.

Normals are in :mod:`workbench.geometry.normals`.
"""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray


def _vf(V: ArrayLike, F: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    v = np.ascontiguousarray(V, dtype=np.float64)
    f = np.ascontiguousarray(F, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"V must be (n, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"F must be (m, 3) triangles, got {f.shape}")
    return v, f


def _full_size(A: sp.spmatrix, n: int) -> sp.csr_matrix:
    """libigl sizes some operators by the largest face index; pad to all n vertices."""
    A = sp.csr_matrix(A)
    if A.shape[0] < n:
        A.resize((n, n))
    return A


def cotangent_laplacian(V: ArrayLike, F: ArrayLike) -> sp.csr_matrix:
    """Cotangent Laplace–Beltrami matrix (negative semi-definite).

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int

    Returns
    -------
    L : (n, n) sparse CSR float64
    """
    v, f = _vf(V, F)
    return _full_size(igl.cotmatrix(v, f), v.shape[0])


def mass_matrix(V: ArrayLike, F: ArrayLike) -> sp.csr_matrix:
    """Diagonal Voronoi-hybrid mass matrix, (n, n) sparse CSR float64."""
    v, f = _vf(V, F)
    return _full_size(igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_VORONOI), v.shape[0])


def bilaplacian(L: sp.spmatrix, M: sp.spmatrix) -> sp.csr_matrix:
    """``L^T M^{-1} L`` for a diagonal mass matrix ``M`` (positive semi-definite).

    Vertices with zero mass (isolated vertices) get an infinite inverse mass;
    they are treated as having unit mass so the operator stays finite.
    """
    m = np.asarray(M.diagonal(), dtype=np.float64)
    inv = np.where(m > 0, 1.0 / np.where(m > 0, m, 1.0), 1.0)
    return sp.csr_matrix(L.T @ sp.diags(inv) @ L)

