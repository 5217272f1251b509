"""How a motion vector on the source is carried onto the target (expression cloning, steps 2-3).

Three motion models, each one (3, 3) matrix ``T`` per source skin vertex
(``m' = T m`` in the working frame), measured between the source neutral ``X0``
and the *deformed source* ``X1`` (the source fitted onto the target):

* ``"frames"`` — Noh & Neumann 2001 as printed (§2.2.1-§2.2.2): a local frame
  on each model (X the vertex normal averaged over its neighbours, Y the
  projection of one fixed edge onto the tangent plane, Z = X × Y) turns the
  vector, ``R = F1 F0ᵀ``; the ratio of the deformed to the rotated source
  one-ring's bounding box along the deformed frame's tangent axes scales it
  (the normal axis takes their geometric mean), outliers (beyond two standard
  deviations in log) replaced by their neighbours' average, then smoothed
  once: ``T = S R``.
* ``"affine"`` — the local deformation of the fit itself: per vertex, the
  least-squares linear map of its one-ring edge vectors, with the smoothed
  normal mapped to the deformed one scaled by the ring's length ratio (a
  deformation gradient at the vertex, as Sumner & Popović define it per
  triangle), then smoothed by implicit diffusion ``(M + t L)⁻¹ M`` (cotangent
  Laplacian and Voronoi mass, libigl; ``t = (smoothing · diagonal)²``), which
  keeps a constant field, so the identity fit still gives ``T = I``. The box
  ratios measure a stretch only along the frame's axes — one arbitrary edge
  direction — and miss shear; the affine map measures both, and the
  smoothing stands in for the outlier filter.
* ``"field"`` (the default) — the Jacobian of one smooth 3-D map fitted to the
  whole correspondence: a thin-plate spline with an affine part (scipy's
  ``RBFInterpolator``) through ``X1 − X0`` at up to :data:`FIELD_CENTRES`
  source vertices whose correspondence the fit accepted (over the target's
  holes the fitted template is pulled to the border, which is no smooth map),
  differentiated by central differences (:func:`field_deformation`). A
  one-ring sees only how the surface stretches in its tangent plane; how the
  face stretches along its normal is not in the surface at all, and the
  one-ring model's guess (the normal scaled by the ring's length ratio) is
  where most of its error was: with the exact correspondence on the sample
  head under the 1.25× jaw warp, the one-ring map leaves 7.3 % of the motion,
  its tangential columns with the true normal column 2.4 %, the field
  2.4–3.4 % (3,000–800 centres; the true Jacobian 1.1 %); under a random warp
  the one-ring map 2.7 %, the field 0.16 % (= the true Jacobian). The spline's smoothness across the
  curved face supplies the normal column. :data:`FIELD_SMOOTHING` was chosen
  on five held-out faces (other warps, proportions, busts and foreign faces),
  where the field beat the one-ring map on each.

Measured on the generated faces of ``benchmarks/bench_expression_cloning.py``
(error over the mean motion; field / affine / frames, the skin's motion model
alone, parts as in a rig transfer): warp + renumber 2.4 / 3.5 / 5.0 %; 27k
remesh + bust 4.6 / 5.7 / 8.0 %; foreign 7.3 / 7.3 / 7.8 %; 1.25× jaw 10.4 /
13.8 / 13.3 %. The cloner also moves matched parts by the field
(:mod:`~workbench.rigging.clone`): 2.1, 4.4, 6.3 and 9.8 %; with the registration's
softer tail (:data:`~workbench.rigging.registration.FINE_SCHEDULE`) 1.4, 4.3, 5.2 and 8.7 %.
The field's centres and smoothing, swept again on that correspondence over five held-out
faces (2,000 / 4,000 centres, smoothing 3e-4 to 1e-2), move the mean error only between
4.1 and 4.6 %.

Hand-written because no kept library implements these motion models; the
spline is scipy's, the normals, Laplacian and mass matrix libigl's, the
factorization :class:`~workbench.geometry.sparse_cholesky.SparseSPDSolver`.
"""

