"""Region sculpting: dragged points followed by a bounded solve over the regions' weights (§4), and motion damping.

Region sculpting solves, for the regions under the pinned vertices ``p``::

    min_δ  sum_p |sum_r W_r(p) sum_k δ_rk Δ_k(p) - (target_p - x_p)|² + λ |δ|²
    s.t.   slider_min_k <= w_rk + δ_rk <= slider_max_k

a bounded linear least-squares problem, solved by
:func:`~workbench.methods.regions.blend.lsq.bounded_lsq`. ``λ`` is
``regularization`` times the mean squared column norm of the system, so it is
unit-free; it keeps the regions' other weights near their current values.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.methods.regions.blend.evaluate import (
    _check,
    _mute,
    _vertex_ids,
    region_blend_positions,
)
from workbench.methods.regions.blend.lsq import bounded_lsq
from workbench.methods.regions.blend.weights import RegionWeights
from workbench.methods.regions.hierarchy import RegionError, Regions

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel


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
