"""Loop subdivision operator (workbench.geometry.subdivision): stencils, identities, model transfer."""

from __future__ import annotations

from pathlib import Path

import igl
import numpy as np
import pytest
import scipy.sparse as sp

from workbench.core.polygons import Polygons
from workbench.geometry.subdivision import (
    loop_subdivision,
    subdivide_model,
    subdivided_vertex_count,
)
from workbench.model import BlendShape, FaceModel, ModelMetadata
from workbench.testing import grid_triangles, grid_vertices

HEAD_OBJ = Path(__file__).resolve().parent.parent / "sample_models" / "head" / "head.obj"

# unit square split along 0-2: an open mesh, every vertex on the boundary
SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])
# closed tetrahedron (valence 3 everywhere), outward orientation
TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
TET_F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def _edge_point_row(S: sp.csr_matrix, n: int, a: int, b: int) -> np.ndarray:
    """The unique edge-point row whose two heaviest parents are a and b."""
    D = S.toarray()[n:]
    hits = [r for r in D if r[a] >= 0.375 and r[b] >= 0.375]
    assert len(hits) == 1
    return hits[0]


def _grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """A bumpy open triangulated grid of nx x ny vertices (boundary + interior vertices)."""
    return grid_vertices(nx, ny, height=lambda x, y: 0.3 * np.sin(x) * np.cos(y)), grid_triangles(nx, ny)


