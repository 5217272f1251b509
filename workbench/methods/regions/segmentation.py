"""Automatic blend-region segmentation with a region hierarchy (Joshi et al. 2003, §2 and §4).

Paper: P. Joshi, W. Tien, M. Desbrun, F. Pighin, "Learning Controls for Blend
Shape Based Realistic Facial Animation", SCA 2003 (in
``shared/papers/siggraph2006-course-performance-driven-facial-animation.md``):
§2 "Segmentation" (deformation map, threshold ``D[n t]``, cleanup, one-vertex
overlap) and §4 "Regions and Region Hierarchy" (fine regions from a high
threshold, contiguous regions merged level by level).

The pipeline, and where it departs from the paper (each choice is pinned by a
test in ``tests/test_regions.py``):

1. **Deformation map.** For every shape ``k`` the displacement field
   ``d_k = Δ_k`` is run through the cotangent Laplacian; the map is
   ``D(v) = max_k |(M⁻¹ L d_k)(v)|``. We use the *mass-normalised* Laplacian
   ``M⁻¹ L`` (the pointwise Laplace–Beltrami of the paper's continuous ``Δd``),
   not the raw ``L`` (an *integrated* Laplacian, which scales with the local
   vertex area): with ``M⁻¹`` the same face subdivided to 25k or 100k vertices
   gives the same map, so the threshold picks the same regions at every resolution.
2. **Threshold.** ``D`` is sorted over the *active* segmentable vertices (skin
   that some shape moves by more than ``1e-3`` of the largest displacement) and
   ``threshold_value = D_sorted[floor(n_active · t)]``; vertices with
   ``D >= threshold_value`` are foreground. So ``t`` is the fraction of the moving
   skin left in the background: **higher t → higher threshold → fewer, smaller
   regions** (the paper's Fig. 3: t = 0.25 "low threshold", t = 0.75 "high
   threshold" with small localised regions). Vertices no shape moves (back of a
   full head) are background for every ``t``; counting them would make ``t``
   measure the skull instead of the face. The paper's face was a mask that
   moved everywhere, so for it the two conventions agree.
3. **Cleanup.** A morphological *close* on the mesh graph (dilate then erode by
   ``close_rings`` rings) fills notches and pinholes (the paper's "minimizing
   concavity"); foreground islands smaller than ``min_region_size`` (a fraction of
   the active area) are absorbed into the background. Both operators are
   increasing, so the foreground area stays monotone in ``t``.
4. **Fine regions.** On the sample head the ARKit shapes all overlap, so the
   foreground is one connected blob (the paper's ten coarse shapes gave
   separate blobs). We split it into *quasi-rigid* pieces: each foreground vertex
   is labelled by the shape that moves it most (``|Δ_k(v)|`` times the slider
   range) and by its side of the mid-plane (``split_midline``; so every region
   is one-sided or on the mid-plane and left/right expressions stay independent),
   pieces are connected components of equal labels, a one-ring mode filter
   smooths their borders and pieces smaller than ``min_region_size`` are merged
   into the neighbour they share most edges with.
   **Features stay whole** (``keep_features``). Labelling by the dominant shape
   alone splits a feature wherever another shape dominates part of it: on the
   sample head browDownLeft's strongly moving vertices fell 51 % / 28 % / 7 % into
   three fine regions (the pieces where browDown, eyeSquint and noseSneer move
   most) and 14 % into the background (where the brow moves as a block, its
   Laplacian is small). Joshi's regions follow
   features, so the fine-piece borders are then moved to the features
   (:func:`_keep_features_whole`): every local, one-sided shape's strong support
   (relative motion ≥ 0.5) joins one *home* piece — features lying mostly
   inside a larger one (the outer brow inside the brow) share its home, and a
   vertex two features claim goes to the more local one. Afterwards every such
   feature (brow, lid, cheek, nose wrinkle, mouth corner, lips) sits ≥ 70 % in one
   region at every level (``tests/test_region_quality.py``,
   ``benchmarks/bench_region_quality.py``).
5. **Hierarchy.** Adjacent pieces are merged greedily by the smallest Ward cost
   on the per-vertex *motion pattern* (the unit-normalised (3k,) displacement
   vector; ``w_A w_B / (w_A + w_B) |μ_A − μ_B|²`` with areas ``w``), i.e. the
   pair whose vertices move most alike goes first. Level 0 is the finest (the
   paper's "lowermost region level"); each coarser level has about ``coarsen``
   times as many regions, so levels nest by construction.
6. **Overlap and blend weights.** Labels are disjoint *cores*. Each level's
   region weights are one step of closed one-ring averaging of the one-hot core
   indicators (background included): ``W = S χ`` with ``S`` the row-normalised
   ``A + I``. ``S`` is row-stochastic, so ``Σ_r W_r + W_bg = 1`` at every vertex,
   and the support of ``W_r`` is the core grown by exactly one ring (the paper's
   "extended by one vertex all around its boundary"). ``overlap_rings`` > 1
   repeats the averaging for wider seams on dense meshes.
7. **Other components.** Only the skin is segmented. What each component is
   comes from :func:`workbench.geometry.parts.component_roles` (its name, else
   its geometry: an unnamed closed sphere in an orbit is an eyeball). Eyeballs,
   teeth and tongue are rigid parts the paper animates separately: each becomes
   its own region on every level (weight 1 on its vertices, no overlap), named
   after its role. Surface attachments (lashes, brows, hair, unrecognised small
   parts) copy the labels and weights of their nearest skin vertex, so lashes
   follow the lid.

The user edits of the result are in :mod:`workbench.methods.regions.edits`; the
:class:`~workbench.methods.regions.hierarchy.Regions` value in
:mod:`workbench.methods.regions.hierarchy`; the mesh-graph operations in
:mod:`workbench.methods.regions.mesh_graph`.

Hand-written because no kept dependency segments a blendshape set: the graph
pieces use scipy (``csgraph.connected_components``, sparse products, ``cKDTree``)
and libigl's cotangent Laplacian; the greedy merge is a ~30-line loop over a few
dozen regions.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.arkit import canonical_arkit_name, shape_group
from workbench.geometry.operators import cotangent_laplacian, mass_matrix
from workbench.geometry.parts import ATTACHED_ROLES, RIGID_ROLES, model_part_roles, role_side
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.mesh_graph import (
    absorb_small_pieces,
    label_pieces,
    mesh_adjacency,
    mode_filter,
    morphological_close,
    piece_adjacency,
    smooth_weights,
)

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = [
    "component_roles",
    "deformation_map",
    "feature_share",
    "segment_blend_regions",
]


Progress = Callable[[float, str], None] | None


#: ARKit shape group -> region stem (eye *lids* on the skin; eyeballs are their own components)
_STEM = {
    "brows": "brow",
    "eyes": "eye",
    "cheeks": "cheek",
    "nose": "nose",
    "mouth": "mouth",
    "jaw": "jaw",
    "tongue": "tongue",
    "other": "region",
}


def component_roles(model: FaceModel) -> NDArray[np.int8]:
    """Per-vertex role: 0 = segmented skin, 1 = rigid own region, 2 = attached to skin.

    Parameters
    ----------
    model : FaceModel

    Returns
    -------
    roles : (n,) int8
        From the part roles of :func:`workbench.geometry.parts.component_roles`
        (names first, else geometry): skin is segmented, eyeballs / teeth /
        tongue are rigid, lashes, brows, hair and unrecognised parts are
        attached. A model without skin has everything segmented.
    """
    parts = model_part_roles(model)
    role_of = np.array(
        [1 if r in RIGID_ROLES else 2 if r in ATTACHED_ROLES else 0 for r in parts], np.int8
    ).reshape(-1)
    if not (role_of == 0).any():
        role_of[:] = 0
    return role_of[model.component_labels]


def deformation_map(
    model: FaceModel,
    *,
    mass_normalized: bool = True,
    mask: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """The paper's deformation map ``D(v) = max_k |Laplacian(Δ_k)(v)|``.

    Parameters
    ----------
    model : FaceModel
    mass_normalized : bool
        ``True`` (default): ``M⁻¹ L Δ_k``, the pointwise Laplacian (resolution
        independent). ``False``: ``L Δ_k`` (area-integrated).
    mask : (n,) bool, optional
        Vertices to report; others get 0.

    Returns
    -------
    D : (n,) float64
        Zero for a model without shapes.
    """
    n = model.n_vertices
    k = len(model.shapes)
    if k == 0:
        return np.zeros(n)
    V, F = model.vertices, model.faces
    L = cotangent_laplacian(V, F)
    X = model.effective_deltas.transpose(1, 0, 2).reshape(n, 3 * k)
    Y = np.asarray(L @ X.astype(np.float64))
    if mass_normalized:
        m = mass_matrix(V, F).diagonal()
        Y *= np.where(m > 0, 1.0 / np.where(m > 0, m, 1.0), 0.0)[:, None]
    Y = Y.reshape(n, k, 3)
    D = np.sqrt(np.einsum("nkc,nkc->nk", Y, Y)).max(axis=1)
    if mask is not None:
        D = np.where(mask, D, 0.0)
    return D


def _merge_by_motion(
    C: NDArray[np.float64],
    energy: NDArray[np.float64],
    w: NDArray[np.float64],
    counts: Sequence[int],
    mirror: NDArray[np.int64] | None = None,
) -> list[NDArray[np.int64]]:
    """Greedy merging of adjacent regions whose motion is most alike.

    The cost of merging ``A`` and ``B`` is ``(1 - cos(E_A, E_B)) w_A w_B / (w_A + w_B)``:
    the dissimilarity of their per-shape motion energies (the same shapes move
    both → near 0) times Ward's size factor (small regions go first, so one region
    does not snowball). A merged region's energy and area are the sums. Ties go
    to the lower index.

    Parameters
    ----------
    C : (R, R) float
        Edge counts between pieces (adjacency).
    energy : (R, k) float
        Non-negative motion energy of each piece per shape.
    w : (R,) float
        Piece areas.
    counts : sequence of int
        Decreasing target numbers of regions, one per coarser level.
    mirror : (R,) int, optional
        Mirror piece of each piece; when given, the mirror pair of every merge is
        merged in the same step, so a symmetric input stays symmetric (a level
        may then end one region below its target).

    Returns
    -------
    list of (R,) int64
        Per target, the cluster id (0..count-1, compact) of every piece.
    """
    R = C.shape[0]
    adj = C > 0
    E = energy.astype(np.float64).copy()
    wt = w.astype(np.float64).copy()
    cluster = np.arange(R)
    alive = np.ones(R, bool)
    out: list[NDArray[np.int64]] = []
    n_alive = R

    def merge(i: int, j: int) -> None:
        E[i] += E[j]
        wt[i] += wt[j]
        adj[i] |= adj[j]
        adj[:, i] |= adj[:, j]
        adj[i, i] = False
        alive[j] = False
        adj[j] = False
        adj[:, j] = False
        cluster[cluster == j] = i

    for target in counts:
        while n_alive > target:
            ii, jj = np.nonzero(np.triu(adj & alive[:, None] & alive[None, :], 1))
            if ii.size == 0:
                break  # no adjacent pair left: the level keeps more regions
            nrm = np.maximum(np.linalg.norm(E, axis=1), 1e-300)
            dissim = 1.0 - np.einsum("ij,ij->i", E[ii], E[jj]) / (nrm[ii] * nrm[jj])
            cost = dissim * wt[ii] * wt[jj] / (wt[ii] + wt[jj])
            b = int(np.argmin(cost))
            i, j = int(ii[b]), int(jj[b])
            mi = mj = -1
            if mirror is not None:
                mi, mj = int(cluster[mirror[i]]), int(cluster[mirror[j]])
            merge(i, j)
            n_alive -= 1
            if mirror is not None:
                mi, mj = int(cluster[mi]), int(cluster[mj])
                if mi != mj and adj[mi, mj]:
                    merge(min(mi, mj), max(mi, mj))
                    n_alive -= 1
        _, compact = np.unique(cluster, return_inverse=True)
        out.append(compact.astype(np.int64))
    return out


def _side_sign(model: FaceModel, skin: NDArray[np.bool_], mid: float) -> float:
    """+1 if the subject's left is +x (from shapes named ...Left), else -1."""
    V = model.vertices
    score = 0.0
    for s in model.shapes:
        c = canonical_arkit_name(s.name) or s.name
        side = 1.0 if c.endswith("Left") else -1.0 if c.endswith("Right") else 0.0
        if side == 0.0:
            continue
        mag = np.linalg.norm(s.delta, axis=1) * skin
        if mag.sum() > 0:
            score += side * float((mag * (V[:, 0] - mid)).sum() / mag.sum())
    return 1.0 if score >= 0 else -1.0


