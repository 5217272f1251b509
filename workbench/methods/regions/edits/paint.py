"""Painting skin vertices into a region, or back to the background.

The region's ancestors follow, its descendants grow by nearest vertex; a
region that would be cut in pieces is refused.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.sparse.csgraph import dijkstra

from workbench.methods.regions.edits.draft import (
    RegionEdit,
    _check_skin_region,
    _Draft,
    _identity_origins,
    _n_pieces,
    _rebuild,
    _skin_core,
    _vertex_ids,
)
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.topology import RegionTopology, _check_topology


def paint_region(
    regions: Regions,
    topology: RegionTopology,
    level: int,
    region: int | str,
    vertices: Any,
    *,
    add: bool = True,
) -> RegionEdit:
    """Assign vertices to a skin region of ``level`` (``add=True``) or take them out of it.

    ``add=True``: the painted skin vertices join ``region`` and, so levels stay
    nested, its ancestor on every coarser level; on finer levels each painted
    vertex joins the descendant of ``region`` that holds its geodesically
    nearest old core vertex (so the children grow into the painted area
    without breaking apart). The painted vertices, together with the region,
    must be connected. ``add=False``: the painted vertices of ``region`` go to
    the background (on every level, as the background is shared by all levels).

    Only segmented skin vertices are painted: other vertices in ``vertices``
    (lashes follow their nearest skin vertex, eyeballs/teeth are rigid) are
    ignored. A region that loses all its vertices disappears; a region that
    would fall into pieces is refused (paint so that it stays in one piece, or
    split it first). Weights and overlaps are recomputed; every region keeps
    its blend weights (``origins`` without the removed ones).

    Parameters
    ----------
    regions : Regions
    topology : RegionTopology
    level : int
    region : int or str
        A skin region of ``level``.
    vertices : int or (m,) int
        The brush's vertices.
    add : bool

    Returns
    -------
    RegionEdit
        ``regions`` is the input object itself when no label changes.

    Raises
    ------
    RegionError
        Naming ``level``/``region``/``vertices`` (no skin vertex, not touching
        the region, or a region that would be cut in pieces).
    """
    topo = _check_topology(regions, topology)
    lv = regions.check_level(level)
    r = regions.region_index(lv, region)
    _check_skin_region(regions, lv, r, "region")
    ids = _vertex_ids(vertices, regions.n_vertices, "vertices")
    ids = ids[topo.skin[ids]]
    if ids.size == 0:
        raise RegionError("vertices: none of them is on the segmented skin")
    rname = regions.names[lv][r]
    old = regions.labels[lv]
    d = _Draft(regions)
    if add:
        T = ids[old[ids] != r]
        if T.size == 0:
            return RegionEdit(regions, _identity_origins(regions))
        core = _skin_core(topo, old.astype(np.int64), r)
        grown = np.union1d(core, T)
        G = topo.skin_graph[grown][:, grown]
        loc_core = np.searchsorted(grown, core)
        _, _, src = dijkstra(G, directed=False, indices=loc_core, min_only=True, return_predecessors=True)
        loc_T = np.searchsorted(grown, T)
        lost = T[src[loc_T] < 0]
        if lost.size:
            raise RegionError(
                f"vertices: {lost.size} painted vertices do not touch region {rname!r} on level {lv} "
                f"(e.g. {lost[:5].tolist()}); paint next to the region"
            )
        nearest_core = grown[src[loc_T]]
        for k in range(regions.n_levels):
            if k >= lv:
                d.labels[k][T] = regions.ancestor(lv, r, k)
            else:
                d.labels[k][T] = d.labels[k][nearest_core]
    else:
        T = ids[old[ids] == r]
        if T.size == 0:
            return RegionEdit(regions, _identity_origins(regions))
        for k in range(regions.n_levels):
            d.labels[k][T] = -1
    for k in range(regions.n_levels):
        touched = set(regions.labels[k][T].tolist()) | set(d.labels[k][T].tolist())
        touched.discard(-1)
        for q in sorted(touched):
            pieces = _n_pieces(topo, _skin_core(topo, d.labels[k], q))
            if pieces > 1:
                raise RegionError(
                    f"vertices: painting would cut region {regions.names[k][q]!r} of level {k} into "
                    f"{pieces} pieces; paint so that it stays in one piece (or split it first)"
                )
    return _rebuild(d, topo)
