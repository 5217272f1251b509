"""Fitting markers frame by frame: blend regions plus an RBF residual (Joshi et al. 2003, §3).

Paper: "Learning Controls for Blend Shape Based Realistic Facial Animation"
(``shared/papers/siggraph2006-course-performance-driven-facial-animation.md``),
§3 "Animation with Motion Capture": per frame, project the marker positions
onto the blend-shape space by bounded least squares (Eq. 2), *per region*
("Instead of solving the above system for the entire model, we solve for each
region"), then translate the mesh by the radial-basis interpolation of the
residual at the markers (Eq. 3) so the markers are met.

Per frame ``t`` with marker vertices ``m`` and measured positions ``M_t``:

1. **Global fit** ``g_t = argmin |sum_k g_k Δ_k(m) - (M_t - neutral(m))|² + λ|g|²``
   within the slider ranges. The background of the regions uses ``g_t``.
2. **Region fit** — all regions that hold a marker, jointly (a marker in an
   overlap depends on both regions): ``w_r = g_t + δ_r`` with
   ``δ = argmin |sum_r W_r(m) sum_k δ_rk Δ_k(m) - (M_t - P_global(m))|² + λ|δ|²``,
   bounded so ``w_r`` stays in range. ``w_r = g_t`` is feasible, so the region fit
   never has a larger marker residual than the global one; regions without
   markers keep ``g_t``. The system matrix is the same for every frame.
3. **Residual** ``R_t = M_t - P_region(m)`` is interpolated by a radial basis
   function with centres at the *neutral* marker positions (the paper evaluates
   at the projected positions; fixed centres make the RBF system constant, one
   factorisation for all frames, and differ only to second order). Kernels:
   the paper's ``"exponential"`` ``exp(-r / s)`` (default; ``s`` = the median
   distance of a marker to its nearest neighbour — the paper's ``exp(-r)`` has no
   scale, which in decimetres would make the kernel almost constant), positive
   definite and decaying to 0 away from the markers; ``"linear"`` ``φ(r) = r`` with
   an affine term (the 3-D biharmonic spline); or ``"thin_plate"`` ``r² log r`` with
   an affine term. On the synthetic performance of the sample head (71 markers)
   the exponential kernel gave the lowest all-vertex error after the residual
   (global fit: 3.0e-3 dm vs 4.0e-3 linear, 4.8e-3 thin plate), see
   :func:`fidelity_table`. The residual moves the skin and the parts attached to
   it (lashes), not eyeballs, teeth or tongue.

Solvers: :func:`workbench.methods.regions.blend.bounded_lsq` (``scipy.optimize.nnls`` with
an upper-bound active set, BVLS fallback) for the bounded fits, block
Gauss–Seidel over regions for the joint region fit, a dense LU
(``scipy.linalg.lu_factor``) for the RBF system
(:mod:`~workbench.methods.regions.marker_fit.rbf`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from workbench.methods.regions.blend.evaluate import _mute, _vertex_ids
from workbench.methods.regions.blend.lsq import bounded_lsq
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.marker_fit.rbf import KERNELS, RBFResidual, _ro
from workbench.methods.regions.marker_fit.result import MarkerFit

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel


def _rbf_scale(centers: NDArray[np.float64]) -> float:
    if centers.shape[0] < 2:
        return 1.0
    d, _ = cKDTree(centers).query(centers, k=2)
    return float(max(np.median(d[:, 1]), 1e-12))


def fit_markers(
    model: FaceModel,
    regions: Regions,
    markers: ArrayLike,
    marker_positions: ArrayLike,
    level: int,
    *,
    regularization: float = 1e-2,
    rbf: str = "exponential",
    use_regions: bool = True,
    sweeps: int = 3,
    progress: Callable[[float, str], None] | None = None,
) -> MarkerFit:
    """Fit region weights to marker positions frame by frame, plus the RBF residual.

    Parameters
    ----------
    model : FaceModel
        Its current slider values are not used; muted shapes are left out.
    regions : Regions
    markers : (M,) int
        Marker vertex ids.
    marker_positions : (T, M, 3) float
        Measured positions in model coordinates (rigid head motion removed).
    level : int
        Region level to fit on.
    regularization : float
        >= 0; relative ridge weight (toward 0 for the global fit, toward the
        global weights for the region fit). Few markers per region make the
        region fit underdetermined; 1e-2 gave the lowest all-vertex error on the
        synthetic performance (1e-3 overfits the noise, 1e-1 under-fits).
    rbf : {"exponential", "linear", "thin_plate"}
        Residual kernel (see the module docstring).
    use_regions : bool
        False: every region gets the global fit (the "global" baseline).
    sweeps : int
        >= 1; block Gauss–Seidel sweeps over the regions for the joint region fit
        (each block is one region's weights, solved exactly; the joint objective
        decreases monotonically; 3 sweeps came within ~1 % of the joint optimum's
        marker error on the sample, at about the speed of OSQP on the joint
        problem with ≈ 500 unknowns — see ``benchmarks/bench_regions.py``).
    progress : callable, optional
        ``progress(fraction, message)`` every 10 frames.

    Returns
    -------
    MarkerFit
    """
    lv = regions.check_level(level)
    ids = _vertex_ids(model, markers, "markers")
    if ids.size == 0:
        raise RegionError("markers: need at least one marker vertex")
    if len(np.unique(ids)) != ids.size:
        raise RegionError("markers: vertex ids must be unique")
    P = np.asarray(marker_positions, dtype=np.float64)
    if P.ndim != 3 or P.shape[1:] != (ids.size, 3):
        raise RegionError(f"marker_positions: expected (T, {ids.size}, 3), got {P.shape}")
    if not np.isfinite(P).all():
        raise RegionError("marker_positions: NaN/inf (fill gaps before fitting)")
    if regions.n_vertices != model.n_vertices:
        raise RegionError(f"regions: made for {regions.n_vertices} vertices, the model has {model.n_vertices}")
    reg = float(regularization)
    if not (np.isfinite(reg) and reg >= 0):
        raise RegionError(f"regularization must be a finite number >= 0, got {regularization!r}")
    if rbf not in KERNELS:
        raise RegionError(f"rbf must be one of {KERNELS}, got {rbf!r}")
    if not isinstance(sweeps, int | np.integer) or isinstance(sweeps, bool) or sweeps < 1:
        raise RegionError(f"sweeps must be an int >= 1, got {sweeps!r}")
    if not model.shapes:
        raise RegionError("model has no blendshapes to fit")

    T, M = P.shape[0], ids.size
    k = len(model.shapes)
    mute = _mute(model).astype(np.float64)
    D = model.effective_deltas[:, ids].astype(np.float64) * mute[:, None, None]  # (k, M, 3)
    lo = np.array([s.slider_min for s in model.shapes])
    hi = np.array([s.slider_max for s in model.shapes])
    neutral = model.vertices[ids]
    # global system: (3M, k); shapes that move no marker stay at 0 (clipped into range)
    Jg = D.transpose(1, 2, 0).reshape(3 * M, k)
    kg = np.flatnonzero(np.abs(Jg).max(axis=0) > 0)
    g0 = np.clip(0.0, lo, hi)
    # region system: unknowns (r, s) for regions holding a marker
    Wm = regions.weight_matrix(lv)[ids].toarray().astype(np.float64)  # (M, R)
    R = Wm.shape[1]
    touched = np.flatnonzero(Wm.max(axis=0) > 0) if use_regions else np.zeros(0, np.intp)
    Jr = (Wm[:, touched][:, :, None, None] * D.transpose(1, 0, 2)[:, None, :, :])  # (M, Rt, k, 3)
    Jr = Jr.transpose(0, 3, 1, 2).reshape(3 * M, touched.size * k)
    ri = np.repeat(touched, k)
    ki = np.tile(np.arange(k), touched.size)
    keep = np.abs(Jr).max(axis=0) > 0
    Jr, ri, ki = Jr[:, keep], ri[keep], ki[keep]

    # one block per region: its unknowns, the marker rows they touch, and the
    # ridge weight of the *joint* problem (the same λ for every block)
    lam_joint = reg * float(np.mean(np.einsum("ij,ij->j", Jr, Jr))) if Jr.shape[1] else 0.0
    blocks = []
    for r in np.unique(ri):
        cols = np.flatnonzero(ri == r)
        rows = np.flatnonzero(np.abs(Jr[:, cols]).max(axis=1) > 0)
        blocks.append((cols, rows, lam_joint))

    G = np.empty((T, k), np.float32)
    RW = np.empty((T, R, k), np.float32)
    resid = np.empty((T, M, 3))
    err_g = np.empty(T)
    err_r = np.empty(T)
    for t in range(T):
        b = (P[t] - neutral).reshape(-1)
        g = g0.copy()
        if kg.size:
            x0 = g0[kg]
            g[kg] = x0 + bounded_lsq(Jg[:, kg], b - Jg[:, kg] @ x0, lo[kg] - x0, hi[kg] - x0, reg)
        fit_g = Jg @ g  # displacement at markers with every region at g (partition of unity)
        err_g[t] = np.sqrt(np.mean(np.sum((b - fit_g).reshape(M, 3) ** 2, axis=1)))
        w = np.tile(g, (R, 1))
        fit_r = fit_g
        if Jr.shape[1]:
            gk = g[ki]
            lo_d, hi_d = np.minimum(lo[ki] - gk, 0.0), np.maximum(hi[ki] - gk, 0.0)
            delta = np.zeros(Jr.shape[1])
            res = b - fit_g
            # block Gauss-Seidel over the regions: each step minimises the joint
            # objective over one region's weights exactly, so it only decreases
            for _ in range(sweeps):
                for cols, rows, lam in blocks:
                    Jb = Jr[np.ix_(rows, cols)]
                    rb = res[rows] + Jb @ delta[cols]
                    new = bounded_lsq(Jb, rb, lo_d[cols], hi_d[cols], 0.0, lam=lam)
                    res[rows] -= Jb @ (new - delta[cols])
                    delta[cols] = new
            w[ri, ki] = gk + delta
            fit_r = fit_g + Jr @ delta
        err_r[t] = np.sqrt(np.mean(np.sum((b - fit_r).reshape(M, 3) ** 2, axis=1)))
        resid[t] = (b - fit_r).reshape(M, 3)
        G[t] = g
        RW[t] = w
        if progress is not None and (t % 10 == 0 or t == T - 1):
            progress((t + 1) / T, f"frame {t + 1}/{T}")
    centers = model.vertices[ids]
    rbf_obj = RBFResidual(centers, rbf, _rbf_scale(centers))
    coef = rbf_obj.coefficients(resid)
    return MarkerFit(
        level=lv,
        shape_names=tuple(model.shape_names),
        region_names=regions.names[lv],
        markers=_ro(ids),
        global_weights=_ro(G),
        region_weights=_ro(RW),
        rbf=rbf_obj,
        rbf_coefficients=_ro(coef),
        marker_error_global=_ro(err_g),
        marker_error_region=_ro(err_r),
    )
