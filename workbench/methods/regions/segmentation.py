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
   (:func:`~workbench.methods.regions.fine_pieces.keep_features_whole`): every local, one-sided shape's strong support
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

The stages after the threshold are modules of their own: the fine pieces
(step 4, :mod:`.fine_pieces`), the hierarchy (step 5, :mod:`.motion_merge`),
the weights, parts and names of each level (steps 6–7, :mod:`.level_weights`,
:mod:`.region_names`). The user edits of the result are in
:mod:`workbench.methods.regions.edits`; the
:class:`~workbench.methods.regions.hierarchy.Regions` value in
:mod:`workbench.methods.regions.hierarchy`; the mesh-graph operations in
:mod:`workbench.methods.regions.mesh_graph`.

Hand-written because no kept dependency segments a blendshape set: the graph
pieces use scipy (``csgraph.connected_components``, sparse products, ``cKDTree``)
and libigl's cotangent Laplacian; the greedy merge is a ~30-line loop over a few
dozen regions.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from workbench.geometry.operators import cotangent_laplacian, mass_matrix
from workbench.geometry.parts import ATTACHED_ROLES, RIGID_ROLES, model_part_roles
from workbench.methods.regions.fine_pieces import fine_pieces
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.level_weights import level_tables
from workbench.methods.regions.mesh_graph import label_pieces, mesh_adjacency, morphological_close
from workbench.methods.regions.motion_merge import level_maps

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = [
    "component_roles",
    "deformation_map",
    "feature_share",
    "segment_blend_regions",
]


Progress = Callable[[float, str], None] | None


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
    A1 = (A + sp.identity(n, dtype=np.int8, format="csr")).tocsr()
    fine = fine_pieces(model, A, A1, fg, skin, mags, area, act_area, min_area, mid, diag,
                       split_midline=split_midline, keep_features=keep_features)
    R0 = fine.count

    report(0.7, "hierarchy")
    skin_maps = level_maps(A, fine, area, levels, coarsen)

    report(0.85, "overlap weights and names")
    tables = level_tables(model, roles, skin, fine, skin_maps, A1, area, mags, mid, diag, int(overlap_rings))

    report(1.0, f"{R0} fine regions in {time.perf_counter() - t0:.2f} s")
    return Regions(
        labels=tables.labels,
        weight_rows=tables.weight_rows,
        weight_cols=tables.weight_cols,
        weight_vals=tables.weight_vals,
        background=tables.background,
        names=tables.names,
        parents=tables.parents,
        kinds=tables.kinds,
        drivers=tables.drivers,
        deformation=D.astype(np.float32),
        threshold=t,
        threshold_value=thr,
        overlap_rings=int(overlap_rings),
    )


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