def _two_components() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An open grid (label 0) and a closed tetrahedron (label 1): two components."""
    Vg, Fg = _grid(5, 4)
    V = np.concatenate([Vg, TET_V + np.array([10.0, 0.0, 0.0])])
    F = np.concatenate([Fg, TET_F + len(Vg)])
    labels = np.r_[np.zeros(len(Vg), np.int32), np.ones(4, np.int32)]
    return V, F, labels


# ----------------------------------------------------------------- stencils


def test_boundary_stencils_on_the_square():
    S, F1 = loop_subdivision(SQUARE_F, 4)
    assert isinstance(S, sp.csr_matrix) and S.dtype == np.float64
    assert S.shape == (4 + 5, 4)  # 5 edges
    assert F1.shape == (8, 3)
    D = S.toarray()
    # boundary vertex rule: 3/4 self, 1/8 each boundary neighbour (not the diagonal)
    np.testing.assert_allclose(D[0], [0.75, 0.125, 0.0, 0.125])
    np.testing.assert_allclose(D[1], [0.125, 0.75, 0.125, 0.0])
    # boundary edge point: midpoint
    np.testing.assert_allclose(_edge_point_row(S, 4, 0, 1), [0.5, 0.5, 0, 0])
    # interior edge 0-2: 3/8 ends, 1/8 opposite corners
    np.testing.assert_allclose(_edge_point_row(S, 4, 0, 2), [0.375, 0.125, 0.375, 0.125])


def test_interior_stencils_on_the_tetrahedron():
    S, F1 = loop_subdivision(TET_F, 4)
    D = S.toarray()
    # valence 3: beta = 3/16 (Loop and Warren agree), self 1 - 3 * 3/16
    np.testing.assert_allclose(D[0], [7 / 16, 3 / 16, 3 / 16, 3 / 16])
    np.testing.assert_allclose(_edge_point_row(S, 4, 0, 1), [3 / 8, 3 / 8, 1 / 8, 1 / 8])
    assert S.shape == (4 + 6, 4) and F1.shape == (16, 3)


def test_matches_igl_loop_positions():
    V, F = _grid(6, 5)
    S, F1 = loop_subdivision(F, len(V), levels=2)
    NV, NF = igl.loop(V, F.astype(np.int64), 2)
    np.testing.assert_allclose(S @ V, NV, atol=1e-12)
    np.testing.assert_array_equal(F1, NF)


def test_orientation_is_kept():
    S, F1 = loop_subdivision(TET_F, 4)
    W = S @ TET_V
    n_old = np.cross(
        TET_V[TET_F[:, 1]] - TET_V[TET_F[:, 0]], TET_V[TET_F[:, 2]] - TET_V[TET_F[:, 0]]
    )
    n_new = np.cross(W[F1[:, 1]] - W[F1[:, 0]], W[F1[:, 2]] - W[F1[:, 0]])
    centre_old, centre_new = TET_V.mean(0), W.mean(0)
    # outward before and after
    assert np.all(np.einsum("ij,ij->i", n_old, TET_V[TET_F[:, 0]] - centre_old) > 0)
    assert np.all(np.einsum("ij,ij->i", n_new, W[F1[:, 0]] - centre_new) > 0)


# --------------------------------------------------------------- identities


def test_rows_are_convex_and_affine_invariant():
    V, F, _ = _two_components()
    S, _ = loop_subdivision(F, len(V), levels=2)
    np.testing.assert_allclose(np.asarray(S.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert S.data.min() >= 0.0
    # subdividing a moved mesh = moving the subdivided mesh (any affine map)
    A = np.array([[0.8, -0.6, 0.1], [0.6, 0.8, 0.2], [0.0, 0.3, 1.5]])
    t = np.array([3.0, -2.0, 7.5])
    np.testing.assert_allclose(S @ (V @ A.T + t), (S @ V) @ A.T + t, atol=1e-10)


def test_old_vertex_rows_touch_only_the_one_ring():
    V, F = _grid(5, 5)
    S, _ = loop_subdivision(F, len(V))
    n = len(V)
    adj = sp.coo_matrix((np.ones(3 * len(F)), (F.ravel(), np.roll(F, -1, 1).ravel())), (n, n))
    adj = ((adj + adj.T) > 0).tocsr()
    for i in range(n):
        support = set(S[i].indices)
        ring = set(adj[i].indices) | {i}
        assert support <= ring
        assert i in support and S[i, i] >= 0.5  # the old vertex dominates its new position
    # interior vertex of valence 6: Warren/Loop beta = 1/16
    centre = 2 * 5 + 2
    np.testing.assert_allclose(S[centre, centre], 1 - 6 / 16)


def test_two_levels_equal_one_level_twice():
    V, F, _ = _two_components()
    S1, F1 = loop_subdivision(F, len(V), 1)
    S1b, F2b = loop_subdivision(F1, S1.shape[0], 1)
    S2, F2 = loop_subdivision(F, len(V), 2)
    np.testing.assert_array_equal(F2, F2b)
    assert abs(S2 - S1b @ S1).max() < 1e-14
    assert loop_subdivision(F, len(V), 0)[0].shape == (len(V), len(V))


def test_vertex_and_face_counts():
    V, F, _ = _two_components()
    n_edges = len(np.unique(np.sort(np.concatenate([F[:, :2], F[:, 1:], F[:, ::2]]), 1), axis=0))
    S, F1 = loop_subdivision(F, len(V))
    assert S.shape == (len(V) + n_edges, len(V))
    assert F1.shape == (4 * len(F), 3)
    assert F1.min() == 0 and F1.max() == S.shape[0] - 1
    for levels in (0, 1, 2, 3):
        S, F_l = loop_subdivision(F, len(V), levels)
        assert subdivided_vertex_count(F, len(V), levels) == S.shape[0]
        assert len(F_l) == 4**levels * len(F)


def test_unreferenced_vertices_stay_put():
    # vertex 2 is used by no triangle (libigl alone would crash on it)
    F = np.array([[0, 1, 3], [1, 4, 3]])
    V = np.array([[0, 0, 0], [1, 0, 0], [5, 5, 5], [0, 1, 0], [1, 1, 0]], dtype=float)
    S, F1 = loop_subdivision(F, 5)
    np.testing.assert_array_equal(S[2].toarray().ravel(), [0, 0, 1, 0, 0])
    assert 2 not in F1
    S_ref, _ = loop_subdivision(np.array([[0, 1, 2], [1, 3, 2]]), 4)
    keep = [0, 1, 3, 4]
    np.testing.assert_allclose((S @ V)[keep], (S_ref @ V[keep])[:4])
    np.testing.assert_allclose((S @ V)[5:], (S_ref @ V[keep])[4:])


@pytest.mark.parametrize(
    ("faces", "n", "message"),
    [
        (np.array([[0, 1, 2, 3]]), 4, r"\(m, 3\)"),
        (np.array([[0, 1, 5]]), 3, "outside 0..2"),
        (np.array([[0, 1, 1]]), 3, "repeats a vertex"),
        (np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]), 5, "edge-manifold"),
        (np.array([[0.0, 1.0, 2.0]]), 3, "integer"),
    ],
)
def test_bad_input_is_rejected(faces, n, message):
    with pytest.raises(ValueError, match=message):
        loop_subdivision(faces, n)


def test_bad_levels_are_rejected():
    with pytest.raises(ValueError, match="levels"):
        loop_subdivision(SQUARE_F, 4, levels=-1)


# --------------------------------------------------------------- the model


def _model() -> FaceModel:
    V, F, labels = _two_components()
    rng = np.random.default_rng(0)
    n = len(V)
    shapes = [
        BlendShape("jawOpen", rng.normal(size=(n, 3)), slider_min=-0.5, slider_max=1.5),
        BlendShape("eyeBlinkLeft", rng.normal(size=(n, 3)), mute=True),
        BlendShape("masked", rng.normal(size=(n, 3)), vertex_mask=rng.uniform(0, 1, n)),
    ]
    meta = ModelMetadata(name="toy", units="dm", provenance=({"source": "test"},))
    return FaceModel(
        V,
        F,
        shapes,
        component_labels=labels,
        component_names=["skin", "eye_left"],
        metadata=meta,
        weights={"jawOpen": 0.7},
    )


def test_subdivided_model_carries_everything():
    m = _model()
    S, F2 = loop_subdivision(m.faces, m.n_vertices, 2)
    m2 = subdivide_model(m, 2)
    assert m2.n_vertices == S.shape[0]
    np.testing.assert_array_equal(m2.faces, F2)
    assert m2.polygons.equals(Polygons.from_triangles(F2))
    np.testing.assert_allclose(m2.vertices, S @ m.vertices, atol=1e-12)
    for s, s2 in zip(m.shapes, m2.shapes, strict=True):
        assert (s2.name, s2.slider_min, s2.slider_max, s2.mute) == (
            s.name,
            s.slider_min,
            s.slider_max,
            s.mute,
        )
        assert s2.delta.dtype == np.float32
        np.testing.assert_allclose(s2.delta, S @ s.delta.astype(np.float64), rtol=1e-5, atol=1e-5)
        if s.vertex_mask is None:
            assert s2.vertex_mask is None
        else:
            np.testing.assert_allclose(s2.vertex_mask, S @ s.vertex_mask, atol=1e-6)
    assert dict(m2.weights) == dict(m.weights)
    assert m2.metadata.units == "dm" and m2.metadata.name == "toy"
    assert len(m2.metadata.provenance) == 2
    assert m2.metadata.provenance[-1]["operation"] == "loop_subdivision"
    assert m2.metadata.provenance[-1]["levels"] == 2


def test_evaluating_the_subdivided_model_equals_subdividing_the_evaluation():
    # the point of one shared operator: S(V + sum w D) = SV + sum w SD
    m = _model()
    m.set_weights({"jawOpen": 0.3, "eyeBlinkLeft": 1.0})  # eyeBlinkLeft is muted
    m2 = subdivide_model(m, 1)
    S, _ = loop_subdivision(m.faces, m.n_vertices, 1)
    np.testing.assert_allclose(m2.evaluate(), S @ m.evaluate().astype(np.float64), atol=2e-5)
    # a vertex mask multiplies the delta, so it is not linear: S(mask * D) != (S mask) * (S D)
    # in general; the subdivided mask is kept editable rather than baked into the delta
    m.set_weights({"masked": 0.8})
    m2.set_weights({"masked": 0.8})
    masked = m2.shape("masked")
    np.testing.assert_allclose(
        m2.evaluate(),
        S @ (m.evaluate() - 0.8 * m.shape("masked").effective_delta()).astype(np.float64)
        + 0.8 * masked.vertex_mask[:, None] * masked.delta,
        atol=2e-5,
    )


def test_component_labels_follow_their_parents():
    m = _model()
    m2 = subdivide_model(m, 2)
    assert m2.component_names == m.component_names
    S, _ = loop_subdivision(m.faces, m.n_vertices, 2)
    S = S.tocsr()
    parent = m.component_labels[S.indices]
    row = np.repeat(np.arange(S.shape[0]), np.diff(S.indptr))
    assert np.array_equal(parent, m2.component_labels[row])  # every parent has the new label
    # old vertices keep their label (rows 0..n-1 are the old vertices)
    np.testing.assert_array_equal(m2.component_labels[: m.n_vertices], m.component_labels)
    # grid 5x4: (V, E, F) = (20, 43, 24) -> (63, 158, 96) -> 221 vertices;
    # tetrahedron: (4, 6, 4) -> (10, 24, 16) -> 34 vertices
    np.testing.assert_array_equal(np.bincount(m2.component_labels), [221, 34])


def test_component_labels_must_be_constant_per_piece():
    V, F = _grid(3, 3)
    labels = np.zeros(len(V), np.int32)
    labels[0] = 1  # a label that cuts through a connected piece
    m = FaceModel(V, F, component_labels=labels, component_names=["a", "b"])
    with pytest.raises(ValueError, match="mixes component labels"):
        subdivide_model(m, 1)


@pytest.mark.skipif(not HEAD_OBJ.is_file(), reason="sample head not built")
def test_sample_head_one_level():
    verts, polys, comp = [], [], []
    for line in HEAD_OBJ.read_text().splitlines():
        if line.startswith("v "):
            verts.append([float(t) for t in line.split()[1:]])
        elif line.startswith("g "):
            comp.append(line.split()[1])
        elif line.startswith("f "):
            polys.append([int(t) - 1 for t in line.split()[1:]])
    V = np.array(verts)
    F, _ = Polygons.from_lists(polys).triangulate()
    S, _ = loop_subdivision(F, len(V), 1)
    # every vertex is on a triangle, so n_new = n + edges, and the mesh is edge-manifold
    assert S.shape[0] == subdivided_vertex_count(F, len(V), 1)
    assert 18_000 < S.shape[0] < 22_000
    np.testing.assert_allclose(np.asarray(S.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    # smoothing shrinks a little, it does not blow up: bounding boxes agree to ~1 cm (0.1 dm)
    W = S @ V
    np.testing.assert_allclose(W.min(0), V.min(0), atol=0.1)
    np.testing.assert_allclose(W.max(0), V.max(0), atol=0.1)