def _mirror_maps(
    model: FaceModel, skin: NDArray[np.bool_], mid: float, diag: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]] | None:
    """Vertex and shape mirror permutations if the skin is mirror-symmetric about x = mid.

    Returns ``(vmap (n,), kmap (k,))`` with ``vmap[v]`` the vertex nearest to the
    reflection of ``v`` (identity off the skin) and ``kmap[k]`` the shape named as
    the mirror of shape ``k`` (itself if unsided), or None if any skin vertex has no
    mirror partner within ``1e-3 * diag`` or a sided shape has no partner.
    """
    from workbench.arkit import mirror_name

    V = model.vertices
    idx = np.flatnonzero(skin)
    refl = V[idx].copy()
    refl[:, 0] = 2.0 * mid - refl[:, 0]
    d, j = cKDTree(V[idx]).query(refl)
    if idx.size == 0 or float(np.max(d)) > 1e-3 * diag:
        return None
    vmap = np.arange(model.n_vertices)
    vmap[idx] = idx[np.asarray(j)]
    names = model.shape_names
    pos = {nm: i for i, nm in enumerate(names)}
    kmap = np.arange(len(names))
    for i, nm in enumerate(names):
        mn = mirror_name(nm)
        if mn is not None:
            if mn not in pos:
                return None
            kmap[i] = pos[mn]
    return vmap, kmap


