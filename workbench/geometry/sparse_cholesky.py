"""Factor a sparse symmetric positive-definite matrix once, solve many times.

A fallback chain over kept libraries, fastest first:

1. ``cholmod`` — SuiteSparse CHOLMOD through scikit-sparse (supernodal, AMD
   ordering). Installed by ``bash .ci/workbench`` (apt ``libsuitesparse-dev`` +
   pip ``scikit-sparse<0.5``); 5–10x faster than SuperLU on face meshes
   (``shared/notes/performance-anchors.md``).
2. ``superlu`` — scipy's SuperLU (``splu``, COLAMD ordering), always present.

Only the dispatch is written here; the factorizations are the libraries'.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

Backend = Literal["auto", "cholmod", "superlu"]


def cholmod_available() -> bool:
    """True when scikit-sparse's CHOLMOD can be imported."""
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


class SparseSPDSolver:
    """A factorization of a sparse SPD matrix ``A`` for repeated solves.

    Parameters
    ----------
    A : (n, n) sparse
        Symmetric positive definite.
    backend : {"auto", "cholmod", "superlu"}
        ``auto`` takes CHOLMOD when installed, else SuperLU.

    Attributes
    ----------
    backend_ : str
        The backend actually used.
    """

    def __init__(self, A: sp.spmatrix, backend: Backend = "auto") -> None:
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"A must be square, got {A.shape}")
        self.backend = backend
        A = sp.csc_matrix(A)
        if backend == "auto":
            backend = "cholmod" if cholmod_available() else "superlu"
        if backend == "cholmod":
            from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

            try:
                self._factor = cholesky(A, ordering_method="amd")
            except CholmodNotPositiveDefiniteError as exc:
                raise np.linalg.LinAlgError(f"matrix is not positive definite: {exc}") from None
            self._solve = self._factor
        elif backend == "superlu":
            try:
                lu = spla.splu(A, permc_spec="COLAMD")
            except RuntimeError as exc:  # SuperLU reports singular factors this way
                raise np.linalg.LinAlgError(f"matrix is singular: {exc}") from None
            diag = lu.U.diagonal()
            if not np.all(np.isfinite(diag)) or np.min(np.abs(diag)) < 1e-300:
                raise np.linalg.LinAlgError("matrix is singular")
            self._factor = lu
            self._solve = lu.solve
        else:
            raise ValueError(f"backend must be 'auto', 'cholmod' or 'superlu', got {backend!r}")
        self.backend_ = backend

    def solve(self, b: NDArray[np.float64] | sp.spmatrix) -> NDArray[np.float64]:
        """Solve ``A x = b`` for a vector or a block of right-hand sides (dense result)."""
        dense = b.toarray() if sp.issparse(b) else b  # type: ignore[union-attr]
        return np.asarray(self._solve(np.asarray(dense, dtype=np.float64)))
