"""Renaming a region, and merging two touching regions (with their coarser parents when they differ).

A merged region takes the blend weights of the larger of the two (its
``origins`` entry).
"""

from __future__ import annotations

import numpy as np

from workbench.methods.regions.edits.draft import (
    RegionEdit,
    _check_new_name,
    _check_skin_region,
    _Draft,
    _identity_origins,
    _rebuild,
)
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.topology import RegionTopology, _check_topology, region_adjacency


def rename_region(regions: Regions, level: int, region: int | str, name: str) -> RegionEdit:
    """Rename one region of ``level`` (labels, weights and the hierarchy are unchanged).

    Parameters
    ----------
    regions : Regions
    level : int
    region : int or str
        Index or current name.
    name : str
        New name, unique on ``level``.

    Returns
    -------
    RegionEdit
        ``origins`` is the identity.
    """
    out = regions.renamed(level, region, name)
    return RegionEdit(out, _identity_origins(regions))


def merge_regions(
    regions: Regions,
    topology: RegionTopology,
    level: int,
    a: int | str,
    b: int | str,
    *,
    name: str | None = None,
) -> RegionEdit:
    """Merge two adjacent skin regions of ``level`` into one.

    The merged region keeps the *lower* of the two indices (regions after the
    other one move down by one) and the name, drivers and blend weights of the
    *larger* region (more core vertices; ``a`` on a tie), unless ``name`` is
    given. Levels stay nested: if ``a`` and ``b`` lie in different regions of
    the next coarser level, those are merged too (the same rule, up to the
    coarsest level); finer levels are unchanged (their regions now share the
    merged parent). Weights and overlaps are recomputed.

    Parameters
    ----------
    regions : Regions
    topology : RegionTopology
        :func:`region_topology` of the model.
    level : int
    a, b : int or str
        Two different skin regions of ``level`` that share a mesh edge.
    name : str, optional
        Name of the merged region (unique on ``level`` apart from ``a`` and ``b``).

    Returns
    -------
    RegionEdit

    Raises
    ------
    RegionError
        Unknown level/region (the message names ``level``/``a``/``b``), ``a == b``,
        a rigid region, regions that do not touch, or a taken ``name``.
    """
    topo = _check_topology(regions, topology)
    lv = regions.check_level(level)
    try:
        ia = regions.region_index(lv, a)
    except RegionError as exc:
        raise RegionError(f"a: {exc}") from None
    try:
        ib = regions.region_index(lv, b)
    except RegionError as exc:
        raise RegionError(f"b: {exc}") from None
    nm = regions.names[lv]
    if ia == ib:
        raise RegionError(f"b: cannot merge region {nm[ia]!r} with itself")
    _check_skin_region(regions, lv, ia, "a")
    _check_skin_region(regions, lv, ib, "b")
    C = region_adjacency(regions, topo, lv)
    if C[ia, ib] == 0:
        near = [nm[i] for i in np.flatnonzero(C[ia] > 0)]
        raise RegionError(
            f"b: region {nm[ib]!r} does not touch {nm[ia]!r} on level {lv}; "
            f"{nm[ia]!r} can merge with {near}"
        )
    if name is not None:
        _check_new_name(name, "name", set(nm) - {nm[ia], nm[ib]}, lv)
    d = _Draft(regions)
    k, x, y = lv, ia, ib
    while True:
        lab = d.labels[k]
        sx, sy = int(np.count_nonzero((lab == x) & topo.skin)), int(np.count_nonzero((lab == y) & topo.skin))
        big = x if sx >= sy else y
        keep_i, drop_i = min(x, y), max(x, y)
        d.names[k][keep_i] = name if (k == lv and name is not None) else regions.names[k][big]
        d.drivers[k][keep_i] = regions.drivers[k][big]
        d.origins[k][keep_i] = big
        lab[lab == drop_i] = keep_i
        d.names[k][drop_i] = ""  # empty now: dropped by _rebuild
        if k + 1 >= regions.n_levels:
            break
        px, py = int(regions.parents[k][x]), int(regions.parents[k][y])
        if px == py:
            break
        k, x, y = k + 1, px, py
    return _rebuild(d, topo)
