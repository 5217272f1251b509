"""The RBF residual (step 3 of :mod:`~workbench.methods.regions.marker_fit.fit`) with fixed centres.

Kernels :data:`KERNELS`: ``"exponential"`` ``exp(-r / s)`` (positive definite,
no affine term), ``"linear"`` ``φ(r) = r`` and ``"thin_plate"`` ``r² log r``
(both with an affine term); one dense LU (``scipy.linalg.lu_factor``) of the
constant system serves every frame. Hand-written rather than
``scipy.interpolate.RBFInterpolator`` because we need the (n, M) kernel matrix
once for every frame; ``tests/test_marker_fit.py`` checks it against
``RBFInterpolator``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.distance import cdist

from workbench.methods.regions.hierarchy import RegionError

KERNELS = ("linear", "thin_plate", "exponential")


def _ro(a: NDArray[Any]) -> NDArray[Any]:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class RBFResidual:
    """Radial-basis interpolation of per-marker residuals with fixed centres.

    Attributes
    ----------
    centers : (M, 3) float64
    kernel : str
        One of ``"linear"``, ``"thin_plate"``, ``"exponential"``.
    scale : float
        Length scale of the exponential kernel (unused by the others).
    """

    centers: NDArray[np.float64]
    kernel: str = "exponential"
    scale: float = 1.0
    _lu: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.kernel not in KERNELS:
            raise RegionError(f"rbf kernel must be one of {KERNELS}, got {self.kernel!r}")
        C = np.asarray(self.centers, dtype=np.float64)
        if C.ndim != 2 or C.shape[1] != 3 or C.shape[0] == 0:
            raise RegionError(f"RBF centers: expected (M, 3) with M >= 1, got {C.shape}")
        object.__setattr__(self, "centers", _ro(C))
        M = C.shape[0]
        K = self.phi(cdist(C, C))
        if self.poly_terms:
            P = np.hstack([np.ones((M, 1)), C])
            A = np.block([[K, P], [P.T, np.zeros((4, 4))]])
        else:
            A = K
        object.__setattr__(self, "_lu", sla.lu_factor(A))

    @property
    def poly_terms(self) -> int:
        """4 (affine term) for the conditionally positive definite kernels, else 0."""
        return 0 if self.kernel == "exponential" else 4

    def phi(self, r: NDArray[np.float64]) -> NDArray[np.float64]:
        """The radial kernel applied elementwise to distances ``r``."""
        if self.kernel == "linear":
            return r
        if self.kernel == "thin_plate":
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where(r > 0, r * r * np.log(np.where(r > 0, r, 1.0)), 0.0)
        return np.exp(-r / self.scale)

    def coefficients(self, residual: ArrayLike) -> NDArray[np.float64]:
        """Solve for the coefficients.

        Parameters
        ----------
        residual : (M, 3) or (T, M, 3) float

        Returns
        -------
        (M + p, 3) or (T, M + p, 3) float64, ``p`` = :attr:`poly_terms`.
        """
        r = np.asarray(residual, dtype=np.float64)
        M = self.centers.shape[0]
        single = r.ndim == 2
        r3 = r[None] if single else r
        if r3.shape[1:] != (M, 3):
            raise RegionError(f"residual: expected (M, 3) or (T, M, 3) with M = {M}, got {r.shape}")
        T = r3.shape[0]
        rhs = np.zeros((M + self.poly_terms, 3 * T))
        rhs[:M] = r3.transpose(1, 0, 2).reshape(M, 3 * T)
        c = sla.lu_solve(self._lu, rhs).reshape(M + self.poly_terms, T, 3).transpose(1, 0, 2)
        return c[0] if single else c

    def basis(self, points: ArrayLike) -> NDArray[np.float64]:
        """(m, M + p) matrix mapping coefficients to values at ``points`` (m, 3)."""
        X = np.asarray(points, dtype=np.float64)
        B = self.phi(cdist(X, self.centers))
        if self.poly_terms:
            B = np.hstack([B, np.ones((X.shape[0], 1)), X])
        return B

    def __call__(self, points: ArrayLike, coefficients: ArrayLike) -> NDArray[np.float64]:
        """Interpolated residual (m, 3) at ``points`` for one frame's coefficients."""
        return self.basis(points) @ np.asarray(coefficients, dtype=np.float64)