from __future__ import annotations

from typing import Any, Literal

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from workbench.geometry.normals import vertex_normals
from workbench.geometry.sparse_cholesky import SparseSPDSolver

MotionModel = Literal["field", "affine", "frames"]
MOTION_MODELS: tuple[MotionModel, ...] = ("field", "affine", "frames")

#: scale ratios beyond this many standard deviations (log) from the mean are outliers (§2.2.2)
_SCALE_SIGMAS = 2.0
#: the affine model's smoothing length, as a fraction of the source skin's bounding diagonal
#: (chosen on the generated faces: 2 % keeps the fit's noise, 10 % blurs a grown jaw)
AFFINE_SMOOTHING = 0.05
#: the field model's thin-plate spline: at most this many source vertices as centres
FIELD_CENTRES = 2000
#: its smoothing (scipy's ``RBFInterpolator(smoothing=)``, in the working frame: head size 1)
FIELD_SMOOTHING = 3e-3


def _adjacency(F: NDArray[np.int64], n: int) -> sp.csr_matrix:
    A = igl.adjacency_matrix(F).tocsr().astype(np.float64)
    A.resize((n, n))
    return A


def _row_mean(A: sp.csr_matrix, x: NDArray[np.float64]) -> NDArray[np.float64]:
    deg = np.maximum(np.asarray(A.sum(1)).ravel(), 1.0)
    return np.asarray(A @ x) / (deg[:, None] if x.ndim == 2 else deg)


def _frames(V: NDArray[np.float64], F: NDArray[np.int64], A: sp.csr_matrix, partner: NDArray[np.int64]
            ) -> NDArray[np.float64]:
    """(n, 3, 3) local frames, columns X (smoothed normal), Y (edge to ``partner`` in the tangent plane), Z."""
    N = vertex_normals(V, F)
    N = _row_mean(A, N) + N  # the noise filter: the vertex's and its neighbours' normals
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)
    e = V[partner] - V
    Y = e - (e * N).sum(1, keepdims=True) * N
    Y /= np.maximum(np.linalg.norm(Y, axis=1, keepdims=True), 1e-300)
    Z = np.cross(N, Y)
    return np.stack([N, Y, Z], axis=2)


def _ring_extent(P: NDArray[np.float64], A: sp.csr_matrix) -> NDArray[np.float64]:
    """(n,): extent (max - min) over each vertex's one-ring and the vertex itself (at 0).

    ``P`` (nnz,) holds each ring member's coordinate relative to its vertex, in the CSR order of ``A``.
    """
    n = A.shape[0]
    starts = A.indptr[:-1]
    has = np.diff(A.indptr) > 0
    hi = np.zeros(n)
    lo = np.zeros(n)
    hi[has] = np.maximum.reduceat(P, starts[has])
    lo[has] = np.minimum.reduceat(P, starts[has])
    return np.maximum(hi, 0.0) - np.minimum(lo, 0.0)  # the vertex itself sits at 0


