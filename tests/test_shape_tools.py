"""Shape tools (issue 15, item 9): symmetry map, split into halves, mirror of shapes, expressions and paint.

On the sample head and on faces it has never seen: the head with an
asymmetrically sculpted cheek (the mesh graph must find the partners the
positions lose) and the head re-triangulated at random and smoothly warped
(the graph is not symmetric, so the map must fall back to positions).
"""

from __future__ import annotations

import numpy as np
import pytest
from grid_meshes import grid_polygons

import workbench
from workbench.arkit import canonical_arkit_name, split_half_of
from workbench.core.polygons import Polygons
from workbench.core.shapes import ModelError
from workbench.methods.paint.painting import Brush, mirror_map
from workbench.methods.shapes.split import side_weights, split_delta, split_names
from workbench.methods.shapes.symmetry import (
    GEOMETRY,
    POSITIONS,
    TOPOLOGY,
    lateral_axis,
    symmetry_map,
)
from workbench.model import BlendShape, FaceModel, ModelMetadata


def head() -> FaceModel:
    return workbench.load_sample("head")


def with_mesh(base: FaceModel, vertices: np.ndarray, polygons: Polygons | None = None) -> FaceModel:
    """``base``'s shapes on other neutral positions and/or faces (an unseen face)."""
    polys = base.polygons if polygons is None else polygons
    return FaceModel(vertices, None, base.shapes, polygons=polys, component_labels=base.component_labels,
                     component_names=base.component_names, metadata=base.metadata)


def cheek_bump(V: np.ndarray) -> np.ndarray:
    """The head with its left cheek sculpted out (up to 0.9 mm, 550 vertices moved off symmetry)."""
    r = np.linalg.norm(V - np.array([0.5, 7.0, 1.0]), axis=1)
    bump = np.exp(-((r / 0.25) ** 2))
    out = V.copy()
    out[:, 2] += 0.08 * bump
    out[:, 0] += 0.03 * bump
    return out


def retriangulated(polys: Polygons, seed: int = 0) -> Polygons:
    """Every quad cut along a random diagonal (the left and right sides disagree about half the time)."""
    rng = np.random.default_rng(seed)
    tris = []
    for i in range(len(polys)):
        q = polys.indices[polys.offsets[i] : polys.offsets[i + 1]].tolist()
        if len(q) == 4 and rng.random() < 0.5:
            tris += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        elif len(q) == 4:
            tris += [[q[1], q[2], q[3]], [q[1], q[3], q[0]]]
        else:
            tris.append(q)
    return Polygons.from_lists(tris)


def symmetric_warp(V: np.ndarray) -> np.ndarray:
    """A smooth warp that keeps the mirror symmetry about x = 0 (odd in x, even elsewhere)."""
    x, y, z = V.T
    return np.stack([x * (1 + 0.1 * (y - 7)), y + 0.05 * x**2, z + 0.1 * np.sin(y)], axis=1)


def warped_head() -> FaceModel:
    base = head()
    return with_mesh(base, symmetric_warp(base.vertices), retriangulated(base.polygons))


# ------------------------------------------------------------------ symmetry map
def test_lateral_axis_follows_the_metadata() -> None:
    assert lateral_axis("+y", "+z") == (0, 1.0)  # the sample: subject's left at +x
    assert lateral_axis("+y", "-z") == (0, -1.0)  # facing -z: the left is -x
    assert lateral_axis("+z", "-y") == (0, 1.0)  # Blender's front view
    assert lateral_axis("+z", "+x") == (1, 1.0)
    with pytest.raises(ModelError, match="up_axis '\\+y' and front_axis '-y' must be different axes"):
        lateral_axis("+y", "-y")


def test_sample_head_map_is_an_involution_found_by_positions_and_edges() -> None:
    m = head()
    sym = m.shape_tools.symmetry()
    n = m.n_vertices
    assert np.array_equal(sym.map[sym.map], np.arange(n))
    assert sym.counts == {"positions": n, "topology": 0, "geometry": 0, "unmatched": 0}
    assert (sym.axis, sym.left_sign, sym.mid) == (0, 1.0, 0.0)
    assert sym.max_error == 0.0  # the sample is exactly symmetric
    # the paint brush's geometric mirror agrees
    np.testing.assert_array_equal(sym.map, mirror_map(m.vertices, 0.0))
    # a mid-plane vertex is its own partner, a left one has a right partner
    on_plane = np.flatnonzero(m.vertices[:, 0] == 0)
    assert on_plane.size and np.array_equal(sym.map[on_plane], on_plane)


