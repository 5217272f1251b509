"""The generated test faces (workbench.testing): identities of every builder.

Each builder is checked by what must hold whatever the numbers: a warp of zero
strength is the identity, a linear warp maps the shapes linearly, a remesh
keeps the surface, a change of units keeps ``metres_per_unit * x``, renamed
shapes keep their deltas, split halves sum to the whole, a bust and a crop
leave the rest as it was, and every builder gives the same face for the same
seed.
"""

from __future__ import annotations

import igl
import numpy as np
import pytest
from scipy.spatial import cKDTree

import workbench
from workbench.arkit import canonical_arkit_name
from workbench.model import FaceModel
from workbench.testing import (
    GeneratedFace,
    LocalScale,
    SmoothWarp,
    add_bust,
    compose,
    cropped,
    cut_hole,
    foreign_face,
    grid_polygons,
    grid_quads,
    grid_triangles,
    grid_vertices,
    in_units,
    opened,
    permute_vertices,
    proportions_warp,
    random_warp,
    remeshed,
    rename_shape,
    renamed_shapes,
    renumbered,
    restyled_shapes,
    split_remesh,
    split_sides,
    unnamed_parts,
    warped,
    with_bust,
    with_hole,
)


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def face(head: FaceModel) -> GeneratedFace:
    return remeshed(head, seed=4, warp=random_warp(head.vertices, seed=4, degrees=10.0, unit=10.0), shapes=True)


def _skin_loops(model: FaceModel) -> list[np.ndarray]:
    F = np.asarray(model.faces, np.int64)
    lab = model.component_labels
    return [np.asarray(lp) for lp in igl.boundary_loop_all(F[lab[F[:, 0]] == 0])]


# ----------------------------------------------------------------------------- warps


def test_a_warp_of_zero_strength_is_the_identity(head: FaceModel) -> None:
    V = head.vertices
    for w in (random_warp(V, seed=3, strength=0.0, anisotropy=0.0), SmoothWarp(), proportions_warp(head),
              LocalScale(np.zeros((1, 3)), np.array([0.5]), np.array([1.0]), np.array([1.0]))):
        np.testing.assert_allclose(w(V), V, atol=1e-12)
    g = warped(head, random_warp(V, seed=3, strength=0.0, anisotropy=0.0))
    np.testing.assert_allclose(g.model.vertices, V, atol=1e-12)
    for s, t in zip(g.model.shapes, head.shapes, strict=True):
        assert s.name == t.name
        np.testing.assert_allclose(s.delta, t.delta, atol=1e-6)


def test_random_warps_are_seeded_and_symmetric_ones_commute_with_the_mirror(head: FaceModel) -> None:
    V = head.vertices
    a, b = random_warp(V, seed=1, anisotropy=0.1), random_warp(V, seed=1, anisotropy=0.1)
    np.testing.assert_array_equal(a(V), b(V))
    assert np.abs(random_warp(V, seed=2)(V) - a(V)).max() > 1e-3
    s = random_warp(V, seed=5, symmetric=True, strength=0.05, anisotropy=0.1)
    mid = 0.5 * (V[:, 0].min() + V[:, 0].max())

    def mirror(P: np.ndarray) -> np.ndarray:
        Q = P.copy()
        Q[:, 0] = 2 * mid - Q[:, 0]
        return Q

    np.testing.assert_allclose(s(mirror(V)), mirror(s(V)), atol=1e-12)
    assert np.abs(s(V) - V).max() > 0.01  # it does move


def test_compose_applies_in_order_and_multiplies_units() -> None:
    P = np.random.default_rng(0).normal(size=(50, 3))
    a = SmoothWarp(scale=np.array([2.0, 1.0, 1.0]), unit=10.0)
    b = SmoothWarp(translation=np.array([0.0, 1.0, 0.0]), unit=0.1)
    np.testing.assert_allclose(compose(a, b)(P), b(a(P)))
    np.testing.assert_allclose(compose(a)(P), a(P))
    assert compose(a, b).unit == pytest.approx(1.0) and compose(a, a).unit == pytest.approx(100.0)


