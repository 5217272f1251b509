"""Blend-region segmentation (Joshi et al. 2003 §2, §4): identities, tiny cases, the sample head."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

import workbench
from workbench.model import BlendShape, FaceModel
from workbench.regions import (
    RegionError,
    Regions,
    deformation_map,
    mesh_adjacency,
    segment_blend_regions,
)


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
    # the mass-normalised map of a uniform refinement keeps its scale; the raw one shrinks with area
    D = deformation_map(head)
    Draw = deformation_map(head, mass_normalized=False)
    skin = _skin(head)
    ratio = np.median(Draw[skin][Draw[skin] > 0]) / np.median(D[skin][D[skin] > 0])
    area = workbench.operators.mass_matrix(head.vertices, head.faces).diagonal()
    assert ratio == pytest.approx(np.median(area[skin]), rel=0.5)


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


def test_a_left_brow_shape_lands_in_one_region(head: FaceModel, regions: Regions) -> None:
    k = head.shape_names.index("browOuterUpLeft")
    mag = np.linalg.norm(head.deltas[k], axis=1)
    moved = mag > 0.5 * mag.max()
    for lv in range(regions.n_levels):
        labs = regions.labels[lv][moved]
        assert (labs >= 0).all()
        # only left-side regions at every level (fine levels split brow and lid) ...
        assert all("_L" in regions.names[lv][r] for r in set(labs.tolist()))
    # ... and a single region at the coarsest level
    assert len(set(regions.labels[2][moved].tolist())) == 1


def test_synthetic_left_only_shape_in_one_region() -> None:
    # a 12x12 grid: shape 'a' bumps the left half, 'b' the right half
    n = 13
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    V = np.stack([xs.ravel() - 6, ys.ravel(), np.zeros(xs.size)], axis=1)
    F = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            F += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]

    def bump(cx: float) -> np.ndarray:
        d = np.zeros((V.shape[0], 3), np.float32)
        d[:, 2] = np.exp(-((V[:, 0] - cx) ** 2 + (V[:, 1] - 6) ** 2) / 4.0)
        return d

    m = FaceModel(V, np.array(F), [BlendShape("browUpLeft", bump(3.5)), BlendShape("browUpRight", bump(-3.5))])
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
    m.set_slot("regions", regions, "Segment regions")
    assert m.regions is regions
    m.undo()
    assert m.regions is None