def test_topology_finds_the_partners_of_an_asymmetric_cheek() -> None:
    base = head()
    want = base.shape_tools.symmetry().map
    V = cheek_bump(base.vertices)
    by_position = symmetry_map(V, base.polygons, mid=0.0, topology=False)
    assert by_position.unmatched_fraction > 0.15  # the sculpted cheek lost its partners
    sym = symmetry_map(V, base.polygons, mid=0.0)
    assert sym.method == "topology"
    assert sym.counts["topology"] > 1000 and sym.counts["unmatched"] == 0
    np.testing.assert_array_equal(sym.map, want)
    print("asymmetric cheek:", sym.summary())


def test_a_retriangulated_warped_head_falls_back_to_geometry() -> None:
    base = head()
    want = base.shape_tools.symmetry().map
    m = warped_head()
    sym = m.shape_tools.symmetry()
    assert sym.method == "geometry"
    assert sym.counts["geometry"] > 0.9 * m.n_vertices
    assert sym.unmatched_fraction == 0.0
    np.testing.assert_array_equal(sym.map, want)
    assert np.array_equal(sym.map[sym.map], np.arange(m.n_vertices))
    print("re-triangulated, warped:", sym.summary())


def test_unmatched_vertices_are_reported_and_mirror_onto_themselves() -> None:
    base = head()
    V = cheek_bump(base.vertices)
    tri = retriangulated(base.polygons)  # no symmetric graph and no symmetric positions on the cheek
    sym = symmetry_map(V, tri, mid=0.0)
    assert 0.05 < sym.unmatched_fraction < 0.2
    un = np.flatnonzero(sym.unmatched)
    assert np.array_equal(sym.map[un], un)
    assert np.array_equal(sym.map[sym.map], np.arange(len(V)))
    assert set(np.unique(sym.source)) <= {0, POSITIONS, TOPOLOGY, GEOMETRY}


# ------------------------------------------------------------------ split
def test_split_weights_are_a_smoothstep_band() -> None:
    x = np.linspace(-1.0, 1.0, 401)
    f = side_weights(x, 0.5)
    assert np.all(f[x <= -0.25] == 0.0) and np.all(f[x >= 0.25] == 1.0)
    assert f[200] == 0.5 and np.all(np.diff(f) >= 0)
    np.testing.assert_allclose(f + f[::-1], 1.0, atol=1e-15)  # f_R = 1 - f_L is its mirror image
    hard = side_weights(x, 0.0)
    assert set(np.unique(hard)) == {0.0, 0.5, 1.0}
    with pytest.raises(ModelError, match="falloff must be a finite width >= 0"):
        side_weights(x, -1.0)


def test_split_halves_sum_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    for scale in (1e-30, 1e-3, 1.0, 1e6):
        D = (rng.normal(size=(20000, 3)) * scale).astype(np.float32)
        f = rng.random(20000)
        f[:100] = 0.5
        dL, dR = split_delta(D, f)
        assert dL.dtype == dR.dtype == np.float32
        np.testing.assert_array_equal(dL + dR, D)
    # on every shape of the sample head, with the default band
    m = head()
    f = m.shape_tools.split_weights()
    for s in m.shapes:
        dL, dR = split_delta(s.delta, f)
        np.testing.assert_array_equal(dL + dR, s.delta, err_msg=s.name)


def test_split_names_are_read_as_halves() -> None:
    assert split_names("browInnerUp") == ("browInnerUp_L", "browInnerUp_R")
    assert split_half_of("browInnerUp_L") == ("browInnerUp", "left")
    assert split_half_of("jawOpen_R") == ("jawOpen", "right")
    # a shape standing for an ARKit pair gets Apple's spelling of the two sides
    assert split_names("mouthSmile") == ("mouthSmileLeft", "mouthSmileRight")
    assert canonical_arkit_name("mouthSmileLeft") == "mouthSmileLeft"
    assert split_names("my_custom") == ("my_custom_L", "my_custom_R")


