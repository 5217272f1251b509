"""The smooth spectral basis of a surface: the lowest eigenvectors of its cotangent Laplacian.

The capture's adaptive rig (:mod:`workbench.capture.adapt`) writes the actor's
identity and each shape's correctives as smooth offsets ``ℓ E z`` in this basis.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.operators import cotangent_laplacian, mass_matrix
from workbench.geometry.sparse_cholesky import SparseSPDSolver

__all__ = ["laplacian_basis"]

#: below this many vertices the basis comes from a dense eigendecomposition
_DENSE_EIG = 600


def laplacian_basis(vertices: ArrayLike, faces: ArrayLike, n_basis: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The smoothest ``n_basis`` eigenvectors of a surface: ``-L e = λ M e`` (cotangent ``L``, mass ``M``).

    Shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) with the shifted matrix
    factored once by :class:`SparseSPDSolver` (CHOLMOD when installed); a dense
    ``scipy.linalg.eigh`` below a few hundred vertices.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    n_basis : int
        ``1 <= n_basis < n``.

    Returns
    -------
    E : (n, n_basis) float64
        Columns with unit RMS over the vertices (``||e||² = n``), ascending λ.
    eigenvalues : (n_basis,) float64
        ``λ`` (``≥ 0``; the first is ~0, the constant).
    """
    V = np.asarray(vertices, np.float64)
    F = np.asarray(faces, np.int64)
    n = V.shape[0]
    if not (1 <= n_basis < n):
        raise ValueError(f"n_basis must be in 1..{n - 1} for a surface of {n} vertices, got {n_basis}")
    L = cotangent_laplacian(V, F)
    M = mass_matrix(V, F)
    m = np.asarray(M.diagonal(), np.float64)
    m = np.where(m > 0, m, max(float(m[m > 0].min()) if (m > 0).any() else 1.0, 1e-300))
    K = sp.csr_matrix(-L)
    Md = sp.diags(m)
    if n <= _DENSE_EIG:
        w, E = sla.eigh(K.toarray(), np.diag(m), subset_by_index=[0, n_basis - 1])
    else:
        area = float(m.sum())
        sigma = -4.0 * math.pi / area  # below the first non-zero eigenvalue (8π/area on a sphere)
        fac = SparseSPDSolver(sp.csc_matrix(K - sigma * Md))
        op = spla.LinearOperator(K.shape, matvec=fac.solve, dtype=np.float64)
        w, E = spla.eigsh(K, k=n_basis, M=Md, sigma=sigma, which="LM", OPinv=op)
    order = np.argsort(w)
    w = np.maximum(np.asarray(w, np.float64)[order], 0.0)
    E = np.asarray(E, np.float64)[:, order]
    E /= np.maximum(np.sqrt((E**2).mean(0)), 1e-300)
    return E, w
