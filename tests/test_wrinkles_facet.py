"""``model.wrinkles``: every edit is one undo step, and undo puts the previous fit back exactly.

Headless (no UI import). The 5k sample head with the default handles and the
procedural examples (fit ~0.3 s per test).
"""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.core.shapes import ModelError
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.paint.painting import Brush, PaintSurface, falloff_curve
from workbench.methods.wrinkles.editing import (
    brush_mask,
    detailed_mesh,
    example_training,
    with_example,
)
from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor
from workbench.methods.wrinkles.features import extract_details, local_frames, tangent_neighbours


@pytest.fixture(scope="module")
def examples():
    m = workbench.load_sample("head")
    s = WrinkleSculptor(m)
    return s, {k: (w, s.detailed(w)) for k, w in EXAMPLE_POSES.items()}


@pytest.fixture
def model(examples):
    m = workbench.load_sample("head")
    m.handles.set(default_face_handles(m), label="Default handles")
    m.wrinkles.fit(examples[1])
    return m


def _brows_up(m, dy: float = 0.05) -> None:
    o = np.zeros((len(m.handles), 3), np.float32)
    for i, n in enumerate(m.handles.names):
        if n.startswith("brows"):
            o[i, 1] = dy
    m.handles.set_offsets(o, label="Lift brows")


def _snapshot(m) -> tuple:
    d = m.wrinkles.details()
    return m.wrinkles.state, np.array(m.evaluate()), None if d is None else np.array(d)


def _same(m, snap) -> None:
    state, mesh, d = snap
    assert m.wrinkles.state is state  # the very same value: no refit
    np.testing.assert_array_equal(m.evaluate(), mesh)
    if d is None:
        assert m.wrinkles.details() is None
    else:
        np.testing.assert_array_equal(m.wrinkles.details(), d)


# ------------------------------------------------------------------ fit, strength, on/off


def test_fit_is_one_undo_step_and_redo_gives_the_same_fit(model) -> None:
    w = model.wrinkles
    assert model.history.undo_labels == ["Default handles", "Fit wrinkles (6 examples)"]
    fit = w.state
    model.undo()
    assert not w.fitted and not w.fresh and w.details() is None and w.strain() is None
    assert w.feature_edges is None
    model.redo()
    assert w.state is fit and w.fresh


@pytest.mark.parametrize(
    ("edit", "label"),
    [
        (lambda w: w.set_strength(0.5), "Wrinkle strength 0.5"),
        (lambda w: w.set_enabled(False), "Wrinkles off"),
        (lambda w: w.edit_example("brow_raise", scale=2.0), "Scale wrinkles of brow_raise ×2"),
        (lambda w: w.edit_example(0, scale=np.linspace(0, 1, w.pose_space.n_vertices)), "Scale wrinkles of brow_raise"),
        (lambda w: w.edit_example("brow_raise", mask=np.ones(w.pose_space.n_vertices)), "Erase wrinkles of brow_raise"),
        (lambda w: w.clear(), "Clear wrinkles"),
    ],
)
def test_an_edit_then_undo_restores_bit_exact_and_redo_repeats_it(model, edit, label) -> None:
    _brows_up(model)
    before = _snapshot(model)
    assert before[2] is not None and np.abs(before[2]).max() > 1e-3  # the brows wrinkle the forehead
    depth = len(model.history.undo_labels)
    edit(model.wrinkles)
    assert model.history.undo_labels[-1] == label and len(model.history.undo_labels) == depth + 1
    after = _snapshot(model)
    assert after[0] is not before[0]
    assert after[2] is None or not np.array_equal(after[2], before[2])
    assert model.undo() == label
    _same(model, before)
    assert model.redo() == label
    _same(model, after)


def test_strength_scales_the_details_and_equal_values_record_nothing(model) -> None:
    w = model.wrinkles
    _brows_up(model)
    full = np.array(w.details())
    w.set_strength(0.5)
    np.testing.assert_allclose(w.details(), 0.5 * full, atol=1e-6)
    depth = len(model.history.undo_labels)
    w.set_strength(0.5)
    w.set_enabled(True)
    assert len(model.history.undo_labels) == depth
    w.set_enabled(False)
    assert w.details() is None and w.strain() is not None  # off: still measured, nothing added


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), "strong", None])
def test_bad_strengths_are_refused(model, bad) -> None:
    depth = len(model.history.undo_labels)
    with pytest.raises(ModelError, match="wrinkle strength must be"):
        model.wrinkles.set_strength(bad)
    assert len(model.history.undo_labels) == depth and model.wrinkles.strength == 1.0


# ------------------------------------------------------------------ example edits


