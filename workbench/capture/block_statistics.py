"""Algorithm 1's decayed normal equations over blocks of unknowns, and block Gauss–Seidel on them (Bouaziz et al. 2013).

The adaptive rig (:mod:`workbench.capture.adapt`) has one block of unknowns for
the neutral (block 0) and one per shape (block ``i + 1``). A frame adds
``ĀᵀĀ`` and ``Āᵀc̄`` restricted to the blocks active in it; older frames decay
by ``γ``: ``s^t = γ s^{t−1} + 1``, ``M^t = (γ s^{t−1} M^{t−1} + ĀᵀĀ) / s^t``,
``y^t = (γ s^{t−1} y^{t−1} + Āᵀc̄) / s^t``. ``M`` is kept as its upper blocks
``(i, j), i ≤ j``, only for pairs that were active together, unnormalised and
scaled by a running factor ``g`` so a frame costs no pass over the old blocks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

__all__ = ["BlockStatistics", "spd_solve"]


def spd_solve(A: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``A⁻¹ b`` for a small SPD ``A`` by Cholesky (LAPACK potrf/potrs).

    ``scipy.linalg.solve(assume_a="pos")`` does the same factorisation but measured
    ~40× slower per 150×150 block on a loaded 2-core machine (scipy 1.17: extra checks,
    and a threaded BLAS whose threads wait for busy cores). These blocks are far too
    small to gain from threads: every public method of the adaptive model that solves
    them holds BLAS to one thread with :func:`workbench.blas.one_blas_thread` once,
    around all its work.
    """
    return sla.cho_solve(sla.cho_factor(A, check_finite=False), b, check_finite=False)


class BlockStatistics:
    """The aggregated ``(M^t, y^t)`` of Algorithm 1 in blocks.

    Parameters
    ----------
    n_blocks : int
        Blocks of unknowns (the neutral and one per shape).
    size : int
        Unknowns per block (``3K``).
    gamma : float
        Temporal decay, ``0 < γ ≤ 1``.
    regularization : (n_blocks, size) float
        The diagonal ``D`` added to each diagonal block when solving.
    """

    def __init__(self, n_blocks: int, size: int, gamma: float, regularization: NDArray[np.float64]) -> None:
        self.gamma = gamma
        self.size = size
        self.reg = regularization
        self._M: dict[tuple[int, int], NDArray[np.float64]] = {}
        self._nbr: list[set[int]] = [set() for _ in range(n_blocks)]
        self._y = np.zeros((n_blocks, size))
        self._g = 1.0  # stored statistics × g = Σ_j γ^{t-j} (frame j's)
        self._s = 0.0

    def has(self, bk: int) -> bool:
        """Whether block ``bk`` has statistics (was active in some frame)."""
        return (bk, bk) in self._M

    def _block(self, i: int, j: int) -> NDArray[np.float64]:
        return self._M[(i, j)] if i <= j else self._M[(j, i)].T

    def _add(self, i: int, j: int, blk: NDArray[np.float64]) -> None:
        key = (i, j) if i <= j else (j, i)
        val = blk if i <= j else blk.T
        cur = self._M.get(key)
        if cur is None:
            self._M[key] = val.copy()
            self._nbr[i].add(j)
            self._nbr[j].add(i)
        else:
            cur += val

    def add_frame(self, blocks: Sequence[int], weights: Mapping[int, float], Q: NDArray[np.float64],
                  P: NDArray[np.float64], cbar: NDArray[np.float64], fixed: NDArray[np.bool_]) -> None:
        """Decay, then add one frame with ``Ā = [Q, w_1 P, w_2 P, ...]`` over ``blocks`` (block 0 first).

        Parameters
        ----------
        blocks : sequence of int
            ``0`` and the active shapes' blocks.
        weights : mapping int -> float
            Each active block's weight (1 for block 0).
        Q, P : (m, size) float
            The neutral's columns and a shape's columns before its weight.
        cbar : (m,) float
        fixed : (n_blocks,) bool
            Blocks fixed for good (saturated): pairs of two are not stored.
        """
        self._s = self.gamma * self._s + 1.0
        self._g *= self.gamma
        if self._g < 1e-150:  # renormalise before the factor underflows
            for key in self._M:
                self._M[key] *= self._g
            self._y *= self._g
            self._g = 1.0
        inv_g = 1.0 / self._g
        PtP = P.T @ P
        QtP = Q.T @ P
        for a_idx, a in enumerate(blocks):
            for b in blocks[a_idx:]:
                if fixed[a] and fixed[b]:
                    continue  # both fixed for good: never read again
                if a == 0 and b == 0:
                    blk = Q.T @ Q
                elif a == 0:
                    blk = weights[b] * QtP
                else:
                    blk = (weights[a] * weights[b]) * PtP
                self._add(a, b, blk * inv_g)
            self._y[a] += (Q.T @ cbar if a == 0 else weights[a] * (P.T @ cbar)) * inv_g

    def gauss_seidel(self, u: NDArray[np.float64], todo: Sequence[int], sweeps: int) -> None:
        """Block Gauss–Seidel sweeps on ``(M^t + D) u = y^t`` over the blocks ``todo``, updating ``u`` (n_blocks, size) in place."""
        if not todo or self._s == 0:
            return
        f = self._g / self._s  # stored → M^t
        for _ in range(sweeps):
            for bk in todo:
                if (bk, bk) not in self._M:
                    continue
                rhs = self._y[bk].copy()
                for j in self._nbr[bk]:
                    if j != bk:
                        rhs -= self._block(bk, j) @ u[j]
                Mbb = f * self._M[(bk, bk)]
                Mbb[np.diag_indices_from(Mbb)] += self.reg[bk]
                u[bk] = spd_solve(Mbb, f * rhs)

    def dense(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(M^t, y^t)`` as dense arrays, ``(nb·size, nb·size)`` and ``(nb·size,)`` (small problems; for checks)."""
        nb = self._y.shape[0]
        K3 = self.size
        f = self._g / self._s if self._s else 0.0
        M = np.zeros((nb * K3, nb * K3))
        for (i, j), blk in self._M.items():
            M[i * K3:(i + 1) * K3, j * K3:(j + 1) * K3] = f * blk
            M[j * K3:(j + 1) * K3, i * K3:(i + 1) * K3] = f * blk.T
        return M, f * self._y.reshape(-1)
