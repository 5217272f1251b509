"""Per-triangle deformation gradients and their Poisson reconstruction.

Sumner & Popović 2004 / Botsch et al. 2006, as Li et al. 2010 §3 use them
(``shared/papers/li2010-example-based-facial-rigging.md``). A triangle
``(v1, v2, v3)`` has the frame ``M = [v3 - v1, v2 - v1]`` (3 × 2; the paper's
third column, the normal, is dropped as Li §3 and Botsch et al. do, which
makes everything below linear in the vertex positions). For a displacement
or a pose ``y`` on a rest mesh with frames ``M0``, the in-plane deformation
gradient is ``∇y = M(y) P`` with ``P = (M0ᵀ M0)⁻¹ M0ᵀ`` the rest frame's
pseudo-inverse, so

    |∇y|_F² = tr(M(y) (M0ᵀ M0)⁻¹ M(y)ᵀ)

is unit-free (relative to each rest triangle's size and shape).

Reconstruction: given target frames ``X_t`` (3 × 2 per triangle), the vertex
positions solve ``min Σ_t a_t |(M_t(x) - X_t) P_t|_F²`` (``a_t`` the rest
area). Its normal matrix ``Dᵀ Q D`` (``D`` the (2T, n) edge operator, ``Q``
the 2 × 2 blocks ``a_t (M0ᵀ M0)⁻¹``) is exactly the cotangent Laplacian
(negated), so the solve is the usual gradient-domain Poisson solve, factored
once per set of fixed vertices with :class:`~workbench.geometry.sparse_cholesky.SparseSPDSolver`
(CHOLMOD when installed).

Hand-written because the operators are a few sparse products; the
factorisations are CHOLMOD's / SuperLU's.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.sparse_cholesky import SparseSPDSolver

__all__ = ["PoissonSolver", "TriangleGradients"]

#: a rest triangle whose squared area is below this fraction of the mean is degenerate
_DEGENERATE = 1e-12


class TriangleGradients:
    """Edge frames, rest metrics and the gradient-domain Laplacian of one rest mesh.

    Parameters
    ----------
    vertices : (n, 3) float
        The rest mesh (the neutral).
    faces : (T, 3) int
        Triangles.

    Attributes
    ----------
    faces : (T, 3) int64
    n_vertices : int
    area : (T,) float64
        Rest triangle areas.
    rest_frames : (T, 3, 2) float64
        The rest mesh's frames ``M0``.
    valid : (T,) bool
        Non-degenerate rest triangles.
    inv_gram : (T, 2, 2) float64
        ``(M0ᵀ M0)⁻¹`` per triangle; zero for degenerate triangles, which then
        carry no gradient (they neither fit nor constrain anything).
    edge_operator : (2T, n) sparse CSR
        ``D``: row ``2t`` gives ``v3 - v1``, row ``2t + 1`` gives ``v2 - v1``.
    """

    def __init__(self, vertices: ArrayLike, faces: ArrayLike) -> None:
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3:
            raise ValueError(f"vertices must be (n, 3), got {V.shape}")
        if F.ndim != 2 or F.shape[1] != 3:
            raise ValueError(f"faces must be (T, 3) triangles, got {F.shape}")
        n, T = V.shape[0], F.shape[0]
        self.faces = F
        self.n_vertices = n
        M0 = self.frames(V)  # (T, 3, 2)
        gram = np.einsum("tci,tcj->tij", M0, M0)
        det = gram[:, 0, 0] * gram[:, 1, 1] - gram[:, 0, 1] * gram[:, 1, 0]
        ok = det > _DEGENERATE * max(float(np.mean(np.abs(det))), 1e-300)
        inv = np.zeros_like(gram)
        d = np.where(ok, det, 1.0)
        inv[:, 0, 0] = gram[:, 1, 1] / d
        inv[:, 1, 1] = gram[:, 0, 0] / d
        inv[:, 0, 1] = inv[:, 1, 0] = -gram[:, 0, 1] / d
        inv[~ok] = 0.0
        self.valid = ok
        self.rest_frames = M0
        self.inv_gram = inv
        self.area = 0.5 * np.sqrt(np.maximum(det, 0.0))
        rows = np.repeat(np.arange(2 * T), 2)
        cols = np.stack([F[:, 2], F[:, 0], F[:, 1], F[:, 0]], axis=1).reshape(-1)
        vals = np.tile([1.0, -1.0], 2 * T)
        self.edge_operator = sp.csr_matrix((vals, (rows, cols)), shape=(2 * T, n))
        Q = self.area[:, None, None] * inv  # (T, 2, 2) blocks
        self._Q = _block_diag_2x2(Q)
        self.laplacian = sp.csr_matrix(self.edge_operator.T @ self._Q @ self.edge_operator)

    @property
    def n_triangles(self) -> int:
        return int(self.faces.shape[0])

    def frames(self, X: ArrayLike) -> NDArray[np.float64]:
        """Edge frames ``[v3 - v1, v2 - v1]`` of ``X`` (..., n, 3) → (..., T, 3, 2)."""
        Y = np.asarray(X, dtype=np.float64)
        F = self.faces
        v1 = Y[..., F[:, 0], :]
        return np.stack([Y[..., F[:, 2], :] - v1, Y[..., F[:, 1], :] - v1], axis=-1)

    def gradient_norms(self, frames: ArrayLike) -> NDArray[np.float64]:
        """``|M P|_F`` per triangle for frames (..., T, 3, 2): the unit-free size of a deformation."""
        E = np.asarray(frames, dtype=np.float64)
        sq = np.einsum("...tci,tij,...tcj->...t", E, self.inv_gram, E)
        return np.sqrt(np.maximum(sq, 0.0))

    def divergence(self, frames: ArrayLike) -> NDArray[np.float64]:
        """``Dᵀ Q X``: the right-hand side of the Poisson solve for target frames (T, 3, 2) → (n, 3)."""
        E = np.asarray(frames, dtype=np.float64)
        flat = E.transpose(0, 2, 1).reshape(-1, 3)  # rows (2t, 2t+1) = the two edges, columns xyz
        return np.asarray(self.edge_operator.T @ (self._Q @ flat))


def _block_diag_2x2(blocks: NDArray[np.float64]) -> sp.csr_matrix:
    """A (2T, 2T) CSR matrix with the given (T, 2, 2) blocks on its diagonal."""
    T = blocks.shape[0]
    base = 2 * np.arange(T)
    rows = np.repeat(base[:, None], 4, axis=1) + np.array([0, 0, 1, 1])
    cols = np.repeat(base[:, None], 4, axis=1) + np.array([0, 1, 0, 1])
    return sp.csr_matrix(
        (blocks.reshape(T, 4).ravel(), (rows.ravel(), cols.ravel())), shape=(2 * T, 2 * T)
    )


class PoissonSolver:
    """Vertex positions from target frames with some vertices held fixed; factored once.

    Solves ``min Σ_t a_t |(M_t(x) - X_t) P_t|_F² + δ |x_free - prior|²`` over the
    free vertices, the fixed ones held at zero (a displacement field). ``δ`` is
    tiny (``1e-6`` of the mean Laplacian diagonal): it only decides the
    translation of a piece with no fixed vertex (an eyeball, the lower teeth),
    which gradients cannot see, by the prior's.

    Parameters
    ----------
    gradients : TriangleGradients
    free : (n,) bool
        Vertices to solve for; the rest stay at zero.
    """

    def __init__(self, gradients: TriangleGradients, free: ArrayLike) -> None:
        mask = np.asarray(free, dtype=bool).reshape(-1)
        if mask.shape[0] != gradients.n_vertices:
            raise ValueError(f"free has {mask.shape[0]} entries, expected {gradients.n_vertices}")
        self.gradients = gradients
        self.free = np.flatnonzero(mask)
        L = gradients.laplacian
        diag = L.diagonal()
        self.delta = 1e-6 * float(np.mean(diag[diag > 0])) if np.any(diag > 0) else 1e-6
        self._solver: SparseSPDSolver | None = None
        if self.free.size:
            K = L[self.free][:, self.free] + self.delta * sp.identity(self.free.size, format="csr")
            self._solver = SparseSPDSolver(K)

    def solve(self, frames: ArrayLike, prior: ArrayLike) -> NDArray[np.float64]:
        """Displacements (n, 3) for target frames (T, 3, 2), zero at the fixed vertices."""
        n = self.gradients.n_vertices
        out = np.zeros((n, 3))
        if self._solver is None:
            return out
        rhs = self.gradients.divergence(frames)[self.free]
        rhs += self.delta * np.asarray(prior, dtype=np.float64)[self.free]
        out[self.free] = self._solver.solve(rhs)
        return out