def test_a_local_scale_is_exact_inside_and_still_outside() -> None:
    c = np.array([1.0, 2.0, 3.0])
    w = LocalScale(c[None], np.array([1.0]), np.array([2.0]), np.array([1.25]))
    rng = np.random.default_rng(1)
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    inside = c + d * rng.uniform(0, 1.0, (200, 1))
    outside = c + d * rng.uniform(2.0, 5.0, (200, 1))
    np.testing.assert_allclose(w(inside), c + 1.25 * (inside - c), atol=1e-12)
    np.testing.assert_array_equal(w(outside), outside)
    between = c + d * 1.5  # half-way: g = 1/2, so the radius grows by a half of 0.25
    np.testing.assert_allclose(np.linalg.norm(w(between) - c, axis=1), 1.5 * (1 + 0.125))
    with pytest.raises(ValueError, match="inner < outer"):
        LocalScale(c[None], np.array([2.0]), np.array([1.0]), np.array([1.1]))


def test_bigger_eyes_scale_the_eyeballs_about_their_centres(head: FaceModel) -> None:
    w = proportions_warp(head, eyes=1.2)
    V = head.vertices
    for name in ("eye_left", "eye_right"):
        E = V[head.component_vertices(name)]
        c = E.mean(0)
        np.testing.assert_allclose(w(E), c + 1.2 * (E - c), atol=1e-12)
    crown = V[[int(np.argmax(V[:, 1]))]]
    np.testing.assert_array_equal(w(crown), crown)
    jaw = proportions_warp(head, jaw=1.1)
    chin = int(np.argmax(np.linalg.norm(head.shape("jawOpen").delta, axis=1)))
    assert np.linalg.norm(jaw(V[[chin]]) - V[chin]) > 0
    np.testing.assert_array_equal(jaw(crown), crown)


# ----------------------------------------------------------------------------- meshes


def test_a_remesh_keeps_the_surface(head: FaceModel) -> None:
    V, F = head.vertices, np.asarray(head.faces, np.int64)
    V2, F2, W = split_remesh(V, F, seed=2)
    np.testing.assert_allclose(W @ V, V2)
    np.testing.assert_allclose(np.asarray(W.sum(axis=1)).ravel(), 1.0)
    on_old, *_ = igl.point_mesh_squared_distance(V2, V, F)
    assert np.sqrt(on_old).max() < 1e-9  # every new vertex on the old surface
    edge = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    back, *_ = igl.point_mesh_squared_distance(V, V2, F2)
    assert np.sqrt(back).max() < edge  # and the old vertices near the new one (it cuts corners a little)


def test_permuted_vertices_are_the_same_mesh() -> None:
    V = grid_vertices(5, 4, height=lambda x, y: np.sin(x) * y)
    F = grid_triangles(5, 4)
    order, F2 = permute_vertices(F, V.shape[0], seed=3)
    assert sorted(order.tolist()) == list(range(V.shape[0])) and not np.array_equal(order, np.arange(V.shape[0]))
    back = order[F2]  # the old ids of every new triangle, same corner order
    canon = {tuple(np.roll(t, -int(np.argmin(t)))) for t in F.tolist()}
    assert {tuple(np.roll(t, -int(np.argmin(t)))) for t in back.tolist()} == canon


def test_a_hole_removes_the_ball_and_nothing_else() -> None:
    V, F = grid_vertices(9), grid_triangles(9)
    V2, F2, kept = cut_hole(V, F, [4.0, 4.0, 0.0], 1.5)
    np.testing.assert_array_equal(V2, V[kept])
    assert (np.linalg.norm(V2 - [4.0, 4.0, 0.0], axis=1) >= 1.5).all()
    assert set(kept.tolist()) == set(np.flatnonzero(np.linalg.norm(V - [4.0, 4.0, 0.0], axis=1) >= 1.5).tolist())
    assert F2.max() == V2.shape[0] - 1


