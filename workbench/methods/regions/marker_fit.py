"""Marker fitting with blend regions plus an RBF residual (Joshi et al. 2003, §3).

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
(``scipy.linalg.lu_factor``) for the RBF system. The RBF is hand-written
rather than ``scipy.interpolate.RBFInterpolator`` because we need the (n, M)
kernel matrix once for every frame; ``tests/test_marker_fit.py`` checks it
against ``RBFInterpolator``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from workbench.methods.regions.blend import (
    RegionWeights,
    _mute,
    _vertex_ids,
    bounded_lsq,
)
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.segmentation import component_roles

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = [
    "MarkerFit",
    "RBFResidual",
    "SyntheticPerformance",
    "fidelity_table",
    "fit_markers",
    "format_fidelity_table",
    "generate_synthetic_marker_performance",
]

KERNELS = ("linear", "thin_plate", "exponential")


def _ro(a: NDArray[Any]) -> NDArray[Any]:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


# ------------------------------------------------------------------------ RBF
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


# -------------------------------------------------------------- performance
@dataclass(frozen=True, eq=False)
class SyntheticPerformance:
    """A marker performance generated from known weight curves.

    The truth has different weights in four smooth quadrants of the face
    (subject's left/right × upper/lower), so it is *more expressive than one
    global weight set*, as the paper's captured motion is.

    Attributes
    ----------
    markers : (M,) int
    marker_positions : (T, M, 3) float32
        Measured positions (truth + Gaussian noise).
    quadrant_weights : (T, Q, k) float32
        True weights of each quadrant per frame (Q = 4).
    masks : (n, Q) float32
        Smooth quadrant masks, summing to 1 at every vertex.
    noise : float
        Standard deviation of the noise per coordinate (model units).
    """

    markers: NDArray[np.intp]
    marker_positions: NDArray[np.float32]
    quadrant_weights: NDArray[np.float32]
    masks: NDArray[np.float32]
    noise: float

    @property
    def n_frames(self) -> int:
        return int(self.marker_positions.shape[0])

    def vertex_weights(self, frame: int) -> NDArray[np.float64]:
        """(n, k) true per-vertex weights of one frame."""
        return self.masks.astype(np.float64) @ self.quadrant_weights[frame].astype(np.float64)

    def positions(self, model: FaceModel, frame: int) -> NDArray[np.float64]:
        """(n, 3) true (noise-free) vertex positions of one frame."""
        W = self.vertex_weights(frame) * _mute(model)[None, :]
        D = model.effective_deltas.astype(np.float64)
        return model.vertices + np.einsum("nk,knc->nc", W, D)


def _smooth_curves(rng: np.random.Generator, T: int, k: int, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T, k) sums of Gaussian bumps (each shape ~0.8 bumps), clipped to [lo, hi]."""
    t = np.arange(T, dtype=np.float64)
    out = np.zeros((T, k))
    for j in range(k):
        for _ in range(rng.poisson(0.8)):
            c = rng.uniform(0, T)
            w = rng.uniform(0.04, 0.15) * T
            out[:, j] += rng.uniform(0.2, 0.9) * np.exp(-0.5 * ((t - c) / w) ** 2)
    return np.clip(out, lo, hi)


def generate_synthetic_marker_performance(
    model: FaceModel,
    markers: ArrayLike,
    n_frames: int = 120,
    seed: int = 0,
    noise: float = 0.0,
    *,
    asymmetry: float = 0.5,
) -> SyntheticPerformance:
    """Marker tracks from known smooth weight curves plus noise.

    Parameters
    ----------
    model : FaceModel
    markers : (M,) int
        Marker vertex ids (e.g. ``default_face_handles(model).vertices``).
    n_frames : int
        >= 1.
    seed : int
        Random seed (the result is a pure function of the arguments).
    noise : float
        >= 0, Gaussian noise per coordinate in model units.
    asymmetry : float
        In [0, 1]: 0 = one weight set for the whole face (a global blend can
        explain it), 1 = independent curves per quadrant.

    Returns
    -------
    SyntheticPerformance
    """
    ids = _vertex_ids(model, markers, "markers")
    if ids.size == 0:
        raise RegionError("markers: need at least one marker vertex")
    if not isinstance(n_frames, int | np.integer) or isinstance(n_frames, bool) or n_frames < 1:
        raise RegionError(f"n_frames must be an int >= 1, got {n_frames!r}")
    nz = float(noise)
    if not (np.isfinite(nz) and nz >= 0):
        raise RegionError(f"noise must be a finite number >= 0, got {noise!r}")
    a = float(asymmetry)
    if not (np.isfinite(a) and 0 <= a <= 1):
        raise RegionError(f"asymmetry must be in [0, 1], got {asymmetry!r}")
    if not model.shapes:
        raise RegionError("model has no blendshapes to animate")
    rng = np.random.default_rng(seed)
    k = len(model.shapes)
    lo = np.array([s.slider_min for s in model.shapes])
    hi = np.array([s.slider_max for s in model.shapes])
    T = int(n_frames)
    base = _smooth_curves(rng, T, k, lo, hi)
    Q = 4
    qw = np.stack([np.clip((1 - a) * base + a * _smooth_curves(rng, T, k, lo, hi), lo, hi) for _ in range(Q)], axis=1)
    # smooth quadrant masks around the centre of the face's motion
    V = model.vertices
    D = model.effective_deltas
    mag = np.sqrt(np.einsum("knc,knc->n", D, D, dtype=np.float64))
    w = mag / max(float(mag.sum()), 1e-30)
    cx, cy = float(w @ V[:, 0]), float(w @ V[:, 1])
    size = float(np.sqrt(w @ ((V[:, 0] - cx) ** 2 + (V[:, 1] - cy) ** 2)))
    s = 0.25 * max(size, 1e-12)
    sx = 1.0 / (1.0 + np.exp(-(V[:, 0] - cx) / s))
    sy = 1.0 / (1.0 + np.exp(-(V[:, 1] - cy) / s))
    masks = np.stack([sx * sy, (1 - sx) * sy, sx * (1 - sy), (1 - sx) * (1 - sy)], axis=1)
    perf0 = SyntheticPerformance(ids, np.zeros((T, ids.size, 3), np.float32), qw.astype(np.float32), masks.astype(np.float32), nz)
    mute = _mute(model)
    Dm = D[:, ids].astype(np.float64)
    pos = np.empty((T, ids.size, 3))
    Mm = masks[ids]
    for t in range(T):
        Wt = (Mm @ qw[t]) * mute[None, :]
        pos[t] = V[ids] + np.einsum("mk,kmc->mc", Wt, Dm)
    pos += rng.normal(0.0, nz, pos.shape) if nz > 0 else 0.0
    return SyntheticPerformance(
        _ro(ids), _ro(pos.astype(np.float32)), _ro(perf0.quadrant_weights), _ro(perf0.masks), nz
    )


# ---------------------------------------------------------------------- fitting
@dataclass(frozen=True, eq=False)
class MarkerFit:
    """Result of :func:`fit_markers`: per-frame weights and the residual RBF.

    Attributes
    ----------
    level : int
    shape_names, region_names : tuple of str
    markers : (M,) int
    global_weights : (T, k) float32
        The global fit; the regions' background uses it.
    region_weights : (T, R, k) float32
        Per region and frame (``g_t`` for regions without markers).
    rbf : RBFResidual
    rbf_coefficients : (T, M + p, 3) float64
    marker_error_global, marker_error_region : (T,) float64
        RMS marker distance of the global and of the region fit (before the RBF).
    """

    level: int
    shape_names: tuple[str, ...]
    region_names: tuple[str, ...]
    markers: NDArray[np.intp]
    global_weights: NDArray[np.float32]
    region_weights: NDArray[np.float32]
    rbf: RBFResidual
    rbf_coefficients: NDArray[np.float64]
    marker_error_global: NDArray[np.float64]
    marker_error_region: NDArray[np.float64]

    @property
    def n_frames(self) -> int:
        return int(self.global_weights.shape[0])

    def weights_at(self, frame: int) -> RegionWeights:
        """The region weights of one frame as a :class:`RegionWeights`."""
        return RegionWeights(self.level, self.shape_names, self.region_names, self.region_weights[frame])

    def tracks(self) -> dict[str, NDArray[np.float32]]:
        """Per-frame weight curves: ``{region name: (T, k)}`` plus ``"background"`` (global).

        Plain arrays; :meth:`FaceModel.key_marker_fit` puts them on the model's
        timeline (weight keys for the global weights, ``"regions/<level>/<region>"``
        keys for the regions), where playback, the file and the exports use them.
        The RBF residual is not keyable (see there).
        """
        out = {nm: self.region_weights[:, r] for r, nm in enumerate(self.region_names)}
        out["background"] = self.global_weights
        return out

    def residual_displacement(self, model: FaceModel, frame: int) -> NDArray[np.float32]:
        """(n, 3) float32: the RBF residual of one frame on the skin (0 on rigid parts)."""
        out = np.zeros((model.n_vertices, 3), np.float32)
        idx = np.flatnonzero(component_roles(model) != 1)
        B = _basis_cache(model, self.rbf, idx)
        out[idx] = (B @ self.rbf_coefficients[frame]).astype(np.float32)
        return out

    def positions(self, model: FaceModel, regions: Regions, frame: int, *, residual: bool = True) -> NDArray[np.float32]:
        """(n, 3) fitted vertex positions of one frame (region blend + RBF residual)."""
        X = _blend_with_global(model, regions, self.weights_at(frame), self.global_weights[frame])
        if residual:
            X = X + self.residual_displacement(model, frame)
        return X.astype(np.float32)


_BASIS: dict[tuple[int, int, int], NDArray[np.float64]] = {}


def _basis_cache(model: FaceModel, rbf: RBFResidual, idx: NDArray[np.intp]) -> NDArray[np.float64]:
    key = (id(model), id(rbf), idx.size)
    B = _BASIS.get(key)
    if B is None:
        if len(_BASIS) > 4:
            _BASIS.clear()
        B = rbf.basis(model.vertices[idx])
        _BASIS[key] = B
    return B


def _blend_with_global(
    model: FaceModel, regions: Regions, rw: RegionWeights, g: ArrayLike, vertices: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Region blend positions with the background at ``g`` instead of the model's sliders."""
    lv = rw.level
    idx = np.arange(model.n_vertices) if vertices is None else np.asarray(vertices, np.intp)
    mute = _mute(model).astype(np.float64)
    coef = np.asarray(regions.weight_matrix(lv)[idx] @ (rw.values.astype(np.float64) * mute[None, :]))
    coef += regions.background[lv][idx, None].astype(np.float64) * (np.asarray(g, np.float64) * mute)[None, :]
    D = model.effective_deltas[:, idx].astype(np.float64)
    return model.vertices[idx] + np.einsum("mk,kmc->mc", coef, D)


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


# --------------------------------------------------------------------- fidelity
def fidelity_table(
    model: FaceModel,
    regions: Regions,
    performance: SyntheticPerformance,
    *,
    levels: list[int] | None = None,
    regularization: float = 1e-2,
    rbf: str = "exponential",
) -> list[dict[str, Any]]:
    """Region-wise vs global fitting error and weight recovery on a synthetic performance.

    Errors are RMS over frames, area-weighted over the moving skin (vertices some
    shape moves), in model units; weight error is the RMS difference of the
    *per-vertex effective weights* (``sum_r W_r(v) w_r + W_bg(v) g``) from the
    truth's, over the same vertices and all shapes.

    Parameters
    ----------
    model : FaceModel
    regions : Regions
    performance : SyntheticPerformance
    levels : list of int, optional
        Region levels to compare (default all).
    regularization : float
    rbf : str

    Returns
    -------
    list of dict
        One row per method (``"global"``, ``"regions L<l>"``) with keys
        ``method, level, n_regions, marker_rms, marker_rms_rbf, vertex_rms,
        vertex_rms_rbf, weight_rms``.
    """
    lvls = list(range(regions.n_levels)) if levels is None else [regions.check_level(x) for x in levels]
    from workbench.geometry.operators import mass_matrix

    roles = component_roles(model)
    D = model.effective_deltas
    maxd = np.sqrt(np.einsum("knc,knc->kn", D, D, dtype=np.float64)).max(axis=0) if len(D) else np.zeros(model.n_vertices)
    eval_v = np.flatnonzero((roles == 0) & (maxd > 1e-3 * maxd.max(initial=0.0)))
    area = np.asarray(mass_matrix(model.vertices, model.faces).diagonal())[eval_v]
    area = area / area.sum()
    T = performance.n_frames
    truth_pos = [performance.positions(model, t)[eval_v] for t in range(T)]
    truth_w = [performance.vertex_weights(t)[eval_v] for t in range(T)]
    rows: list[dict[str, Any]] = []
    runs: list[tuple[str, int, bool]] = [("global", lvls[0], False)] + [(f"regions L{lv}", lv, True) for lv in lvls]
    for name, lv, use in runs:
        fit = fit_markers(
            model, regions, performance.markers, performance.marker_positions, lv,
            regularization=regularization, rbf=rbf, use_regions=use,
        )
        Wv = regions.weight_matrix(lv)[eval_v]
        bgv = regions.background[lv][eval_v].astype(np.float64)
        ev, evr, ew, emr = 0.0, 0.0, 0.0, 0.0
        for t in range(T):
            X = _blend_with_global(model, regions, fit.weights_at(t), fit.global_weights[t], eval_v)
            Xr = X + fit.residual_displacement(model, t)[eval_v]
            ev += float(area @ np.sum((X - truth_pos[t]) ** 2, axis=1))
            evr += float(area @ np.sum((Xr - truth_pos[t]) ** 2, axis=1))
            weff = np.asarray(Wv @ fit.region_weights[t].astype(np.float64)) + bgv[:, None] * fit.global_weights[t][None, :]
            ew += float(area @ np.mean((weff - truth_w[t]) ** 2, axis=1))
            # marker error after the RBF (should be ~0)
            Xm = _blend_with_global(model, regions, fit.weights_at(t), fit.global_weights[t], performance.markers)
            Xm = Xm + fit.residual_displacement(model, t)[performance.markers]
            emr += float(np.mean(np.sum((Xm - performance.marker_positions[t]) ** 2, axis=1)))
        rows.append(
            {
                "method": name,
                "level": lv if use else None,
                "n_regions": regions.n_regions(lv) if use else 0,
                "marker_rms": float(np.sqrt(np.mean(fit.marker_error_region**2))),
                "marker_rms_rbf": float(np.sqrt(emr / T)),
                "vertex_rms": float(np.sqrt(ev / T)),
                "vertex_rms_rbf": float(np.sqrt(evr / T)),
                "weight_rms": float(np.sqrt(ew / T)),
            }
        )
    return rows


def format_fidelity_table(rows: list[dict[str, Any]], units: str = "dm") -> str:
    """A markdown table of :func:`fidelity_table` rows."""
    head = (
        f"| method | regions | marker RMS ({units}) | after RBF | vertex RMS ({units}) | vertex RMS + RBF | weight RMS |\n"
        "|---|---|---|---|---|---|---|\n"
    )
    body = "".join(
        f"| {r['method']} | {r['n_regions']} | {r['marker_rms']:.2e} | {r['marker_rms_rbf']:.1e} | "
        f"{r['vertex_rms']:.2e} | {r['vertex_rms_rbf']:.2e} | {r['weight_rms']:.3f} |\n"
        for r in rows
    )
    return head + body
