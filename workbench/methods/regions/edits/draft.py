"""What every region edit shares: the draft it changes, the rebuild of every derived array, the checks.

Each edit changes labels only, on a :class:`_Draft`, and then recomputes every
derived array exactly as the segmentation does (:func:`_rebuild`): parents from
the labels, the smooth one-ring weights ``S^rings χ`` on the skin, attachments
copying their nearest skin vertex, rigid parts weight 1
(:func:`recompute_region_weights` of a fresh segmentation is bit-identical).
So edited :class:`~workbench.methods.regions.hierarchy.Regions` keep every
invariant of a segmented one: skin regions connected, levels nested, overlaps
exactly ``overlap_rings`` rings, weights summing to 1. :class:`RegionEdit`
``origins`` say which old region's blend weights each new region takes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.mesh_graph import smooth_weights
from workbench.methods.regions.topology import RegionTopology, _check_topology


class RegionEdit(NamedTuple):
    """Result of a region edit.

    Attributes
    ----------
    regions : Regions
        The edited regions (the input object itself if nothing changed).
    origins : tuple of (R_l,) int32
        Per level, for every region of the result, the index of the region of
        the *input* whose blend weights (and drivers) it takes: itself when
        unchanged, the larger of two merged regions, the split region for
        both halves.
    """

    regions: Regions
    origins: tuple[NDArray[np.int32], ...]


def _identity_origins(regions: Regions) -> tuple[NDArray[np.int32], ...]:
    return tuple(np.arange(regions.n_regions(lv), dtype=np.int32) for lv in range(regions.n_levels))


def _vertex_ids(value: Any, n: int, what: str) -> NDArray[np.int64]:
    """Unique vertex ids from an int or a sequence, or a RegionError naming ``what``."""
    try:
        a = np.asarray(value)
    except Exception:  # pragma: no cover - exotic input
        raise RegionError(f"{what} must be vertex ids, got {value!r}") from None
    if a.dtype == bool or (a.size and not np.issubdtype(a.dtype, np.integer)):
        if a.size and np.issubdtype(a.dtype, np.floating) and np.all(a == np.round(a)):
            a = a.astype(np.int64)
        else:
            raise RegionError(f"{what} must be integer vertex ids, got {value!r}")
    a = a.astype(np.int64).reshape(-1)
    if a.size and (a.min() < 0 or a.max() >= n):
        raise RegionError(f"{what}: vertex ids must be in 0..{n - 1}, got {a[(a < 0) | (a >= n)][:5].tolist()}")
    return np.unique(a)


def _n_pieces(topo: RegionTopology, verts: NDArray[np.int64]) -> int:
    """Connected pieces of a vertex set on the skin graph (0 for an empty set)."""
    if verts.size == 0:
        return 0
    sub = topo.adjacency[verts][:, verts]
    return int(connected_components(sub, directed=False)[0])


def _skin_core(topo: RegionTopology, lab: NDArray[np.int64], r: int) -> NDArray[np.int64]:
    return np.flatnonzero((lab == r) & topo.skin)


def _fresh_name(candidate: str, used: set[str]) -> str:
    if candidate not in used:
        return candidate
    i = 2
    while f"{candidate}{i}" in used:
        i += 1
    return f"{candidate}{i}"


def _check_new_name(name: Any, what: str, used: set[str], level: int) -> str:
    if not isinstance(name, str) or not name.strip():
        raise RegionError(f"{what} must be a non-empty string, got {name!r}")
    if name in used:
        raise RegionError(f"{what} {name!r} is already used on level {level}")
    return name


def _check_skin_region(regions: Regions, level: int, r: int, what: str) -> None:
    if regions.kinds[level][r] != "skin":
        raise RegionError(
            f"{what}: {regions.names[level][r]!r} is a rigid part (a whole eyeball/teeth/tongue "
            "component); only skin regions can be edited"
        )


class _Draft:
    """Mutable per-level labels and region tables an edit works on before :func:`_rebuild`."""

    def __init__(self, regions: Regions) -> None:
        self.src = regions
        self.labels = [np.array(a, dtype=np.int64) for a in regions.labels]
        self.names = [list(x) for x in regions.names]
        self.kinds = [list(x) for x in regions.kinds]
        self.drivers = [list(x) for x in regions.drivers]
        self.origins = [list(range(len(x))) for x in regions.names]

    def insert_after(self, level: int, r: int) -> int:
        """A new (empty) region at index ``r + 1`` of ``level`` copying ``r``'s tables."""
        lab = self.labels[level]
        lab[lab > r] += 1
        self.names[level].insert(r + 1, "")  # set by the caller
        self.kinds[level].insert(r + 1, self.kinds[level][r])
        self.drivers[level].insert(r + 1, self.drivers[level][r])
        self.origins[level].insert(r + 1, self.origins[level][r])
        return r + 1