def _unique_names(names: list[str], order: Sequence[float] | None = None) -> tuple[str, ...]:
    """Number repeated names ``_1, _2, ...`` in ascending ``order`` (default: position)."""
    keys = list(order) if order is not None else list(range(len(names)))
    keys += [float("inf")] * (len(names) - len(keys))
    out = list(names)
    for nm in set(names):
        idx = [i for i, x in enumerate(names) if x == nm]
        if len(idx) > 1:
            for c, i in enumerate(sorted(idx, key=lambda i: (keys[i], i)), start=1):
                out[i] = f"{nm}_{c}"
    return tuple(out)


def segment_blend_regions(
    model: FaceModel,
    threshold: float = 0.25,
    *,
    levels: int = 3,
    coarsen: float = 0.5,
    min_region_size: float = 0.01,
    close_radius: float = 0.02,
    overlap_rings: int = 1,
    split_midline: bool = True,
    mass_normalized: bool = True,
    keep_features: bool = True,
    progress: Progress = None,
) -> Regions:
    """Segment a blendshape model into overlapping blend regions with a hierarchy.

    Parameters
    ----------
    model : FaceModel
        Needs blendshapes; the mid-plane is the middle of the skin's x range.
    threshold : float
        ``t`` in [0, 1]: the fraction of the moving skin put in the background
        before cleanup (higher ``t`` → smaller regions; see the module docstring).
    levels : int
        Number of hierarchy levels (>= 1); level 0 is the finest.
    coarsen : float
        In (0, 1): each level has about ``coarsen`` times the skin regions of the
        next finer one.
    min_region_size : float
        In [0, 1): pieces smaller than this fraction of the moving skin area are
        absorbed (into a neighbouring region, or the background if isolated).
    close_radius : float
        Radius of the morphological close, as a fraction of the moving skin's
        bounding-box diagonal; converted to whole rings of the mesh (at least 1;
        0 disables the close).
    overlap_rings : int
        How many rings each region grows into its neighbours (>= 1; the paper: 1).
    split_midline : bool
        Keep fine regions on one side of the mid-plane (see step 4).
    mass_normalized : bool
        Use ``M⁻¹ L`` (default) or ``L`` for the deformation map.
    keep_features : bool
        Move the fine-piece borders so that every local one-sided feature lies
        in one piece (default; see step 4). ``False`` keys the pieces by the
        dominant shape alone (the previous behaviour).
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    Regions

    Raises
    ------
    RegionError
        If an argument is out of range or the model has no shapes / no moving skin.
    """
    from workbench.core.state import FaceState

    if not isinstance(model, FaceState):
        raise RegionError(f"model must be a FaceModel, got {type(model).__name__}")
    t = _check_fraction("threshold", threshold, 0.0, 1.0, closed_hi=True)
    if not isinstance(levels, int | np.integer) or isinstance(levels, bool) or levels < 1:
        raise RegionError(f"levels must be an int >= 1, got {levels!r}")
    _check_fraction("coarsen", coarsen, 0.0, 1.0, open_lo=True)
    mrs = _check_fraction("min_region_size", min_region_size, 0.0, 1.0)
    cr = _check_fraction("close_radius", close_radius, 0.0, 1.0)
    if not isinstance(overlap_rings, int | np.integer) or isinstance(overlap_rings, bool) or overlap_rings < 1:
        raise RegionError(f"overlap_rings must be an int >= 1, got {overlap_rings!r}")
    if not model.shapes:
        raise RegionError("model has no blendshapes to learn regions from")

    def report(f: float, msg: str) -> None:
        if progress is not None:
            progress(f, msg)

    t0 = time.perf_counter()
    n = model.n_vertices
    V = model.vertices
    roles = component_roles(model)
    skin = roles == 0
    report(0.05, "deformation map")
    D = deformation_map(model, mass_normalized=mass_normalized, mask=skin)
    deltas = model.effective_deltas
    ranges = np.array([max(abs(s.slider_min), abs(s.slider_max)) for s in model.shapes])
    mags = np.sqrt(np.einsum("knc,knc->kn", deltas, deltas, dtype=np.float32)) * ranges[:, None].astype(np.float32)
    maxdisp = mags.max(axis=0)
    active = skin & (maxdisp > 1e-3 * float(maxdisp[skin].max() if skin.any() else 0.0))
    if not active.any():
        raise RegionError("model: no blendshape moves the skin, nothing to segment")
    n_active = int(active.sum())
    Va = V[active]
    diag = float(np.linalg.norm(Va.max(0) - Va.min(0)))
    mid = 0.5 * float(V[skin, 0].min() + V[skin, 0].max())
    Ds = np.sort(D[active])
    thr = float(Ds[min(int(np.floor(n_active * t)), n_active - 1)])
    fg = active & (D >= thr)

    report(0.3, "cleanup")
    A = mesh_adjacency(model.faces, n)
    area = np.asarray(mass_matrix(V, model.faces).diagonal(), dtype=np.float64)
    act_area = float(area[active].sum())
    coo = A.tocoo()
    e_skin = skin[coo.row] & skin[coo.col]
    mean_edge = float(np.linalg.norm(V[coo.row[e_skin]] - V[coo.col[e_skin]], axis=1).mean()) if e_skin.any() else 1.0
    rings = 0 if cr == 0 else max(1, round(cr * diag / mean_edge))
    if rings:
        fg = morphological_close(A, fg, skin, rings)
    min_area = mrs * act_area
    comp = label_pieces(A, np.where(fg, 0, -1))
    if (comp >= 0).any():
        sizes = np.bincount(comp[comp >= 0], weights=area[comp >= 0])
        fg = fg & (comp >= 0) & (sizes[np.maximum(comp, 0)] >= min_area)

    report(0.5, "fine regions")
    # relative motion: each shape scaled to its own peak, so broad strong shapes
    # (jawOpen) do not swallow the local ones (mouthSmile) that peak elsewhere
    rel = mags / np.maximum(mags[:, skin].max(axis=1, initial=0.0), 1e-30)[:, None]
    mirror = _mirror_maps(model, skin, mid, diag) if split_midline else None
    if mirror is not None:
        # a mirror-symmetric face: average each vertex with its mirror image so
        # near-ties between shapes (the targets are symmetric only to ~1e-2 dm)
        # break the same way on both sides
        vmap, kmap = mirror
        rel = 0.5 * (rel + rel[kmap][:, vmap])
    dom = np.argmax(rel, axis=0).astype(np.int64)
    # side of the mid-plane: 0 = -x, 1 = on it (within 1e-4 of the face size), 2 = +x
    side3 = (np.sign(np.where(np.abs(V[:, 0] - mid) <= 1e-4 * diag, 0.0, V[:, 0] - mid)) + 1).astype(np.int8)
    key = dom * 3 + (side3 if split_midline else 0)
    lab0 = label_pieces(A, np.where(fg, key, -1))
    A1 = (A + sp.identity(n, dtype=np.int8, format="csr")).tocsr()
    lab0 = mode_filter(A1, lab0, 2)
    if split_midline:
        lab0 = label_pieces(A, np.where(lab0 >= 0, lab0 * 3 + side3, -1))
    lab0 = absorb_small_pieces(A, lab0, area, min_area, side3 if split_midline else None)
    if keep_features:
        lab0 = _keep_features_whole(A, lab0, rel, skin, side3, area, act_area, min_area)
    R0 = int(lab0.max()) + 1 if (lab0 >= 0).any() else 0

    report(0.7, "hierarchy")
    # motion energy per shape of every piece: E[r, k] = sum_v area_v rel_k(v)^2
    fidx = np.flatnonzero(lab0 >= 0)
    P = sp.csr_matrix((area[fidx], (lab0[fidx], np.arange(fidx.size))), shape=(R0, fidx.size))
    feats = np.asarray(P @ (rel[:, fidx] ** 2).T)
    wpiece = np.asarray(P.sum(axis=1)).ravel()
    C = piece_adjacency(A, lab0, R0)
    counts: list[int] = []
    c = R0
    for _ in range(levels - 1):
        c = max(1, round(c * coarsen))
        counts.append(c)
    pmirror = None
    if mirror is not None and R0:
        # mirror piece = the piece holding the mirror images of most of its vertices
        M = sp.csr_matrix((area[fidx], (lab0[fidx], np.maximum(lab0[mirror[0][fidx]], 0))), shape=(R0, R0))
        pmirror = np.asarray(M.argmax(axis=1)).ravel().astype(np.int64)
    merges = _merge_by_motion(C, feats, wpiece, counts, pmirror) if R0 else [np.zeros(0, np.int64) for _ in counts]
    skin_maps = [np.arange(R0, dtype=np.int64), *merges]  # fine piece -> region of each level

    report(0.85, "overlap weights and names")
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
    side_sign = _side_sign(model, skin, mid)
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
            stem = _region_stem(energy, groups)
            x = V[vv, 0] - mid
            xc = float((x * area[vv]).sum() / area[vv].sum())
            if x.min() < -half_tol and x.max() > half_tol:
                side = ""  # spans the mid-plane
            else:
                side = "_L" if xc * side_sign > 0 else "_R"
            names.append(stem + side)
            kinds.append("skin")
            heights.append(-float((V[vv, 1] * area[vv]).sum() / area[vv].sum()))
        names = list(_unique_names(names, heights))
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
            names.append(_rigid_name(model.component_names[ci], part_roles[ci]))
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
        names_out.append(_unique_names(names))
        kinds_out.append(tuple(kinds))
        drivers_out.append(tuple(drivers))

    parents: list[NDArray[np.int32]] = []
    for lv in range(levels - 1):
        fine, coarse = skin_maps[lv], skin_maps[lv + 1]
        Rs_f = int(fine.max()) + 1 if fine.size else 0
        Rs_c = int(coarse.max()) + 1 if coarse.size else 0
        par = np.zeros(Rs_f, np.int64)
        par[fine] = coarse
        n_rigid = len(rigid_comps)
        parents.append(np.concatenate([par, Rs_c + np.arange(n_rigid)]).astype(np.int32))

    report(1.0, f"{R0} fine regions in {time.perf_counter() - t0:.2f} s")
    return Regions(
        labels=tuple(labels_out),
        weight_rows=tuple(rows_out),
        weight_cols=tuple(cols_out),
        weight_vals=tuple(vals_out),
        background=tuple(bg_out),
        names=tuple(names_out),
        parents=tuple(parents),
        kinds=tuple(kinds_out),
        drivers=tuple(drivers_out),
        deformation=D.astype(np.float32),
        threshold=t,
        threshold_value=thr,
        overlap_rings=int(overlap_rings),
    )


