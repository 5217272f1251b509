"""The blend-region hierarchy as a value: :class:`Regions` and :class:`RegionError`.

A :class:`Regions` holds, per hierarchy level (0 = finest), the disjoint core
label of every vertex, the sparse per-vertex region weights (each core grown by
``overlap_rings`` rings, summing to 1 with the background), region names,
kinds (skin or rigid) and drivers, and the parent of every region on the next
coarser level (Joshi et al. 2003, §4 "Regions and Region Hierarchy").

Paper: P. Joshi, W. Tien, M. Desbrun, F. Pighin, "Learning Controls for Blend
Shape Based Realistic Facial Animation", SCA 2003 (in
``shared/papers/siggraph2006-course-performance-driven-facial-animation.md``).

Built by :func:`workbench.methods.regions.segmentation.segment_blend_regions`
and changed by the edits of :mod:`workbench.methods.regions.edits`; this module
only holds the immutable value and its queries.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = [
    "RegionError",
    "Regions",
]


class RegionError(ValueError):
    """Bad argument to a region function (the message names the argument)."""


def _ro(a: NDArray[Any]) -> NDArray[Any]:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Regions:
    """Blend regions of a model on several hierarchy levels (immutable).

    Level 0 is the finest; level ``n_levels - 1`` the coarsest. Every region of
    level ``l`` lies inside exactly one region of level ``l + 1``.

    Attributes
    ----------
    labels : tuple of (n,) int32
        Per level, the disjoint *core* label of every vertex; ``-1`` = background.
    weight_rows, weight_cols : tuple of (nnz,) int32
        Per level, the sparse per-vertex region weights ``W[v, r]`` in COO form
        (see :meth:`weight_matrix`); the support of column ``r`` is the core of
        region ``r`` grown by ``overlap_rings`` rings.
    weight_vals : tuple of (nnz,) float32
    background : tuple of (n,) float32
        Per level, the background weight; ``W.sum(1) + background == 1``.
    names : tuple of tuple of str
        Per level, one unique name per region ("brow_L", "mouth_R", "eyeball_L").
    parents : tuple of (R_l,) int32
        ``parents[l][r]`` is the level ``l + 1`` region containing region ``r`` of
        level ``l`` (``n_levels - 1`` arrays).
    kinds : tuple of tuple of str
        Per level and region: ``"skin"`` (segmented) or ``"rigid"`` (a whole
        eyeball / teeth / tongue component).
    drivers : tuple of tuple of tuple of str
        Per level and region, the (up to) three shapes that move it most
        (relative to each shape's peak) — the sliders worth showing for it.
    deformation : (n,) float32
        The deformation map ``D`` (0 off the segmentable components).
    threshold : float
        ``t`` in [0, 1].
    threshold_value : float
        ``D_sorted[floor(n_active t)]``.
    overlap_rings : int
    """

    labels: tuple[NDArray[np.int32], ...]
    weight_rows: tuple[NDArray[np.int32], ...]
    weight_cols: tuple[NDArray[np.int32], ...]
    weight_vals: tuple[NDArray[np.float32], ...]
    background: tuple[NDArray[np.float32], ...]
    names: tuple[tuple[str, ...], ...]
    parents: tuple[NDArray[np.int32], ...]
    kinds: tuple[tuple[str, ...], ...]
    drivers: tuple[tuple[tuple[str, ...], ...], ...]
    deformation: NDArray[np.float32]
    threshold: float
    threshold_value: float
    overlap_rings: int = 1

    def __post_init__(self) -> None:
        L = len(self.labels)
        if L == 0:
            raise RegionError("Regions: need at least one level of labels")
        n = self.labels[0].shape[0]
        for name in ("weight_rows", "weight_cols", "weight_vals", "background", "names", "kinds", "drivers"):
            if len(getattr(self, name)) != L:
                raise RegionError(f"Regions.{name}: expected {L} levels, got {len(getattr(self, name))}")
        if len(self.parents) != L - 1:
            raise RegionError(f"Regions.parents: expected {L - 1} arrays, got {len(self.parents)}")
        for lv in range(L):
            lab = self.labels[lv]
            if lab.shape != (n,):
                raise RegionError(f"Regions.labels[{lv}]: expected shape ({n},), got {lab.shape}")
            R = len(self.names[lv])
            if lab.size and (lab.min() < -1 or lab.max() >= R):
                raise RegionError(f"Regions.labels[{lv}]: labels must be in -1..{R - 1}")
            if len(set(self.names[lv])) != R:
                raise RegionError(f"Regions.names[{lv}]: names must be unique")
        for lv, p in enumerate(self.parents):
            if p.shape != (len(self.names[lv]),):
                raise RegionError(f"Regions.parents[{lv}]: expected one parent per level-{lv} region")
        for f in ("labels", "weight_rows", "weight_cols", "weight_vals", "background", "parents"):
            object.__setattr__(self, f, tuple(_ro(a) for a in getattr(self, f)))
        object.__setattr__(self, "deformation", _ro(self.deformation))

    # ------------------------------------------------------------------ queries
    @property
    def n_levels(self) -> int:
        """Number of hierarchy levels (0 = finest)."""
        return len(self.labels)

    @property
    def n_vertices(self) -> int:
        return int(self.labels[0].shape[0])

    def check_level(self, level: int) -> int:
        """``level`` as an int, or a :class:`RegionError` naming the valid range."""
        if not isinstance(level, int | np.integer) or not 0 <= int(level) < self.n_levels:
            raise RegionError(f"level must be an int in 0..{self.n_levels - 1}, got {level!r}")
        return int(level)

    def n_regions(self, level: int) -> int:
        """Number of regions on ``level`` (background not counted)."""
        return len(self.names[self.check_level(level)])

    def weight_matrix(self, level: int) -> sp.csr_matrix:
        """(n, R) sparse CSR float32 per-vertex region weights ``W[v, r]``.

        Built once per level and cached; treat it as read-only.
        """
        lv = self.check_level(level)
        cache: dict[int, sp.csr_matrix] = self.__dict__.setdefault("_wcache", {})
        if lv not in cache:
            cache[lv] = sp.csr_matrix(
                (self.weight_vals[lv], (self.weight_rows[lv], self.weight_cols[lv])),
                shape=(self.n_vertices, len(self.names[lv])),
            )
        return cache[lv]

    def weights_dense(self, level: int) -> NDArray[np.float32]:
        """(n, R + 1) float32: region weights with the background as the last column."""
        lv = self.check_level(level)
        W = self.weight_matrix(lv).toarray()
        return np.concatenate([W, self.background[lv][:, None]], axis=1).astype(np.float32)

    def core(self, level: int, region: int | str) -> NDArray[np.intp]:
        """Vertex ids whose core label is ``region`` (an index or a name)."""
        lv = self.check_level(level)
        return np.flatnonzero(self.labels[lv] == self.region_index(lv, region))

    def members(self, level: int, region: int | str) -> NDArray[np.intp]:
        """Vertex ids where the region's weight is > 0 (the core grown by the overlap)."""
        lv = self.check_level(level)
        r = self.region_index(lv, region)
        sel = (self.weight_cols[lv] == r) & (self.weight_vals[lv] > 0)
        return np.unique(self.weight_rows[lv][sel]).astype(np.intp)

    def region_index(self, level: int, region: int | str) -> int:
        """Index of a region given by index or name on ``level``."""
        lv = self.check_level(level)
        names = self.names[lv]
        if isinstance(region, str):
            if region not in names:
                raise RegionError(f"region {region!r} not on level {lv}; regions are {list(names)}")
            return names.index(region)
        if not isinstance(region, int | np.integer) or not 0 <= int(region) < len(names):
            raise RegionError(f"region must be a name or an int in 0..{len(names) - 1}, got {region!r}")
        return int(region)

    def regions_at(self, level: int, vertex: int) -> dict[int, float]:
        """``{region: weight}`` of the regions whose (grown) support contains ``vertex``."""
        lv = self.check_level(level)
        if not isinstance(vertex, int | np.integer) or not 0 <= int(vertex) < self.n_vertices:
            raise RegionError(f"vertex must be an int in 0..{self.n_vertices - 1}, got {vertex!r}")
        W = self.weight_matrix(lv)
        row = W.getrow(int(vertex))
        return {int(c): float(v) for c, v in zip(row.indices, row.data, strict=True) if v > 0}

    def ancestor(self, level: int, region: int, to_level: int) -> int:
        """The region of ``to_level`` (>= ``level``) that contains ``region`` of ``level``."""
        lv, tl = self.check_level(level), self.check_level(to_level)
        if tl < lv:
            raise RegionError(f"to_level must be >= level ({lv}), got {tl}")
        r = self.region_index(lv, region)
        for i in range(lv, tl):
            r = int(self.parents[i][r])
        return r

    def renamed(self, level: int, region: int | str, new_name: str) -> Regions:
        """A copy with one region renamed (user edit; store it with ``model.set_slot``)."""
        lv = self.check_level(level)
        r = self.region_index(lv, region)
        if not isinstance(new_name, str) or not new_name.strip():
            raise RegionError(f"new_name must be a non-empty string, got {new_name!r}")
        if new_name in self.names[lv] and self.names[lv][r] != new_name:
            raise RegionError(f"new_name {new_name!r} is already used on level {lv}")
        names = list(self.names)
        lvl = list(names[lv])
        lvl[r] = new_name
        names[lv] = tuple(lvl)
        return Regions(
            self.labels, self.weight_rows, self.weight_cols, self.weight_vals, self.background,
            tuple(names), self.parents, self.kinds, self.drivers, self.deformation, self.threshold,
            self.threshold_value, self.overlap_rings,
        )
