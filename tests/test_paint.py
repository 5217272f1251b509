"""Painterly blending (Pighin et al. 1998): convexity, exact reproduction, mirror, undo, locality."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import workbench
import workbench.methods.paint.painting as paint_module
from workbench.methods.paint.painting import (
    Brush,
    PaintMix,
    PaintSurface,
    Stroke,
    apply_dab,
    eyes_vertical_extent,
    feathered_presets,
    flood,
    normalize,
    regional_mix,
)
from workbench.model import BlendShape, FaceModel, ModelError
from workbench.testing import grid_triangles, grid_vertices


@pytest.fixture(scope="module")
def head_data() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture
def head(head_data: FaceModel) -> FaceModel:
    m = FaceModel(
        head_data.vertices, head_data.faces, head_data.shapes,
        component_labels=head_data.component_labels, component_names=head_data.component_names,
        metadata=head_data.metadata,
    )
    return m


def _mouth_corner(m: FaceModel, side: float = 1.0) -> int:
    d = np.linalg.norm(m.shape("mouthSmileLeft" if side > 0 else "mouthSmileRight").delta, axis=1)
    return int(np.argmax(d))


def test_hard_opaque_brush_reproduces_the_expression_inside(head: FaceModel) -> None:
    c = _mouth_corner(head)
    brush = Brush(radius=0.4, opacity=1.0, falloff="constant")
    head.paint.dab("mouthSmileLeft", c, brush)
    ids, _ = head.paint.surface.within(c, 0.4)
    expected = head.vertices[ids] + head.shape("mouthSmileLeft").delta[ids]
    np.testing.assert_allclose(head.evaluate()[ids], expected, atol=1e-6)
    assert np.all(head.paint["mouthSmileLeft"][ids] == 1.0)


def test_opaque_brush_reproduces_the_expression_over_region_weights(head: FaceModel) -> None:
    # the region blend is a layer below the paint: it belongs to the base, which an
    # opacity-1 dab replaces by the expression, however the regions are weighted
    from workbench.methods.regions.blend import RegionWeights

    state = head.segment_regions(0.25)
    c = _mouth_corner(head)
    lv = state.level
    under = state.regions.regions_at(lv, c)
    region = max(under, key=lambda r: under[r])
    rw = RegionWeights.from_global(head, state.regions, lv)
    head.regions.set_weights(rw.with_region(region, {"jawOpen": 1.0, "mouthSmileLeft": 0.3}))
    head.set_weight("browInnerUp", 0.5)
    ids, _ = head.paint.surface.within(c, 0.4)
    assert np.abs(head.evaluate()[ids] - head.blended()[ids]).max() > 0.05  # the regions move it
    head.paint.dab("mouthPucker", c, Brush(radius=0.4, opacity=1.0, falloff="constant"))
    expected = head.vertices[ids] + head.shape("mouthPucker").delta[ids]
    np.testing.assert_allclose(head.evaluate()[ids], expected, atol=1e-5)
    # half opacity: halfway between the region-blended face and the expression
    head.paint.clear()
    below = head.evaluate()[ids].copy()
    head.paint.dab("mouthPucker", c, Brush(radius=0.4, opacity=0.5, falloff="constant"))
    np.testing.assert_allclose(head.evaluate()[ids], 0.5 * (below + expected), atol=1e-5)


def test_brush_uses_surface_distance_not_straight_line(head: FaceModel) -> None:
    """A dab on the upper lip must not reach the lower lip right below it (across the mouth)."""
    jaw = np.linalg.norm(head.shape("jawOpen").delta, axis=1)
    skin = head.component_vertices("skin")
    lower_lip = int(skin[np.argmax(jaw[skin])])  # the jaw moves the lower lip most
    V = head.vertices
    # the upper-lip vertex right above it: near in space, not moved by jawOpen
    cand = skin[(jaw[skin] < 0.05 * jaw.max()) & (V[skin, 1] > V[lower_lip, 1])]
    upper = int(cand[np.argmin(np.linalg.norm(V[cand] - V[lower_lip], axis=1))])
    straight = float(np.linalg.norm(V[upper] - V[lower_lip]))
    radius = 2.0 * straight
    ids, _ = head.paint.surface.within(upper, radius)
    assert lower_lip not in ids  # a straight-line radius of 2x the gap would include it


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["mouthSmileLeft", "eyeBlinkLeft", "browInnerUp"]),
            st.integers(0, 4327),
            st.floats(0.05, 0.6),
            st.floats(0.0, 1.0),
            st.sampled_from(["smooth", "linear", "constant", "sphere"]),
            st.sampled_from(["add", "subtract", "smooth"]),
            st.booleans(),
        ),
        min_size=1,
        max_size=8,
    )
)
def test_weights_stay_convex_after_any_strokes(head: FaceModel, strokes) -> None:
    head.paint.clear()
    for name, centre, radius, opacity, falloff, mode, mirror in strokes:
        head.paint.dab(name, centre, Brush(radius, opacity, falloff, mode, mirror))
    maps = list(head.paint.values())
    for w in maps:
        assert w.min() >= 0.0 and w.max() <= 1.0
    if maps:
        assert np.sum(maps, axis=0).max() <= 1.0 + 1e-6


_EXPRESSIONS = ["mouthSmileLeft", "eyeBlinkLeft", "browInnerUp"]
_dab = st.tuples(
    st.just("dab"),
    st.sampled_from(_EXPRESSIONS),
    st.integers(0, 5083),
    st.floats(0.05, 0.6),
    st.floats(0.0, 1.0),
    st.sampled_from(["smooth", "linear", "constant", "sphere"]),
    st.sampled_from(["add", "subtract", "smooth"]),
    st.booleans(),  # mirror
    st.booleans(),  # inside a stroke (opacity capped against the stroke's start)
)
_flood = st.tuples(st.just("flood"), st.sampled_from(_EXPRESSIONS), st.floats(0.0, 1.0), st.booleans())
_regional = st.tuples(
    st.just("regional"),
    st.lists(
        st.tuples(st.sampled_from(_EXPRESSIONS), st.floats(0.0, 1.0), st.sampled_from(_EXPRESSIONS), st.floats(0.0, 1.0)),
        min_size=6,
        max_size=6,
    ),
    st.floats(0.01, 0.5),
)
_ops = st.lists(st.one_of(_dab, _dab, _flood, st.tuples(st.just("normalize")), _regional), min_size=1, max_size=10)


@pytest.fixture(scope="module")
def head_surface(head_data: FaceModel) -> PaintSurface:
    return PaintSurface(head_data.vertices, head_data.faces)


@settings(max_examples=40, deadline=None)
@given(_ops)
def test_paint_arithmetic_is_convex_before_the_round_off_clamp(head_data: FaceModel, head_surface: PaintSurface, ops) -> None:
    """Every paint operation keeps W >= 0 and sum W <= 1 by itself (to 1e-6): the
    clamp of ``_clip_convex`` only guards float round-off, so it is switched off here."""
    n = head_data.n_vertices
    rng = np.random.default_rng(len(ops))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(paint_module, "_clip_convex", lambda maps, ids: None)
        mix = PaintMix()
        stroke: Stroke | None = None
        for op in ops:
            if op[0] == "dab":
                _, name, centre, radius, opacity, falloff, mode, mirror, in_stroke = op
                if in_stroke and stroke is None:
                    stroke = Stroke(mix, n)
                elif not in_stroke:
                    stroke = None  # a new stroke starts from the current mix
                brush = Brush(radius, opacity, falloff, mode, mirror)
                mix = apply_dab(mix, name, head_surface, brush, centre, stroke)
            else:
                stroke = None
                if op[0] == "flood":
                    _, name, opacity, everywhere = op
                    ids = None if everywhere else rng.choice(n, n // 3, replace=False)
                    mix = flood(mix, name, opacity, n, ids)
                elif op[0] == "normalize":
                    mix = normalize(mix, n)
                else:
                    _, per_region, feather = op
                    _, R = feathered_presets(head_data.vertices, "six", feather=feather)
                    mixes = []
                    for e1, a, e2, b in per_region:  # two expressions, scaled to sum to <= 1
                        m: dict[str, float] = {}
                        for e, w in ((e1, a), (e2, b)):
                            m[e] = m.get(e, 0.0) + w / max(1.0, a + b)
                        mixes.append(m)
                    mix = regional_mix(R, mixes, n)
            maps = np.array([np.asarray(w, np.float64) for w in mix.values()]).reshape(-1, n)
            assert maps.min(initial=0.0) >= -1e-6, op
            assert maps.sum(axis=0).max(initial=0.0) <= 1.0 + 1e-6, op


def test_mirror_painting_is_symmetric(head: FaceModel) -> None:
    c = _mouth_corner(head)
    head.paint.dab("mouthPucker", c, Brush(radius=0.35, opacity=0.8, mirror=True))
    w = head.paint["mouthPucker"]
    mirror = head.paint.surface.mirror
    painted = np.flatnonzero(w > 0.05)
    assert painted.size > 10
    off_plane = painted[np.abs(head.vertices[painted, 0]) > 1e-6]
    assert (mirror[off_plane] != off_plane).all()  # the sample head is symmetric: all have partners
    np.testing.assert_allclose(w[mirror[painted]], w[painted], atol=0.05)
    left = (head.vertices[painted, 0] > 0.01).sum()
    right = (head.vertices[painted, 0] < -0.01).sum()
    assert abs(left - right) <= 0.1 * painted.size


def test_mirror_map_uses_the_mid_plane_and_skips_vertices_without_a_partner() -> None:
    n = 9
    V, F = grid_vertices(n, x=(4.0, 6.0), y=(0.0, 2.0)), grid_triangles(n)  # mirror plane x = 5
    i, j = np.arange(n * n) % n, np.arange(n * n) // n
    expected = j * n + (n - 1 - i)  # column i <-> column n - 1 - i, about x = 5 (not x = 0)
    p = 4 * n + 6  # right of the plane; its partner is 4 * n + 2
    V[p, 1] += 0.05  # far beyond the tolerance (1e-3 of the diagonal, 0.0028)
    expected[[p, 4 * n + 2]] = [p, 4 * n + 2]  # no partner: mapped to themselves
    surf = PaintSurface(V, F)
    np.testing.assert_array_equal(surf.mirror, expected)
    np.testing.assert_array_equal(surf.mirror[4::n], np.arange(4, n * n, n))  # on the plane: itself
    # the model's surface mirrors about the middle of its skin, with the same tolerance
    m = FaceModel(V, F, [BlendShape("up", np.tile([0.0, 0.0, 1.0], (n * n, 1)))])
    np.testing.assert_array_equal(m.paint.surface.mirror, expected)

    brush = Brush(radius=0.3, opacity=0.8, falloff="linear", mirror=True)
    # a centre with a partner: the same dab on the other side
    c = 6 * n + 7
    w = apply_dab(PaintMix(), "up", surf, brush, c)["up"]
    assert w[V[:, 0] < 5.0].max() > 0.5
    np.testing.assert_allclose(w[expected[c]], w[c])
    # a centre without one: one side only, exactly the dab without mirror
    q = 4 * n + 2
    w_mirror = apply_dab(PaintMix(), "up", surf, brush, q)["up"]
    w_plain = apply_dab(PaintMix(), "up", surf, Brush(0.3, 0.8, "linear"), q)["up"]
    np.testing.assert_array_equal(w_mirror, w_plain)
    assert not w_mirror[V[:, 0] > 5.0 + 1e-9].any()


def test_paint_follows_a_change_of_the_shell_stiffness(head: FaceModel) -> None:
    from workbench.methods.handles.presets import default_face_handles

    def prepared(m: FaceModel) -> FaceModel:
        m.handles.set(default_face_handles(m))
        m.move_handle(3, [0.0, 0.2, 0.1])
        return m

    prepared(head)
    head.paint.flood("mouthSmileLeft", 0.5)
    before = head.evaluate().copy()
    head.handles.set_stiffness(1.0, 100.0)
    fresh = prepared(FaceModel(
        head.vertices, head.faces, head.shapes,
        component_labels=head.component_labels, component_names=head.component_names,
    ))
    fresh.handles.set_stiffness(1.0, 100.0)
    fresh.paint.flood("mouthSmileLeft", 0.5)
    assert np.abs(head.evaluate() - before).max() > 1e-3  # the stiffness matters here
    np.testing.assert_allclose(head.evaluate(), fresh.evaluate(), atol=1e-6)


def test_stroke_is_one_undo_step_and_undo_is_bit_exact(head: FaceModel) -> None:
    c = _mouth_corner(head)
    head.paint.dab("mouthSmileLeft", c, Brush(opacity=0.3))
    before = {k: v.copy() for k, v in head.paint.items()}
    ev_before = head.evaluate().copy()
    head.paint_stroke("eyeBlinkLeft", [c, c + 1, c + 2], Brush(opacity=0.7, radius=0.5))
    assert head.history.undo_labels[-1] == "Paint eyeBlinkLeft"
    head.undo()
    assert set(head.paint) == set(before)
    for k, v in before.items():
        assert np.array_equal(head.paint[k], v)
    assert np.array_equal(head.evaluate(), ev_before)


def test_a_dab_changes_only_the_vertices_under_the_brush(head: FaceModel) -> None:
    c = _mouth_corner(head)
    head.paint.dab("mouthSmileLeft", c, Brush(opacity=0.5))
    a = head.evaluate().copy()
    brush = Brush(radius=0.25, opacity=0.5)
    head.paint.dab("mouthSmileLeft", c, brush)
    b = head.evaluate()
    ids, _ = head.paint.surface.within(c, 0.25)
    changed = np.flatnonzero(np.any(a != b, axis=1))
    assert changed.size > 0 and np.isin(changed, ids).all()
    # the incremental layer equals a from-scratch evaluation
    fresh = FaceModel(head.vertices, head.faces, head.shapes)
    fresh.paint.set(head.paint)
    np.testing.assert_allclose(fresh.evaluate(), b, atol=1e-6)


def test_paint_composes_with_the_global_blend_as_a_convex_combination(head: FaceModel) -> None:
    head.set_weight("jawOpen", 0.5)
    head.paint.flood("mouthSmileLeft", 0.25)
    D_base = 0.5 * head.shape("jawOpen").delta
    expected = head.vertices + 0.75 * D_base + 0.25 * head.shape("mouthSmileLeft").delta
    np.testing.assert_allclose(head.evaluate(), expected, atol=1e-5)
    head.paint.normalize()
    np.testing.assert_allclose(head.evaluate(), head.vertices + head.shape("mouthSmileLeft").delta, atol=1e-5)


def test_saved_expressions_paint_and_bake(head: FaceModel) -> None:
    head.set_weights({"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0})
    smile = head.expressions.save("smile")
    head.reset_weights()
    assert "smile" in head.expressions
    np.testing.assert_allclose(smile.displacement, head.shape("mouthSmileLeft").delta + head.shape("mouthSmileRight").delta, atol=1e-6)
    head.paint.dab("smile", _mouth_corner(head), Brush(radius=0.6, opacity=1.0))
    before = head.evaluate().copy()
    head.paint.bake_to_shape("painted_smile")
    assert len(head.paint) == 0 and head.weights["painted_smile"] == 1.0
    np.testing.assert_allclose(head.evaluate(), before, atol=1e-5)
    with pytest.raises(KeyError, match="no expression named 'nope'"):
        head.paint.dab("nope", 0)


def test_a_painted_expression_keys_exactly_as_saved_and_undo_removes_all_keying_made(head: FaceModel) -> None:
    # Pighin et al. 1998 sec. 4: paint a smile (itself a saved expression) over the
    # mouth of the neutral face and a half blink on one lid; the painted blend is a
    # new expression of the library, which the timeline then interpolates.
    head.set_weights({"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0})
    head.expressions.save("smile")
    head.reset_weights()
    head.paint_stroke("smile", [_mouth_corner(head)], Brush(radius=0.5, opacity=1.0, mirror=True))
    lid = int(np.argmax(np.linalg.norm(head.shape("eyeBlinkLeft").delta, axis=1)))
    head.paint_stroke("eyeBlinkLeft", [lid], Brush(radius=0.15, opacity=0.5))
    saved = head.evaluate().copy()
    assert not any(head.weights.values())  # the look is in the paint only
    assert np.abs(saved - head.vertices).max() > 0.05
    head.expressions.save("debauched")
    head.paint.clear()
    shapes_before, labels_before = head.shape_names, head.history.undo_labels

    head.key_expression(1.0, "debauched")
    np.testing.assert_allclose(head.evaluate_at(1.0), saved, rtol=0, atol=1e-6)
    # the exporters' sampler plays it too: the look is a blendshape keyed at 1
    np.testing.assert_allclose(head.evaluate_at(1.0, head.tracks), saved, rtol=0, atol=1e-6)
    (baked,) = set(head.shape_names) - set(shapes_before)
    assert "debauched" in baked
    np.testing.assert_array_equal(head.shape(baked).delta, head.expressions["debauched"].displacement)
    assert head.weights[baked] == 0.0  # keying leaves the live face alone
    assert head.history.undo_labels == [*labels_before, "Key debauched at 1s"]

    head.undo()
    assert head.shape_names == shapes_before and not head.tracks.tracks
    assert head.history.undo_labels == labels_before
    head.redo()
    np.testing.assert_allclose(head.evaluate_at(1.0), saved, rtol=0, atol=1e-6)


def test_regional_presets_are_partitions_of_unity(head: FaceModel) -> None:
    for preset, count in (("upper_lower", 2), ("six", 6)):
        names, R = feathered_presets(head.vertices, preset, feather=0.2)
        assert len(names) == count and R.shape == (count, head.n_vertices)
        assert R.min() >= -1e-12
        np.testing.assert_allclose(R.sum(axis=0), 1.0, atol=1e-9)
    names, R = feathered_presets(head.vertices, "six", feather=0.2)
    mixes = [{"browInnerUp": 1.0} if n.startswith("forehead") else {"mouthSmileLeft": 0.5} if n == "lower_L" else {} for n in names]
    mix = regional_mix(R, mixes, head.n_vertices)
    head.paint.set(mix, "Regional blend")
    assert set(head.paint) == {"browInnerUp", "mouthSmileLeft"}
    left_lower = (head.vertices[:, 0] > 0.3) & (head.vertices[:, 1] < np.percentile(head.vertices[:, 1], 30))
    assert head.paint["mouthSmileLeft"][left_lower].max() == pytest.approx(0.5, abs=1e-6)
    with pytest.raises(ValueError, match="sum to <= 1"):
        regional_mix(R, [{"a": 0.7, "b": 0.7}] * 6, head.n_vertices)


def test_regional_presets_put_eyes_up_and_mouth_down_on_the_head(head: FaceModel) -> None:
    """Pighin's bands on the sample head: eyes with the forehead in "upper", and in "eyes"."""
    V = head.vertices
    labels, comps = head.component_labels, list(head.component_names)
    eyes = np.isin(labels, [comps.index("eye_left"), comps.index("eye_right")])
    skin = labels == comps.index("skin")
    mouth = skin & (np.abs(V[:, 0]) < 0.3) & (np.abs(V[:, 1] - 6.62) < 0.08) & (V[:, 2] > 1.0)
    crown = skin & (V[:, 1] > 8.0)
    eyes_y = eyes_vertical_extent(V, labels, comps)
    assert eyes_y is not None and eyes_y[0] < eyes_y[1]
    for ey in (eyes_y, None):  # from the eye components, and the fallback fractions
        names, R = feathered_presets(V, "upper_lower", feather=0.05, eyes_y=ey)
        up = R[names.index("upper")]
        assert up[eyes].min() > 0.99 and up[mouth].max() < 0.01 and up[crown].min() > 0.99
        names, R = feathered_presets(V, "six", feather=0.05, eyes_y=ey)
        band = {b: R[names.index(f"{b}_L")] + R[names.index(f"{b}_R")] for b in ("forehead", "eyes", "lower")}
        assert band["eyes"][eyes].mean() > 0.9
        assert band["forehead"][crown].min() > 0.99 and band["lower"][mouth].min() > 0.99
    mesh_without_eyes = eyes_vertical_extent(V, np.zeros(len(V), int), ["skin"])
    assert mesh_without_eyes is None