def test_split_replaces_the_shape_by_halves_that_play_the_same() -> None:
    m = head()
    m.set_weights({"browInnerUp": 0.8, "jawOpen": 0.3})
    m.timeline.key_weights(0.0, ["browInnerUp"])
    m.set_weight("browInnerUp", 0.2)
    m.timeline.key_weights(1.0, ["browInnerUp"])
    before = m.evaluate().copy()
    before_at = m.evaluate_at(0.5).copy()
    whole = m.shape("browInnerUp").delta.copy()
    i = m.shape_names.index("browInnerUp")
    left, right = m.shape_tools.split("browInnerUp")
    assert (left, right) == ("browInnerUp_L", "browInnerUp_R")
    assert m.shape_names[i : i + 2] == [left, right] and "browInnerUp" not in m.shape_names
    dL, dR = m.shape(left).delta, m.shape(right).delta
    np.testing.assert_array_equal(dL + dR, whole)
    # the left half is zero beyond the band on the right, and the other way round
    band = m.shape_tools.default_falloff()
    x = m.vertices[:, 0]
    assert 0.05 < band < 0.15  # 5 % of a 1.76 dm head
    assert not np.any(dL[x < -band / 2]) and not np.any(dR[x > band / 2])
    assert np.any(dL[x > band / 2]) and np.any(dR[x < -band / 2])
    # weights and keys moved to both halves: the face plays as before
    assert m.weights[left] == m.weights[right] == pytest.approx(0.2)
    assert set(m.tracks.weight_tracks) == {left, right}
    np.testing.assert_allclose(m.evaluate(), before, atol=2e-6)
    np.testing.assert_allclose(m.evaluate_at(0.5), before_at, atol=2e-6)
    # one undo step each way
    assert m.undo() == "Split browInnerUp"
    assert m.shape_names[i] == "browInnerUp" and left not in m.shape_names
    np.testing.assert_array_equal(m.evaluate(), before)
    assert set(m.tracks.weight_tracks) == {"browInnerUp"}
    m.redo()
    np.testing.assert_array_equal(m.shape(left).delta, dL)


def test_split_keep_and_explicit_names_and_falloff() -> None:
    m = head()
    m.set_weight("jawOpen", 0.5)
    before = m.evaluate().copy()
    left, right = m.shape_tools.split("jawOpen", falloff=0.0, names=("jawL", "jawR"), keep=True)
    assert m.shape_names[-2:] != [left, right] and "jawOpen" in m.shape_names
    assert m.weights[left] == m.weights[right] == 0.0
    np.testing.assert_array_equal(m.evaluate(), before)
    x = m.vertices[:, 0]
    dL = m.shape(left).delta
    assert not np.any(dL[x < 0]) and np.array_equal(dL[x > 0], m.shape("jawOpen").delta[x > 0])


def test_split_errors_name_the_argument() -> None:
    m = head()
    with pytest.raises(KeyError, match="no blendshape named 'nope'"):
        m.shape_tools.split("nope")
    with pytest.raises(ModelError, match=r"names\[0\]: a blendshape named 'jawOpen' already exists"):
        m.shape_tools.split("browInnerUp", names=("jawOpen", "x"))
    with pytest.raises(ModelError, match="names must differ"):
        m.shape_tools.split("browInnerUp", names=("a", "a"))
    with pytest.raises(ModelError, match="falloff must be"):
        m.shape_tools.split("browInnerUp", falloff=float("nan"))
    m.paint.flood("browInnerUp", 0.5, vertices=np.arange(10))
    with pytest.raises(ModelError, match="'browInnerUp' is painted"):
        m.shape_tools.split("browInnerUp")
    m.shape_tools.split("browInnerUp", keep=True)  # keeping the original is fine
    assert not m.history.can_redo