def _keep_features_whole(
    A: sp.csr_matrix,
    lab0: NDArray[np.int64],
    rel: NDArray[np.float32] | NDArray[np.float64],
    skin: NDArray[np.bool_],
    side3: NDArray[np.int8],
    area: NDArray[np.float64],
    act_area: float,
    min_area: float,
    *,
    strong: float = 0.5,
    max_support: float = 0.1,
    nested: float = 0.6,
    rounds: int = 2,
) -> NDArray[np.int64]:
    """Move fine-piece borders so that every local one-sided feature lies in one piece.

    A *feature* is a shape whose strong support ``S_k = {v on the skin: rel_k(v) >=
    strong}`` covers at most ``max_support`` of the moving skin area, at least 80 %
    of it on one side of the mid-plane. A feature whose support lies at least
    ``nested`` inside a larger feature's support (the outer brow inside the brow)
    belongs to that feature's family; the family's *home* is the piece of its side
    holding most of the largest member's support. Every vertex of some ``S_k``
    (background ones included, the mid-plane column excluded) moves to the home
    of the most local feature that holds it (the smallest support: the inner
    brow goes with the brow, whose support it is half of, not with the nose
    wrinkler, whose support it is a quarter of). Two rounds, the homes
    recomputed in between; pieces left disconnected split, and splinters below
    ``min_area`` are absorbed as in step 4.

    Returns
    -------
    (n,) int64
        Connected pieces 0..R-1, -1 background.
    """
    sided = skin & (side3 != 1)
    sup = (rel >= strong) & sided[None, :]
    areas = sup.astype(np.float64) @ area
    left = (sup & (side3 == 2)[None, :]).astype(np.float64) @ area
    one_sided = np.maximum(left, areas - left) >= 0.8 * areas
    feats = np.flatnonzero((areas > 0) & (areas <= max_support * act_area) & one_sided)
    lab = lab0.copy()
    if feats.size == 0 or not (lab >= 0).any():
        return lab
    S = sup[feats]
    fa = areas[feats]
    fside = np.where(left[feats] * 2 >= fa, 2, 0)
    # families: each feature points to the larger feature containing most of it
    inter = (S.astype(np.float64) * area[None, :]) @ S.T.astype(np.float64)
    contain = inter / fa[:, None]  # share of row's support inside column's
    np.fill_diagonal(contain, 0.0)
    contain[fa[:, None] >= fa[None, :]] = 0.0  # only into larger features
    parent = np.where(contain.max(axis=1) >= nested, np.argmax(contain, axis=1), np.arange(feats.size))
    root = parent.copy()
    for _ in range(feats.size):
        root = parent[root]
    order = np.argsort(fa, kind="stable")  # most local first
    rank = np.empty(feats.size, np.int64)
    rank[order] = np.arange(feats.size)
    for _ in range(rounds):
        R = int(lab.max()) + 1
        pside = np.full(R, 1, np.int64)
        fgv = np.flatnonzero((lab >= 0) & (side3 != 1))
        for sd in (0, 2):
            cnt = np.bincount(lab[fgv], weights=(side3[fgv] == sd).astype(np.float64), minlength=R)
            pside[cnt > 0] = sd
        home = np.full(feats.size, -1, np.int64)
        for i in np.unique(root):
            vv = np.flatnonzero(S[i] & (lab >= 0))
            vv = vv[pside[lab[vv]] == fside[i]]
            if vv.size:
                home[i] = int(np.argmax(np.bincount(lab[vv], weights=area[vv], minlength=R)))
        fhome = home[root]
        claim = np.where(S & (fhome >= 0)[:, None] & (side3[None, :] == fside[:, None]), rank[:, None], np.iinfo(np.int64).max)
        best = np.argmin(claim, axis=0)
        cols = np.flatnonzero(claim[best, np.arange(claim.shape[1])] < np.iinfo(np.int64).max)
        lab[cols] = fhome[best[cols]]
        lab = label_pieces(A, lab)
    # as in step 4: pieces keyed by side, the mid-plane column absorbed last
    lab = label_pieces(A, np.where(lab >= 0, lab * 3 + side3, -1))
    return absorb_small_pieces(A, lab, area, min_area, side3)