def test_bad_brush_and_paint_arguments() -> None:
    with pytest.raises(ValueError, match="radius must be > 0"):
        Brush(radius=0)
    with pytest.raises(ValueError, match=r"opacity must be in \[0, 1\]"):
        Brush(opacity=2)
    with pytest.raises(ValueError, match="falloff must be"):
        Brush(falloff="spiky")  # type: ignore[arg-type]
    m = FaceModel(np.eye(3), [[0, 1, 2]])
    with pytest.raises(ModelError, match="PaintMix"):
        m.paint.set({"x": np.zeros(3)})  # type: ignore[arg-type]
    assert isinstance(m.paint.mix, PaintMix)


def test_a_stroke_never_paints_beyond_the_brush_opacity(head: FaceModel) -> None:
    c = _mouth_corner(head)
    brush = Brush(radius=0.3, opacity=0.5, falloff="constant")
    head.paint_stroke("mouthSmileLeft", [c] * 6, brush)  # six dabs on one spot, one stroke
    assert head.paint["mouthSmileLeft"][c] == pytest.approx(0.5)
    head.paint_stroke("mouthSmileLeft", [c], brush)  # a second stroke builds on the first
    assert head.paint["mouthSmileLeft"][c] == pytest.approx(0.75)
    for _ in range(2):  # outside a stroke, dabs compound
        head.paint.dab("eyeBlinkLeft", c, brush)
    assert head.paint["eyeBlinkLeft"][c] == pytest.approx(0.75)


def test_facet_total_is_the_sum_of_the_painted_maps(head: FaceModel) -> None:
    assert not head.paint.total().any()
    c = _mouth_corner(head)
    head.paint.dab("mouthSmileLeft", c, Brush(radius=0.3, opacity=0.5))
    head.paint.dab("jawOpen", c, Brush(radius=0.3, opacity=0.5))
    expected = head.paint["mouthSmileLeft"] + head.paint["jawOpen"]
    np.testing.assert_array_equal(head.paint.total(), expected)
    assert head.paint.total().shape == (head.n_vertices,)
    assert float(head.paint.total().max()) <= 1.0 + 1e-6
