"""Splitting a region in two around clicked seeds.

On level 0 the split is the geodesic Voronoi partition of two clicked seeds; on
coarser levels a grouping of whole children, so levels stay nested. Both
halves inherit the split region's blend weights.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra

from workbench.methods.regions.edits.draft import (
    RegionEdit,
    _check_new_name,
    _check_skin_region,
    _Draft,
    _fresh_name,
    _n_pieces,
    _rebuild,
    _skin_core,
    _vertex_ids,
)
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.topology import RegionTopology, _check_topology


def _as_seeds(value: Any, n: int, what: str) -> NDArray[np.int64]:
    ids = _vertex_ids(value, n, what)
    if ids.size == 0:
        raise RegionError(f"{what} must hold at least one vertex")
    return ids


def split_region(
    regions: Regions,
    topology: RegionTopology,
    level: int,
    region: int | str,
    seeds_a: Any,
    seeds_b: Any,
    *,
    names: tuple[str, str] | None = None,
) -> RegionEdit:
    """Split a skin region in two around two (sets of) clicked vertices.

    On level 0 the split is the **geodesic Voronoi partition** of the region's
    core: every core vertex goes to the half whose seed is nearer along the
    skin's mesh edges (Dijkstra on edge lengths), so two clicks give a cut
    halfway between them that follows the surface. On a coarser level the
    region is the union of its level-``l-1`` children and the split keeps the
    hierarchy nested by **grouping whole children**: the children holding the
    seeds go to their half and every other child to the half whose seed child
    is nearer in the children's adjacency graph (centroid distances). If both
    seeds lie in the same child, that child is split first (recursively, down
    to level 0), so two clicks always succeed. Each half is connected.

    Half A (around ``seeds_a``) keeps the region's index; half B is inserted
    right after it (later regions move up by one). Both halves inherit the
    region's drivers and blend weights (``origins``); they are named
    ``<name>_a`` / ``<name>_b`` unless ``names`` is given. Levels above are
    unchanged (both halves lie in the old parent).

    Parameters
    ----------
    regions : Regions
    topology : RegionTopology
    level : int
    region : int or str
        A skin region of ``level``.
    seeds_a, seeds_b : int or (s,) int
        Skin vertices of the region's core, none in both.
    names : (str, str), optional

    Returns
    -------
    RegionEdit

    Raises
    ------
    RegionError
        Naming ``level``, ``region``, ``seeds_a``/``seeds_b`` (outside the region,
        shared, empty, or a half that is not connected) or ``names``.
    """
    topo = _check_topology(regions, topology)
    lv = regions.check_level(level)
    r = regions.region_index(lv, region)
    _check_skin_region(regions, lv, r, "region")
    n = regions.n_vertices
    sa = _as_seeds(seeds_a, n, "seeds_a")
    sb = _as_seeds(seeds_b, n, "seeds_b")
    lab = regions.labels[lv]
    rname = regions.names[lv][r]
    for what, s in (("seeds_a", sa), ("seeds_b", sb)):
        bad = s[(lab[s] != r) | ~topo.skin[s]]
        if bad.size:
            raise RegionError(
                f"{what}: vertices {bad[:5].tolist()} are not in the core of region {rname!r} on level {lv}"
            )
    both = np.intersect1d(sa, sb)
    if both.size:
        raise RegionError(f"seeds_b: vertices {both[:5].tolist()} are also in seeds_a")
    used = set(regions.names[lv]) - {rname}
    if names is not None:
        if not isinstance(names, tuple | list) or len(names) != 2:
            raise RegionError(f"names must be two strings (half a, half b), got {names!r}")
        na = _check_new_name(names[0], "names[0]", used, lv)
        nb = _check_new_name(names[1], "names[1]", used | {na}, lv)
    else:
        na = _fresh_name(f"{rname}_a", used)
        nb = _fresh_name(f"{rname}_b", used | {na})
    d = _Draft(regions)
    _split_into(d, topo, lv, r, sa, sb, (na, nb))
    return _rebuild(d, topo)


def _split_into(
    d: _Draft,
    topo: RegionTopology,
    k: int,
    r: int,
    sa: NDArray[np.int64],
    sb: NDArray[np.int64],
    names: tuple[str, str],
) -> None:
    """Split region ``r`` of level ``k`` in the draft (see :func:`split_region`)."""
    if k == 0:
        core = _skin_core(topo, d.labels[0], r)
        G = topo.skin_graph[core][:, core]
        loc = np.searchsorted(core, np.concatenate([sa, sb]))
        _, _, src = dijkstra(G, directed=False, indices=loc, min_only=True, return_predecessors=True)
        if (src < 0).any():  # pragma: no cover - the core is connected
            raise RegionError("region: the region's core is not connected")
        in_b = np.isin(src, loc[sa.size:])
        side_b = core[in_b]
    else:
        while True:
            lab_c = d.labels[k - 1]
            ca, cb = set(lab_c[sa].tolist()), set(lab_c[sb].tolist())
            shared = sorted(ca & cb)
            if not shared:
                break
            c = shared[0]
            sub_a, sub_b = sa[lab_c[sa] == c], sb[lab_c[sb] == c]
            used = set(d.names[k - 1]) - {d.names[k - 1][c]}
            base = d.names[k - 1][c]
            na = _fresh_name(f"{base}_a", used)
            nb = _fresh_name(f"{base}_b", used | {na})
            _split_into(d, topo, k - 1, c, sub_a, sub_b, (na, nb))
        core = _skin_core(topo, d.labels[k], r)
        ch = d.labels[k - 1][core]
        kids, inv = np.unique(ch, return_inverse=True)
        m = kids.size
        V = topo.vertices
        cent = np.stack([V[core[inv == i]].mean(axis=0) for i in range(m)])
        P = sp.csr_matrix((np.ones(core.size), (np.arange(core.size), inv)), shape=(core.size, m))
        Cc = np.asarray((P.T @ topo.adjacency[core][:, core].astype(np.float64) @ P).todense())
        np.fill_diagonal(Cc, 0.0)
        ii, jj = np.nonzero(Cc)
        w = np.maximum(np.linalg.norm(cent[ii] - cent[jj], axis=1), 1e-12)
        G = sp.csr_matrix((w, (ii, jj)), shape=(m, m))
        src_a = np.searchsorted(kids, sorted(ca))
        src_b = np.searchsorted(kids, sorted(cb))
        _, _, src = dijkstra(
            G, directed=False, indices=np.concatenate([src_a, src_b]), min_only=True, return_predecessors=True
        )
        kid_b = np.isin(src, src_b)
        side_b = core[kid_b[inv]]
    new = d.insert_after(k, r)
    d.names[k][r], d.names[k][new] = names
    d.labels[k][side_b] = new
    for what, half in (("seeds_a", r), ("seeds_b", new)):
        pieces = _n_pieces(topo, _skin_core(topo, d.labels[k], half))
        if pieces != 1:
            raise RegionError(
                f"{what}: the half around these seeds would be in {pieces} pieces on level {k} "
                "(seeds of the other half lie between them); click one vertex per half"
            )
