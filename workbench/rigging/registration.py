"""Fit the template's skin onto the target surface: rigid, then non-rigid (ICP with a smooth displacement).

**Rigid** (:func:`rigid_icp`): a similarity (scale, rotation, translation)
from landmark pairs when given (Umeyama), refined by trimmed ICP of the
template skin against the target surface.

**Non-rigid** (:func:`nonrigid_icp`): the template's vertices ``x = x0 + u``
minimise, at each step,

    alpha * u^T K u  +  sum_i m_i w_i |x_i - c_i|^2  +  beta * sum_l |x_l - p_l|^2  +  eps * |x - x_prev|_M^2

with ``K = L^T M^-1 L`` the bilaplacian of the template (cotangent ``L``,
Voronoi mass ``M``: the bending of the displacement, zero for affine
motion), ``c_i`` the closest target point of vertex ``i`` and ``w_i`` in
{0, 1}: a correspondence is rejected when it is far (beyond 3 median
distances), when the target normal there disagrees with the template's
(> 60 deg), or when it lies on the target's border (a hole, or where the target
surface ends). ``p_l`` are landmark positions. The stiffness ``alpha`` falls
from smooth (a tenth of the head) to fine (a few millimetres) over the
schedule, as in Amberg et al. 2007. Each stiffness factors its sparse SPD
matrix once with CHOLMOD (:class:`workbench.geometry.sparse_cholesky.SparseSPDSolver`)
and keeps the factor while the accepted correspondences change by less than
1 % (a dropped one then holds its vertex in place, a new one waits for the
next factor); each step is then one back-substitution.
**Soft tail** (:func:`planar_refine`, used for expression cloning): at low
stiffness point-to-point pulls hold each vertex where its closest point is, so
the fit creeps along the surface a little per step and a locally grown part
(a 1.25x jaw) stays under-stretched. The tail measures the data along the
target normal only (the template slides freely on the surface) and the bending
after each vertex's local similarity (a local scale or turn bends nothing), at
stiffnesses falling to a smoothing length of about half a millimetre
(:data:`FINE_SCHEDULE`); one coupled factorisation per step. On the
1.25x-jaw face the jaw's correspondence error falls from 5.6 to 0.8 mm (head
386 mm; with the two-stiffness tail before).
Extra target surface (neck, bust, shoulders) attracts nothing: only template
vertices look for a partner. Coordinates here are in head units (the template
skin's bounding-box diagonal is 1).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from workbench.geometry.normals import vertex_normals
from workbench.geometry.operators import cotangent_laplacian, mass_matrix
from workbench.geometry.similarity import Similarity, fit_similarity
from workbench.geometry.sparse_cholesky import SparseSPDSolver
from workbench.geometry.surface import SurfaceQuery

__all__ = ["DEFAULT_SCHEDULE", "FINE_SCHEDULE", "NonRigidResult", "affine_icp", "nonrigid_icp", "planar_refine",
           "rigid_icp"]

#: (alpha, iterations): stiffness in head units^4 (alpha**0.25 is the smoothing length in head units)
DEFAULT_SCHEDULE: tuple[tuple[float, int], ...] = (
    (1e-2, 3), (1e-3, 3), (1e-4, 3), (1e-5, 3), (1e-6, 4), (3e-7, 4), (1e-7, 4), (3e-8, 4),
)

#: the soft tail of :func:`planar_refine` (below DEFAULT_SCHEDULE's last stiffness): the same 20 steps
#: spread down to a smoothing length of ~1e-3 head (0.5 mm). Chosen on five held-out faces (other
#: warps, proportions, a remesh, two foreign faces): cloning error 5.0 -> 4.2 % of the motion on
#: average (each face: 2.4 -> 2.0, 6.9 -> 5.9, 4.1 -> 4.3, 6.1 -> 4.3, 5.6 -> 4.4 %; two stages of
#: 10 steps, 1e-8 and 3e-9, before), at the same set-up time (the same number of factorisations).
#: Going on to 1e-12, changing ``eps`` or three times the steps (the jaw face 8.9 -> 9.0 %, the foreign
#: face 5.60 -> 5.59 %, twice the set-up) gained nothing more. What it does not change: a
#: grown part's stretch — a 1.25x jaw's edges come out 0.96-0.97 of their true length, the shrunk
#: side's 1.03 (the bending, not the data, places a vertex along the surface).
FINE_SCHEDULE: tuple[tuple[float, int], ...] = (
    (1e-8, 3), (3e-9, 3), (1e-9, 3), (3e-10, 3), (1e-10, 2), (3e-11, 2), (1e-11, 2), (3e-12, 2),
)


def _accept(
    query: SurfaceQuery,
    X: NDArray[np.float64],
    normals: NDArray[np.float64],
    *,
    floor: float,
    max_angle_cos: float = 0.5,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Closest target points of ``X``, which correspondences to keep, their distances and the target normals there."""
    dist, face, C, bary = query.closest(X)
    tn = query.normals_at(face, bary)
    med = float(np.median(dist))
    ok = dist <= max(3.0 * med, floor)
    ok &= (normals * tn).sum(1) >= max_angle_cos
    ok &= ~query.on_boundary(face, bary)
    return C, ok, dist, tn


