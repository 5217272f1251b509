"""FaceModel: evaluation, events, interactions, undo/redo."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from workbench.model import BlendShape, FaceModel, HandleSet, ModelError


def test_triangulates_quads_and_keeps_polygons(tiny_model: FaceModel) -> None:
    assert tiny_model.faces.shape == (8, 3)
    assert len(tiny_model.polygons) == 4
    assert tiny_model.polygons[0].tolist() == [0, 1, 4, 3]
    # fan triangulation keeps the polygon's orientation: normals point +z
    V = tiny_model.vertices
    a, b, c = (V[tiny_model.faces[:, i]] for i in range(3))
    assert np.all(np.cross(b - a, c - a)[:, 2] > 0)


def test_evaluate_is_neutral_plus_weighted_deltas(tiny_model: FaceModel) -> None:
    np.testing.assert_array_equal(tiny_model.evaluate(), tiny_model.vertices.astype(np.float32))
    tiny_model.set_weights({"up": 0.25, "left": 2.0})
    expected = tiny_model.vertices.copy()
    expected[4, 2] += 0.25
    expected[[0, 3, 6], 0] += -1.0
    np.testing.assert_allclose(tiny_model.evaluate(), expected, atol=1e-7)
    assert tiny_model.evaluate().dtype == np.float32
    assert not tiny_model.evaluate().flags.writeable


def test_evaluate_dense_path_matches_axpy_path() -> None:
    rng = np.random.default_rng(0)
    V = rng.normal(size=(50, 3))
    F = np.array([[0, 1, 2]])
    shapes = [BlendShape(f"s{i}", rng.normal(size=(50, 3))) for i in range(8)]
    m = FaceModel(V, F, shapes)
    w = rng.uniform(size=8)
    m.set_weights({f"s{i}": w[i] for i in range(8)})  # dense path (all active)
    dense = m.evaluate().copy()
    ref = V + np.einsum("k,knc->nc", w, np.stack([s.delta for s in shapes]).astype(np.float64))
    np.testing.assert_allclose(dense, ref, atol=1e-5)
    m.set_weights({f"s{i}": 0.0 for i in range(1, 8)})  # one active: axpy path
    np.testing.assert_allclose(m.evaluate(), V + w[0] * shapes[0].delta, atol=1e-5)


def test_cache_invalidated_only_by_dependencies(tiny_model: FaceModel) -> None:
    a = tiny_model.evaluate()
    assert tiny_model.evaluate() is a
    tiny_model.set_weight("up", 1.0)
    b = tiny_model.evaluate()
    assert b is not a and b[4, 2] == 1.0
    tiny_model.set_shape_mute("up", True)
    assert tiny_model.evaluate()[4, 2] == 0.0
    assert tiny_model.weights["up"] == 1.0  # mute keeps the weight


def test_weights_clamped_to_slider_range(tiny_model: FaceModel) -> None:
    tiny_model.set_weight("up", 5.0)
    assert tiny_model.weights["up"] == 1.0
    tiny_model.set_weight("left", -3.0)
    assert tiny_model.weights["left"] == -1.0
    with pytest.raises(ModelError, match="finite"):
        tiny_model.set_weight("up", float("nan"))
    with pytest.raises(KeyError, match="no blendshape named 'nope'"):
        tiny_model.set_weight("nope", 1.0)


def test_vertex_mask_scales_delta(tiny_model: FaceModel) -> None:
    mask = np.zeros(9)
    mask[3] = 0.5
    tiny_model.set_shape_mask("left", mask)
    tiny_model.set_weight("left", 1.0)
    ev = tiny_model.evaluate()
    assert ev[0, 0] == 0.0 and ev[3, 0] == pytest.approx(-0.25)
    # the stored delta itself is unchanged
    assert tiny_model.deltas[1, 0, 0] == -0.5


def test_undo_redo_every_edit(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weight("up", 0.5)
    m.add_shape("new", np.ones((9, 3)), weight=0.5)
    m.rename_shape("left", "west")
    m.set_shape_mute("up", True)
    m.set_shape_range("west", -2.0, 3.0)
    m.remove_shape("new")
    assert m.shape_names == ["up", "west"]
    labels = m.history.undo_labels
    assert labels == [
        "Set up", "Add shape new", "Rename left to west", "Mute up", "Range of west", "Remove shape new",
    ]
    for _ in labels:
        assert m.undo() is not None
    assert m.undo() is None
    assert m.shape_names == ["up", "left"]
    assert dict(m.weights) == {"up": 0.0, "left": 0.0}
    assert not m.shape("up").mute
    np.testing.assert_array_equal(m.evaluate(), m.vertices.astype(np.float32))
    for _ in labels:
        m.redo()
    assert m.shape_names == ["up", "west"]
    assert m.shape("west").slider_max == 3.0 and m.shape("up").mute
    assert m.weights["up"] == 0.5


def test_new_edit_clears_redo(tiny_model: FaceModel) -> None:
    tiny_model.set_weight("up", 0.5)
    tiny_model.undo()
    assert tiny_model.can_redo
    tiny_model.set_weight("left", 0.5)
    assert not tiny_model.can_redo


def test_interaction_emits_changing_then_one_changed_and_one_undo_step(tiny_model: FaceModel) -> None:
    changing: list[dict] = []
    changed: list[dict] = []
    deformed: list[bool] = []
    tiny_model.events.weights_changing.connect(changing.append)
    tiny_model.events.weights.connect(changed.append)
    tiny_model.events.deformed.connect(deformed.append)
    with tiny_model.interaction("Drag up"):
        for v in np.linspace(0.1, 0.9, 9):
            tiny_model.set_weight("up", v)
        assert changed == []
    assert len(changing) == 9
    assert changed == [{"up": pytest.approx(0.9)}]
    assert deformed == [False] * 9 + [True]
    assert tiny_model.history.undo_labels == ["Drag up"]
    tiny_model.undo()
    assert tiny_model.weights["up"] == 0.0
    tiny_model.redo()
    assert tiny_model.weights["up"] == pytest.approx(0.9)


def test_interaction_that_returns_to_start_records_nothing(tiny_model: FaceModel) -> None:
    with tiny_model.interaction("Wiggle"):
        tiny_model.set_weight("up", 0.3)
        tiny_model.set_weight("up", 0.0)
    assert not tiny_model.can_undo


def test_shape_edits_refused_inside_interaction(tiny_model: FaceModel) -> None:
    with tiny_model.interaction("Drag"), pytest.raises(ModelError, match="interaction"):
        tiny_model.add_shape("x", np.zeros((9, 3)))


def test_handles_slot_is_undoable_and_evented(tiny_model: FaceModel) -> None:
    seen: list[str] = []
    tiny_model.events.handles.connect(lambda: seen.append("handles"))
    assert len(tiny_model.handles) == 0
    tiny_model.set_handles(HandleSet([4, 0], np.zeros((2, 3)), ("centre", "corner"), [-1, -1]))
    assert tiny_model.handles.vertices.tolist() == [4, 0]
    tiny_model.undo()
    assert len(tiny_model.handles) == 0
    assert seen == ["handles", "handles"]
    with pytest.raises(ModelError, match="vertex ids"):
        tiny_model.set_handles(HandleSet([99], np.zeros((1, 3))))
    assert tiny_model.regions is None and dict(tiny_model.paint_layers) == {} and not tiny_model.tracks.tracks


def test_registered_layer_adds_to_evaluation(tiny_model: FaceModel) -> None:
    extra = np.zeros((9, 3), np.float32)
    extra[8, 1] = 2.0
    tiny_model.register_layer("test", lambda m: extra)
    assert tiny_model.evaluate()[8, 1] == 4.0  # grid y=2 plus 2


def test_history_is_bounded_by_bytes() -> None:
    V = np.zeros((1000, 3))
    m = FaceModel(V, np.array([[0, 1, 2]]))
    m.history.max_bytes = 100_000  # each added shape holds 12 kB
    for i in range(20):
        m.add_shape(f"s{i}", np.ones((1000, 3)))
    assert 0 < len(m.history.undo_labels) < 20
    assert m.history.nbytes <= 100_000 + 12_000 + 64 * 20


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"vertices": np.zeros((0, 3))}, "non-empty"),
        ({"vertices": np.full((3, 3), np.nan)}, "NaN/inf"),
        ({"faces": np.array([[0, 1, 7]])}, "outside"),
        ({"shapes": [BlendShape("a", np.zeros((4, 3)))]}, "4 vertices, the neutral has 3"),
        ({"shapes": [BlendShape("a", np.zeros((3, 3))), BlendShape("a", np.zeros((3, 3)))]}, "duplicate"),
    ],
)
def test_constructor_rejects_bad_input(kwargs: dict, match: str) -> None:
    args = {"vertices": np.eye(3), "faces": np.array([[0, 1, 2]]), "shapes": []}
    args.update(kwargs)
    with pytest.raises(ModelError, match=match):
        FaceModel(args["vertices"], args["faces"], args["shapes"])


def test_blendshape_validation() -> None:
    with pytest.raises(ModelError, match="NaN/inf at vertex 1"):
        BlendShape("a", np.array([[0, 0, 0], [np.inf, 0, 0]]))
    with pytest.raises(ModelError, match="slider_min < slider_max"):
        BlendShape("a", np.zeros((2, 3)), 1.0, 0.0)
    with pytest.raises(ModelError, match="vertex_mask"):
        BlendShape("a", np.zeros((2, 3)), vertex_mask=[0.5, 2.0])


def test_concurrent_set_weight_from_threads_is_consistent(tiny_model: FaceModel) -> None:
    def worker(name: str) -> None:
        for v in np.linspace(0, 1, 200):
            tiny_model.set_weight(name, float(v))

    threads = [threading.Thread(target=worker, args=(n,)) for n in ("up", "left")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert tiny_model.weights["up"] == 1.0 and tiny_model.weights["left"] == 1.0
    expected = tiny_model.vertices.copy()
    expected[4, 2] += 1.0
    expected[[0, 3, 6], 0] -= 0.5
    np.testing.assert_allclose(tiny_model.evaluate(), expected, atol=1e-7)
    assert len(tiny_model.history.undo_labels) == 256  # bounded; oldest dropped


def test_history_group_is_one_step_and_rolls_back_on_error(tiny_model: FaceModel) -> None:
    with tiny_model.history.group("Two edits"):
        tiny_model.set_weight("up", 0.5)
        tiny_model.add_shape("x", np.zeros((9, 3)))
    assert tiny_model.history.undo_labels == ["Two edits"]
    tiny_model.undo()
    assert tiny_model.shape_names == ["up", "left"] and tiny_model.weights["up"] == 0.0
    with pytest.raises(KeyError), tiny_model.history.group("Fails"):
        tiny_model.set_weight("up", 0.7)
        tiny_model.set_weight("missing", 1.0)
    assert tiny_model.weights["up"] == 0.0  # the partial edit was rolled back
    assert tiny_model.history.undo_labels == []