def test_a_bust_hangs_below_the_loop_with_the_same_orientation() -> None:
    V, F = grid_vertices(5, 5, x=(-1.0, 1.0), y=(-1.0, 1.0)), grid_triangles(5)
    # roll the grid into an open tube along z ("up"): its bottom row is a loop
    ang = np.pi * (V[:, 0] + 1.0) * 0.999
    tube = np.stack([np.cos(ang), np.sin(ang), V[:, 1]], 1)
    loop = np.flatnonzero(V[:, 1] == -1.0)
    V2, F2 = add_bust(tube, F, loop, rings=3, up=(0.0, 0.0, 1.0))
    np.testing.assert_array_equal(V2[: len(tube)], tube)
    assert (V2[len(tube):, 2] < -1.0).all()
    half = np.concatenate([F2[:, [0, 1]], F2[:, [1, 2]], F2[:, [2, 0]]])
    assert len({tuple(e) for e in half.tolist()}) == len(half)  # no half-edge twice: one orientation


# ----------------------------------------------------------------------------- faces


def test_a_linear_warp_maps_the_true_shapes_linearly(head: FaceModel) -> None:
    R = SmoothWarp.rotation_xyz([10, -20, 30])
    lin = SmoothWarp(scale=np.array([1.1, 0.9, 1.0]), rotation=R, unit=100.0, translation=np.array([1.0, 2.0, 3.0]))
    g = remeshed(head, seed=1, warp=lin)
    assert g.model.metadata.units == "mm" and g.model.shapes == ()
    np.testing.assert_allclose(g.model.vertices, lin(g.W @ head.vertices))
    A = 100.0 * R @ np.diag([1.1, 0.9, 1.0])
    for name in ("jawOpen", "eyeBlinkLeft"):
        np.testing.assert_allclose(g.truth(name), (g.W @ head.shape(name).delta.astype(np.float64)) @ A.T, atol=1e-9)


def test_true_shapes_poses_and_places_agree(head: FaceModel, face: GeneratedFace) -> None:
    m = face.model
    assert m.metadata.units == "cm" and len(m.shapes) == len(head.shapes)
    for name in ("jawOpen", "mouthSmileLeft"):
        np.testing.assert_allclose(m.shape(name).delta, face.truth(name), atol=1e-5)
        np.testing.assert_allclose(face.pose({name: 1.0}) - m.vertices, face.truth(name), atol=1e-9)
    np.testing.assert_allclose(face.pose({}), m.vertices)
    both = face.pose({"jawOpen": 0.5, "eyeBlinkLeft": 1.0})
    p = face.points + face.W @ (0.5 * head.shape("jawOpen").delta + head.shape("eyeBlinkLeft").delta)
    np.testing.assert_allclose(both, face.warp(p), atol=1e-9)
    # a whole source mesh carried over is the pose of the same displacement
    sculpt = head.vertices + 0.5 * head.shape("jawOpen").delta + head.shape("eyeBlinkLeft").delta
    np.testing.assert_allclose(face.displaced(sculpt - head.vertices), both, atol=1e-9)
    np.testing.assert_allclose(face.displaced(np.zeros_like(head.vertices)), m.vertices, atol=1e-12)
    tip = int(np.argmax(head.vertices[:, 2]))
    np.testing.assert_allclose(face.place([tip]), face.warp(head.vertices[[tip]]))
    assert face.on_source.all()


