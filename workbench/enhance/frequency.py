"""Frequency separation by one implicit curvature-flow step (Bermano et al. 2014, §4.2, eq. 1).

The paper (after Desbrun et al. 1999) takes one large implicit step of curvature
flow, ``(I − λdt K) X_low = X``, with ``λdt = 125`` and the cotangent operator
``K_ij = ±(cot α_j + cot β_j) / (4 A_i)`` (``A_i`` the summed area of the
triangles around vertex ``i``), followed by one iteration of uniform Laplacian
smoothing.

Sign and scale, pinned by ``tests/test_enhance_database.py``
-----------------------------------------------------------
* The paper prints ``K_ij = −(cot α + cot β)/(4A_i)`` off the diagonal, which
  makes ``K`` positive semi-definite and ``I − λdt K`` indefinite — that would
  *sharpen*. Desbrun's operator is the curvature normal ``K x_i =
  (1/4A_i) Σ_j (cot α_j + cot β_j)(x_j − x_i)``, i.e. ``K = D⁻¹ L`` with
  libigl's negative semi-definite ``L`` (``L_ij = (cot α + cot β)/2``) and
  ``D = diag(2 A_i)``. We solve the symmetric positive-definite form
  ``(D − λdt L) X_low = D X`` (a smooth sphere shrinks by ``1/(1 + λdt/(3r²))``,
  bumps are flattened). Note ``2 A_i`` is six times the barycentric mass.
* ``λdt`` has units of length². The paper's 125 is taken to be in mm² (its
  scans are in millimetres); for a model in other units it is rescaled by
  ``(1 mm / unit)²`` — 0.0125 dm² for the decimetre sample head.
* The operator is built **once**, on the reference (neutral) mesh, and factored
  once (CHOLMOD via :mod:`workbench.geometry.sparse_cholesky`): every frame is a
  back-substitution. Desbrun re-evaluates ``K`` on the mesh being smoothed; with
  frames of one face in correspondence the neutral's operator is the same
  simplification the paper makes for its reconstruction Laplacian (§5.5), and it
  makes the filter linear: constants are kept exactly and it commutes with
  affine maps of the coordinates.

Hand-written because it is a two-line linear system around libigl's
``cotmatrix``/``doublearea`` and the project's factorization wrapper; no library
ships this exact filter.
"""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.sparse_cholesky import Backend, SparseSPDSolver

__all__ = ["CurvatureFlowFilter", "lumped_areas"]


def lumped_areas(V: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.float64]:
    """``A_i``: the summed area of the triangles around each vertex, (n,)."""
    area = 0.5 * np.asarray(igl.doublearea(V, F)).ravel()
    return np.bincount(F.ravel(), weights=np.repeat(area, 3), minlength=V.shape[0]).astype(np.float64)


class CurvatureFlowFilter:
    """One implicit curvature-flow step plus one uniform Laplacian step, factored once.

    Parameters
    ----------
    lambda_dt : float
        The step ``λdt`` in mm² (the paper's 125).
    metres_per_unit : float
        Size of one model unit (1e-3 for millimetres, 0.1 for the sample head's decimetres).
    uniform_steps : int
        Iterations of uniform (umbrella) smoothing after the implicit step (paper: 1).
    backend : {"auto", "cholmod", "superlu"}
        Factorization (see :class:`~workbench.geometry.sparse_cholesky.SparseSPDSolver`).

    Attributes
    ----------
    lambda_units_ : float
        ``λdt`` in model units².
    areas_ : (n,) float
        ``2 A_i`` (the diagonal ``D``); isolated vertices get the mean so ``D`` stays positive.
    solver_ : SparseSPDSolver
        The factorization of ``D − λdt L``.
    """

    def __init__(
        self,
        lambda_dt: float = 125.0,
        *,
        metres_per_unit: float = 1e-3,
        uniform_steps: int = 1,
        backend: Backend = "auto",
    ) -> None:
        self.lambda_dt = lambda_dt
        self.metres_per_unit = metres_per_unit
        self.uniform_steps = uniform_steps
        self.backend = backend

    def fit(self, V: ArrayLike, F: ArrayLike) -> CurvatureFlowFilter:
        """Build and factor the operator on the reference mesh ``V`` (n, 3), ``F`` (m, 3)."""
        if not np.isfinite(self.lambda_dt) or self.lambda_dt < 0:
            raise ValueError(f"lambda_dt must be a finite number >= 0, got {self.lambda_dt!r}")
        if not np.isfinite(self.metres_per_unit) or self.metres_per_unit <= 0:
            raise ValueError(f"metres_per_unit must be > 0, got {self.metres_per_unit!r}")
        if int(self.uniform_steps) != self.uniform_steps or self.uniform_steps < 0:
            raise ValueError(f"uniform_steps must be an integer >= 0, got {self.uniform_steps!r}")
        v = np.ascontiguousarray(V, np.float64)
        f = np.ascontiguousarray(F, np.int64)
        n = v.shape[0]
        self.lambda_units_ = float(self.lambda_dt) * (1e-3 / float(self.metres_per_unit)) ** 2
        d = 2.0 * lumped_areas(v, f)
        pos = d > 0
        d = np.where(pos, d, d[pos].mean() if pos.any() else 1.0)
        self.areas_ = d
        L = sp.csr_matrix(igl.cotmatrix(v, f))
        if L.shape[0] < n:
            L.resize((n, n))
        self.solver_ = SparseSPDSolver(sp.csc_matrix(sp.diags(d) - self.lambda_units_ * L), backend=self.backend)
        A = sp.csr_matrix(igl.adjacency_matrix(f), dtype=np.float64)
        if A.shape[0] < n:
            A.resize((n, n))
        deg = np.asarray(A.sum(1)).ravel()
        keep = deg == 0
        self._umbrella = sp.diags(np.where(keep, 0.0, 1.0 / np.maximum(deg, 1))) @ A + sp.diags(keep.astype(float))
        self.n_vertices_ = n
        return self

    def transform(self, X: ArrayLike) -> NDArray[np.float64]:
        """The low-frequency version of one frame (n, 3) or of a stack (k, n, 3)."""
        x = np.asarray(X, np.float64)
        single = x.ndim == 2
        if single:
            x = x[None]
        if x.ndim != 3 or x.shape[1:] != (self.n_vertices_, 3):
            raise ValueError(f"X must be ({self.n_vertices_}, 3) or (k, {self.n_vertices_}, 3), got {np.shape(X)}")
        k, n = x.shape[0], x.shape[1]
        rhs = (self.areas_[:, None, None] * x.transpose(1, 0, 2)).reshape(n, 3 * k)
        low = self.solver_.solve(rhs)
        for _ in range(int(self.uniform_steps)):
            low = np.asarray(self._umbrella @ low)
        out = low.reshape(n, k, 3).transpose(1, 0, 2)
        return np.ascontiguousarray(out[0] if single else out)
