"""The ``"regions"`` pipeline layer, and its description as a linear layer (gain and constant)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.core.linear import LinearTerms
from workbench.methods.regions.blend.evaluate import _mute, region_blend_displacement
from workbench.methods.regions.blend.weights import RegionState
from workbench.methods.regions.hierarchy import RegionError
from workbench.methods.regions.tracks import region_level, region_tracks

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView


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
        if R.n_vertices != view.n_vertices or tuple(state.weights.shape_names) != tuple(view.shape_names):
            return None  # stale after a shape edit: the global blend, as displacement() shows
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
        rt = {} if timeline is None else region_tracks(timeline)
        if rt:
            if not isinstance(view.slot("regions"), RegionState):
                raise RegionError(f"the timeline keys region weights ({len(rt)} region tracks) "
                                  "but the model has no regions")
            return LinearTerms(baked=f"region weights keyed on level {region_level(timeline)} "
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