def local_scales(X0: NDArray[np.float64], X1: NDArray[np.float64], A: sp.csr_matrix, R: NDArray[np.float64],
                 F1: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 3) scale of the deformed one-ring over the rotated source one-ring along ``F1``'s axes (§2.2.2).

    Parameters
    ----------
    X0, X1 : (n, 3) float
        Source and deformed source vertices.
    A : (n, n) sparse
        Vertex adjacency.
    R : (n, 3, 3) float
        Per-vertex rotation source -> deformed.
    F1 : (n, 3, 3) float
        Deformed frames (columns: normal, tangent, tangent).
    """
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    cols = A.indices
    d0 = np.einsum("kij,kj->ki", R[rows], X0[cols] - X0[rows])  # rotated source ring offsets
    d1 = X1[cols] - X1[rows]
    S = np.ones((A.shape[0], 3))
    for a in (1, 2):  # the tangent axes
        ax = F1[rows, :, a]
        s0 = _ring_extent((d0 * ax).sum(1), A)
        s1 = _ring_extent((d1 * ax).sum(1), A)
        ok = s0 > 1e-12
        S[ok, a] = s1[ok] / s0[ok]
    S[:, 0] = np.sqrt(S[:, 1] * S[:, 2])
    # outliers (a bump in either model) -> their neighbours' average; then one pass of smoothing
    L = np.log(np.maximum(S, 1e-6))
    mu, sd = L.mean(0), L.std(0)
    bad = np.abs(L - mu) > _SCALE_SIGMAS * np.maximum(sd, 1e-12)
    if bad.any():
        keep = (~bad).astype(np.float64)
        num = np.asarray(A @ (L * keep))
        den = np.asarray(A @ keep)
        L = np.where(bad, np.where(den > 0, num / np.maximum(den, 1e-300), mu), L)
    L = 0.5 * (L + _row_mean(A, L))
    return np.exp(L)


def local_deformation(X0: NDArray[np.float64], X1: NDArray[np.float64], F: NDArray[np.int64], A: sp.csr_matrix,
                      N0: NDArray[np.float64], N1: NDArray[np.float64], smoothing: float = AFFINE_SMOOTHING
                      ) -> NDArray[np.float64]:
    """(n, 3, 3) per-vertex linear map of the source one-ring onto the deformed one, smoothed.

    Parameters
    ----------
    X0, X1 : (n, 3) float
        Source and deformed source vertices.
    F : (f, 3) int
        Triangles (for the Laplacian and mass matrix).
    A : (n, n) sparse
        Vertex adjacency.
    N0, N1 : (n, 3) float
        Unit (smoothed) normals of the two.
    smoothing : float
        Diffusion length over the source's bounding diagonal (0: none).
    """
    n = A.shape[0]
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    cols = A.indices
    e0, e1 = X0[cols] - X0[rows], X1[cols] - X1[rows]
    M0 = np.zeros((n, 3, 3))
    M1 = np.zeros((n, 3, 3))
    np.add.at(M0, rows, e0[:, :, None] * e0[:, None, :])
    np.add.at(M1, rows, e1[:, :, None] * e0[:, None, :])
    l0 = np.bincount(rows, (e0 * e0).sum(1), minlength=n)
    l1 = np.bincount(rows, (e1 * e1).sum(1), minlength=n)
    w = l0 / np.maximum(np.diff(A.indptr), 1)  # the normal weighs like one mean edge
    w = np.where(w > 0, w, 1.0)
    sn = np.sqrt(np.where(l0 > 0, l1 / np.maximum(l0, 1e-300), 1.0))
    M0 += w[:, None, None] * N0[:, :, None] * N0[:, None, :]
    M1 += (w * sn)[:, None, None] * N1[:, :, None] * N0[:, None, :]
    J = M1 @ np.linalg.inv(M0)
    if smoothing > 0:
        diag = float(np.linalg.norm(X0.max(0) - X0.min(0)))
        L = -igl.cotmatrix(X0, F)
        M = igl.massmatrix(X0, F, igl.MASSMATRIX_TYPE_VORONOI)
        solver = SparseSPDSolver((M + (smoothing * diag) ** 2 * L).tocsc())
        J = solver.solve(np.asarray(M @ J.reshape(n, 9))).reshape(n, 3, 3)
    return J


def fit_field(X0: NDArray[np.float64], X1: NDArray[np.float64], *, trusted: NDArray[np.bool_] | None = None,
              centres: int = FIELD_CENTRES, smoothing: float = FIELD_SMOOTHING, seed: int = 0) -> Any:
    """A smooth map of space fitted to ``X0 → X1``: the displacement as a thin-plate spline.

    scipy's ``RBFInterpolator`` (thin-plate kernel, affine part) through ``X1 − X0`` at up to
    ``centres`` of the ``trusted`` source vertices (default all; drawn with ``seed``);
    :func:`field_jacobian` differentiates it anywhere in space.

    Parameters
    ----------
    X0, X1 : (n, 3) float
        Source and deformed source vertices.
    trusted : (n,) bool, optional
        Vertices whose ``X1`` may be fitted (the fit's accepted correspondences).
    centres : int
    smoothing : float
        ``RBFInterpolator``'s smoothing (0 interpolates the centres exactly).
    seed : int
    """
    from scipy.interpolate import RBFInterpolator

    pool = np.arange(X0.shape[0]) if trusted is None else np.flatnonzero(trusted)
    if pool.size < 10:
        pool = np.arange(X0.shape[0])
    idx = pool if pool.size <= centres else np.sort(np.random.default_rng(seed).choice(pool, centres, replace=False))
    return RBFInterpolator(X0[idx], (X1 - X0)[idx], kernel="thin_plate_spline", degree=1, smoothing=smoothing)


def field_step(X0: NDArray[np.float64]) -> float:
    """The central-difference step of :func:`field_jacobian` for a field fitted on ``X0``: 1e-4 of its diagonal."""
    return 1e-4 * float(np.linalg.norm(X0.max(0) - X0.min(0)))


def field_jacobian(field: Any, P: NDArray[np.float64], h: float) -> NDArray[np.float64]:
    """(p, 3, 3) Jacobian of the map ``x ↦ x + field(x)`` at the points ``P`` (central differences of step ``h``)."""
    cols = [(field(P + h * e) - field(P - h * e)) / (2.0 * h) for e in np.eye(3)]
    return np.stack(cols, axis=2) + np.eye(3)[None]


def field_deformation(X0: NDArray[np.float64], X1: NDArray[np.float64], *, trusted: NDArray[np.bool_] | None = None,
                      centres: int = FIELD_CENTRES, smoothing: float = FIELD_SMOOTHING, seed: int = 0
                      ) -> NDArray[np.float64]:
    """(n, 3, 3) Jacobian at each source vertex of a smooth spatial map fitted to ``X0 → X1`` (:func:`fit_field`).

    The surface alone fixes only the tangential columns of a vertex's map; the spline's
    3-D smoothness gives the normal one too.
    """
    field = fit_field(X0, X1, trusted=trusted, centres=centres, smoothing=smoothing, seed=seed)
    return field_jacobian(field, X0, field_step(X0))


def motion_transforms(X0: NDArray[np.float64], X1: NDArray[np.float64], F: NDArray[np.int64],
                      model: MotionModel = "field", smoothing: float = AFFINE_SMOOTHING, field: Any = None
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(T (n, 3, 3), S (n, 3))``: the motion transform of each source vertex and its scales.

    ``S`` is (normal, tangent, tangent): for ``"frames"`` the §2.2.2 box ratios, for
    ``"field"`` and ``"affine"`` the map's stretch of the source normal and its two
    singular values in the tangent plane. ``smoothing`` is the affine model's;
    ``field`` the field model's :func:`fit_field` (default: fitted to every vertex).
    """
    if model not in MOTION_MODELS:
        raise ValueError(f"motion must be one of {list(MOTION_MODELS)}, got {model!r}")
    n = X0.shape[0]
    A = _adjacency(F, n)
    # one fixed edge per vertex (its first neighbour) gives Y on both models
    partner = np.where(np.diff(A.indptr) > 0, A.indices[np.minimum(A.indptr[:-1], A.indices.size - 1)],
                       np.arange(n))
    F0, F1 = _frames(X0, F, A, partner), _frames(X1, F, A, partner)
    if model == "frames":
        R = F1 @ F0.transpose(0, 2, 1)
        S = local_scales(X0, X1, A, R, F1)
        return (F1 * S[:, None, :]) @ F1.transpose(0, 2, 1) @ R, S
    if model == "field":
        J = field_jacobian(fit_field(X0, X1) if field is None else field, X0, field_step(X0))
    else:
        J = local_deformation(X0, X1, F, A, F0[:, :, 0], F1[:, :, 0], smoothing)
    tangent = np.linalg.svd(J @ F0[:, :, 1:], compute_uv=False)  # (n, 2)
    normal = np.linalg.norm(np.einsum("nij,nj->ni", J, F0[:, :, 0]), axis=1)
    return J, np.column_stack([normal, tangent])
