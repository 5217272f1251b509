"""The result of a marker fit (:class:`MarkerFit`): per-frame weights, and the positions they give."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.methods.regions.blend.evaluate import _mute
from workbench.methods.regions.blend.weights import RegionWeights
from workbench.methods.regions.hierarchy import Regions
from workbench.methods.regions.marker_fit.rbf import RBFResidual
from workbench.methods.regions.segmentation import component_roles

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel


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

        Plain arrays; :meth:`RegionsFacet.key_marker_fit` (``model.regions``) puts them on the model's
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
