"""Per-region blend weights (:class:`RegionWeights`) and what the ``regions`` slot holds (:class:`RegionState`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.methods.regions.hierarchy import RegionError, Regions

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel


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
