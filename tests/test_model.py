"""FaceModel: evaluation, events, interactions, undo/redo."""

from __future__ import annotations

import gc
import threading
import types
from typing import Any

import numpy as np
import pytest

from workbench.core.pipeline import FunctionLayer
from workbench.model import BlendShape, FaceModel, HandleSet, ModelError, ModelMetadata


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
    tiny_model.handles.set(HandleSet([4, 0], np.zeros((2, 3)), ("centre", "corner"), [-1, -1]))
    assert tiny_model.handles.vertices.tolist() == [4, 0]
    tiny_model.undo()
    assert len(tiny_model.handles) == 0
    assert seen == ["handles", "handles"]
    with pytest.raises(ModelError, match="vertex ids"):
        tiny_model.handles.set(HandleSet([99], np.zeros((1, 3))))
    assert tiny_model.regions.state is None and dict(tiny_model.paint) == {} and not tiny_model.tracks.tracks


def test_registered_layer_adds_to_evaluation(tiny_model: FaceModel) -> None:
    extra = np.zeros((9, 3), np.float32)
    extra[8, 1] = 2.0
    tiny_model.register_layer(FunctionLayer("test", lambda m: extra))
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


def _array_bytes_held(root: Any, model: FaceModel) -> int:
    """Bytes of the numpy buffers reachable from ``root`` without going through ``model``.

    Views count as their whole base buffer (a view of one row of a (k, n, 3)
    stack keeps the whole stack alive). Functions are followed through their
    closures and defaults only (not their module globals), and classes and
    modules are not entered, so only what the history itself keeps alive counts.
    """
    seen: set[int] = set()
    buffers: dict[int, int] = {}
    todo = [root]
    while todo:
        o = todo.pop()
        if id(o) in seen or o is model or isinstance(o, type | types.ModuleType):
            continue
        seen.add(id(o))
        if isinstance(o, np.ndarray):
            base = o
            while isinstance(base.base, np.ndarray):
                base = base.base
            buffers[id(base)] = base.nbytes
        elif isinstance(o, types.FunctionType):
            todo.extend(o.__closure__ or ())
            todo.extend(o.__defaults__ or ())
        else:
            todo.extend(gc.get_referents(o))
    return sum(buffers.values())


def _big_model(n: int = 4000, k: int = 8) -> FaceModel:
    rng = np.random.default_rng(1)
    shapes = [BlendShape(f"s{i}", rng.normal(size=(n, 3))) for i in range(k)]
    return FaceModel(rng.normal(size=(n, 3)), np.array([[0, 1, 2]]), shapes)


def test_shape_property_edits_hold_no_delta_memory_in_the_history() -> None:
    m = _big_model()
    stack_bytes = m.deltas.nbytes  # 384 kB: 30 whole-stack references would be 11.5 MB
    for i in range(10):
        m.set_shape_mute("s1", i % 2 == 0)
        m.rename_shape(f"s2{'' if i == 0 else f'_{i - 1}'}", f"s2_{i}")
        m.set_shape_range("s3", -1.0 - i, 1.0 + i)
    assert len(m.history.undo_labels) == 30
    held = _array_bytes_held(m.history, m)
    assert held < m.shape("s0").delta.nbytes  # not even one delta, let alone a stack
    assert held <= m.history.nbytes  # the byte budget sees everything the steps hold
    for _ in range(30):
        m.undo()
    assert m.shape_names == [f"s{i}" for i in range(8)]
    assert not m.shape("s1").mute and m.shape("s3").slider_max == 1.0
    assert _array_bytes_held(m.history, m) < stack_bytes


def test_add_remove_and_mask_steps_hold_only_what_changed() -> None:
    m = _big_model()
    removed = m.shape("s5").delta.copy()
    delta_bytes = removed.nbytes
    mask = np.linspace(0.0, 1.0, m.n_vertices)
    m.set_shape_mask("s0", mask)
    m.add_shape("extra", np.ones((m.n_vertices, 3)))
    m.remove_shape("s5")
    held = _array_bytes_held(m.history, m)
    # the added delta, the removed delta and the new mask, nothing else
    assert held <= 2 * delta_bytes + 2 * mask.astype(np.float32).nbytes
    assert held <= m.history.nbytes
    m.undo()
    np.testing.assert_array_equal(m.shape("s5").delta, removed)
    assert m.shape_names.index("s5") == 5
    m.undo()
    m.undo()
    assert m.shape("s0").vertex_mask is None and "extra" not in m.shape_names
    m.redo()
    np.testing.assert_allclose(m.shape("s0").vertex_mask, mask, atol=1e-7)


