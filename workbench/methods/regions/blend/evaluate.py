"""The region blend evaluated: as a correction of the global blend, and as positions (Joshi et al. 2003, §2).

Evaluation with regions (level ``l``, regions ``r`` with weight fields ``W_r``
from :class:`workbench.methods.regions.hierarchy.Regions`, background weight ``W_bg``)::

    x(v) = neutral(v) + sum_r W_r(v) sum_k w_rk Δ_k(v) + W_bg(v) sum_k g_k Δ_k(v)

with ``g`` the model's global weights (the background follows the global
sliders) and ``sum_r W_r + W_bg = 1``. As a model layer (added on top of the
global blend that :meth:`FaceModel.evaluate` already does) this is the
*correction* ``sum_r W_r(v) sum_k (w_rk - g_k) Δ_k(v)``, exactly zero when
every region's weights equal the global ones. Muted shapes contribute nothing
and vertex masks apply, as in ``evaluate()``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.methods.regions.blend.weights import RegionWeights
from workbench.methods.regions.hierarchy import RegionError, Regions

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState as FaceModel


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


def _vertex_ids(model: FaceModel, vertices: ArrayLike, name: str) -> NDArray[np.intp]:
    v = np.asarray(vertices)
    if v.ndim == 0:
        v = v.reshape(1)
    if v.ndim != 1 or (v.size and not np.issubdtype(v.dtype, np.integer)):
        raise RegionError(f"{name}: expected a 1-D array of vertex ids, got {v.dtype} {v.shape}")
    if v.size and (v.min() < 0 or v.max() >= model.n_vertices):
        raise RegionError(f"{name}: vertex ids must be in 0..{model.n_vertices - 1}")
    return v.astype(np.intp)