def test_edits_that_change_nothing_record_nothing(model) -> None:
    w = model.wrinkles
    ps, depth = w.pose_space, len(model.history.undo_labels)
    n = model.n_vertices
    assert w.edit_example("smile") is ps
    assert w.edit_example("smile", scale=1.0, mask=np.zeros(n)) is ps
    assert w.edit_example("smile", mask=-np.ones(n)) is ps  # clipped to 0: nothing to erase
    assert len(model.history.undo_labels) == depth and w.pose_space is ps


def test_bad_example_edits_name_what_is_wrong(model) -> None:
    w = model.wrinkles
    n = model.n_vertices
    depth = len(model.history.undo_labels)
    with pytest.raises(KeyError, match="no wrinkle example 'nope'"):
        w.edit_example("nope", scale=2.0)
    with pytest.raises(IndexError, match=r"must be in 0\.\.5"):
        w.edit_example(6, scale=2.0)
    with pytest.raises(ModelError, match=rf"mask must be a number or \({n},\) values"):
        w.edit_example("smile", mask=np.ones(n - 1))
    with pytest.raises(ModelError, match="scale must be finite"):
        w.edit_example("smile", scale=float("nan"))
    with pytest.raises(ModelError, match="scale must be a number"):
        w.edit_example("smile", scale="double")
    assert len(model.history.undo_labels) == depth
    w.clear()
    for call in (lambda: w.edit_example("smile", scale=2.0), lambda: w.example_detailed("smile"),
                 lambda: w.add_example("x", {"jawOpen": 0.5}, model.vertices)):
        with pytest.raises(ModelError, match="nothing is fitted"):
            call()


def test_example_detailed_gives_back_the_sculpted_example(model, examples) -> None:
    skin = np.asarray(model.component_labels) == model.component_names.index("skin")
    for name, (_weights, detailed) in examples[1].items():
        X, D = model.wrinkles.example_detailed(name)
        np.testing.assert_allclose(X, model.wrinkles.example_mesh(name), rtol=0, atol=0)
        np.testing.assert_allclose(D[skin], detailed[skin], atol=1e-5)
        np.testing.assert_array_equal(D[~skin], X[~skin])  # details live on the skin only
    model.wrinkles.edit_example("smile", scale=0.0)
    X, D = model.wrinkles.example_detailed("smile")
    np.testing.assert_allclose(D, X, atol=1e-12)


def test_add_example_is_one_step_keeps_earlier_edits_and_undo_restores(model, examples) -> None:
    s, _ = examples
    w = model.wrinkles
    w.edit_example("smile", scale=2.0)
    edited = w.pose_space
    _brows_up(model)
    before = _snapshot(model)
    weights = {"mouthSmileLeft": 0.8, "jawOpen": 0.3}
    ps = w.add_example("half_smile", weights, s.detailed(weights))
    assert model.history.undo_labels[-1] == "Add wrinkle example half_smile"
    assert w.pose_space is ps and w.example_names == [*EXAMPLE_POSES, "half_smile"]
    assert w.example_weights[-1] == weights
    # the earlier examples' (edited) training values are kept bit for bit; the graph too
    np.testing.assert_array_equal(ps.train_values[:-1], edited.train_values)
    assert ps.alpha is edited.alpha and w.graph is before[0].graph
    # dialling the new pose in reproduces it on the skin
    model.handles.reset_offsets()
    model.set_weights({**dict.fromkeys(model.shape_names, 0.0), **weights})
    skin = np.asarray(model.component_labels) == model.component_names.index("skin")
    ok = skin & ~ps.singular
    np.testing.assert_allclose(model.evaluate()[ok], s.detailed(weights)[ok], atol=3e-4)
    model.undo()
    model.undo()
    assert model.undo() == "Add wrinkle example half_smile"
    _same(model, before)
    assert w.pose_space is edited


def test_bad_new_examples_are_refused(model, examples) -> None:
    s, _ = examples
    w = model.wrinkles
    good = s.detailed({"jawOpen": 0.5})
    depth = len(model.history.undo_labels)
    cases = [
        (("", {"jawOpen": 0.5}, good), "needs a name"),
        (("smile", {"jawOpen": 0.5}, good), "'smile' exists already"),
        (("rest", {"jawOpen": 0.0}, good), "every weight is 0"),
        (("again", dict(EXAMPLE_POSES["pucker"]), good), "weights of example 'pucker'"),
        (("flat", {"jawOpen": 0.5}, good[:-1]), r"detailed must be \(5084, 3\)"),
        (("nan", {"jawOpen": 0.5}, np.full_like(good, np.nan)), "finite"),
    ]
    for args, match in cases:
        with pytest.raises(ModelError, match=match):
            w.add_example(*args)
    with pytest.raises(KeyError, match="unknown blendshape 'noSuchShape'"):
        w.add_example("x", {"noSuchShape": 1.0}, good)
    assert len(model.history.undo_labels) == depth


