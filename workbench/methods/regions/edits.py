"""User edits of blend regions: merge, split, rename and paint.

The artist's corrections of the automatic regions of
:func:`workbench.methods.regions.segmentation.segment_blend_regions`
(:func:`merge_regions`, :func:`split_region`, :func:`rename_region`,
:func:`paint_region`; undoable through the ``FaceModel`` methods of the same
names). Each edit changes labels only, on a draft, and then recomputes every
derived array exactly as the segmentation does (``_rebuild``): parents from
the labels, the smooth one-ring weights ``S^rings χ`` on the skin, attachments
copying their nearest skin vertex, rigid parts weight 1
(:func:`recompute_region_weights` of a fresh segmentation is bit-identical).
So edited :class:`~workbench.methods.regions.hierarchy.Regions` keep every
invariant of a segmented one: skin regions connected, levels nested, overlaps
exactly ``overlap_rings`` rings, weights summing to 1.

Merges need touching regions and merge the coarser parents too when they
differ; a split is the geodesic Voronoi partition of two clicked seeds on
level 0 and a grouping of whole children on coarser levels; painting assigns
skin vertices to a region (its ancestors follow, its descendants grow by
nearest vertex) or returns them to the background, and refuses to cut a
region in pieces. :class:`RegionEdit` ``origins`` say which old region's blend
weights each new region takes (the larger one of a merge; both halves of a
split inherit). The mesh data the edits need is a
:class:`~workbench.methods.regions.topology.RegionTopology`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components, dijkstra

from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.mesh_graph import smooth_weights
from workbench.methods.regions.topology import RegionTopology, _check_topology, region_adjacency

__all__ = [
    "RegionEdit",
    "merge_regions",
    "paint_region",
    "recompute_region_weights",
    "rename_region",
    "split_region",
]


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