def _rebuild(draft: _Draft, topo: RegionTopology) -> RegionEdit:
    """Drop empty regions, derive parents, recompute weights; returns the new Regions and origins."""
    src = draft.src
    L = src.n_levels
    labels: list[NDArray[np.int64]] = []
    names: list[tuple[str, ...]] = []
    kinds: list[tuple[str, ...]] = []
    drivers: list[tuple[tuple[str, ...], ...]] = []
    origins: list[NDArray[np.int32]] = []
    for lv in range(L):
        lab = draft.labels[lv].copy()
        if topo.attached.size:
            lab[topo.attached] = lab[topo.nearest]
        R = len(draft.names[lv])
        present = np.zeros(R, bool)
        present[lab[lab >= 0]] = True
        remap = np.cumsum(present) - 1
        lab = np.where(lab >= 0, remap[np.maximum(lab, 0)], -1)
        keep = np.flatnonzero(present)
        labels.append(lab)
        names.append(tuple(draft.names[lv][i] for i in keep))
        kinds.append(tuple(draft.kinds[lv][i] for i in keep))
        drivers.append(tuple(draft.drivers[lv][i] for i in keep))
        origins.append(np.array([draft.origins[lv][i] for i in keep], np.int32))
    parents: list[NDArray[np.int32]] = []
    for lv in range(L - 1):
        fine, coarse = labels[lv], labels[lv + 1]
        R = len(names[lv])
        has = fine >= 0
        par = np.full(R, -1, np.int64)
        par[fine[has]] = coarse[has]
        if not (np.array_equal(coarse >= 0, has) and np.array_equal(coarse[has], par[fine[has]])):
            raise RegionError(f"region edit: levels {lv} and {lv + 1} no longer nest (internal error)")
        parents.append(par.astype(np.int32))
    rows_out, cols_out, vals_out, bg_out = [], [], [], []
    for lv in range(L):
        rows, cols, vals, bgw = _level_weights(topo, labels[lv], kinds[lv], src.overlap_rings)
        rows_out.append(rows)
        cols_out.append(cols)
        vals_out.append(vals)
        bg_out.append(bgw)
    out = Regions(
        labels=tuple(a.astype(np.int32) for a in labels),
        weight_rows=tuple(rows_out),
        weight_cols=tuple(cols_out),
        weight_vals=tuple(vals_out),
        background=tuple(bg_out),
        names=tuple(names),
        parents=tuple(parents),
        kinds=tuple(kinds),
        drivers=tuple(drivers),
        deformation=src.deformation,
        threshold=src.threshold,
        threshold_value=src.threshold_value,
        overlap_rings=src.overlap_rings,
    )
    return RegionEdit(out, tuple(origins))


def _level_weights(
    topo: RegionTopology, lab: NDArray[np.int64], kinds: Sequence[str], rings: int
) -> tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.float32], NDArray[np.float32]]:
    """One level's COO weights and background, computed as in :func:`segment_blend_regions`."""
    n = lab.size
    R = len(kinds)
    skin_lab = np.where(topo.skin, lab, -1)
    W = smooth_weights(topo.smoothing, skin_lab, R, topo.skin, rings)
    Wcoo = W.tocoo()
    rows, cols, vals = Wcoo.row.astype(np.int64), Wcoo.col.astype(np.int64), Wcoo.data
    bgw = np.zeros(n, np.float64)
    isbg = cols == R
    bgw[rows[isbg]] = vals[isbg]
    rows, cols, vals = rows[~isbg], cols[~isbg], vals[~isbg]
    att, nearest = topo.attached, topo.nearest
    if att.size:
        bgw[att] = bgw[nearest]
        Wr = sp.csr_matrix((vals, (rows, cols)), shape=(n, R + 1))[nearest].tocoo()
        rows = np.concatenate([rows, att[Wr.row]])
        cols = np.concatenate([cols, Wr.col])
        vals = np.concatenate([vals, Wr.data])
    for r, kind in enumerate(kinds):
        if kind != "rigid":
            continue
        vv = np.flatnonzero(lab == r)
        rows = np.concatenate([rows, vv])
        cols = np.concatenate([cols, np.full(vv.size, r)])
        vals = np.concatenate([vals, np.ones(vv.size)])
    order = np.lexsort((cols, rows))
    return (
        rows[order].astype(np.int32),
        cols[order].astype(np.int32),
        vals[order].astype(np.float32),
        bgw.astype(np.float32),
    )


def recompute_region_weights(regions: Regions, topology: RegionTopology) -> Regions:
    """``regions`` with parents and weights recomputed from its labels (a no-op on a fresh segmentation).

    Parameters
    ----------
    regions : Regions
    topology : RegionTopology
        Of the model the regions belong to.

    Returns
    -------
    Regions
        Bit-identical to ``regions`` if it came from :func:`segment_blend_regions`
        (the tests pin this: every edit recomputes the weights this way).
    """
    topo = _check_topology(regions, topology)
    return _rebuild(_Draft(regions), topo).regions
