"""Each level's regions as blend weights: overlapping skin regions, attached parts, rigid parts, names.

Steps 6 and 7 of :mod:`workbench.methods.regions.segmentation`: per level, the
skin regions' one-hot cores are averaged over ``overlap_rings`` closed one-rings
(so the weights and the background sum to 1 at every vertex and each region
grows one ring into its neighbours); attached parts (lashes, brows) copy their
nearest skin vertex; each rigid part (eyeball, teeth, tongue) is a region of
its own with weight 1. Regions are named (:mod:`.region_names`) and keep the
three shapes that move them most as their drivers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.arkit import canonical_arkit_name, shape_group
from workbench.geometry.parts import model_part_roles
from workbench.methods.regions.fine_pieces import FinePieces
from workbench.methods.regions.mesh_graph import smooth_weights
from workbench.methods.regions.region_names import region_stem, rigid_name, side_sign, unique_names

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = ["LevelTables", "level_tables"]


@dataclass
class LevelTables:
    """Per level (finest first): what :class:`~workbench.methods.regions.hierarchy.Regions` holds of it."""

    labels: tuple[NDArray[np.int32], ...]
    weight_rows: tuple[NDArray[np.int32], ...]
    weight_cols: tuple[NDArray[np.int32], ...]
    weight_vals: tuple[NDArray[np.float32], ...]
    background: tuple[NDArray[np.float32], ...]
    names: tuple[tuple[str, ...], ...]
    kinds: tuple[tuple[str, ...], ...]
    drivers: tuple[tuple[tuple[str, ...], ...], ...]
    parents: tuple[NDArray[np.int32], ...]


def level_tables(
    model: FaceModel,
    roles: NDArray[np.int8],
    skin: NDArray[np.bool_],
    fine: FinePieces,
    skin_maps: list[NDArray[np.int64]],
    A1: sp.csr_matrix,
    area: NDArray[np.float64],
    mags: NDArray[np.float32],
    mid: float,
    diag: float,
    overlap_rings: int,
) -> LevelTables:
    """Weights, labels, names and parents of every level.

    Parameters
    ----------
    roles : (n,) int8
        0 segmented skin, 1 rigid, 2 attached (:func:`.segmentation.component_roles`).
    skin : (n,) bool
    fine : FinePieces
    skin_maps : list of (R0,) int
        Per level, the region of every fine piece (:func:`.motion_merge.level_maps`).
    A1 : (n, n) sparse
        The mesh adjacency with its diagonal.
    area : (n,) float
    mags : (k, n) float
        Each shape's displacement length times its slider range.
    mid, diag : float
        The mid-plane's x and the moving skin's diagonal.
    overlap_rings : int
    """
    n = model.n_vertices
    V = model.vertices
    lab0, rel, side3 = fine.labels, fine.rel, fine.side3
    levels = len(skin_maps)
    # rigid components: one region each, on every level
    rigid_comps = [c for c in np.unique(model.component_labels[roles == 1])]
    part_roles = model_part_roles(model)
    deg = np.asarray(A1.sum(axis=1)).ravel().astype(np.float64)
    S = sp.diags(1.0 / np.maximum(deg, 1.0)) @ A1.astype(np.float64)
    S = sp.csr_matrix(S)
    attached = np.flatnonzero(roles == 2)
    nearest = np.zeros(0, np.int64)
    skin_idx = np.flatnonzero(skin)
    if attached.size and skin_idx.size:
        _, j = cKDTree(V[skin_idx]).query(V[attached])
        nearest = skin_idx[np.asarray(j)]
    side_sign_ = side_sign(model, skin, mid)
    names_all = model.shape_names
    groups = [shape_group(canonical_arkit_name(s) or s) for s in names_all]
    half_tol = 0.02 * diag

    labels_out, rows_out, cols_out, vals_out, bg_out, names_out, kinds_out = [], [], [], [], [], [], []
    drivers_out: list[tuple[tuple[str, ...], ...]] = []
    for mp in skin_maps:
        Rs = int(mp.max()) + 1 if mp.size else 0
        lab = np.where(lab0 >= 0, mp[np.maximum(lab0, 0)], -1) if mp.size else np.full(n, -1, np.int64)
        # names from the shape moving the region most (area-weighted squared motion) and its side
        names: list[str] = []
        kinds: list[str] = []
        drivers: list[tuple[str, ...]] = []
        heights: list[float] = []
        for r in range(Rs):
            vv = np.flatnonzero(lab == r)
            # name from the shape moving the region most (relative motion, area
            # weighted); the mid-plane column is left out so mirror regions agree
            vn = vv[side3[vv] != 1] if (side3[vv] != 1).any() else vv
            energy = (rel[:, vn] ** 2) @ area[vn]
            top = np.argsort(-energy, kind="stable")[:3]
            drivers.append(tuple(names_all[i] for i in top))
            stem = region_stem(energy, groups)
            x = V[vv, 0] - mid
            xc = float((x * area[vv]).sum() / area[vv].sum())
            if x.min() < -half_tol and x.max() > half_tol:
                side = ""  # spans the mid-plane
            else:
                side = "_L" if xc * side_sign_ > 0 else "_R"
            names.append(stem + side)
            kinds.append("skin")
            heights.append(-float((V[vv, 1] * area[vv]).sum() / area[vv].sum()))
        names = list(unique_names(names, heights))
        W = smooth_weights(S, lab, Rs, skin, overlap_rings)
        Wcoo = W.tocoo()
        rows, cols, vals = Wcoo.row.astype(np.int64), Wcoo.col.astype(np.int64), Wcoo.data
        bgw = np.zeros(n, np.float64)
        isbg = cols == Rs
        bgw[rows[isbg]] = vals[isbg]
        rows, cols, vals = rows[~isbg], cols[~isbg], vals[~isbg]
        lab_full = lab.copy()
        # attached parts copy their nearest skin vertex
        if attached.size:
            lab_full[attached] = lab[nearest]
            bgw[attached] = bgw[nearest]
            Wr = sp.csr_matrix((vals, (rows, cols)), shape=(n, Rs + 1))[nearest].tocoo()
            rows = np.concatenate([rows, attached[Wr.row]])
            cols = np.concatenate([cols, Wr.col])
            vals = np.concatenate([vals, Wr.data])
        for ci in rigid_comps:
            vv = np.flatnonzero(model.component_labels == ci)
            r = len(names)
            lab_full[vv] = r
            rows = np.concatenate([rows, vv])
            cols = np.concatenate([cols, np.full(vv.size, r)])
            vals = np.concatenate([vals, np.ones(vv.size)])
            names.append(rigid_name(model.component_names[ci], part_roles[ci]))
            kinds.append("rigid")
            energy = (mags[:, vv] ** 2).sum(axis=1)
            drivers.append(tuple(names_all[i] for i in np.argsort(-energy, kind="stable")[:3]))
        # background weight where nothing else is (non-skin vertices of no region: none)
        order = np.lexsort((cols, rows))
        labels_out.append(lab_full.astype(np.int32))
        rows_out.append(rows[order].astype(np.int32))
        cols_out.append(cols[order].astype(np.int32))
        vals_out.append(vals[order].astype(np.float32))
        bg_out.append(bgw.astype(np.float32))
        names_out.append(unique_names(names))
        kinds_out.append(tuple(kinds))
        drivers_out.append(tuple(drivers))

    parents: list[NDArray[np.int32]] = []
    for lv in range(levels - 1):
        finer, coarse = skin_maps[lv], skin_maps[lv + 1]
        Rs_f = int(finer.max()) + 1 if finer.size else 0
        Rs_c = int(coarse.max()) + 1 if coarse.size else 0
        par = np.zeros(Rs_f, np.int64)
        par[finer] = coarse
        n_rigid = len(rigid_comps)
        parents.append(np.concatenate([par, Rs_c + np.arange(n_rigid)]).astype(np.int32))

    return LevelTables(tuple(labels_out), tuple(rows_out), tuple(cols_out), tuple(vals_out), tuple(bg_out),
                       tuple(names_out), tuple(kinds_out), tuple(drivers_out), tuple(parents))
