"""The linear expression-transfer operators ``T_i*`` of a template rig (Bouaziz et al. 2013, appendix, eq. 7).

``T_i* b0`` carries template shape ``i`` onto another neutral ``b0`` of the same
mesh: the affine map ``S_t = S_i S_0⁻¹`` of every template skin triangle (the
tetrahedron of two edges and the scaled normal, Sumner & Popović 2004,
:func:`workbench.geometry.frames.triangle_frames`) is applied to the three
edges of the same triangle of ``b0``, and the vertices are the least-squares
fit to those edges (a graph Laplacian ``GᵀG`` with unit edge weights, so
``T_i*`` is linear in ``b0``). Vertices the template shape does not move keep
the neutral's position (hard pins). With ``b0 = b0*`` it returns ``b_i*``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.frames import triangle_frames
from workbench.geometry.sparse_cholesky import SparseSPDSolver

__all__ = ["PIN_TOL", "ExpressionTransfer", "TransferRows", "sub_faces"]

#: a template vertex moving less than this (times the length scale) in a shape is pinned in its transfer
PIN_TOL = 1e-7


def sub_faces(F: NDArray[np.int64], ids: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """Faces with all corners in ``ids``, renumbered into ``ids``."""
    local = np.full(n, -1, np.int64)
    local[ids] = np.arange(ids.size)
    Fl = local[F]
    return Fl[(Fl >= 0).all(1)]


class ExpressionTransfer:
    """The paper's linear expression-transfer operators ``T_i*`` of a template rig (appendix, eq. 7).

    ``T_i* b0`` minimises ``Σ_t Σ_edges |S_t e_t(b0) − e_t(b_i)|²`` over the skin
    triangles (``S_t`` the template triangle's affine map from ``b0*`` to
    ``b_i*``, built on the tetrahedron of two edges and the normal scaled by
    ``1/√|n|``), with the vertices that the template shape leaves in place held
    at ``b0`` (hard pins). Vertices off the skin get the template's delta.

    Parameters
    ----------
    vertices : (n, 3) float
        The template neutral ``b0*``.
    faces : (T, 3) int
    deltas : (k, n, 3) float
        The template shapes ``b_i* − b0*``.
    skin : (s,) int, optional
        Vertex ids of the skin (default all).
    length_scale : float, optional
        For the pin tolerance (default the RMS radius of the skin).

    Attributes
    ----------
    skin : (s,) int64
    n_shapes : int
    """

    def __init__(self, vertices: ArrayLike, faces: ArrayLike, deltas: ArrayLike, *, skin: ArrayLike | None = None,
                 length_scale: float | None = None) -> None:
        V = np.asarray(vertices, np.float64)
        F = np.asarray(faces, np.int64)
        D = np.asarray(deltas, np.float64)
        n = V.shape[0]
        if D.ndim != 3 or D.shape[1:] != (n, 3):
            raise ValueError(f"deltas must be (k, {n}, 3), got {D.shape}")
        self.n_vertices = n
        self.n_shapes = D.shape[0]
        self.skin = np.arange(n, dtype=np.int64) if skin is None else np.unique(np.asarray(skin, np.int64))
        self._deltas = D
        Fs = sub_faces(F, self.skin, n)
        ns, T = self.skin.size, Fs.shape[0]
        self._T = T
        # G: three edges per triangle, row j*T + t = v[(j+1)%3] − v[j]
        rows = np.repeat(np.arange(3 * T), 2)
        a = np.concatenate([Fs[:, 0], Fs[:, 1], Fs[:, 2]])
        b = np.concatenate([Fs[:, 1], Fs[:, 2], Fs[:, 0]])
        cols = np.stack([b, a], 1).reshape(-1)
        self._G = sp.csr_matrix((np.tile([1.0, -1.0], 3 * T), (rows, cols)), shape=(3 * T, ns))
        self._GtG = sp.csr_matrix(self._G.T @ self._G)
        # where each edge's four Laplacian entries land in the CSR pattern of GᵀG (for _rhs)
        self._pattern = self._GtG
        self._pattern.sort_indices()
        ea = np.concatenate([a, b, a, b])
        eb = np.concatenate([a, b, b, a])
        key = ea * ns + eb
        pr = np.repeat(np.arange(ns), np.diff(self._pattern.indptr))
        pkey = pr * ns + self._pattern.indices
        slot = np.searchsorted(pkey, key)
        self._scatter = sp.csr_matrix((np.ones(slot.size), (slot, np.arange(slot.size))),
                                      shape=(self._pattern.nnz, slot.size))
        Vs = V[self.skin]
        inv0, ok0 = self._frames_inverse(Vs, Fs)
        self._Fs = Fs
        self._inv0 = inv0
        self._ok0 = ok0
        Ds = D[:, self.skin]
        if length_scale is None:
            length_scale = float(np.sqrt(((Vs - Vs.mean(0)) ** 2).sum(1).mean())) if ns else 1.0
        mag = np.linalg.norm(Ds, axis=2)
        #: (k, s) bool: skin vertices each shape moves (the rest are pinned to the neutral)
        self.free = mag > PIN_TOL * max(length_scale, 1e-300)
        self._Vs = Vs

    def _frames_inverse(self, X: NDArray[np.float64], F: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        S0 = triangle_frames(X, F)
        det = np.linalg.det(S0)
        scale = float(np.median(np.abs(det))) if det.size else 1.0
        ok = np.abs(det) > 1e-12 * max(scale, 1e-300)
        inv = np.zeros_like(S0)
        inv[ok] = np.linalg.inv(S0[ok])
        return inv, ok

    def strain(self, i: int) -> NDArray[np.float64]:
        """``S_t − I`` of shape ``i`` per skin triangle, (T, 3, 3) (zero on degenerate template triangles)."""
        Si = triangle_frames(self._Vs + self._deltas[i, self.skin], self._Fs)
        C = Si @ self._inv0 - np.eye(3)
        C[~self._ok0] = 0.0
        return C

    def _system(self, i: int) -> tuple[NDArray[np.int64], SparseSPDSolver | None]:
        free = np.flatnonzero(self.free[i])
        if free.size == 0:
            return free, None
        K = self._GtG[free][:, free]
        diag = K.diagonal()
        ridge = 1e-10 * float(diag.mean()) if diag.size else 1e-10
        return free, SparseSPDSolver(sp.csc_matrix(K + ridge * sp.identity(free.size)))

    def _rhs(self, C: NDArray[np.float64], fields: NDArray[np.float64], rows: NDArray[np.int64]) -> NDArray[np.float64]:
        """Rows ``rows`` of ``Gᵀ (H − I) G f`` for scalar fields ``f`` (s, q) along each axis → (r, 3 coords, q, 3 axes).

        ``Gᵀ diag(C_cd) G`` is a weighted graph Laplacian per pair of axes ``(c, d)``;
        the nine share the sparsity pattern of ``GᵀG``.
        """
        Ct = np.concatenate([C, C, C]).reshape(3 * self._T, 9)  # the triangle of each edge row
        data9 = np.asarray(self._scatter @ np.concatenate([Ct, Ct, -Ct, -Ct]))  # (nnz, 9)
        P = self._pattern
        starts, lens = P.indptr[rows], np.diff(P.indptr)[rows]
        offs = np.concatenate([[0], np.cumsum(lens)])
        idx = np.repeat(starts - offs[:-1], lens) + np.arange(offs[-1])
        sub_indices = P.indices[idx]
        f = np.ascontiguousarray(fields, dtype=np.float64)
        s, q = f.shape
        out = np.empty((rows.size, 3, q, 3), order="F")  # Fortran: columns contiguous for the solver
        for cd in range(9):
            Lcd = sp.csr_matrix((data9[idx, cd], sub_indices, offs), shape=(rows.size, s))
            out[:, cd // 3, :, cd % 3] = Lcd @ f
        return out

    def delta(self, i: int, neutral: ArrayLike) -> NDArray[np.float64]:
        """``T_i* b0 − b0`` for a neutral ``b0`` (n, 3): the transferred delta of shape ``i``, (n, 3)."""
        b0 = np.asarray(neutral, np.float64)
        if b0.shape != (self.n_vertices, 3):
            raise ValueError(f"neutral must be ({self.n_vertices}, 3), got {b0.shape}")
        out = self._deltas[i].copy()
        out[self.skin] = 0.0
        free, solver = self._system(i)
        if solver is None:
            return out
        C = self.strain(i)
        Gb = (self._G @ b0[self.skin]).reshape(3, self._T, 3)  # edges per triangle
        CGb = np.einsum("tcd,jtd->jtc", C, Gb).reshape(3 * self._T, 3)
        rhs = self._G.T @ CGb
        res = np.zeros((self.skin.size, 3))
        res[free] = solver.solve(rhs[free])
        out[self.skin] = res
        return out

    def apply(self, neutral: ArrayLike) -> NDArray[np.float64]:
        """All transferred deltas ``T_i* b0 − b0``, (k, n, 3)."""
        return np.stack([self.delta(i, neutral) for i in range(self.n_shapes)]) if self.n_shapes else \
            np.zeros((0, self.n_vertices, 3))

    def basis_rows(self, i: int, fields: ArrayLike, rows: ArrayLike) -> NDArray[np.float64]:
        """``(T_i* − I)`` applied to the vector fields ``f_q ⊗ axis_d`` at some skin vertices.

        Parameters
        ----------
        i : int
            Shape.
        fields : (s, q) float
            Scalar fields on the skin (one value per skin vertex).
        rows : (r,) int
            Positions in :attr:`skin` where the result is wanted.

        Returns
        -------
        X : (r, 3, q, 3) float64
            ``X[v, c, j, d]``: coordinate ``c`` at vertex ``rows[v]`` of ``(T_i* − I)(f_j axis_d)``.
        """
        f = np.asarray(fields, np.float64)
        r = np.asarray(rows, np.int64)
        q = f.shape[1]
        out = np.zeros((r.size, 3, q, 3))
        free, solver = self._system(i)
        if solver is None or r.size == 0:
            return out
        pos = np.full(self.skin.size, -1, np.int64)
        pos[free] = np.arange(free.size)
        want = pos[r] >= 0
        if not want.any():
            return out
        rhs = self._rhs(self.strain(i), f, free)  # (f, 3, q, 3)
        sol = solver.solve(rhs.reshape(free.size, -1, order="F")).reshape(free.size, 3, q, 3, order="F")
        out[want] = sol[pos[r[want]]]
        return out


class TransferRows:
    """``(T_i* − I) E`` at the constraint vertices, per shape: how the neutral's coefficients move each shape.

    Kept only at the rows shape ``i`` moves (zero elsewhere), in float32: shape
    ``i``'s rows are ``values[offsets[i]:offsets[i + 1]]`` at rows ``rows[i]`` of
    a ``(3p, 3K)`` block over the constraint coordinates ``[x0, y0, z0, x1, ...]``.
    One sparse solve per shape (:meth:`ExpressionTransfer.basis_rows`), once.

    Parameters
    ----------
    transfer : ExpressionTransfer
    basis : (s, K) float
        The basis ``E`` on the transfer's skin vertices.
    skin_rows : (p,) int
        Each constraint vertex's position in ``transfer.skin`` (-1 off the skin: no transfer there).
    progress : callable, optional
        ``progress(fraction, message)`` per shape.
    names : sequence of str, optional
        Shape names for the progress messages.
    """

    def __init__(self, transfer: ExpressionTransfer, basis: NDArray[np.float64], skin_rows: NDArray[np.int64],
                 progress: Callable[[float, str], Any] | None = None, names: Sequence[str] = ()) -> None:
        k = transfer.n_shapes
        p = skin_rows.size
        K3 = 3 * basis.shape[1]
        self.n_shapes, self.p, self.K3 = k, p, K3
        blocks, rows_of = [], []
        for i in range(k):
            if progress is not None:
                name = names[i] if i < len(names) else f"shape {i}"
                progress(i / max(k, 1), f"adaptive model: transfer rows of {name} ({i + 1} of {k})")
            on = np.flatnonzero(skin_rows >= 0)
            on = on[transfer.free[i][skin_rows[on]]]
            X = transfer.basis_rows(i, basis, skin_rows[on])  # (r, 3, K, 3)
            blocks.append(X.reshape(3 * on.size, K3).astype(np.float32))
            rows_of.append((3 * on[:, None] + np.arange(3)).reshape(-1))
        self.values = np.concatenate(blocks) if blocks else np.zeros((0, K3), np.float32)
        self.rows = rows_of
        self.offsets = np.concatenate([[0], np.cumsum([r.size for r in rows_of])]).astype(np.int64)
        self._flat = np.concatenate([i * 3 * p + r for i, r in enumerate(rows_of)]) if rows_of else \
            np.zeros(0, np.int64)

    def of_neutral(self, u0: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(T_i* − I) E u0`` for every shape at the constraint vertices, (k, p, 3)."""
        tr = np.zeros(self.n_shapes * 3 * self.p)
        tr[self._flat] = self.values @ u0.astype(np.float32)
        return tr.reshape(self.n_shapes, self.p, 3)

    def weighted(self, x: NDArray[np.float64], active: NDArray[np.intp]) -> NDArray[np.float64]:
        """``Σ_i x_i (T_i* − I) E`` over the ``active`` shapes, (3p, 3K)."""
        out = np.zeros((3 * self.p, self.K3))
        for i in active:
            out[self.rows[i]] += x[i] * self.values[self.offsets[i]:self.offsets[i + 1]]
        return out