def test_a_retriangulated_rig_cuts_every_quad_along_its_other_diagonal(head: FaceModel) -> None:
    g = warped(head, retriangulate=True)
    np.testing.assert_array_equal(g.model.vertices, head.vertices)
    old, new = np.sort(head.faces, axis=1), np.sort(g.model.faces, axis=1)
    assert len(new) == len(old)
    quads = head.polygons.sizes == 4
    tri_of_quad = np.repeat(quads, head.polygons.sizes - 2)
    shared = {tuple(t) for t in old[tri_of_quad].tolist()} & {tuple(t) for t in new.tolist()}
    assert not shared
    for s in head.shapes[:5]:
        np.testing.assert_array_equal(g.model.shape(s.name).delta, s.delta)


def test_renumbering_permutes_everything_consistently(face: GeneratedFace) -> None:
    r = renumbered(face, seed=9)
    _, order = cKDTree(face.points).query(r.points)  # new vertex -> old vertex
    np.testing.assert_array_equal(r.points, face.points[order])
    assert not np.array_equal(order, np.arange(order.size))
    np.testing.assert_allclose(r.truth("jawOpen"), face.truth("jawOpen")[order])
    np.testing.assert_array_equal(r.model.component_labels, face.model.component_labels[order])
    np.testing.assert_allclose(r.model.shape("jawOpen").delta, face.model.shape("jawOpen").delta[order])
    assert len(r.model.faces) == len(face.model.faces)


def test_a_change_of_units_keeps_metres(head: FaceModel, face: GeneratedFace) -> None:
    mm = in_units(head, "mm")
    assert mm.metadata.units == "mm"
    np.testing.assert_allclose(mm.vertices * mm.metadata.metres_per_unit, head.vertices * head.metadata.metres_per_unit)
    np.testing.assert_allclose(mm.shape("jawOpen").delta * 1e-3, head.shape("jawOpen").delta * 0.1, atol=1e-7)
    back = in_units(mm, head.metadata.units)
    np.testing.assert_allclose(back.vertices, head.vertices, atol=1e-12)
    m = in_units(face, "m")  # a generated face: its truth follows
    np.testing.assert_allclose(m.model.vertices, face.model.vertices * 0.01)
    np.testing.assert_allclose(m.truth("jawOpen"), face.truth("jawOpen") * 0.01, atol=1e-12)
    np.testing.assert_allclose(m.warp(m.points), m.model.vertices)


def test_renamed_shapes_keep_their_deltas(head: FaceModel) -> None:
    for style in ("LR", "pascal", "snake", "namespaced"):
        r = renamed_shapes(head, style)
        for s, t in zip(r.shapes, head.shapes, strict=True):
            assert s.name == rename_shape(t.name, style) and canonical_arkit_name(s.name) == t.name
            assert s.delta is t.delta or np.array_equal(s.delta, t.delta)
    assert rename_shape("eyeBlinkLeft", "LR") == "eyeBlink_L" and rename_shape("jawOpen", "pascal") == "JawOpen"
    assert rename_shape("mouthSmileRight", "snake") == "mouth_smile_right"
    two = renamed_shapes(head, ("pascal", "numbered"))
    assert two.shape_names[head.shape_names.index("jawOpen")] == "JawOpen.001"
    table = renamed_shapes(head, {"jawOpen": "mouthOpen"})
    assert "mouthOpen" in table.shape_names and "jawOpen" not in table.shape_names
    np.testing.assert_array_equal(table.shape("mouthOpen").delta, head.shape("jawOpen").delta)
    with pytest.raises(ValueError, match="unknown style"):
        rename_shape("jawOpen", "klingon")


def test_split_halves_sum_to_the_whole(head: FaceModel, face: GeneratedFace) -> None:
    s = split_sides(head, blend=0.1)
    sided = [n for n in head.shape_names if n.endswith(("Left", "Right"))]
    assert len(s.shapes) == 2 * len(head.shapes) - len(sided)
    x = head.vertices[:, 0]
    width = np.ptp(x)
    for name in ("jawOpen", "browInnerUp"):
        L, R = s.shape(name + "_L").delta, s.shape(name + "_R").delta
        np.testing.assert_allclose(L + R, head.shape(name).delta, atol=1e-6)
        assert not L[x < -0.05 * width].any() and not R[x > 0.05 * width].any()  # the subject's left is +x
    np.testing.assert_array_equal(s.shape("eyeBlinkLeft").delta, head.shape("eyeBlinkLeft").delta)
    g = split_sides(face, ["jawOpen"])
    np.testing.assert_allclose(g.model.shape("jawOpen_L").delta + g.model.shape("jawOpen_R").delta,
                               g.truth("jawOpen"), atol=1e-5)
    with pytest.raises(ValueError, match="unknown shapes"):
        split_sides(head, ["noSuchShape"])


