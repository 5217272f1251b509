"""Per-region blend weights, smooth blending over overlaps, and region sculpting (Joshi et al. 2003, §2–§4).

Paper: "Learning Controls for Blend Shape Based Realistic Facial Animation"
(``shared/papers/siggraph2006-course-performance-driven-facial-animation.md``).
§2: "linear blending in each of these regions will reconstruct much more detail";
§4 "Creating Keyframes": the user drags points, a minimisation over the region's
blending weights makes them follow; "Motion Damping" scales the mouse motion.

Evaluation with regions (level ``l``, regions ``r`` with weight fields ``W_r``
from :class:`workbench.methods.regions.hierarchy.Regions`, background weight ``W_bg``)::

    x(v) = neutral(v) + sum_r W_r(v) sum_k w_rk Δ_k(v) + W_bg(v) sum_k g_k Δ_k(v)

with ``g`` the model's global weights (the background follows the global
sliders) and ``sum_r W_r + W_bg = 1``. As a model layer (added on top of the
global blend that :meth:`FaceModel.evaluate` already does) this is the
*correction* ``sum_r W_r(v) sum_k (w_rk - g_k) Δ_k(v)``, exactly zero when
every region's weights equal the global ones. Muted shapes contribute nothing
and vertex masks apply, as in ``evaluate()``.

Region sculpting solves, for the regions under the pinned vertices ``p``::

    min_δ  sum_p |sum_r W_r(p) sum_k δ_rk Δ_k(p) - (target_p - x_p)|² + λ |δ|²
    s.t.   slider_min_k <= w_rk + δ_rk <= slider_max_k

a bounded linear least-squares problem. Solver: ``scipy.optimize.nnls``
(compiled Lawson–Hanson active set) on ``w - slider_min`` with a small outer
active set for the upper bounds, KKT-checked, falling back to
``scipy.optimize.lsq_linear(method="bvls")`` — both maintained in scipy, already
a core dependency. NNLS is exact and ~100–500× faster than BVLS when many
weights sit at 0 (the usual case); ``benchmarks/bench_regions.py`` compares it
with OSQP through qpsolvers on the same problems. ``λ`` is ``regularization`` times the mean
squared column norm of the system, so it is unit-free; it keeps the regions'
other weights near their current values.

Hand-written because this blend (per-region weights, overlap weights, a bounded
solve restricted to the touched regions) is specific to the paper; the numerics
are numpy/scipy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import lsq_linear, nnls

from workbench.core.linear import LinearTerms
from workbench.methods.regions.hierarchy import RegionError, Regions

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState as FaceModel

__all__ = [
    "RegionLayer",
    "RegionState",
    "RegionWeights",
    "damp_drag",
    "drag_damping",
    "region_blend_displacement",
    "region_blend_positions",
    "solve_region_drag",
]


def _ro(a: NDArray[Any]) -> NDArray[Any]:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class RegionWeights:
    """Blend weights of every region of one hierarchy level (immutable).

    Attributes
    ----------
    level : int
        The :class:`Regions` level these weights belong to.
    shape_names : tuple of str
        Column order (the model's shape order).
    region_names : tuple of str
        Row order (the level's region names).
    values : (R, k) float32
        ``values[r, k]`` = weight of shape ``k`` in region ``r`` (read-only).
    """

    level: int
    shape_names: tuple[str, ...]
    region_names: tuple[str, ...]
    values: NDArray[np.float32]

    def __post_init__(self) -> None:
        v = np.array(self.values, dtype=np.float32)
        shape = (len(self.region_names), len(self.shape_names))
        if v.shape != shape:
            raise RegionError(f"RegionWeights.values: expected shape {shape} (regions, shapes), got {v.shape}")
        if not np.isfinite(v).all():
            raise RegionError("RegionWeights.values: NaN/inf weight")
        object.__setattr__(self, "values", _ro(v))
        object.__setattr__(self, "shape_names", tuple(self.shape_names))
        object.__setattr__(self, "region_names", tuple(self.region_names))
        object.__setattr__(self, "level", int(self.level))

    @classmethod
    def from_global(
        cls, model: FaceModel, regions: Regions, level: int, weights: ArrayLike | None = None
    ) -> RegionWeights:
        """Every region gets the same weights: ``weights`` (k,) or the model's current ones."""
        lv = regions.check_level(level)
        names = tuple(model.shape_names)
        if weights is None:
            g = np.array([model.weights[nm] for nm in names], np.float32)
        else:
            g = np.asarray(weights, np.float32).reshape(-1)
            if g.shape != (len(names),):
                raise RegionError(f"weights: expected ({len(names)},) one per shape, got {g.shape}")
        R = regions.n_regions(lv)
        return cls(lv, names, regions.names[lv], np.tile(g, (R, 1)))

    def region_index(self, region: int | str) -> int:
        if isinstance(region, str):
            if region not in self.region_names:
                raise RegionError(f"region {region!r} unknown; regions are {list(self.region_names)}")
            return self.region_names.index(region)
        if not isinstance(region, int | np.integer) or not 0 <= int(region) < len(self.region_names):
            raise RegionError(f"region must be a name or an int in 0..{len(self.region_names) - 1}, got {region!r}")
        return int(region)

    def region(self, region: int | str) -> dict[str, float]:
        """``{shape: weight}`` of one region."""
        return dict(zip(self.shape_names, self.values[self.region_index(region)].tolist(), strict=True))

    def with_region(self, region: int | str, weights: Mapping[str, float]) -> RegionWeights:
        """A copy with some weights of one region replaced (unnamed shapes keep theirs)."""
        r = self.region_index(region)
        v = self.values.copy()
        for nm, w in weights.items():
            if nm not in self.shape_names:
                raise RegionError(f"weights: unknown shape {nm!r}")
            v[r, self.shape_names.index(nm)] = float(w)
        return RegionWeights(self.level, self.shape_names, self.region_names, v)

    def to_level(self, regions: Regions, level: int) -> RegionWeights:
        """The same expression on another level of the hierarchy.

        Going finer, every region inherits its ancestor's weights (exact: the
        blend is unchanged wherever the finer level's overlaps agree). Going
        coarser, a region gets the area-weighted mean of its descendants (the
        coarser level cannot hold different weights inside one region).
        """
        src, dst = self.level, regions.check_level(level)
        if len(self.region_names) != regions.n_regions(src):
            raise RegionError(f"regions: level {src} has {regions.n_regions(src)} regions, weights have {len(self.region_names)}")
        if dst == src:
            return self
        if dst < src:
            idx = np.array([regions.ancestor(dst, r, src) for r in range(regions.n_regions(dst))], np.intp)
            return RegionWeights(dst, self.shape_names, regions.names[dst], self.values[idx])
        Rd = regions.n_regions(dst)
        size = np.bincount(regions.labels[src][regions.labels[src] >= 0], minlength=regions.n_regions(src))
        acc = np.zeros((Rd, len(self.shape_names)))
        tot = np.zeros(Rd)
        for r in range(regions.n_regions(src)):
            a = regions.ancestor(src, r, dst)
            acc[a] += size[r] * self.values[r]
            tot[a] += size[r]
        mean = (acc / np.maximum(tot, 1)[:, None]).astype(np.float32)
        return RegionWeights(dst, self.shape_names, regions.names[dst], mean)


@dataclass(frozen=True, eq=False)
class RegionState:
    """What the lead stores in ``model.set_slot("regions", ...)``: segmentation, level and weights.

    Attributes
    ----------
    regions : Regions
    level : int
        The level shown / edited.
    weights : RegionWeights or None
        Per-region weights (on ``level``); None = regions shown but not blended.
    """

    regions: Regions
    level: int = 0
    weights: RegionWeights | None = None

    def __post_init__(self) -> None:
        lv = self.regions.check_level(self.level)
        if self.weights is not None and self.weights.level != lv:
            object.__setattr__(self, "weights", self.weights.to_level(self.regions, lv))


# ------------------------------------------------------------------ evaluation
def _check(model: FaceModel | StateView, regions: Regions, rw: RegionWeights, level: int | None) -> tuple[int, RegionWeights]:
    if regions.n_vertices != model.n_vertices:
        raise RegionError(f"regions: made for {regions.n_vertices} vertices, the model has {model.n_vertices}")
    if tuple(model.shape_names) != rw.shape_names:
        raise RegionError("region_weights: shape names differ from the model's shapes (re-create them)")
    lv = rw.level if level is None else regions.check_level(level)
    if len(rw.region_names) != regions.n_regions(rw.level):
        raise RegionError(f"region_weights: {len(rw.region_names)} regions, level {rw.level} has {regions.n_regions(rw.level)}")
    return lv, rw.to_level(regions, lv)


def _mute(model: FaceModel | StateView) -> NDArray[np.float32]:
    return np.array([0.0 if s.mute else 1.0 for s in model.shapes], np.float32)


def _global(model: FaceModel | StateView) -> NDArray[np.float32]:
    return np.array([model.weights[nm] for nm in model.shape_names], np.float32)


def region_blend_displacement(
    model: FaceModel | StateView, regions: Regions, region_weights: RegionWeights, level: int | None = None
) -> NDArray[np.float32]:
    """The region blend as a layer on top of the model's global blend.

    Parameters
    ----------
    model : FaceModel
    regions : Regions
    region_weights : RegionWeights
        Converted with :meth:`RegionWeights.to_level` if it is on another level.
    level : int, optional
        Level to blend on (default: the weights' level).

    Returns
    -------
    (n, 3) float32
        ``sum_r W_r(v) sum_k (w_rk - g_k) Δ_k(v)``; ``model.evaluate()`` plus this
        is the region-blended face. Exactly zero when all region weights equal
        the global weights.
    """
    lv, rw = _check(model, regions, region_weights, level)
    n = model.n_vertices
    out = np.zeros((n, 3), np.float32)
    diff = (rw.values - _global(model)[None, :]) * _mute(model)[None, :]  # (R, k)
    active_r = np.flatnonzero(np.abs(diff).max(axis=1, initial=0.0) > 0)
    if active_r.size == 0:
        return out
    W = regions.weight_matrix(lv)[:, active_r].tocsr()
    rows = np.flatnonzero(np.diff(W.indptr) > 0)
    cols = np.flatnonzero(np.abs(diff[active_r]).max(axis=0) > 0)
    coef = np.asarray(W[rows] @ diff[np.ix_(active_r, cols)], dtype=np.float32)  # (m, kc)
    D = model.effective_deltas
    out[rows] = np.einsum("mk,kmc->mc", coef, D[cols][:, rows])
    return out


def region_blend_positions(
    model: FaceModel, regions: Regions, region_weights: RegionWeights, level: int | None = None,
    vertices: ArrayLike | None = None,
) -> NDArray[np.float32]:
    """Region-blended vertex positions (neutral + blend; no other layers).

    Parameters
    ----------
    model, regions, region_weights, level
        As in :func:`region_blend_displacement`.
    vertices : (m,) int, optional
        Only these vertices (default all).

    Returns
    -------
    (m, 3) float32
        ``neutral + sum_r W_r sum_k w_rk Δ_k + W_bg sum_k g_k Δ_k``.
    """
    lv, rw = _check(model, regions, region_weights, level)
    idx = np.arange(model.n_vertices) if vertices is None else _vertex_ids(model, vertices, "vertices")
    mute = _mute(model)
    g = _global(model) * mute
    Wr = regions.weight_matrix(lv)[idx]
    coef = np.asarray(Wr @ (rw.values * mute[None, :]), dtype=np.float64)
    coef += regions.background[lv][idx, None].astype(np.float64) * g[None, :]
    D = model.effective_deltas[:, idx]
    disp = np.einsum("mk,kmc->mc", coef, D.astype(np.float64))
    return (model.vertices[idx] + disp).astype(np.float32)


class RegionLayer:
    """Pipeline layer ``"regions"``: the region blend stored in the ``regions`` slot.

    A correction of the blend below (it reads the weights), zero unless the slot
    holds a :class:`RegionState` with weights; stale weights after a shape edit
    show the global blend.
    """

    name = "regions"
    reads = ("regions",)
    linear = True
    #: its gain is the blend's (it reads the weights, not the mesh below): it must come first
    gain_scales = "blend"

    def displacement(self, view: StateView, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        state = view.slot("regions")
        if not isinstance(state, RegionState) or state.weights is None:
            return None
        try:
            return region_blend_displacement(view, state.regions, state.weights, state.level)
        except RegionError:
            return None

    # -- linear description (workbench.core.linear): Σ_r W_r Σ_k (w_rk − g_k) Δ_k = C_R − S_R Σ_k g_k Δ_k
    @staticmethod
    def _blend(view: StateView) -> tuple[RegionState, int, Any] | None:
        state = view.slot("regions")
        if not isinstance(state, RegionState) or state.weights is None:
            return None
        R = state.regions
        if R.n_vertices != view.n_vertices:
            return None
        try:
            level = R.check_level(state.level)
        except (RegionError, IndexError, ValueError):
            return None
        return state, level, R.weight_matrix(level)

    def gain(self, view: StateView) -> NDArray[np.float64] | None:
        """``1 − S_R``: the share of the global blend outside the regions' own weights."""
        blend = self._blend(view)
        if blend is None:
            return None
        cover = np.asarray(blend[2].sum(axis=1), np.float64).reshape(-1)
        return 1.0 - cover if np.any(cover) else None

    def controls(self, view: StateView, timeline: Any) -> None:
        return None

    def linear_terms(self, view: StateView, timeline: Any) -> LinearTerms:
        """Constant ``C_R = Σ_k (Σ_r W_r w_rk) Δ_k`` and gain ``1 − S_R``; baked when region weights are keyed."""
        rt = {} if timeline is None else timeline.region_tracks
        if rt:
            if not isinstance(view.slot("regions"), RegionState):
                raise RegionError(f"the timeline keys region weights ({len(rt)} region tracks) "
                                  "but the model has no regions")
            return LinearTerms(baked=f"region weights keyed on level {timeline.region_level} "
                                     f"({len(rt)} region tracks) vary over time")
        blend = self._blend(view)
        if blend is None:
            return LinearTerms(detail="no region weights")
        state, level, W = blend
        cover = np.asarray(W.sum(axis=1), np.float64).reshape(-1)
        rows = np.flatnonzero(cover > 0)
        if not rows.size:
            return LinearTerms(detail="no region covers a vertex")
        rw = state.weights.to_level(state.regions, level)  # type: ignore[union-attr]
        vals = rw.values.astype(np.float64) * _mute(view)[None, :]
        coef = np.asarray(W[rows] @ vals, np.float64)  # (m, k)
        constant = np.zeros((view.n_vertices, 3), np.float64)
        constant[rows] = np.einsum("mk,kmc->mc", coef, view.effective_deltas[:, rows].astype(np.float64))
        return LinearTerms(gain=1.0 - cover, constant=constant,
                           detail=f"level {level}, {rw.values.shape[0]} regions over {rows.size} vertices: "
                                  "constant target + shape targets scaled by (1 - coverage)")


def _vertex_ids(model: FaceModel, vertices: ArrayLike, name: str) -> NDArray[np.intp]:
    v = np.asarray(vertices)
    if v.ndim == 0:
        v = v.reshape(1)
    if v.ndim != 1 or (v.size and not np.issubdtype(v.dtype, np.integer)):
        raise RegionError(f"{name}: expected a 1-D array of vertex ids, got {v.dtype} {v.shape}")
    if v.size and (v.min() < 0 or v.max() >= model.n_vertices):
        raise RegionError(f"{name}: vertex ids must be in 0..{model.n_vertices - 1}")
    return v.astype(np.intp)


# ------------------------------------------------------------------ sculpting
def _pins(model: FaceModel, pinned: Mapping[int, ArrayLike]) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    if not isinstance(pinned, Mapping) or len(pinned) == 0:
        raise RegionError("pinned must be a non-empty mapping {vertex id: target (3,)}")
    ids = _vertex_ids(model, np.array(list(pinned.keys())), "pinned")
    T = np.array([np.asarray(t, dtype=np.float64).reshape(-1) for t in pinned.values()])
    if T.shape != (ids.size, 3) or not np.isfinite(T).all():
        raise RegionError("pinned: every target must be a finite (3,) position")
    return ids, T


def drag_system(
    model: FaceModel,
    regions: Regions,
    level: int,
    region_weights: RegionWeights,
    pinned: Mapping[int, ArrayLike],
    *,
    current_positions: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.intp], NDArray[np.intp], RegionWeights]:
    """The linear system of a region drag (exposed for benchmarks and tests).

    Returns
    -------
    J : (3P, u) float64
        Change of the pinned positions per unit change of each unknown weight.
    b : (3P,) float64
        ``target - current`` at the pins.
    reg_idx, shape_idx : (u,) int
        Region and shape of each unknown.
    rw : RegionWeights
        The weights on ``level``.
    """
    lv, rw = _check(model, regions, region_weights, level)
    ids, T = _pins(model, pinned)
    W = regions.weight_matrix(lv)[ids].toarray().astype(np.float64)  # (P, R)
    touched = np.flatnonzero(W.max(axis=0) > 0)
    if touched.size == 0:
        raise RegionError(
            f"pinned: vertices {ids.tolist()} lie in the background of level {lv}; "
            "drag a point inside a region or use the global sliders"
        )
    if current_positions is None:
        X0 = region_blend_positions(model, regions, rw, lv, vertices=ids).astype(np.float64)
    else:
        X0 = np.asarray(current_positions, dtype=np.float64)
        if X0.shape == (model.n_vertices, 3):
            X0 = X0[ids]
        if X0.shape != (ids.size, 3):
            raise RegionError(f"current_positions: expected ({model.n_vertices}, 3) or ({ids.size}, 3), got {X0.shape}")
    D = model.effective_deltas[:, ids].astype(np.float64) * _mute(model)[:, None, None]  # (k, P, 3)
    moves = np.abs(D).max(axis=(1, 2)) > 0
    ks = np.flatnonzero(moves)
    # unknown (r, k): region r touched, shape k moves some pin in r's support
    reg_idx = np.repeat(touched, ks.size)
    shape_idx = np.tile(ks, touched.size)
    # J[(p, c), (r, k)] = W[p, r] * D[k, p, c]
    J = (W[:, touched][:, :, None, None] * D[ks].transpose(1, 0, 2)[:, None, :, :])  # (P, Rt, kc, 3)
    J = J.transpose(0, 3, 1, 2).reshape(3 * ids.size, touched.size * ks.size)
    keep = np.abs(J).max(axis=0) > 0
    b = (T - X0).reshape(-1)
    return J[:, keep], b, reg_idx[keep], shape_idx[keep], rw


def solve_region_drag(
    model: FaceModel,
    regions: Regions,
    level: int,
    region_weights: RegionWeights,
    pinned: Mapping[int, ArrayLike],
    *,
    regularization: float = 1e-3,
    current_positions: ArrayLike | None = None,
) -> RegionWeights:
    """New region weights that make the pinned vertices follow their targets (paper §4).

    Only the regions whose (overlapping) support contains a pinned vertex change;
    weights stay inside each shape's slider range.

    Parameters
    ----------
    model : FaceModel
    regions : Regions
    level : int
        Hierarchy level to sculpt on (coarse → fine refinement: solve on a high
        level, then ``to_level`` a finer one and solve again).
    region_weights : RegionWeights
        Current weights (any level; converted).
    pinned : mapping {vertex id: (3,) target position}
        Dragged points and points held in place (several allowed).
    regularization : float
        >= 0; pull toward the current weights, relative to the system's scale.
    current_positions : (n, 3) or (P, 3) float, optional
        Where the pins are now (e.g. ``model.evaluate()`` with other layers);
        default: the region blend.

    Returns
    -------
    RegionWeights
        On ``level``.

    Raises
    ------
    RegionError
        Bad arguments, or every pin lies in the background.
    """
    reg = float(regularization)
    if not (np.isfinite(reg) and reg >= 0):
        raise RegionError(f"regularization must be a finite number >= 0, got {regularization!r}")
    J, b, ri, ki, rw = drag_system(model, regions, level, region_weights, pinned, current_positions=current_positions)
    if J.shape[1] == 0:
        return rw  # no shape moves the pinned points
    w0 = rw.values[ri, ki].astype(np.float64)
    lo = np.array([model.shapes[k].slider_min for k in ki]) - w0
    hi = np.array([model.shapes[k].slider_max for k in ki]) - w0
    lo = np.minimum(lo, 0.0)  # a weight already outside its range may stay there
    hi = np.maximum(hi, 0.0)
    delta = bounded_lsq(J, b, lo, hi, reg)
    v = rw.values.copy()
    v[ri, ki] = (w0 + delta).astype(np.float32)
    return RegionWeights(rw.level, rw.shape_names, rw.region_names, v)


def bounded_lsq(
    J: NDArray[np.float64],
    b: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    reg: float,
    *,
    lam: float | None = None,
) -> NDArray[np.float64]:
    """``argmin |J x - b|² + λ|x|²`` s.t. ``lo <= x <= hi``, ``λ = reg · mean(|J_col|²)``.

    Parameters
    ----------
    J : (m, u) float
    b : (m,) float
    lo, hi : (u,) float
        With ``lo <= 0 <= hi``.
    reg : float
    lam : float, optional
        Use this absolute ``λ`` instead (``reg`` is then ignored).

    Returns
    -------
    x : (u,) float64
    """
    u = J.shape[1]
    if lam is None:
        lam = reg * float(np.mean(np.einsum("ij,ij->j", J, J))) if u else 0.0
    if lam > 0:
        A = np.vstack([J, np.sqrt(lam) * np.eye(u)])
        rhs = np.concatenate([b, np.zeros(u)])
    else:
        A, rhs = J, b
    x = _box_nnls(A, rhs, lo, hi)
    if x is not None:
        return x
    # lsq_linear needs lo < hi strictly; pin fixed unknowns by a tiny box
    hi = np.where(hi <= lo, lo + 1e-12, hi)
    res = lsq_linear(A, rhs, bounds=(lo, hi), method="bvls", lsmr_tol=None)
    return np.asarray(res.x, dtype=np.float64)


def _box_nnls(
    A: NDArray[np.float64], b: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Exact box-constrained least squares by NNLS on ``x - lo``, upper bounds by an active set.

    ``scipy.optimize.nnls`` (Lawson–Hanson, compiled) is ~100–500× faster than
    ``lsq_linear(method="bvls")`` on these problems when many weights sit at 0.
    Variables above ``hi`` are fixed there and the rest re-solved; a fixed
    variable whose gradient asks to decrease is released. The result is returned
    only if it satisfies the KKT conditions of the box problem (so it is the
    optimum); otherwise None (the caller falls back to BVLS).
    """
    u = A.shape[1]
    if u == 0:
        return np.zeros(0)
    at_hi = np.zeros(u, bool)
    x = lo.copy()
    for _ in range(2 * u + 2):
        free = ~at_hi
        x = np.where(at_hi, hi, lo)
        r = b - A[:, at_hi] @ hi[at_hi] - A[:, free] @ lo[free]
        if free.any():  # scipy 1.17's nnls aborts the process (double free) on a 0-column matrix
            try:
                y, _ = nnls(A[:, free], r, maxiter=max(50, 6 * u))
            except RuntimeError:
                return None
            x[free] = lo[free] + y
        g = A.T @ (A @ x - b)  # gradient / 2
        over = free & (x > hi)
        release = at_hi & (g > 1e-12 * (1.0 + np.abs(g).max()))
        if not over.any() and not release.any():
            tol = 1e-9 * (1.0 + np.abs(g).max())
            ok_lo = np.all(g[(x <= lo) & free] >= -tol)
            ok_mid = np.all(np.abs(g[(x > lo) & (x < hi) & free]) <= 1e-6 * (1.0 + np.abs(A.T @ b).max()))
            return x if ok_lo and ok_mid else None
        at_hi = (at_hi | over) & ~release
    return None


# ------------------------------------------------------------------ damping
def drag_damping(model: FaceModel, vertices: ArrayLike | None = None) -> NDArray[np.float64]:
    """Per-vertex mouse-motion scale for dragging (the paper's "Motion Damping").

    The factor is ``m(v) / max_u m(u)`` with ``m(v) = max_k |Δ_k(v)| ·
    max(|slider_min_k|, |slider_max_k|)``, the largest displacement the shapes
    allow at ``v``. The paper words it "inversely proportional to the maximum
    displacement"; read literally that would *amplify* the mouse at the nose tip,
    the opposite of its stated aim (a small mouse motion there must not trigger
    a dramatic change). What is inversely proportional to ``m(v)`` is the weight
    change per unit of mouse motion; scaling the mouse by ``m(v)`` makes that
    sensitivity the same everywhere, so we do that.

    Parameters
    ----------
    model : FaceModel
    vertices : (m,) int, optional
        Default: all vertices.

    Returns
    -------
    (m,) float64 in [0, 1]
    """
    D = model.effective_deltas
    ranges = np.array([0.0 if s.mute else max(abs(s.slider_min), abs(s.slider_max)) for s in model.shapes])
    if D.shape[0] == 0:
        m = np.zeros(model.n_vertices)
    else:
        m = (np.sqrt(np.einsum("knc,knc->kn", D, D, dtype=np.float64)) * ranges[:, None]).max(axis=0)
    top = float(m.max(initial=0.0))
    f = m / top if top > 0 else m
    return f if vertices is None else f[_vertex_ids(model, vertices, "vertices")]


def damp_drag(model: FaceModel, vertex: int, mouse_delta: ArrayLike) -> NDArray[np.float64]:
    """Scale a mouse displacement (3,) in model units by :func:`drag_damping` at ``vertex``."""
    d = np.asarray(mouse_delta, dtype=np.float64).reshape(-1)
    if d.shape != (3,) or not np.isfinite(d).all():
        raise RegionError(f"mouse_delta must be a finite (3,) vector, got {np.asarray(mouse_delta).shape}")
    return d * float(drag_damping(model, np.array([vertex]))[0])
