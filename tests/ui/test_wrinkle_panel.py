"""WrinklePanel (widgets/wrinkles/) and the viewport's feature-graph overlay, without a browser.

Buttons are clicked and widgets set from Python; the checks are on the model
(weights, undo history, evaluated mesh), ``model.wrinkles`` (strength, on/off,
fitted examples, details) and the viewport's binary traits. Runs on the 5k
sample head (fit ~1 s).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("anywidget")

import ipywidgets as W

from widgets import Viewport, Workbench
from widgets.wrinkles import WrinklePanel
from workbench import load_sample
from workbench.core.shapes import ModelError
from workbench.methods.wrinkles.examples import EXAMPLE_POSES
from workbench.model import HandleSet

pytestmark = pytest.mark.ui


def _errors(out: W.Output) -> str:
    return "".join(o.get("text", "") for o in out.outputs)


@pytest.fixture
def setup():
    model = load_sample("head")
    errors = W.Output()
    vp = Viewport(model, errors=errors)
    panel = WrinklePanel(model, vp, errors=errors, thumbnails=False)
    yield model, vp, panel, errors
    panel.close()
    vp.close()


@pytest.fixture
def fitted(setup):
    _, _, panel, errors = setup
    panel.fit_button.click()
    assert _errors(errors) == ""
    return setup


def _lift_brows(model, amount: float = 0.05) -> None:
    names = list(model.handles.names)
    o = np.zeros((len(names), 3), np.float32)
    for i, n in enumerate(names):
        if n.startswith("brows"):
            o[i, 1] = amount
    model.handles.set_offsets(o, label="Lift brows")


def _near(a, b, ref, rel: float = 0.25) -> bool:
    """``a`` matches ``b`` up to ``rel`` of the size of ``ref`` (WPSD reproduces its examples
    only approximately: per-vertex weights use each vertex's strongest edges and a pinv cut-off)."""
    return float(np.linalg.norm(np.asarray(a, float) - b)) <= rel * float(np.linalg.norm(ref))


def _detail(model, panel) -> np.ndarray:
    d = model.wrinkles.details()
    return np.zeros((model.n_vertices, 3), np.float32) if d is None else d


def test_fit_button_sets_handles_fits_and_draws_the_feature_graph(setup) -> None:
    model, vp, panel, errors = setup
    assert not model.wrinkles.fitted and len(model.handles) == 0
    assert panel.controls.layout.display == "none"  # nothing to control before the fit
    assert "not fitted" in panel.status.value
    panel.fit_button.click()
    assert _errors(errors) == "" and panel.error_line.value == ""
    layer = model.wrinkles
    assert layer.fitted and panel.fresh
    assert layer.example_names == list(EXAMPLE_POSES)
    assert model.history.undo_labels == ["Default handles", "Fit wrinkles (6 examples)"]
    assert panel.progress.layout.visibility == "hidden" and panel.progress.value == 1.0
    assert panel.controls.layout.display == ""
    assert panel.fit_button.description == "Refit from examples"
    assert (
        list(panel.example.options) == layer.example_names and panel.example.value == "brow_raise"
    )
    assert len(panel.cards.children) == len(layer.example_names)
    assert f"<b>{len(layer.graph)}</b> feature edges" in panel.status.value
    # the overlay: one segment per feature edge between handle vertices, grey (zero strain)
    pairs = vp.feature_edges
    np.testing.assert_array_equal(pairs, model.handles.vertices[layer.graph.edges])
    assert vp.feature_strain.shape == (len(layer.graph),) and not vp.feature_strain.any()
    assert panel.last_fit_s > 0


def test_dragging_sends_the_strain_only_when_it_changes(fitted) -> None:
    model, vp, panel, _ = fitted
    sent = vp.feature_updates_sent
    with model.interaction("Drag"):
        _lift_brows(model, 0.02)
        _lift_brows(model, 0.05)
    layer = model.wrinkles
    assert layer.last_strain is not None and np.abs(layer.last_strain).max() > 0.05
    np.testing.assert_array_equal(layer.strain(), layer.last_strain)
    np.testing.assert_allclose(vp.feature_strain, layer.last_strain, atol=1e-6)
    assert vp.feature_updates_sent > sent
    assert "strain" in panel.status.value
    # the same state again: nothing new to send
    sent = vp.feature_updates_sent
    model.register_layer(layer.layer)  # invalidates the cache, emits deformed; same strain
    assert vp.feature_updates_sent == sent
    # hidden: kept, not sent; shown again: sent at once
    panel.show_graph.value = False
    assert vp.feature_graph is False
    model.handles.reset_offsets()
    assert vp.feature_updates_sent == sent
    panel.show_graph.value = True
    assert vp.feature_updates_sent == sent + 1 and np.abs(vp.feature_strain).max() < 1e-5


def test_wrinkles_toggle_and_strength_are_undoable(fitted) -> None:
    model, _, panel, _ = fitted
    _lift_brows(model)
    d1 = _detail(model, panel)
    assert np.abs(d1).max() > 0.002  # > 0.2 mm on the 5k head (units: dm)
    shell = np.asarray(model.blended()) + model.handles.displacement()
    np.testing.assert_allclose(model.evaluate(), shell + d1, atol=1e-5)

    w = model.wrinkles
    panel.enabled.value = False
    assert w.enabled is False and model.history.undo_labels[-1] == "Wrinkles off"
    np.testing.assert_allclose(model.evaluate(), shell, atol=1e-6)
    model.undo()
    assert w.enabled is True and panel.enabled.value is True
    np.testing.assert_allclose(model.evaluate(), shell + d1, atol=1e-5)

    panel.strength.value = 0.5
    assert w.strength == 0.5 and model.history.undo_labels[-1] == "Wrinkle strength 0.5"
    np.testing.assert_allclose(_detail(model, panel), 0.5 * d1, atol=1e-6)
    model.undo()
    assert w.strength == 1.0 and panel.strength.value == 1.0
    model.redo()
    assert w.strength == 0.5 and panel.strength.value == 0.5
    # from code: the same edit, and the slider follows
    depth = len(model.history.undo_labels)
    w.set_strength(1.5)
    assert panel.strength.value == 1.5 and len(model.history.undo_labels) == depth + 1
    w.set_strength(1.5)  # no change, no step
    assert len(model.history.undo_labels) == depth + 1
    with pytest.raises(ModelError, match=">= 0"):
        w.set_strength(-1)
    w.set_enabled(False)
    assert panel.enabled.value is False


def test_view_and_scale_an_example_propagates(fitted) -> None:
    model, _, panel, _ = fitted
    panel.cards.children[0].children[0].click()  # the "brow_raise" button of the first card
    assert model.history.undo_labels[-1] == "View example brow_raise"
    w = {k: v for k, v in model.weights.items() if v}
    assert w == EXAMPLE_POSES["brow_raise"]
    d0 = _detail(model, panel)
    # at the example pose the fit reproduces the example's detail
    X, D = model.wrinkles.example_detailed("brow_raise")
    assert _near(model.evaluate(), D, D - X)
    assert np.abs(d0).max() > 0.002
    # another example is interpolated exactly: the edit must not leak into it ...
    panel.view_example("surprise")
    s0 = _detail(model, panel)
    # ... while a pose near brow_raise that is not an example follows the edit
    near = dict.fromkeys(model.shape_names, 0.0)
    near.update({k: 0.9 * v for k, v in EXAMPLE_POSES["brow_raise"].items()})
    model.set_weights(near)
    n0 = _detail(model, panel)

    panel.example.value = "brow_raise"
    panel.scale.value = 0.5
    panel.scale_button.click()
    assert panel.error_line.value == ""
    assert "×0.50" in panel.cards.children[0].children[-1].value
    model.set_weights(near)
    n1 = _detail(model, panel)
    assert np.linalg.norm(n1) < 0.8 * np.linalg.norm(n0)  # the edit reached a neighbouring pose
    panel.view_example("surprise")
    np.testing.assert_allclose(_detail(model, panel), s0, atol=2e-4 * np.abs(s0).max())
    panel.view_example("brow_raise")
    ratio = np.linalg.norm(_detail(model, panel)) / np.linalg.norm(d0)
    assert abs(ratio - 0.5) < 0.1, ratio
    # the smile is far from the brow raise in strain space: still its own wrinkles
    panel.view_example("smile")
    X, D = model.wrinkles.example_detailed("smile")
    assert _near(_detail(model, panel), D - X, D - X)


def test_add_current_pose_as_example_keeps_edits(fitted) -> None:
    model, _, panel, _ = fitted
    model.wrinkles.edit_example("smile", scale=2.0)
    smile_before = model.wrinkles.example_detailed("smile")[1]
    model.set_weights({"mouthSmileLeft": 0.8, "jawOpen": 0.3})
    panel.new_name.value = "half_smile"
    panel.add_button.click()
    assert panel.error_line.value == ""
    layer = model.wrinkles
    assert model.history.undo_labels[-1] == "Add wrinkle example half_smile"
    assert layer.example_names[-1] == "half_smile" and len(panel.cards.children) == 7
    assert layer.example_weights[-1] == {"mouthSmileLeft": 0.8, "jawOpen": 0.3}
    assert panel.new_name.value == "half_smile_1"
    # the new pose is reproduced: blend + the sculptor's wrinkles for these weights
    want = panel.sculptor().detailed({"mouthSmileLeft": 0.8, "jawOpen": 0.3})
    assert _near(model.evaluate(), want, want - np.asarray(model.blended()))
    # the earlier edit survived the refit
    np.testing.assert_allclose(layer.example_detailed("smile")[1], smile_before, atol=2e-5)
    # undo removes the example again: the earlier fit, exactly, and its cards
    before = layer.pose_space
    model.undo()
    assert layer.example_names == list(EXAMPLE_POSES) and len(panel.cards.children) == 6
    model.redo()
    assert layer.pose_space is before and len(panel.cards.children) == 7


def test_errors_are_reported_in_the_panel(setup) -> None:
    model, _, panel, errors = setup
    panel.scale_button.click()  # before any fit
    assert "Fit wrinkles from examples" in panel.error_line.value
    assert "scale wrinkles" in _errors(errors)
    panel.fit_button.click()
    panel.error_line.value = ""
    panel.add_button.click()  # the rest pose
    assert "rest pose" in panel.error_line.value
    panel.view_example("smile")
    panel.new_name.value = "smile_again"
    panel.add_button.click()  # the weights of an example
    assert "example &#x27;smile&#x27;" in panel.error_line.value
    _lift_brows(model)
    model.set_weight("jawOpen", 0.4)
    panel.add_button.click()  # handle offsets are not part of an example
    assert "bake the handle edit" in panel.error_line.value
    panel.scale.value = 0.0
    panel.example.value = "pucker"
    panel.scale_button.click()  # 0 is allowed: paints the example's wrinkles out
    assert "pucker" in panel.status.value


def test_a_failing_fit_shows_the_error_and_leaves_the_panel_usable() -> None:
    model = load_sample("head")
    for name in list(model.shape_names):
        if not name.startswith("eye"):
            model.remove_shape(name)  # no example pose can be built from eye shapes alone
    errors = W.Output()
    panel = WrinklePanel(model, errors=errors, thumbnails=False)
    try:
        panel.fit_button.click()
        assert "example poses can be built" in panel.error_line.value
        assert "example poses can be built" in _errors(errors)
        assert panel.progress.bar_style == "danger" and "failed" in panel.progress_label.value
        assert panel.fit_button.disabled is False
        assert not model.wrinkles.fitted and panel.controls.layout.display == "none"
    finally:
        panel.close()


def test_a_rig_missing_a_shape_fits_the_others_and_says_so() -> None:
    model = load_sample("head")
    model.remove_shape("browInnerUp")  # the brow-raise example is built without it
    panel = WrinklePanel(model, thumbnails=False)
    try:
        panel.fit()
        assert model.wrinkles.fitted and "browInnerUp" in panel.status.value
        assert panel.error_line.value == ""
    finally:
        panel.close()


def test_undo_and_redo_of_the_fit(fitted) -> None:
    model, vp, panel, _ = fitted
    fit = model.wrinkles.pose_space
    model.undo()  # "Fit wrinkles (6 examples)"
    assert not model.wrinkles.fitted and panel.cards.children == ()
    assert panel.controls.layout.display == "none" and vp.feature_edges.shape == (0, 2)
    assert "not fitted" in panel.status.value
    model.redo()
    assert model.wrinkles.pose_space is fit and len(panel.cards.children) == 6
    assert vp.feature_edges.shape == (len(model.wrinkles.graph), 2)


def test_changed_handles_make_the_fit_stale(fitted) -> None:
    model, vp, panel, _ = fitted
    n = len(model.wrinkles.graph)
    model.handles.add(int(np.flatnonzero(model.component_labels == 0)[0]))
    assert not panel.fresh
    assert vp.feature_edges.shape == (0, 2)
    assert "handles changed" in panel.status.value
    assert model.wrinkles.details() is None  # the core ignores a stale fit
    assert model.wrinkles.strain() is None and model.wrinkles.fitted
    model.undo()
    assert panel.fresh and vp.feature_edges.shape == (n, 2)
    model.handles.set(HandleSet(), label="Clear")
    assert not panel.fresh and panel.current_strain() is None


def test_thumbnails_are_rendered_and_follow_edits() -> None:
    model = load_sample("head")
    panel = WrinklePanel(model)
    try:
        panel.fit()
        imgs = [c.children[0] for c in panel.cards.children]
        assert all(isinstance(i, W.Image) and i.value[:4] == b"\x89PNG" for i in imgs)
        before = {c.children[1].description: c.children[0].value for c in panel.cards.children}
        panel.scale_example("brow_raise", 0.0)
        after = {c.children[1].description: c.children[0].value for c in panel.cards.children}
        assert after["brow_raise"] != before["brow_raise"]
        assert after["smile"] == before["smile"]  # cached: its details did not change
    finally:
        panel.close()


def test_viewport_feature_graph_validation() -> None:
    model = load_sample("head")
    vp = Viewport(model)
    try:
        with pytest.raises(ValueError, match="vertex ids"):
            vp.set_feature_graph([[0, model.n_vertices]])
        vp.set_feature_graph([[0, 1], [1, 2]])
        assert vp.feature_edges.tolist() == [[0, 1], [1, 2]]
        with pytest.raises(ValueError, match="expected 2 values"):
            vp.set_feature_strain([0.1])
        with pytest.raises(ValueError, match="NaN"):
            vp.set_feature_strain([0.1, np.nan])
        assert vp.set_feature_strain([0.1, -0.1])
        assert not vp.set_feature_strain([0.1 + 1e-6, -0.1])  # below the tolerance
        assert vp.set_feature_strain([0.0, 0.0])  # back to rest is always sent
        vp.set_feature_graph(None)
        assert vp.feature_edges.shape == (0, 2)
    finally:
        vp.close()


def test_workbench_shows_the_wrinkle_panel_in_the_sculpt_tab() -> None:
    wb = Workbench(load_sample("head"))
    try:
        assert wb.tabs.children[1].children == (wb.sculpt, wb.wrinkles)
        assert wb.wrinkles.viewport is wb.viewport
        wb.wrinkles.fit()
        _lift_brows(wb.model)
        wb.wrinkles.enabled.value = False
        wb.undo()  # the top bar's Undo
        assert wb.model.wrinkles.enabled is True and wb.wrinkles.enabled.value is True
    finally:
        wb.close()


# ---------------------------------------------------------------- erasing wrinkles with the brush


def _strongest_detail_vertex(model, panel) -> int:
    return int(np.argmax(np.linalg.norm(_detail(model, panel), axis=1)))


def test_erase_toggle_turns_brush_strokes_into_a_paint_out_mask(fitted) -> None:
    model, vp, panel, errors = fitted
    panel.view_example("brow_raise")
    d0 = _detail(model, panel)
    v = _strongest_detail_vertex(model, panel)  # on the forehead furrows
    tool = vp.tool
    # the card's toggle: the viewport's paint tool now sends its strokes to the eraser
    card = panel.cards.children[0]
    toggle = panel.erase_toggles["brow_raise"]
    assert toggle in card.children and toggle.description == "Erase"
    assert "Erase wrinkles with the brush" in toggle.tooltip
    toggle.value = True
    assert panel.erasing == "brow_raise" and panel.eraser is not None
    assert vp.tool == "paint" and vp.stroke_handler is panel.eraser
    assert "brow_raise" in vp.stroke_target and panel.erase_box.layout.display == ""
    depth = len(model.history.undo_labels)

    # one stroke (press, two moves, release) driven on the handler directly
    panel.erase_radius.value = 0.3
    assert vp.brush_radius == 0.3  # the eraser's radius is the viewport's brush (cursor ring)
    eraser = panel.eraser
    eraser.begin()
    eraser.dab([v])
    eraser.dab([v, int(model.paint.surface.mirror[v])])
    assert eraser.stroking and len(model.history.undo_labels) == depth  # nothing yet
    ov = eraser.overlay()
    assert ov is not None and ov[v] == pytest.approx(1.0) and 0 < np.count_nonzero(ov) < 2000
    assert eraser.end() is True
    assert _errors(errors) == "" and panel.error_line.value == ""
    assert model.history.undo_labels[-1] == "Erase wrinkles of brow_raise"
    assert len(model.history.undo_labels) == depth + 1  # one undo step per stroke
    mask = eraser.last_mask
    d1 = _detail(model, panel)
    # erased under the brush (at the example pose its details are reproduced), kept elsewhere
    inside, outside = mask >= 0.999, mask == 0
    assert (
        np.linalg.norm(d1[inside], axis=1).max() < 0.05 * np.linalg.norm(d0[inside], axis=1).max()
    )
    assert np.allclose(d1[outside], d0[outside], atol=0.05 * np.abs(d0).max())
    assert np.linalg.norm(d1[outside]) > 0.5 * np.linalg.norm(d0[outside])
    assert "erased <b>brow_raise</b>" in panel.status.value
    assert panel.erasing == "brow_raise" and panel.erase_toggles["brow_raise"].value

    # undo puts the earlier details back exactly, redo erases again
    model.undo()
    np.testing.assert_array_equal(_detail(model, panel), d0)
    model.redo()
    np.testing.assert_array_equal(_detail(model, panel), d1)

    # an empty stroke (cancelled, or nothing under the brush) is no undo step
    eraser.begin()
    eraser.cancel()
    assert eraser.end() is False and len(model.history.undo_labels) == depth + 1

    # untoggling gives the previous tool back; strokes paint expressions again
    panel.erase_toggles["brow_raise"].value = False
    assert panel.eraser is None and vp.stroke_handler is None and vp.stroke_target == ""
    assert vp.tool == tool and panel.erase_box.layout.display == "none"


def test_eraser_strokes_from_the_viewport_messages(fitted) -> None:
    model, vp, panel, errors = fitted
    panel.view_example("brow_raise")
    v = _strongest_detail_vertex(model, panel)
    panel.start_erasing("brow_raise")
    panel.erase_toggles["smile"].value = True  # one example at a time
    assert panel.erasing == "smile" and not panel.erase_toggles["brow_raise"].value
    panel.start_erasing("brow_raise")
    depth = len(model.history.undo_labels)
    sent = dict(vp.tint_updates_sent)
    msg = {"type": "stroke"}
    vp._on_frontend_msg(vp, {**msg, "phase": "start", "vertices": [v], "seq": 1}, [])
    # the stroke's mask is the viewport's paint overlay while painting; no paint layer
    w = np.frombuffer(vp._tint, np.float32)
    assert w.size == model.n_vertices and w[v] == pytest.approx(1.0)
    vp._on_frontend_msg(vp, {**msg, "phase": "move", "vertices": [v + 1], "seq": 2}, [])
    vp._on_frontend_msg(vp, {**msg, "phase": "end", "vertices": [], "seq": 3}, [])
    assert _errors(errors) == ""
    assert vp.tint_updates_sent != sent
    assert len(model.paint) == 0 and not model.interacting
    assert model.history.undo_labels[-1] == "Erase wrinkles of brow_raise"
    assert len(model.history.undo_labels) == depth + 1
    assert vp._tint == b""  # the overlay goes with the stroke
    assert np.linalg.norm(_detail(model, panel)[v]) < 1e-4
    # a bad message cancels the stroke and reports; no half edit
    vp._on_frontend_msg(vp, {**msg, "phase": "start", "vertices": [model.n_vertices], "seq": 4}, [])
    assert "vertex ids must be in" in _errors(errors) and len(model.history.undo_labels) == depth + 1
    panel.stop_erasing()
    assert vp.stroke_handler is None


def test_erase_from_code_and_scale_are_undoable_and_a_refit_ends_erasing(fitted) -> None:
    model, vp, panel, _ = fitted
    panel.view_example("brow_raise")
    d0 = _detail(model, panel)
    right = (np.asarray(model.vertices)[:, 0] < 0).astype(float)
    assert panel.erase_wrinkles("brow_raise", right)
    assert not panel.erase_wrinkles("brow_raise", np.zeros(model.n_vertices))  # no step
    panel.scale_example("brow_raise", 2.0)
    assert model.history.undo_labels[-2:] == [
        "Erase wrinkles of brow_raise",
        "Scale wrinkles of brow_raise ×2",
    ]
    edited = model.wrinkles.pose_space
    d2 = _detail(model, panel)
    model.undo()
    model.undo()
    np.testing.assert_array_equal(_detail(model, panel), d0)
    with pytest.raises(KeyError, match="no example"):
        panel.start_erasing("nope")
    panel.start_erasing("brow_raise")
    assert vp.tool == "paint"
    model.redo()
    model.redo()
    assert model.wrinkles.pose_space is edited  # the same fit back: no refit
    np.testing.assert_array_equal(_detail(model, panel), d2)
    panel.fit()  # a refit is an undo step too; the edits' steps stay behind it
    assert model.history.undo_labels[-1] == "Fit wrinkles (6 examples)"
    assert panel.erasing == "brow_raise"  # same examples: still erasing
    np.testing.assert_allclose(_detail(model, panel), d0, atol=1e-6)
    model.undo()  # the edited fit back, exactly
    assert model.wrinkles.pose_space is edited
    np.testing.assert_array_equal(_detail(model, panel), d2)
    vp.tool = "orbit"  # another tool (a cell, another tab) ends erasing
    assert panel.eraser is None and vp.stroke_handler is None


def test_workbench_keeps_the_sculpt_tab_while_erasing() -> None:
    wb = Workbench(load_sample("head"))
    try:
        wb.tabs.selected_index = 1  # Sculpt
        wb.wrinkles.fit()
        wb.wrinkles.erase_toggles["brow_raise"].value = True
        assert wb.viewport.tool == "paint" and wb.tabs.selected_index == 1
        assert not wb.panel_built("paint")  # the Paint tab was not opened
        wb.wrinkles.erase_toggles["brow_raise"].value = False
        assert wb.viewport.tool == "sculpt" and wb.tabs.selected_index == 1
        wb.wrinkles.start_erasing("smile")
        wb.tabs.selected_index = 3  # Paint: its strokes paint expressions, not wrinkles
        assert wb.wrinkles.eraser is None and wb.viewport.stroke_handler is None
        assert wb.viewport.tool == "paint"
        assert wb.errors.outputs == ()
    finally:
        wb.close()