# ------------------------------------------------------------------ mirror
def test_mirror_of_eye_blink_left_is_eye_blink_right() -> None:
    m = head()
    m.shape_tools.mirror("eyeBlinkLeft", target="blinkMirrored")
    got = m.shape("blinkMirrored").delta
    want = m.shape("eyeBlinkRight").delta
    err = float(np.abs(got - want).max())
    print(f"mirror(eyeBlinkLeft) vs eyeBlinkRight: max |error| {err:.3g} dm "
          f"(the shape moves {float(np.abs(want).max()):.3g} dm)")
    assert err <= 1e-6
    assert m.shape_names.index("blinkMirrored") == m.shape_names.index("eyeBlinkLeft") + 1
    # the other sided pairs of the sample: its targets are stored to 1e-3 dm, so most differ from
    # the mirror by one step; mouthSmile's sides really differ (1.1 mm at the lip corner)
    sym = m.shape_tools.symmetry()
    errors = {}
    for s in m.shapes:
        if s.name.endswith("Left"):
            other = m.shape(s.name[: -len("Left")] + "Right").delta
            errors[s.name[: -len("Left")]] = float(np.abs(sym.mirror_vectors(s.delta) - other).max())
    print("mirror(...Left) vs ...Right, max |error| in dm:", {k: round(v, 4) for k, v in errors.items()})
    assert len(errors) == 20 and max(errors.values()) <= 0.0115
    assert sorted(errors.values())[10] <= 0.001 + 1e-6


@pytest.mark.parametrize("which", ["sample", "warped"])
def test_mirror_of_a_mirror_is_the_identity(which: str) -> None:
    m = head() if which == "sample" else warped_head()
    sym = m.shape_tools.symmetry()
    for s in m.shapes:
        twice = sym.mirror_vectors(sym.mirror_vectors(s.delta))
        np.testing.assert_array_equal(twice, s.delta, err_msg=s.name)
    # and through the facet: flip an unsided shape in place twice
    jaw = m.shape("jawLeft").delta.copy()
    m.shape_tools.mirror("jawLeft", target="jawLeft")
    assert not np.array_equal(m.shape("jawLeft").delta, jaw)
    np.testing.assert_allclose(m.shape("jawLeft").delta, m.shape("jawRight").delta, atol=1.01e-3)
    m.shape_tools.mirror("jawLeft", target="jawLeft")
    np.testing.assert_array_equal(m.shape("jawLeft").delta, jaw)


def test_mirror_into_an_existing_shape_keeps_its_place_weight_and_keys() -> None:
    m = head()
    m.set_shape_delta("mouthSmileRight", np.zeros((m.n_vertices, 3)))
    m.set_weight("mouthSmileRight", 0.6)
    m.timeline.key_weights(0.0, ["mouthSmileRight"])
    i = m.shape_names.index("mouthSmileRight")
    assert m.shape_tools.mirror("mouthSmileLeft") == "mouthSmileRight"
    assert m.shape_names.index("mouthSmileRight") == i and m.weights["mouthSmileRight"] == 0.6
    assert "mouthSmileRight" in m.tracks.weight_tracks
    sym = m.shape_tools.symmetry()
    np.testing.assert_array_equal(m.shape("mouthSmileRight").delta,
                                  sym.mirror_vectors(m.shape("mouthSmileLeft").delta))
    assert m.undo() == "Mirror mouthSmileLeft to mouthSmileRight"
    assert not np.any(m.shape("mouthSmileRight").delta)


def test_mirror_carries_the_mask_and_refuses_an_asymmetric_mesh() -> None:
    m = head()
    mask = np.clip(m.vertices[:, 1] - 6.5, 0, 1).astype(np.float32)
    m.set_shape_mask("browDownLeft", mask)
    m.shape_tools.mirror("browDownLeft", target="browDown_mirror")
    sym = m.shape_tools.symmetry()
    np.testing.assert_array_equal(m.shape("browDown_mirror").vertex_mask, mask[sym.map])
    # a grid spaced unevenly across: nothing on the left has a partner on the right
    V, polys = grid_polygons(6, 4)
    V[:, 0] = V[:, 0] ** 1.5
    d = np.zeros((len(V), 3), np.float32)
    d[V[:, 0] > 10, 2] = 1.0
    half = FaceModel(V, None, [BlendShape("liftLeft", d)], polygons=polys,
                     metadata=ModelMetadata(up_axis="+y", front_axis="+z"))
    with pytest.raises(ModelError, match="the mesh is not symmetric where it moves"):
        half.shape_tools.mirror("liftLeft")
    with pytest.raises(KeyError, match="no blendshape named 'nope'"):
        m.shape_tools.mirror("nope")


