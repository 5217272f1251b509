"""Blend-region segmentation (Joshi et al. 2003 §2, §4): identities, tiny cases, the sample head."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest
import scipy.sparse as sp
from grid_meshes import two_bump_grid
from scipy.sparse.csgraph import connected_components

import workbench
from workbench.methods.regions.blend import RegionState
from workbench.methods.regions.hierarchy import RegionError, Regions
from workbench.methods.regions.mesh_graph import mesh_adjacency
from workbench.methods.regions.segmentation import deformation_map, segment_blend_regions
from workbench.model import BlendShape, FaceModel


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def regions(head: FaceModel) -> Regions:
    return segment_blend_regions(head, 0.25)


def _skin(model: FaceModel) -> np.ndarray:
    return model.component_labels == model.component_names.index("skin")


def test_mesh_adjacency_of_one_triangle() -> None:
    A = mesh_adjacency(np.array([[0, 1, 2]]), 4)
    assert A.toarray().tolist() == [[0, 1, 1, 0], [1, 0, 1, 0], [1, 1, 0, 0], [0, 0, 0, 0]]


def test_deformation_map_zero_for_translation_and_positive_for_a_bump(tiny_model: FaceModel) -> None:
    # a shape translating every vertex has zero Laplacian; 'up' lifts the centre only
    V = tiny_model.vertices
    move = np.tile(np.array([[0.3, -0.2, 0.1]], np.float32), (V.shape[0], 1))
    bump = np.zeros_like(move)
    bump[4, 2] = 1.0
    m = FaceModel(V, tiny_model.faces, [BlendShape("move", move)])
    assert np.allclose(deformation_map(m), 0.0, atol=1e-9)
    m2 = FaceModel(V, tiny_model.faces, [BlendShape("move", move), BlendShape("bump", bump)])
    D = deformation_map(m2)
    assert D[4] == D.max() and D[4] > 0
    # mass-normalised vs not: same ordering role, different units (L D vs M^-1 L D)
    D_raw = deformation_map(m2, mass_normalized=False)
    assert D_raw[4] > 0 and not np.allclose(D_raw, D)


def test_deformation_map_is_resolution_independent_with_mass_normalisation(head: FaceModel) -> None:
    # One Loop level (samples.py): the first n vertices of the 25k head are the base
    # head's vertices (smoothed in place, same ids and components), so the two maps
    # can be compared vertex by vertex. The pointwise map M^-1 L d keeps its scale;
    # the integrated L d scales with the vertex area, which one level divides by ~4.
    fine = workbench.load_sample("head", resolution="25k")
    n = head.n_vertices
    assert fine.n_vertices > 3 * n
    np.testing.assert_array_equal(fine.component_labels[:n], head.component_labels)
    assert np.abs(fine.vertices[:n] - head.vertices).max() < 0.1  # the same places (dm)
    skin = _skin(head)

    def both(mass_normalized: bool) -> tuple[np.ndarray, np.ndarray]:
        D0 = deformation_map(head, mass_normalized=mass_normalized, mask=skin)
        D1 = deformation_map(fine, mass_normalized=mass_normalized, mask=_skin(fine))[:n]
        act = skin & (D0 > 0)
        return D0[act], D1[act]

    D0, D1 = both(True)
    ratio = D1 / D0
    # measured: median 1.004, 10-90 % of vertices within [0.87, 1.22]
    assert np.median(ratio) == pytest.approx(1.0, abs=0.05)
    assert np.mean((ratio > 0.75) & (ratio < 1.33)) > 0.8
    # the threshold picks the same value at t = 0.25, 0.5, 0.75 (measured within 4 %)
    for t in (0.25, 0.5, 0.75):
        assert np.quantile(D1, t) == pytest.approx(np.quantile(D0, t), rel=0.1), t
    # the un-normalised map fails both checks: it shrinks ~4x (measured median 0.246)
    R0, R1 = both(False)
    assert np.median(R1 / R0) == pytest.approx(0.25, abs=0.05)
    assert np.quantile(R1, 0.5) < 0.5 * np.quantile(R0, 0.5)


def test_regions_are_connected_on_the_skin(head: FaceModel, regions: Regions) -> None:
    A = mesh_adjacency(head.faces, head.n_vertices)
    skin = _skin(head)
    for lv in range(regions.n_levels):
        for r in range(regions.n_regions(lv)):
            core = regions.core(lv, r)
            assert core.size > 0
            if regions.kinds[lv][r] == "skin":
                core = core[skin[core]]  # lashes copy the label of the nearest skin vertex
            nc, _ = connected_components(A[core][:, core], directed=False)
            if regions.kinds[lv][r] == "skin":
                assert nc == 1, (lv, regions.names[lv][r])


def test_overlap_is_exactly_one_ring(head: FaceModel, regions: Regions) -> None:
    A = mesh_adjacency(head.faces, head.n_vertices)
    skin = _skin(head)
    lv = 0
    overlaps = 0
    for r in range(regions.n_regions(lv)):
        if regions.kinds[lv][r] != "skin":
            continue
        core = np.zeros(head.n_vertices, bool)
        core[regions.core(lv, r)] = True
        core &= skin  # lashes copy their nearest skin vertex; compare on the skin
        ring = (A @ core.astype(np.int32) > 0) & ~core & skin
        members = np.zeros(head.n_vertices, bool)
        members[regions.members(lv, r)] = True
        assert np.array_equal(members & skin, core | ring), regions.names[lv][r]
        overlaps += int((ring & (regions.labels[lv] >= 0)).sum())
    assert overlaps > 0  # neighbouring regions do overlap


def test_region_weights_partition_unity(regions: Regions) -> None:
    for lv in range(regions.n_levels):
        W = regions.weights_dense(lv)
        assert W.min() >= 0
        np.testing.assert_allclose(W.sum(axis=1), 1.0, atol=1e-6)
        # a vertex deep inside a core has weight 1 for its own region
        lab = regions.labels[lv]
        inside = np.flatnonzero((lab >= 0) & (W.max(axis=1) == 1.0))
        assert inside.size > 0
        assert np.all(W[inside, lab[inside]] == 1.0)


def test_threshold_is_monotonic_in_region_area(head: FaceModel) -> None:
    areas = []
    for t in (0.1, 0.3, 0.5, 0.7, 0.9):
        R = segment_blend_regions(head, t, levels=1)
        areas.append(int((R.labels[0][_skin(head)] >= 0).sum()))
        assert R.threshold == t
    assert all(a > b for a, b in itertools.pairwise(areas)), areas


def test_threshold_value_follows_the_sorted_map(head: FaceModel) -> None:
    R = segment_blend_regions(head, 0.5, levels=1)
    D = R.deformation[_skin(head)]
    # about half of the moving skin lies at or above the threshold value
    moving = D[D > 0]
    frac = float((moving >= R.threshold_value).mean())
    assert 0.4 < frac < 0.6


def test_hierarchy_levels_nest(regions: Regions) -> None:
    assert regions.n_levels == 3
    for lv in range(regions.n_levels - 1):
        fine, coarse = regions.labels[lv], regions.labels[lv + 1]
        par = regions.parents[lv]
        has = fine >= 0
        assert np.array_equal(coarse[has], par[fine[has]])
        assert np.array_equal(coarse >= 0, has)
        assert regions.n_regions(lv + 1) < regions.n_regions(lv)


def test_sample_head_region_names(regions: Regions) -> None:
    names0 = set(regions.names[0])
    assert {"eyeball_L", "eyeball_R", "tongue", "teeth_lower", "teeth_upper"} <= names0
    for stem in ("brow", "eye", "mouth", "cheek", "nose"):
        assert any(stem in nm for nm in names0), stem
    # mirror-symmetric face -> every _L region has its _R twin
    for nm in names0:
        if "_L" in nm:
            assert nm.replace("_L", "_R") in names0
    assert len(set(regions.names[2])) == regions.n_regions(2)


def test_a_left_brow_shape_lands_in_left_regions_and_one_region_when_coarse(
    head: FaceModel, regions: Regions
) -> None:
    # Step 4 of the segmentation keys every fine piece by its side of the mid-plane
    # (x = 0 on the sample head; the subject's left is +x), so a core holds no
    # vertex of the other side; only the mid-plane column (|x| <= 1e-4 of the face
    # size) may join a neighbour on either side. Coarse levels merge mirror pairs
    # and may straddle the mid-plane (the jaw, the mouth), but not where the brow is.
    skin = _skin(head)
    V = head.vertices
    tol = 1e-4 * float(np.linalg.norm(V[skin].max(0) - V[skin].min(0)))
    moved_by: dict[str, np.ndarray] = {}
    for name in ("browOuterUpLeft", "browOuterUpRight"):
        mag = np.linalg.norm(head.shape(name).delta, axis=1)
        moved_by[name] = np.flatnonzero(mag > 0.5 * mag.max())
    moved = moved_by["browOuterUpLeft"]
    assert moved.size >= 10 and skin[moved].all() and (V[moved, 0] > 0).all()
    for lv in range(regions.n_levels):
        labs = regions.labels[lv][moved]
        assert (labs >= 0).all(), lv  # strongly moved skin is never background
        for r in set(labs.tolist()):
            assert regions.kinds[lv][r] == "skin"
            core = regions.core(lv, r)
            assert V[core, 0].min() >= -tol, (lv, regions.names[lv][r])  # nothing on the right
            assert re.search(r"_L(_\d+)?$", regions.names[lv][r]), (lv, regions.names[lv][r])
        # the mirror shape's vertices lie in other regions at every level
        other = set(regions.labels[lv][moved_by["browOuterUpRight"]].tolist())
        assert not other & set(labs.tolist()), lv
    # on the coarsest level (the notebook's "coarse" view) the outer brow is one region
    assert len(set(regions.labels[regions.n_levels - 1][moved].tolist())) == 1


def test_synthetic_left_only_shape_in_one_region() -> None:
    # a 12x12 grid: shape 'a' bumps the left half, 'b' the right half
    m = two_bump_grid()
    R = segment_blend_regions(m, 0.3, levels=1, min_region_size=0.02)
    moved = np.linalg.norm(m.deltas[0], axis=1) > 0.5
    labs = R.labels[0][moved]
    assert (labs >= 0).all() and len(set(labs.tolist())) == 1
    assert R.names[0][labs[0]] == "brow_L"


def test_region_queries_and_rename(regions: Regions) -> None:
    r = regions.region_index(0, "eyeball_L")
    assert regions.regions_at(0, int(regions.core(0, r)[0])) == {r: 1.0}
    assert regions.ancestor(0, r, 2) == regions.region_index(2, "eyeball_L")
    R2 = regions.renamed(0, "eyeball_L", "left_eye")
    assert R2.names[0][r] == "left_eye" and regions.names[0][r] == "eyeball_L"
    with pytest.raises(RegionError, match="new_name"):
        regions.renamed(0, "eyeball_L", "eyeball_R")
    with pytest.raises(RegionError, match="level"):
        regions.n_regions(7)
    with pytest.raises(RegionError, match="region"):
        regions.core(0, "nope")


def test_regions_are_immutable(regions: Regions) -> None:
    with pytest.raises(ValueError):
        regions.labels[0][0] = 3
    with pytest.raises(AttributeError):
        regions.threshold = 0.5  # type: ignore[misc]


def test_weight_matrix_is_sparse_and_cached(regions: Regions) -> None:
    W = regions.weight_matrix(1)
    assert sp.issparse(W) and W is regions.weight_matrix(1)


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"threshold": 1.5}, "threshold"),
        ({"threshold": "x"}, "threshold"),
        ({"levels": 0}, "levels"),
        ({"coarsen": 0.0}, "coarsen"),
        ({"min_region_size": 1.0}, "min_region_size"),
        ({"overlap_rings": 0}, "overlap_rings"),
    ],
)
def test_bad_arguments_name_the_argument(head: FaceModel, kwargs: dict, word: str) -> None:
    with pytest.raises(RegionError, match=word):
        segment_blend_regions(head, **kwargs)


def test_model_without_shapes_is_refused(tiny_model: FaceModel) -> None:
    m = FaceModel(tiny_model.vertices, tiny_model.faces)
    with pytest.raises(RegionError, match="no blendshapes"):
        segment_blend_regions(m)
    with pytest.raises(RegionError, match="model"):
        segment_blend_regions("head")  # type: ignore[arg-type]


def test_stored_in_the_model_slot_is_undoable(head: FaceModel, regions: Regions) -> None:
    m = workbench.load_sample("head")
    m.set_slot("regions", RegionState(regions), "Segment regions")
    assert m.regions.regions is regions
    m.undo()
    assert m.regions.state is None


# --------------------------------------------------------------- user edits
from workbench.methods.regions.edits import (  # noqa: E402
    merge_regions,
    paint_region,
    recompute_region_weights,
    rename_region,
    split_region,
)
from workbench.methods.regions.topology import (  # noqa: E402
    RegionTopology,
    adjacent_regions,
    region_adjacency,
    region_topology,
)

_ARRAYS = ("labels", "weight_rows", "weight_cols", "weight_vals", "background", "parents")


@pytest.fixture(scope="module")
def topo(head: FaceModel) -> RegionTopology:
    return region_topology(head)


def assert_same_regions(a: Regions, b: Regions, names: bool = True) -> None:
    """Bit-exact equality of every array (and the tables)."""
    for f in _ARRAYS:
        for x, y in zip(getattr(a, f), getattr(b, f), strict=True):
            assert x.dtype == y.dtype and np.array_equal(x, y), f
    assert a.kinds == b.kinds
    if names:
        assert a.names == b.names and a.drivers == b.drivers


def assert_invariants(R: Regions, topo: RegionTopology) -> None:
    """What the segmentation guarantees: connected skin regions, nesting, one-ring overlaps, unity."""
    A, skin = topo.adjacency, topo.skin
    for lv in range(R.n_levels):
        W = R.weights_dense(lv)
        np.testing.assert_allclose(W.sum(axis=1), 1.0, atol=1e-6)
        for r in range(R.n_regions(lv)):
            if R.kinds[lv][r] != "skin":
                continue
            c = np.zeros(R.n_vertices, bool)
            c[R.core(lv, r)] = True
            c &= skin
            core = np.flatnonzero(c)
            assert core.size > 0, (lv, R.names[lv][r])
            assert connected_components(A[core][:, core], directed=False)[0] == 1, (lv, R.names[lv][r])
            ring = (A @ c.astype(np.int32) > 0) & ~c & skin
            members = np.zeros(R.n_vertices, bool)
            members[R.members(lv, r)] = True
            assert np.array_equal(members & skin, c | ring), (lv, R.names[lv][r])
    for lv in range(R.n_levels - 1):
        fine, coarse, par = R.labels[lv], R.labels[lv + 1], R.parents[lv]
        has = fine >= 0
        assert np.array_equal(coarse >= 0, has)
        assert np.array_equal(coarse[has], par[fine[has]])
    # attachments copy their nearest skin vertex on every level
    for lv in range(R.n_levels):
        assert np.array_equal(R.labels[lv][topo.attached], R.labels[lv][topo.nearest])


def _far_pair(R: Regions, topo: RegionTopology, level: int, region: str, axis: int) -> tuple[int, int]:
    core = R.core(level, region)
    core = core[topo.skin[core]]
    x = topo.vertices[core, axis]
    return int(core[np.argmin(x)]), int(core[np.argmax(x)])


def test_recomputing_the_weights_of_a_segmentation_is_bit_exact(regions: Regions, topo: RegionTopology) -> None:
    assert_same_regions(recompute_region_weights(regions, topo), regions)
    assert region_topology(workbench.load_sample("head")).n_vertices == regions.n_vertices


def test_rename_keeps_labels_and_weights(regions: Regions) -> None:
    e = rename_region(regions, 0, "mouth_L_2", "lip_corner_L")
    assert e.regions.names[0][regions.region_index(0, "mouth_L_2")] == "lip_corner_L"
    for f in _ARRAYS:
        for x, y in zip(getattr(e.regions, f), getattr(regions, f), strict=True):
            assert x is y or np.array_equal(x, y)
    assert all(np.array_equal(o, np.arange(regions.n_regions(lv))) for lv, o in enumerate(e.origins))


def test_merge_adjacent_regions(regions: Regions, topo: RegionTopology) -> None:
    a = regions.region_index(0, "mouth_L_2")
    b = adjacent_regions(regions, topo, 0, a)[0]
    e = merge_regions(regions, topo, 0, a, b)
    R = e.regions
    assert R.n_regions(0) == regions.n_regions(0) - 1
    keep = min(a, b)
    merged = np.flatnonzero((regions.labels[0] == a) | (regions.labels[0] == b))
    assert np.array_equal(np.flatnonzero(R.labels[0] == keep), merged)
    # name, drivers and weights of the larger region
    sizes = {r: int(((regions.labels[0] == r) & topo.skin).sum()) for r in (a, b)}
    big = max((a, b), key=lambda r: (sizes[r], -(r == b)))
    assert R.names[0][keep] == regions.names[0][big]
    assert R.drivers[0][keep] == regions.drivers[0][big]
    assert e.origins[0][keep] == big
    assert_invariants(R, topo)


def test_merge_across_coarse_parents_merges_the_parents_too(regions: Regions, topo: RegionTopology) -> None:
    C = region_adjacency(regions, topo, 0)
    assert np.array_equal(C, C.T) and np.all(np.diag(C) == 0)
    par = regions.parents[0]
    pairs = [(a, b) for a, b in zip(*np.nonzero(np.triu(C)), strict=True) if par[a] != par[b]]
    a, b = (int(x) for x in pairs[0])
    e = merge_regions(regions, topo, 0, a, b, name="merged")
    R = e.regions
    assert "merged" in R.names[0]
    assert R.n_regions(1) == regions.n_regions(1) - 1
    lab1 = R.labels[1]
    assert len(set(lab1[(regions.labels[1] == par[a]) | (regions.labels[1] == par[b])].tolist())) == 1
    assert_invariants(R, topo)


def test_merge_errors_name_the_argument(regions: Regions, topo: RegionTopology) -> None:
    a = regions.region_index(0, "brow_nose_L")
    far = regions.region_index(0, "jaw_R_1")
    with pytest.raises(RegionError, match="b: region 'jaw_R_1' does not touch 'brow_nose_L'"):
        merge_regions(regions, topo, 0, a, far)
    with pytest.raises(RegionError, match="b: cannot merge"):
        merge_regions(regions, topo, 0, a, "brow_nose_L")
    with pytest.raises(RegionError, match=r"a: .*rigid"):
        merge_regions(regions, topo, 0, "eyeball_L", a)
    with pytest.raises(RegionError, match="b: region 'nope'"):
        merge_regions(regions, topo, 0, a, "nope")
    with pytest.raises(RegionError, match="level"):
        merge_regions(regions, topo, 5, a, far)
    b = adjacent_regions(regions, topo, 0, a)[0]
    with pytest.raises(RegionError, match="name 'jaw_R_1' is already used"):
        merge_regions(regions, topo, 0, a, b, name="jaw_R_1")
    with pytest.raises(RegionError, match="topology"):
        merge_regions(regions, "mesh", 0, a, b)  # type: ignore[arg-type]


def test_split_then_merge_restores_the_partition_on_level_0(regions: Regions, topo: RegionTopology) -> None:
    r = regions.region_index(0, "cheek_eye_L")
    sa, sb = _far_pair(regions, topo, 0, "cheek_eye_L", 1)
    e = split_region(regions, topo, 0, r, sa, sb)
    R = e.regions
    assert R.names[0][r : r + 2] == ("cheek_eye_L_a", "cheek_eye_L_b")
    assert R.labels[0][sa] == r and R.labels[0][sb] == r + 1
    assert e.origins[0][r] == e.origins[0][r + 1] == r  # both halves inherit
    # geodesic Voronoi: the two halves partition the old core, both non-empty
    old = regions.labels[0] == r
    assert np.array_equal((R.labels[0] == r) | (R.labels[0] == r + 1), old)
    assert R.n_regions(1) == regions.n_regions(1)  # coarser levels unchanged
    assert np.array_equal(R.labels[1], regions.labels[1])
    assert_invariants(R, topo)
    back = merge_regions(R, topo, 0, r + 1, r, name="cheek_eye_L").regions
    assert_same_regions(back, regions)


def test_split_on_a_coarse_level_groups_children_and_merge_undoes_it(
    regions: Regions, topo: RegionTopology
) -> None:
    r = regions.region_index(2, "mouth_jaw")
    sa, sb = _far_pair(regions, topo, 2, "mouth_jaw", 1)  # the chin and the upper lip: two children
    e = split_region(regions, topo, 2, r, sa, sb, names=("jaw", "mouth"))
    R = e.regions
    assert R.names[2][r : r + 2] == ("jaw", "mouth")
    for lv in (0, 1):  # whole children: finer levels unchanged
        assert np.array_equal(R.labels[lv], regions.labels[lv])
    assert_invariants(R, topo)
    back = merge_regions(R, topo, 2, r, r + 1, name="mouth_jaw").regions
    assert_same_regions(back, regions)


def test_split_with_both_seeds_in_one_child_splits_the_child_first(
    regions: Regions, topo: RegionTopology
) -> None:
    lv0 = regions.region_index(0, "mouth_L_2")
    r1 = int(regions.parents[0][lv0])
    sa, sb = _far_pair(regions, topo, 0, "mouth_L_2", 1)
    e = split_region(regions, topo, 1, r1, sa, sb)
    R = e.regions
    assert R.n_regions(0) == regions.n_regions(0) + 1
    assert R.n_regions(1) == regions.n_regions(1) + 1
    assert R.labels[1][sa] != R.labels[1][sb] and R.labels[0][sa] != R.labels[0][sb]
    assert_invariants(R, topo)


def test_split_errors_name_the_argument(regions: Regions, topo: RegionTopology) -> None:
    sa, sb = _far_pair(regions, topo, 0, "brow_nose_L", 1)
    other = int(regions.core(0, "brow_nose_R")[0])
    with pytest.raises(RegionError, match=r"seeds_b: vertices .* not in the core of region 'brow_nose_L'"):
        split_region(regions, topo, 0, "brow_nose_L", sa, other)
    with pytest.raises(RegionError, match=r"seeds_b: vertices .* also in seeds_a"):
        split_region(regions, topo, 0, "brow_nose_L", [sa, sb], sb)
    with pytest.raises(RegionError, match="seeds_a must hold at least one vertex"):
        split_region(regions, topo, 0, "brow_nose_L", [], sb)
    with pytest.raises(RegionError, match="seeds_a: vertex ids must be in"):
        split_region(regions, topo, 0, "brow_nose_L", -3, sb)
    with pytest.raises(RegionError, match="region: 'eyeball_L' is a rigid part"):
        split_region(regions, topo, 0, "eyeball_L", sa, sb)
    with pytest.raises(RegionError, match=r"names\[1\] 'brow_nose_R' is already used"):
        split_region(regions, topo, 0, "brow_nose_L", sa, sb, names=("x", "brow_nose_R"))
    # seeds of one half on both sides of the other half's seed: that half is in two pieces
    core = regions.core(0, "brow_nose_L")
    core = core[topo.skin[core]]
    y = topo.vertices[core, 1]
    mid = int(core[np.argsort(y)[core.size // 2]])
    with pytest.raises(RegionError, match="seeds_a: the half around these seeds would be in 2 pieces"):
        split_region(regions, topo, 0, "brow_nose_L", [sa, sb], mid)


def _ring(R: Regions, topo: RegionTopology, level: int, r: int) -> np.ndarray:
    c = np.zeros(R.n_vertices, bool)
    c[R.core(level, r)] = True
    c &= topo.skin
    return np.flatnonzero((topo.adjacency @ c.astype(np.int32) > 0) & ~c & topo.skin)


def test_paint_assigns_vertices_and_keeps_regions_connected(regions: Regions, topo: RegionTopology) -> None:
    r = regions.region_index(0, "mouth_L_2")
    ring = _ring(regions, topo, 0, r)
    T = ring[topo.vertices[ring, 0] > 0][:12]  # on its side: the mid-plane column belongs to -x regions
    e = paint_region(regions, topo, 0, r, T)
    R = e.regions
    assert (R.labels[0][T] == r).all()
    for lv in (1, 2):  # the ancestors follow
        assert (R.labels[lv][T] == regions.ancestor(0, r, lv)).all()
    changed = np.flatnonzero(R.labels[0] != regions.labels[0])
    assert set(changed.tolist()) <= set(T.tolist()) | set(topo.attached.tolist())
    assert_invariants(R, topo)
    # painting on a coarse level: the painted vertices join a child of the region on finer levels
    r2 = regions.region_index(1, "mouth_L")
    T2 = _ring(regions, topo, 1, r2)
    T2 = T2[topo.vertices[T2, 0] > 0][:12]
    R2 = paint_region(regions, topo, 1, r2, T2).regions
    assert (R2.labels[1][T2] == r2).all()
    assert (R2.parents[0][R2.labels[0][T2]] == r2).all()
    assert_invariants(R2, topo)


def test_paint_erase_returns_vertices_to_the_background_on_every_level(
    regions: Regions, topo: RegionTopology
) -> None:
    r = regions.region_index(0, "cheek_eye_L")
    core = regions.core(0, r)
    core = core[topo.skin[core]]
    border = np.intersect1d(core, _ring(regions, topo, 0, regions.region_index(0, "mouth_L_2")))[:4]
    e = paint_region(regions, topo, 0, r, border, add=False)
    for lv in range(regions.n_levels):
        assert (e.regions.labels[lv][border] == -1).all()
    assert_invariants(e.regions, topo)


def test_paint_no_change_is_the_same_object_and_errors_name_vertices(
    regions: Regions, topo: RegionTopology
) -> None:
    r = regions.region_index(0, "mouth_L_2")
    core = regions.core(0, r)
    e = paint_region(regions, topo, 0, r, core[:5])
    assert e.regions is regions
    far = regions.core(0, "brow_nose_R")[:3]
    with pytest.raises(RegionError, match="vertices: 3 painted vertices do not touch region 'mouth_L_2'"):
        paint_region(regions, topo, 0, r, far)
    eye = regions.core(0, "eyeball_L")[:3]
    with pytest.raises(RegionError, match="vertices: none of them is on the segmented skin"):
        paint_region(regions, topo, 0, r, eye)
    with pytest.raises(RegionError, match="region: 'eyeball_L' is a rigid part"):
        paint_region(regions, topo, 0, "eyeball_L", core[:3])
    with pytest.raises(RegionError, match="vertices must be integer"):
        paint_region(regions, topo, 0, r, [0.5])
    # erasing a band across a region cuts it in two: refused
    q = regions.region_index(0, "cheek_eye_L")
    cq = regions.core(0, q)
    cq = cq[topo.skin[cq]]
    y = topo.vertices[cq, 1]
    band = cq[np.abs(y - np.median(y)) < 0.15 * np.ptp(y)]
    with pytest.raises(RegionError, match="vertices: painting would cut region 'cheek_eye_L'"):
        paint_region(regions, topo, 0, q, band, add=False)