def test_history_byte_budget_bounds_the_memory_really_held() -> None:
    m = _big_model()
    m.history.max_bytes = 200_000  # a delta is 48 kB
    for i in range(20):
        m.add_shape(f"extra{i}", np.full((m.n_vertices, 3), float(i)))
        m.set_shape_mute(f"extra{i}", True)
        m.set_shape_range(f"extra{i}", -1.0, 2.0)
    held = _array_bytes_held(m.history, m)
    assert held <= m.history.max_bytes + m.shape("s0").delta.nbytes


def test_set_metadata_is_one_undoable_step_with_events(tiny_model: FaceModel) -> None:
    seen: list[str] = []
    tiny_model.events.metadata.connect(lambda: seen.append("metadata"))
    old = tiny_model.metadata
    new = ModelMetadata(name="grid", units="cm")
    tiny_model.set_metadata(new)
    assert tiny_model.metadata is new and tiny_model.history.undo_labels == ["Set metadata"]
    assert tiny_model.undo() == "Set metadata"
    assert tiny_model.metadata is old
    tiny_model.redo()
    assert tiny_model.metadata is new
    assert seen == ["metadata"] * 3
    with pytest.raises(ModelError, match="ModelMetadata"):
        tiny_model.set_metadata({"name": "x"})  # type: ignore[arg-type]


def test_set_shell_stiffness_is_one_undoable_step_with_events() -> None:
    from grid_meshes import grid_polygons

    V, polys = grid_polygons(6, 6)  # the boundary is held, so inner vertices follow the shell
    m = FaceModel(V, None, [], polygons=polys)
    m.handles.set(HandleSet([24, 0], [[0.0, 0.0, 0.5], [0.0, 0.0, 0.0]], ("c", "corner"), [-1, -1]))
    m.history.clear()
    before = m.evaluate().copy()
    old = m.handles.stiffness
    seen: list[str] = []
    m.events.shell_stiffness.connect(lambda: seen.append("stiffness"))
    m.events.deformed.connect(lambda final: seen.append(f"deformed {final}"))
    m.handles.set_stiffness(old[0] * 100.0, old[1] / 100.0)
    after = m.evaluate().copy()
    assert np.abs(after - before).max() > 1e-3  # the stiffness really changes the handle layer
    assert m.history.undo_labels == ["Shell stiffness"]
    m.undo()
    assert m.handles.stiffness == old
    np.testing.assert_allclose(m.evaluate(), before, atol=1e-6)
    m.redo()
    assert m.handles.stiffness == (old[0] * 100.0, old[1] / 100.0)
    np.testing.assert_allclose(m.evaluate(), after, atol=1e-6)
    assert seen == ["stiffness", "deformed True"] * 3
    m.handles.set_stiffness(*m.handles.stiffness)  # no change: no step
    assert m.history.undo_labels == ["Shell stiffness"]
    with pytest.raises(ModelError, match="finite k_s >= 0"):
        m.handles.set_stiffness(float("nan"), 1.0)


def test_a_model_without_blendshapes_evaluates_to_its_neutral() -> None:
    m = FaceModel(np.eye(3), np.array([[0, 1, 2]]))
    np.testing.assert_array_equal(m.evaluate(), np.eye(3, dtype=np.float32))


def test_to_pyvista_without_the_ui_module_names_what_to_import(tiny_model, monkeypatch):
    """The core never imports pyvista: without widgets.render registered, a clear error."""
    from workbench import converters

    monkeypatch.setattr(converters, "_CONVERTERS", {})
    with pytest.raises(ImportError, match=r"import widgets\.render"):
        tiny_model.to_pyvista()
    with pytest.raises(ImportError, match=r"import widgets\.render"):
        FaceModel.from_pyvista(object())
