"""The two alternating steps of :func:`workbench.rigging.refine_rig` (Li et al. 2010 §3).

Step A (:class:`GradientStep`, the paper's; :class:`VertexStep`, its
vertex-space ablation) refits the blendshapes with the weights fixed; step B
(:func:`solve_weights`) refits every example's weights with the shapes fixed.
The energies, weights and units are described in :mod:`workbench.rigging.refine`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg import solve_triangular
from scipy.optimize import lsq_linear
from scipy.sparse.csgraph import connected_components

from workbench.rigging.gradients import PoissonSolver, TriangleGradients

__all__ = ["GradientStep", "VertexStep", "rms_errors", "solve_weights", "triangle_weights"]

Progress = Callable[[float, str], None]

#: the paper's template size (its 11k vertices)
REFERENCE_VERTICES = 11_000
#: triangles (or vertices) per batched solve in step A
_CHUNK = 4096


# ---------------------------------------------------------------------- step A


def triangle_weights(
    grads: TriangleGradients, A: NDArray[np.float64], mm: float, kappa: float, theta: float
) -> NDArray[np.float64]:
    """Li §3's ``w_i = ((1 + |M_i^A|) / (κ + |M_i^A|))^θ`` per shape and triangle, (k, T).

    ``|M_i^A|_F`` is the paper's frame norm in millimetres on its 11k-vertex
    template, measured without depending on this mesh's triangle sizes: the
    template shape's deformation gradient ``|M(A_i) P|_F`` (a strain) times
    the mean rest frame size ``|M0|_F`` in mm that this face would have at
    11,000 vertices. Large (→ (1/κ)^θ = 100) where the template does not
    deform, → 1 where it deforms strongly. ``mm`` converts the model's units
    to millimetres.
    """
    frame = np.linalg.norm(grads.rest_frames.reshape(-1, 6), axis=1)
    size = (
        float(np.mean(frame[grads.valid])) * mm * math.sqrt(grads.n_vertices / REFERENCE_VERTICES)
    )
    g = grads.gradient_norms(grads.frames(A)) * size
    return np.asarray(((1.0 + g) / (kappa + g)) ** theta)


def _blend_solve(
    alpha: NDArray[np.float64],
    R: NDArray[np.float64],
    prior: NDArray[np.float64],
    w: NDArray[np.float64],
    active: NDArray[np.bool_],
    beta: float,
) -> NDArray[np.float64]:
    """Per element e: ``min Σ_j |R_je - Σ_i α_ij X_ie|² + β Σ_i w_ie |X_ie - prior_ie|²``.

    ``R`` (m, E, d), ``prior`` (k, E, d), ``w`` and ``active`` (k, E); inactive
    unknowns are held at zero. Returns ``X`` (k, E, d).
    """
    k, E, d = prior.shape
    G = alpha.T @ alpha  # (k, k)
    X = np.zeros((k, E, d))
    eye = np.eye(k, dtype=bool)
    for e0 in range(0, E, _CHUNK):
        e1 = min(E, e0 + _CHUNK)
        act = active[:, e0:e1].T  # (C, k)
        wa = (beta * w[:, e0:e1].T) * act
        H = G[None] * (act[:, :, None] & act[:, None, :])
        H[:, eye] += wa + ~act
        b = np.einsum("mk,mcd->ckd", alpha, R[:, e0:e1])
        b += wa[..., None] * prior[:, e0:e1].transpose(1, 0, 2)
        b *= act[..., None]
        X[:, e0:e1] = np.linalg.solve(H, b).transpose(1, 0, 2)
    return X


class GradientStep:
    """Step A in gradient space: per-triangle blend solve, then one Poisson solve per shape.

    Gradients do not see where a piece with no fixed vertex sits (an eyeball or
    the lower teeth moved whole by a shape): the mean displacement of such a
    piece is solved like a frame, by the same blend solve on the pieces' mean
    example displacements, regularised toward the template's (w = 1).
    """

    def __init__(
        self,
        grads: TriangleGradients,
        A: NDArray[np.float64],
        residual: NDArray[np.float64],
        moving: NDArray[np.bool_],
        w: NDArray[np.float64],
        report: Progress,
    ) -> None:
        F = grads.faces
        T = grads.n_triangles
        ko, n = moving.shape
        # a triangle is an unknown of a shape when one of its vertices moves in the template
        active = moving[:, F].any(axis=2) & grads.valid[None]  # (ko, T)
        self.tri = tri = np.flatnonzero(active.any(axis=0))
        self.A = A
        self.T = T
        self.active = active[:, tri]
        self.w = w[:, tri]
        self.prior = grads.frames(A)[:, tri].reshape(ko, tri.size, 6)
        self.R = grads.frames(residual)[:, tri].reshape(residual.shape[0], tri.size, 6)
        # connected pieces of the mesh; a piece floats in a shape when all its vertices move
        adj = sp.coo_matrix(
            (np.ones(3 * T), (F.ravel(), np.roll(F, 1, axis=1).ravel())), shape=(n, n)
        )
        n_pieces, piece = connected_components(adj, directed=False)
        sizes = np.bincount(piece, minlength=n_pieces)
        moving_count = np.stack(
            [np.bincount(piece, weights=mv, minlength=n_pieces) for mv in moving]
        )
        floating = moving_count == sizes[None]  # (ko, n_pieces)
        keep = np.flatnonzero(floating.any(axis=0))
        self.floating = floating[:, keep]
        inv = np.full(n_pieces, -1)
        inv[keep] = np.arange(keep.size)
        rows = inv[piece]
        sel = rows >= 0
        self.mean_op = sp.csr_matrix(
            (1.0 / sizes[piece[sel]], (rows[sel], np.flatnonzero(sel))), shape=(keep.size, n)
        )
        self.piece_of = rows  # vertex -> floating piece row (or -1)
        self.R_mean = np.stack([self.mean_op @ r for r in residual]) if keep.size else None
        self.A_mean = np.stack([self.mean_op @ a for a in A]) if keep.size else None
        self.solvers = []
        for i in range(ko):
            self.solvers.append(PoissonSolver(grads, moving[i]))
            report(0.02 + 0.08 * (i + 1) / ko, f"factored shape {i + 1}/{ko}")

    def solve(self, alpha: NDArray[np.float64], beta: float) -> NDArray[np.float64]:
        X = _blend_solve(alpha, self.R, self.prior, self.w, self.active, beta)  # (ko, t, 6)
        out = np.empty_like(self.A)
        frames = np.zeros((self.T, 3, 2))
        for i, solver in enumerate(self.solvers):
            frames[self.tri] = X[i].reshape(-1, 3, 2)
            out[i] = solver.solve(frames, self.A[i])
        if self.R_mean is not None and self.A_mean is not None:
            means = np.stack([self.mean_op @ b for b in out])  # (ko, pieces, 3)
            anchored = np.einsum("mk,kpd->mpd", alpha, means * ~self.floating[..., None])
            target = _blend_solve(
                alpha,
                self.R_mean - anchored,
                self.A_mean,
                np.ones(self.floating.shape),
                self.floating,
                beta,
            )
            shift = np.where(self.floating[..., None], target - means, 0.0)  # (ko, pieces, 3)
            sel = self.piece_of >= 0
            out[:, sel] += shift[:, self.piece_of[sel]]
        return out


class VertexStep:
    """Step A in vertex space (the paper's ablation, Li §4 Fig. 4).

    The same energy with the displacements as unknowns: per vertex, the fit
    to the examples plus ``β Σ_i w_i |B_i(v) - A_i(v)|²`` with the paper's
    per-triangle weights area-averaged onto the vertices, the same fixed
    vertices; no reconstruction step.
    """

    def __init__(
        self,
        grads: TriangleGradients,
        A: NDArray[np.float64],
        residual: NDArray[np.float64],
        moving: NDArray[np.bool_],
        w: NDArray[np.float64],
    ) -> None:
        F = grads.faces
        n = grads.n_vertices
        acc = np.zeros((n, A.shape[0]))
        area = np.zeros(n)
        aw = (w * grads.area[None]).T  # (T, k)
        for c in range(3):
            np.add.at(acc, F[:, c], aw)
            np.add.at(area, F[:, c], grads.area)
        wv = np.where(area[:, None] > 0, acc / np.where(area > 0, area, 1.0)[:, None], 1.0).T
        self.vert = v = np.flatnonzero(moving.any(axis=0))
        self.A = A
        self.active = moving[:, v]
        self.w = wv[:, v]
        self.prior = A[:, v]
        self.R = residual[:, v]

    def solve(self, alpha: NDArray[np.float64], beta: float) -> NDArray[np.float64]:
        out = np.zeros_like(self.A)
        out[:, self.vert] = _blend_solve(alpha, self.R, self.prior, self.w, self.active, beta)
        return out


# ---------------------------------------------------------------------- step B


def solve_weights(
    B: NDArray[np.float64],
    residual: NDArray[np.float64],
    scale: float,
    alpha_star: NDArray[np.float64],
    gamma: float,
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    pairs: list[tuple[int, int]],
) -> NDArray[np.float64]:
    """Li §3 step B for every example: the bounded QP, exclusive pairs enforced."""
    ko = B.shape[0]
    Dm = B.reshape(ko, -1)
    H = scale * (Dm @ Dm.T) + gamma * np.eye(ko)
    H[np.diag_indices(ko)] += 1e-12 * max(float(np.trace(H)) / ko, 1e-300)
    Q = scale * (residual.reshape(residual.shape[0], -1) @ Dm.T) + gamma * alpha_star  # (m, ko)
    out = np.empty_like(alpha_star)
    for j in range(Q.shape[0]):
        out[j] = _exclusive_qp(H, Q[j], lo, hi, pairs)
    return out


def _box_qp(
    H: NDArray[np.float64],
    q: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    keep: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.float64], float]:
    """``min ½ xᵀHx - qᵀx`` with ``lo ≤ x ≤ hi`` (variables outside ``keep`` held at 0); x and its value."""
    x = np.zeros_like(q)
    idx = np.arange(q.size) if keep is None else np.flatnonzero(keep)
    if idx.size == 0:
        return x, 0.0
    Hs = H[np.ix_(idx, idx)]
    L = np.linalg.cholesky(Hs)
    c = solve_triangular(L, q[idx], lower=True)
    res = lsq_linear(L.T, c, bounds=(lo[idx], hi[idx]), method="bvls", lsmr_tol=None)
    x[idx] = np.clip(res.x, lo[idx], hi[idx])
    return x, float(0.5 * x @ H @ x - q @ x)


def _exclusive_qp(
    H: NDArray[np.float64],
    q: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    pairs: list[tuple[int, int]],
) -> NDArray[np.float64]:
    """The box QP with ``x_a x_b = 0`` for every pair: branch on which of a violated pair is zero."""
    x, _ = _box_qp(H, q, lo, hi)
    if not pairs:
        return x
    keep = np.ones(q.size, dtype=bool)
    while True:
        bad = [(a, b) for a, b in pairs if keep[a] and keep[b] and x[a] != 0.0 and x[b] != 0.0]
        if not bad:
            return x
        best: tuple[float, NDArray[np.float64], NDArray[np.bool_]] | None = None
        if len(bad) <= 8:
            choices: Any = itertools.product(*[(a, b) for a, b in bad])
        else:  # too many to enumerate: zero the smaller of each pair
            choices = [tuple(a if abs(x[a]) < abs(x[b]) else b for a, b in bad)]
        for zeroed in choices:
            trial = keep.copy()
            trial[list(zeroed)] = False
            xt, value = _box_qp(H, q, lo, hi, trial)
            if best is None or value < best[0]:
                best = (value, xt, trial)
        assert best is not None
        _, x, keep = best


def rms_errors(
    residual: NDArray[np.float64], B: NDArray[np.float64], alpha: NDArray[np.float64]
) -> NDArray[np.float64]:
    """RMS vertex distance between each example and the rig at its weights."""
    fit = np.einsum("mk,knd->mnd", alpha, B)
    return np.asarray(np.sqrt(np.mean(np.sum((residual - fit) ** 2, axis=2), axis=1)))