def test_mirror_expression_moves_recipe_displacement_and_handles() -> None:
    m = head()
    m.handles.set(__import__("workbench.methods.handles.presets", fromlist=["x"]).default_face_handles(m))
    h = m.handles.value
    i = int(np.flatnonzero(h.mirror >= 0)[0])
    m.set_weights({"eyeBlinkLeft": 1.0, "jawOpen": 0.4})
    m.handles.move(i, [0.0, 0.02, 0.01])
    smirk = m.expressions.save("smirkLeft")
    new = m.shape_tools.mirror_expression("smirkLeft")
    assert new.name == "smirkRight" and "smirkRight" in m.expressions
    assert dict(new.weights) == {**{k: 0.0 for k in smirk.weights}, "eyeBlinkLeft": 0.0,
                                 "eyeBlinkRight": 1.0, "jawOpen": 0.4}
    sym = m.shape_tools.symmetry()
    np.testing.assert_array_equal(new.displacement, sym.mirror_vectors(smirk.displacement))
    # the offset moved to the mirror handle, reflected, in the handle set's order
    np.testing.assert_array_equal(new.handle_vertices, h.vertices)
    j = int(h.mirror[i])
    np.testing.assert_allclose(new.handle_offsets[j], [-0.0, 0.02, 0.01])
    assert not np.any(np.delete(new.handle_offsets, j, axis=0))
    # and it plays back as keyed from its recipe: the mirrored face
    m.reset_weights()
    m.handles.reset_offsets()
    m.expressions.key(0.0, "smirkRight")
    np.testing.assert_allclose(m.evaluate_at(0.0) - m.vertices32, new.displacement, atol=1e-5)
    while m.undo() != "Mirror expression smirkLeft to smirkRight":
        assert "smirkRight" in m.expressions
    assert "smirkRight" not in m.expressions
    with pytest.raises(KeyError, match="no saved expression named 'nope'"):
        m.shape_tools.mirror_expression("nope")


def test_mirror_paint_paints_the_other_side() -> None:
    m = head()
    left = np.flatnonzero((m.vertices[:, 0] > 0.3) & (m.vertices[:, 1] < 7.0))
    m.paint.flood("mouthSmileLeft", 0.8, vertices=left)
    m.paint.flood("jawOpen", 0.5, vertices=np.flatnonzero(m.vertices[:, 1] < 6.5))
    painted = m.paint["mouthSmileLeft"].copy()  # 0.8, 0.4 where the jaw's flood composited over it
    m.shape_tools.mirror_paint("mouthSmileLeft")
    sym = m.shape_tools.symmetry()
    right = sym.map[left]
    mix = m.paint.mix
    np.testing.assert_allclose(np.unique(painted[left]), [0.4, 0.8], rtol=1e-6)
    np.testing.assert_array_equal(mix["mouthSmileRight"][right], painted[left])
    # this side keeps its paint where the other side had none
    np.testing.assert_array_equal(mix["mouthSmileLeft"][left], painted[left])
    assert mix.total(m.n_vertices).max() <= 1.0 + 1e-6
    assert m.undo() == "Mirror paint of mouthSmileLeft"
    assert "mouthSmileRight" not in m.paint
    # an expression without a mirrored name is made symmetric
    m.paint_stroke("jawOpen", [int(left[0])], Brush(radius=0.3, opacity=1.0))
    m.shape_tools.mirror_paint("jawOpen")
    w = m.paint["jawOpen"]
    assert w[sym.map[left[0]]] >= w[left[0]] - 1e-6
    with pytest.raises(KeyError, match="'browInnerUp' is not painted"):
        m.shape_tools.mirror_paint("browInnerUp")