def test_restyled_shapes_keep_names_and_bound_the_gain(head: FaceModel) -> None:
    same = restyled_shapes(head, gain=0.0, turn=0.0)
    assert same.shape_names == head.shape_names
    np.testing.assert_allclose(same.deltas, head.deltas, atol=1e-7)
    r = restyled_shapes(head, seed=3, gain=0.3, turn=0.5)
    np.testing.assert_array_equal(r.deltas, restyled_shapes(head, seed=3, gain=0.3, turn=0.5).deltas)
    old, new = np.linalg.norm(head.deltas, axis=2), np.linalg.norm(r.deltas, axis=2)
    moving = old > 1e-4
    ratio = new[moving] / old[moving]  # a turn keeps the length: only the gain changes it
    assert ratio.min() >= 0.7 - 1e-3 and ratio.max() <= 1.3 + 1e-3 and np.ptp(ratio) > 0.3
    assert np.abs(r.deltas - head.deltas).max() > 0.01


def test_unnamed_parts_keep_the_labels(head: FaceModel) -> None:
    u = unnamed_parts(head)
    assert u.component_names == [f"mesh_{i}" for i in range(len(head.component_names))]
    np.testing.assert_array_equal(u.component_labels, head.component_labels)
    one = unnamed_parts(head, merge=True)
    assert one.component_names == ["mesh"] and not one.component_labels.any()


def test_a_bust_adds_still_shoulders(head: FaceModel, face: GeneratedFace) -> None:
    b = with_bust(face, rings=5)
    n = face.model.n_vertices
    np.testing.assert_array_equal(b.model.vertices[:n], face.model.vertices)
    assert b.on_source[:n].all() and not b.on_source[n:].any()
    assert b.model.n_vertices > n
    np.testing.assert_array_equal(b.truth("jawOpen")[n:], 0.0)
    np.testing.assert_allclose(b.model.shape("jawOpen").delta[:n], face.model.shape("jawOpen").delta, atol=1e-6)
    neck = min(_skin_loops(face.model), key=lambda lp: face.points[lp, 1].mean())
    assert (b.points[n:, 1] < face.points[neck, 1].max()).all()  # below the neck (the source is +y up)
    assert len(_skin_loops(b.model)) == 1  # the new bottom ring is the only border


def test_a_cropped_face_keeps_only_the_front(face: GeneratedFace) -> None:
    c = cropped(face, depth=0.4)
    z = face.points[face.model.component_labels == 0, 2]  # the source looks toward +z
    assert (c.points[:, 2] >= z.max() - 0.4 * np.ptp(z)).all()
    assert c.model.n_vertices < face.model.n_vertices
    _, kept = cKDTree(face.points).query(c.points)
    np.testing.assert_allclose(c.truth("jawOpen"), face.truth("jawOpen")[kept], atol=1e-12)


def test_a_hole_in_a_generated_face(face: GeneratedFace) -> None:
    centre = np.array([-0.45, 7.9, 0.9])
    h = with_hole(face, centre, 0.25)
    assert (np.linalg.norm(h.points - centre, axis=1) >= 0.25).all()
    assert len(_skin_loops(h.model)) == len(_skin_loops(face.model)) + 1