def _vertex_masses(X0: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.float64]:
    """(n,) Voronoi masses of the template, a vertex without area given the smallest one."""
    m = np.asarray(mass_matrix(X0, F).diagonal(), np.float64)
    return np.where(m > 0, m, m[m > 0].min() if (m > 0).any() else 1.0)


def _landmark_terms(
    landmarks: tuple[NDArray[np.int64], NDArray[np.float64]] | None, weight: float, m: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-vertex landmark weight (n,) and its right-hand side (n, 3): ``weight`` median masses per landmark."""
    n = m.shape[0]
    lm_w = np.zeros(n)
    lm_rhs = np.zeros((n, 3))
    if landmarks is not None and landmarks[0].size:
        wl = weight * float(np.median(m))
        np.add.at(lm_w, landmarks[0], wl)
        np.add.at(lm_rhs, landmarks[0], wl * landmarks[1])
    return lm_w, lm_rhs


def rigid_icp(
    X: NDArray[np.float64],
    F: NDArray[np.int64],
    query: SurfaceQuery,
    start: Similarity,
    *,
    iterations: int = 30,
    sample: int = 2000,
    scale: bool = True,
    landmarks: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
    landmark_weight: float = 0.0,
) -> tuple[Similarity, float, float]:
    """Trimmed similarity ICP of the template skin ``(X, F)`` onto the target (``query``).

    Parameters
    ----------
    X, F
        Template skin in head units.
    query
        The target surface (head units, already roughly placed by ``start``'s inverse).
    start
        Initial similarity applied to ``X``.
    landmarks
        Template vertex ids and their target positions (a soft pull of weight
        ``landmark_weight`` times the mean correspondence weight per landmark).

    Returns
    -------
    (similarity, accepted share, median distance) — the last two for the final step.
    """
    rng = np.random.default_rng(0)
    idx = np.arange(X.shape[0]) if X.shape[0] <= sample else np.sort(rng.choice(X.shape[0], sample, replace=False))
    N0 = vertex_normals(X, F)[idx]
    P0 = X[idx]
    T = start
    share, med = 0.0, np.inf
    for _ in range(iterations):
        P = T(P0)
        N = N0 @ T.R.T
        C, ok, dist, _ = _accept(query, P, N, floor=0.02, max_angle_cos=0.3)
        share = float(ok.mean())
        med = float(np.median(dist[ok])) if ok.any() else np.inf
        if ok.sum() < 10:
            break
        src, dst, w = P0[ok], C[ok], np.ones(int(ok.sum()))
        if landmarks is not None and landmark_weight > 0:
            src = np.concatenate([src, X[landmarks[0]]])
            dst = np.concatenate([dst, landmarks[1]])
            w = np.concatenate([w, np.full(landmarks[0].size, landmark_weight * ok.sum() / max(landmarks[0].size, 1))])
        new = fit_similarity(src, dst, w, scale=scale)
        change = float(np.abs(new(P0) - P).max())
        T = new
        if change < 1e-5:
            break
    return T, share, med


def affine_icp(
    X: NDArray[np.float64],
    F: NDArray[np.int64],
    query: SurfaceQuery,
    *,
    iterations: int = 20,
    sample: int = 2000,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Trimmed ICP with a global affine map ``x -> x @ A.T + b`` (after the similarity): absorbs anisotropic scale.

    Returns ``(A, b)``; the identity when too few correspondences are accepted.
    """
    rng = np.random.default_rng(1)
    idx = np.arange(X.shape[0]) if X.shape[0] <= sample else np.sort(rng.choice(X.shape[0], sample, replace=False))
    P0 = X[idx]
    N0 = vertex_normals(X, F)[idx]
    A, b = np.eye(3), np.zeros(3)
    H = np.c_[P0, np.ones(len(P0))]
    for _ in range(iterations):
        P = P0 @ A.T + b
        N = N0 @ np.linalg.inv(A)  # normals transform by the inverse transpose
        N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)
        C, ok, _, _ = _accept(query, P, N, floor=0.01, max_angle_cos=0.3)
        if ok.sum() < 0.5 * len(P0):
            break
        sol, *_ = np.linalg.lstsq(H[ok], C[ok], rcond=None)
        A_new, b_new = sol[:3].T, sol[3]
        sv = np.linalg.svd(A_new, compute_uv=False)
        if sv.min() <= 0.5 or sv.max() >= 2.0 or np.linalg.det(A_new) <= 0:
            break  # not a plausible head shape change
        change = float(np.abs((P0 @ A_new.T + b_new) - P).max())
        A, b = A_new, b_new
        if change < 1e-5:
            break
    return A, b


@dataclass
class NonRigidResult:
    """The template skin fitted onto the target.

    Attributes
    ----------
    positions : (n, 3) float
        Fitted template vertices (head units).
    accepted : (n,) bool
        Vertices with an accepted target correspondence in the last step.
    distance : (n,) float
        Distance of each fitted vertex to the target surface.
    iterations : int
        ICP steps.
    factorizations : int
        Sparse Cholesky factorisations (one per stiffness, more when many correspondences changed).
    """

    positions: NDArray[np.float64]
    accepted: NDArray[np.bool_]
    distance: NDArray[np.float64]
    iterations: int
    factorizations: int = 0


def nonrigid_icp(
    X0: NDArray[np.float64],
    F: NDArray[np.int64],
    query: SurfaceQuery,
    *,
    landmarks: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
    landmark_weight: float = 10.0,
    schedule: Sequence[tuple[float, int]] | None = None,
    progress: Callable[[float, str], None] | None = None,
    tol: float = 2e-4,
    refactor_share: float = 0.01,
) -> NonRigidResult:
    """Fit the template skin ``(X0, F)`` onto the target surface (see the module docstring).

    Parameters
    ----------
    X0 : (n, 3) float
        Template skin after the rigid alignment (head units).
    F : (m, 3) int
    query : SurfaceQuery
        The target surface.
    landmarks
        Template vertex ids and target positions, pulled with ``landmark_weight``
        (relative to a data weight of one vertex's area).
    schedule
        ``(alpha, iterations)`` steps.
    tol
        A stiffness step ends early when 99 % of the vertices moved less than this (head units).
    refactor_share
        Refactor within a stiffness when more than this share of the accepted
        correspondences changed (1 %: 17 factorisations for 27 steps on the sample;
        3 % saves a third of the time and costs 15 % in the worst shape's error).
    progress
        ``progress(fraction, message)``.
    """
    if schedule is None:
        schedule = DEFAULT_SCHEDULE
    n = X0.shape[0]
    L = cotangent_laplacian(X0, F)
    m = _vertex_masses(X0, F)
    K = sp.csr_matrix(L.T @ sp.diags(1.0 / m) @ L)
    KX0 = K @ X0
    eps = 1e-3
    lm_w, lm_rhs = _landmark_terms(landmarks, landmark_weight, m)
    X = X0.copy()
    total = sum(it for _, it in schedule)
    done = 0
    accepted = np.zeros(n, bool)
    dist = np.zeros(n)
    refactors = 0
    for alpha, iters in schedule:
        solver: SparseSPDSolver | None = None
        held = np.zeros(n, bool)  # the correspondences the current factor holds
        for _ in range(iters):
            C, accepted, dist, _ = _accept(query, X, vertex_normals(X, F), floor=0.005)
            # refactor at each stiffness and when the accepted set changed by more than 1 %; otherwise the
            # factor's correspondences stay (a dropped one holds its vertex where it is, a new one waits)
            if solver is None or int((accepted != held).sum()) > refactor_share * n:
                held = accepted
                diag = m * held + eps * m + lm_w
                solver = SparseSPDSolver((alpha * K + sp.diags(diag)).tocsc())
                refactors += 1
            target = np.where((held & accepted)[:, None], C, X)
            rhs = alpha * KX0 + (m * held)[:, None] * target + (eps * m)[:, None] * X + lm_rhs
            Xn = solver.solve(rhs)
            step = float(np.percentile(np.linalg.norm(Xn - X, axis=1), 99))
            X = Xn
            done += 1
            if progress is not None:
                progress(done / total, f"non-rigid fit: stiffness {alpha:.0e}, step {done}/{total}")
            if step < tol:
                break
    dist, *_ = query.closest(X)
    return NonRigidResult(X, accepted, dist, done, refactors)


def _local_similarities(X0: NDArray[np.float64], X: NDArray[np.float64], A: sp.csr_matrix) -> NDArray[np.float64]:
    """(n, 3, 3) per vertex ``s R``: the similarity taking ``X0``'s two-ring edges closest to ``X``'s."""
    n = X0.shape[0]
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    e0, e1 = X0[A.indices] - X0[rows], X[A.indices] - X[rows]
    C = np.zeros((n, 3, 3))
    np.add.at(C, rows, e1[:, :, None] * e0[:, None, :])
    l0 = np.bincount(rows, (e0 * e0).sum(1), minlength=n)
    P = (A + sp.identity(n)).tocsr()  # pooled over the neighbours: a two-ring
    C = np.asarray(P @ C.reshape(n, 9)).reshape(n, 3, 3)
    l0 = np.asarray(P @ l0)
    U, sig, Vt = np.linalg.svd(C)
    D = np.ones((n, 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    s = (sig * D).sum(1) / np.maximum(l0, 1e-300)
    return s[:, None, None] * ((U * D[:, None, :]) @ Vt)


def planar_refine(
    X: NDArray[np.float64],
    X0: NDArray[np.float64],
    F: NDArray[np.int64],
    query: SurfaceQuery,
    *,
    landmarks: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
    landmark_weight: float = 10.0,
    schedule: Sequence[tuple[float, int]] = FINE_SCHEDULE,
    eps: float = 1e-3,
) -> NonRigidResult:
    """A soft tail after :func:`nonrigid_icp`: point-to-plane data, similarity-invariant bending.

    Point-to-point ICP (``nonrigid_icp``) pins each vertex to its current closest point, so
    at a low stiffness the fit creeps along the surface by a small fraction per step and a
    grown jaw stays under-stretched. Here each step minimises

        alpha |L x - S(L x0)|^2_{M^-1}  +  sum_i m_i (n_i . (x_i - c_i))^2  +  eps |x - x_prev|_M^2

    with ``n_i`` the target normal at the closest point (free sliding along the surface) and
    ``S`` each vertex's local similarity (``s R``, from the current fit: a local scale or
    turn bends nothing). One coupled (3n, 3n) factorisation per step.

    Parameters
    ----------
    X : (n, 3) float
        The fit so far (``nonrigid_icp(...).positions``).
    X0 : (n, 3) float
        The template after the rigid/affine alignment (what the bending is measured from).
    """
    n = X0.shape[0]
    L = cotangent_laplacian(X0, F)
    m = _vertex_masses(X0, F)
    Lm = sp.csr_matrix(L.T @ sp.diags(1.0 / m))
    K3 = sp.kron(Lm @ L, sp.identity(3), format="csr")
    LX0 = np.asarray(L @ X0)
    A = sp.csr_matrix(sp.csr_matrix(L, copy=True) != 0, dtype=np.float64)
    A.setdiag(0.0)
    A.eliminate_zeros()
    lm_w, lm_rhs = _landmark_terms(landmarks, landmark_weight, m)
    idx = 3 * np.arange(n)[:, None, None] + np.arange(3)
    rows, cols = np.broadcast_to(idx.transpose(0, 2, 1), (n, 3, 3)), np.broadcast_to(idx, (n, 3, 3))
    X = X.copy()
    accepted = np.zeros(n, bool)
    done = 0
    for alpha, iters in schedule:
        for _ in range(iters):
            C, accepted, _, tn = _accept(query, X, vertex_normals(X, F), floor=0.005)
            w = m * accepted
            B = w[:, None, None] * tn[:, :, None] * tn[:, None, :] + ((eps * m + lm_w)[:, None, None] * np.eye(3))
            D = sp.csr_matrix((B.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * n, 3 * n))
            S = _local_similarities(X0, X, A)
            reg = Lm @ np.einsum("nij,nj->ni", S, LX0)
            rhs = alpha * reg + (w * (tn * C).sum(1))[:, None] * tn + (eps * m)[:, None] * X + lm_rhs
            X = SparseSPDSolver((alpha * K3 + D).tocsc()).solve(rhs.ravel()).reshape(n, 3)
            done += 1
    dist, *_ = query.closest(X)
    return NonRigidResult(X, accepted, dist, done, done)