def feature_share(
    model: FaceModel, regions: Regions, shape: str, level: int, *, strong: float = 0.5
) -> tuple[float, float]:
    """How whole a shape's feature is on one level: the share of its strongly moving vertices in one region.

    Parameters
    ----------
    model : FaceModel
    regions : Regions
    shape : str
        A blendshape name.
    level : int
    strong : float
        Vertices moved by at least ``strong`` times the shape's largest
        displacement are its strongly moving ones.

    Returns
    -------
    best : float
        Fraction of them in the region holding most of them (Joshi's regions
        follow features: a brow, a lid, a mouth corner should be ≥ 0.7).
    background : float
        Fraction of them in the background.
    """
    lv = regions.check_level(level)
    mag = np.linalg.norm(model.shape(shape).delta, axis=1)
    sel = np.flatnonzero(mag >= strong * float(mag.max())) if mag.max() > 0 else np.zeros(0, np.intp)
    if sel.size == 0:
        return 0.0, 0.0
    lab = regions.labels[lv][sel]
    inside = lab[lab >= 0]
    best = int(np.bincount(inside).max()) if inside.size else 0
    return best / sel.size, float((lab < 0).mean())


def _region_stem(energy: NDArray[np.float64], groups: Sequence[str]) -> str:
    """Name stem from the ARKit groups with most motion energy ("mouth", "brow_eye").

    The second group joins the name when it has at least 60 % of the first's energy.
    """
    tot: dict[str, float] = {}
    for e, g in zip(energy, groups, strict=True):
        tot[g] = tot.get(g, 0.0) + float(e)
    ranked = sorted(tot.items(), key=lambda kv: -kv[1])
    stems = [_STEM.get(ranked[0][0], "region")]
    if len(ranked) > 1 and ranked[1][1] >= 0.6 * ranked[0][1] > 0:
        stems.append(_STEM.get(ranked[1][0], "region"))
    return "_".join(stems)


def _rigid_name(component: str, role: str) -> str:
    """Region name of a rigid part: from its role ("eyeball_L", "teeth_upper", "tongue")."""
    if role.startswith("eyeball"):
        side = role_side(role)
        if not side:  # both eyes in one component, or a side only the name tells
            c = component.lower()
            side = "_L" if re.search(r"left|(^|_)l($|_)", c) else "_R" if re.search(r"right|(^|_)r($|_)", c) else ""
        return "eyeball" + (side or "s")
    return role


def _check_fraction(
    name: str, value: Any, lo: float, hi: float, *, closed_hi: bool = False, open_lo: bool = False
) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise RegionError(f"{name} must be a number, got {value!r}") from None
    ok_lo = v > lo if open_lo else v >= lo
    ok_hi = v <= hi if closed_hi else v < hi
    if not (np.isfinite(v) and ok_lo and ok_hi):
        lo_b = "(" if open_lo else "["
        hi_b = "]" if closed_hi else ")"
        raise RegionError(f"{name} must be in {lo_b}{lo}, {hi}{hi_b}, got {value!r}")
    return v