def test_open_mouth_and_eyes_are_borders_of_the_skin(head: FaceModel) -> None:
    g = remeshed(head, seed=2)
    assert len(_skin_loops(g.model)) == 1  # the neck
    o = opened(g)
    loops = _skin_loops(o.model)
    assert len(loops) == 4  # the neck, the mouth, two eyes
    for name in ("eye_left", "eye_right"):
        E = head.vertices[head.component_vertices(name)]
        c, r = E.mean(0), np.linalg.norm(E - E.mean(0), axis=1).max()
        assert sum(np.linalg.norm(o.points[lp] - c, axis=1).max() < 1.2 * r for lp in loops) == 1
    # the mouth's border runs along both lips: jawOpen moves part of it (the lower lip) far more than the rest
    teeth = head.vertices[head.component_vertices("teeth_upper")]
    mouth = [lp for lp in loops if teeth[:, 1].min() - 0.2 < o.points[lp, 1].mean() < teeth[:, 1].max()]
    assert len(mouth) == 1
    move = np.linalg.norm(o.truth("jawOpen")[mouth[0]], axis=1)
    assert move.max() > 10 * np.quantile(move, 0.1)
    assert len(_skin_loops(opened(g, eyes=False).model)) == 2


def test_a_foreign_face_is_seeded_and_keeps_its_truth(head: FaceModel) -> None:
    a, b = foreign_face(head, seed=1), foreign_face(head, seed=1)
    np.testing.assert_array_equal(a.model.vertices, b.model.vertices)
    np.testing.assert_array_equal(a.model.faces, b.model.faces)
    assert a.model.shape_names == b.model.shape_names
    m = a.model
    assert m.metadata.units == "cm" and m.component_names[0] == "mesh_0"
    assert "eyeBlink_L" in m.shape_names and "jawOpen_L" in m.shape_names and "jawOpen" not in m.shape_names
    np.testing.assert_allclose(m.shape("eyeBlink_L").delta, a.truth("eyeBlinkLeft"), atol=1e-5)
    np.testing.assert_allclose(m.shape("jawOpen_L").delta + m.shape("jawOpen_R").delta, a.truth("jawOpen"), atol=1e-5)
    assert len(_skin_loops(m)) == 4  # the bust's bottom, the mouth, two eyes
    c = foreign_face(head, seed=2)
    assert c.model.n_vertices != m.n_vertices or np.abs(c.model.vertices - m.vertices).max() > 0.1
    # shoulders: a number of rings adds still skin below the neck; none leaves the neck open
    ring = foreign_face(head, seed=1, bust=4)
    more = foreign_face(head, seed=1, bust=24)
    bare = foreign_face(head, seed=1, bust=False)
    assert bare.model.n_vertices < ring.model.n_vertices < more.model.n_vertices
    assert (~bare.on_source).sum() < (~ring.on_source).sum() < (~more.on_source).sum()
    np.testing.assert_allclose(more.truth("jawOpen")[~more.on_source], 0.0)


# ----------------------------------------------------------------------------- grids


def test_grids_are_row_major_and_counter_clockwise() -> None:
    V = grid_vertices(4, 3, x=(0.0, 3.0), y=(10.0, 12.0))
    np.testing.assert_array_equal(V[2 * 4 + 1], [1.0, 12.0, 0.0])  # vertex (i, j) = (1, 2)
    F = grid_triangles(4, 3)
    assert F.shape == (2 * 3 * 2, 3)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert (n[:, 2] > 0).all() and np.allclose(np.abs(n[:, 2]).sum() / 2, 3.0 * 2.0)
    Q = grid_quads(4, 3)
    assert Q.shape == (6, 4) and set(Q.ravel().tolist()) == set(range(12))
    V2, P = grid_polygons(3, 2)  # cells, not vertices
    assert V2.shape == (12, 3) and len(P) == 6
    np.testing.assert_array_equal(P.indices.reshape(-1, 4), grid_quads(4, 3))
    with pytest.raises(ValueError, match="at least 2"):
        grid_vertices(1, 3)