# ------------------------------------------------------------------ reading


def test_fresh_feature_edges_and_strain_follow_the_handles(model) -> None:
    w = model.wrinkles
    np.testing.assert_array_equal(w.feature_edges, model.handles.vertices[w.graph.edges])
    assert np.abs(w.strain()).max() < 1e-4  # the rest pose
    _brows_up(model)
    model.evaluate()
    f = w.strain()
    assert np.abs(f).max() > 0.02
    np.testing.assert_array_equal(f, w.last_strain)  # what the layer measured
    np.testing.assert_array_equal(w.details(), model.layer_displacement("wrinkles"))
    X = np.asarray(w.large_scale())
    np.testing.assert_array_equal(w.details(X), w.details())
    model.handles.add(int(np.flatnonzero(model.component_labels == 0)[0]))  # another handle set
    assert w.fitted and not w.fresh and w.strain() is None and w.details() is None
    model.undo()
    assert w.fresh


def test_prepare_changes_nothing(model) -> None:
    _brows_up(model)
    model.evaluate()
    snap, labels, seen = _snapshot(model), model.history.undo_labels, model.wrinkles.last_strain
    model.wrinkles.prepare()
    _same(model, snap)
    assert model.history.undo_labels == labels and model.wrinkles.last_strain is seen


# ------------------------------------------------------------------ the numerics


def test_detailed_mesh_inverts_extract_details(model) -> None:
    rng = np.random.default_rng(0)
    X = np.asarray(model.vertices, np.float64)
    D = X + 1e-3 * rng.standard_normal(X.shape)
    nb = tangent_neighbours(model.faces, model.n_vertices)
    d = extract_details(D, X, local_frames(X, model.faces, nb))
    np.testing.assert_allclose(detailed_mesh(X, model.faces, nb, d), D, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="detailed_mesh: need"):
        detailed_mesh(X, model.faces, nb, d[:-1])


def test_with_example_appends_and_refuses_the_rest_pose(model) -> None:
    ps = model.wrinkles.pose_space
    st = model.wrinkles.state
    X = model.wrinkles.example_mesh("smile")
    nb = tangent_neighbours(model.faces, model.n_vertices)
    f, d = example_training(st.graph, st.handles, X, X, model.faces, nb, np.ones(model.n_vertices, bool))
    assert not np.any(d)
    new = with_example(ps, 0.5 * f, d)
    assert new.train_features.shape[0] == ps.train_features.shape[0] + 1 and new.basis[-1] == 6
    with pytest.raises(ValueError, match="no strain"):
        with_example(ps, np.zeros_like(f), d)
    with pytest.raises(ValueError, match="need a feature"):
        with_example(ps, f[:-1], d)


def test_brush_mask_keeps_the_largest_strength_and_mirrors() -> None:
    m = workbench.load_sample("head")
    surface = m.paint.surface
    skin = np.flatnonzero(np.asarray(m.component_labels) == 0)
    V = np.asarray(m.vertices)
    c = int(skin[np.argmax(V[skin, 0])])  # off the mirror plane
    brush = Brush(radius=0.2, opacity=0.6, falloff="smooth")
    zero = np.zeros(m.n_vertices, np.float32)
    one = brush_mask(zero, surface, brush, [c])
    assert not zero.any() and one is not zero and one.dtype == np.float32
    near, dist = surface.within(c, brush.radius)
    want = (0.6 * falloff_curve(dist / 0.2, "smooth")).astype(np.float32)
    np.testing.assert_array_equal(one[near], want)
    assert np.count_nonzero(one) == np.count_nonzero(want)
    np.testing.assert_array_equal(brush_mask(one, surface, brush, [c, c]), one)  # capped, not summed
    weak = brush_mask(one, surface, Brush(radius=0.2, opacity=0.1), [c])
    np.testing.assert_array_equal(weak, one)
    both = brush_mask(zero, surface, Brush(radius=0.2, opacity=0.6, mirror=True), np.array([c]))
    assert both[surface.mirror[c]] == pytest.approx(0.6) and both[c] == pytest.approx(0.6)
    with pytest.raises(ValueError, match="vertex ids must be in"):
        brush_mask(zero, surface, brush, [m.n_vertices])
    with pytest.raises(ValueError, match="the mask has 3 values"):
        brush_mask(np.zeros(3), surface, brush, [c])
    assert isinstance(surface, PaintSurface)
