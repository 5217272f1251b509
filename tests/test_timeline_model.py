"""Keys on the model: keying, scrubbing, evaluate_at, undo."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.model import FaceModel, HandleSet, ModelError


def test_key_scrub_and_evaluate_at(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weight("up", 0.0)
    m.timeline.key_weights(0.0, ["up"], interpolation="linear")
    m.set_weight("up", 1.0)
    m.timeline.key_weights(2.0, interpolation="linear")
    assert m.tracks.start == 0.0 and m.tracks.end == 2.0
    mid = m.evaluate_at(1.0)
    assert mid[4, 2] == pytest.approx(0.5)
    assert m.weights["up"] == 1.0  # evaluate_at changes nothing
    seen: list[float] = []
    m.events.time.connect(seen.append)
    m.set_time(0.5)
    assert seen == [0.5] and m.weights["up"] == pytest.approx(0.25)
    np.testing.assert_allclose(m.evaluate(), m.evaluate_at(0.5), atol=1e-7)


def test_key_edits_are_undoable(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weight("up", 0.3)
    m.timeline.key_weights(1.0)
    assert "weights/up" in m.tracks.tracks
    m.undo()
    assert not m.tracks.tracks
    m.redo()
    m.timeline.move_key("weights/up", 0, 1.5)
    assert m.tracks.tracks["weights/up"].times.tolist() == [1.5]
    m.timeline.delete_key("weights/up", 0)
    assert not m.tracks.tracks
    m.undo()
    m.undo()
    assert m.tracks.tracks["weights/up"].times.tolist() == [1.0]


def test_key_expression_keys_its_weights_and_zeroes_other_keyed_shapes(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weight("left", 1.0)
    m.expressions.save("west")
    m.reset_weights()
    m.key_expression(0.0, "up")
    m.key_expression(1.0, "west")
    s0, s1 = m.tracks.evaluate(0.0), m.tracks.evaluate(1.0)
    assert s0.weights == {"up": 1.0, "left": 0.0}
    assert s1.weights == {"up": 0.0, "left": 1.0}
    with pytest.raises(KeyError, match="no expression"):
        m.key_expression(2.0, "nope")


def test_a_painted_expression_becomes_a_keyed_blendshape_reused_when_keyed_again(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.paint.flood("left", 0.5)  # half of 'left' painted on the neutral: no slider moved
    painted = m.evaluate().copy()
    m.expressions.save("half_west")
    m.paint.clear()
    m.key_expression(0.0, "up", interpolation="linear")
    m.key_expression(1.0, "half_west", interpolation="linear")
    (baked,) = set(m.shape_names) - {"up", "left"}
    np.testing.assert_array_equal(m.shape(baked).delta, painted - m.vertices.astype(np.float32))
    np.testing.assert_allclose(m.evaluate_at(1.0), painted, rtol=0, atol=1e-7)
    # linear in between: half of 'up' plus half of the painted look (worked by hand)
    mid = m.vertices.copy()
    mid[4, 2] += 0.5 * 1.0
    mid[[0, 3, 6], 0] += 0.5 * 0.5 * -0.5
    np.testing.assert_allclose(m.evaluate_at(0.5), mid, rtol=0, atol=1e-6)
    m.key_expression(2.0, "half_west")  # the same look again: the same shape, one more key
    assert len(m.shape_names) == 3 and m.history.undo_labels[-1] == "Key half_west at 2s"
    np.testing.assert_allclose(m.evaluate_at(2.0), painted, rtol=0, atol=1e-7)
    assert m.tracks.evaluate(0.0).weights == {"up": 1.0, baked: 0.0}
    m.undo()
    m.undo()
    assert m.shape_names == ["up", "left"] and set(m.tracks.weight_tracks) == {"up"}
    m.redo()
    np.testing.assert_allclose(m.evaluate_at(1.0), painted, rtol=0, atol=1e-7)


def test_a_baked_expression_holds_keyed_handles_at_rest(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.handles.set(HandleSet([4], [[0, 0, 0]], ("c",), [-1]))
    m.move_handle(0, [0.0, 0.0, 0.4])
    m.handles.key(0.0, interpolation="linear")
    m.handles.reset_offsets()
    m.paint.flood("up", 0.25)
    painted = m.evaluate().copy()
    m.expressions.save("quarter_up")
    m.paint.clear()
    m.key_expression(1.0, "quarter_up", interpolation="linear")
    assert "handles" in m.tracks.evaluate(1.0).others
    np.testing.assert_array_equal(m.tracks.evaluate(1.0).others["handles"], [[0.0, 0.0, 0.0]])
    np.testing.assert_allclose(m.evaluate_at(1.0), painted, rtol=0, atol=1e-7)


def test_a_plain_expression_keys_its_recipe_without_a_new_shape(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weights({"up": 0.5, "left": 1.0})
    saved = m.evaluate().copy()
    m.expressions.save("mix")
    m.reset_weights()
    m.key_expression(1.0, "mix")
    assert m.shape_names == ["up", "left"]
    assert m.tracks.evaluate(1.0).weights == {"up": 0.5, "left": 1.0}
    np.testing.assert_allclose(m.evaluate_at(1.0), saved, rtol=0, atol=1e-7)


def test_handle_keys_animate_the_shell_layer(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.handles.set(HandleSet([4], [[0, 0, 0]], ("c",), [-1]))
    m.handles.key(0.0, interpolation="linear")
    m.move_handle(0, [0.0, 0.0, 0.4])
    m.handles.key(1.0, interpolation="linear")
    m.handles.reset_offsets()
    assert m.evaluate_at(0.5)[4, 2] == pytest.approx(0.2, abs=1e-6)
    m.set_time(1.0)
    assert m.handles.offsets[0, 2] == pytest.approx(0.4)


def test_bad_time_and_timeline(tiny_model: FaceModel) -> None:
    with pytest.raises(ModelError, match="finite"):
        tiny_model.set_time(float("nan"))
    with pytest.raises(ModelError, match="Timeline"):
        tiny_model.timeline.set({"x": 1})  # type: ignore[arg-type]
    with pytest.raises(ModelError, match="no handles"):
        tiny_model.handles.key(0.0)


# ------------------------------------------------------------------ head pose
HALF = float(np.sqrt(0.5))
QZ90 = [0.0, 0.0, HALF, HALF]  # 90 degrees about +z: (x, y, z) -> (-y, x, z)


def test_head_pose_keys_move_the_shown_face_like_evaluate_at(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weight("up", 1.0)
    m.timeline.key_head_pose(0.0, [0, 0, 0, 1], [0, 0, 0], interpolation="linear")
    m.timeline.key_head_pose(2.0, QZ90, [1.0, 2.0, 3.0], interpolation="linear")
    assert m.history.undo_labels[-1] == "Key head pose at 2s"
    local = m.evaluate(posed=False).copy()
    # at a key, by hand: vertex 1 = (1, 0, 0) -> R(1, 0, 0) + t = (0, 1, 0) + (1, 2, 3);
    # vertex 4 = (1, 1, 0) lifted by 'up' to (1, 1, 1) -> (-1, 1, 1) + (1, 2, 3)
    at2 = m.evaluate_at(2.0)
    np.testing.assert_allclose(at2[1], [1.0, 3.0, 3.0], atol=1e-6)
    np.testing.assert_allclose(at2[4], [0.0, 3.0, 4.0], atol=1e-6)
    for t in (2.0, 0.7, 1.0):
        m.set_time(t)
        np.testing.assert_array_equal(m.evaluate(), m.evaluate_at(t))
        np.testing.assert_array_equal(m.evaluate(posed=False), local)  # the pose is not a layer
    # half-way: slerp to 45 degrees, translation half-way
    p = m.timeline.head_pose
    assert p is not None
    np.testing.assert_allclose(p, [0.5, 1.0, 1.5, 0, 0, np.sin(np.pi / 8), np.cos(np.pi / 8)], atol=1e-12)
    np.testing.assert_allclose(m.head_matrix()[:3, 3], [0.5, 1.0, 1.5])


def test_undoing_a_head_pose_key_moves_the_face_back_at_once(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_time(1.0)
    rest = m.evaluate().copy()
    shown: list[bool] = []
    m.events.deformed.connect(shown.append)
    m.timeline.key_head_pose(1.0, QZ90)  # at the playhead: the face turns without set_time
    assert shown == [True] and m.timeline.head_pose is not None
    np.testing.assert_allclose(m.evaluate()[1], [0.0, 1.0, 0.0], atol=1e-6)
    np.testing.assert_array_equal(m.evaluate(), m.evaluate_at(1.0))
    m.undo()
    assert not m.tracks.tracks and m.timeline.head_pose is None and shown == [True, True]
    np.testing.assert_array_equal(m.evaluate(), rest)
    m.redo()
    np.testing.assert_array_equal(m.evaluate(), m.evaluate_at(1.0))


def test_key_head_pose_defaults_matrices_and_errors(tiny_model: FaceModel) -> None:
    m = tiny_model
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # the same 90 degrees about z
    m.timeline.key_head_pose(0.0, R, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(m.tracks.head_pose.keys[0].value, [0, 0, 1, *QZ90], atol=1e-12)
    m.timeline.key_head_pose(1.0, translation=[2.0, 0.0, 0.0])  # rotation defaults to the one at t=1
    np.testing.assert_allclose(m.tracks.head_pose.keys[1].value, [2, 0, 0, *QZ90], atol=1e-12)
    m.timeline.key_head_pose(1.0, [0, 0, 0, 2])  # translation defaults to the one at t=1; normalised
    np.testing.assert_allclose(m.tracks.head_pose.keys[1].value, [2, 0, 0, 0, 0, 0, 1])
    with pytest.raises(ModelError, match="rotation must be a non-zero finite"):
        m.timeline.key_head_pose(0.0, [0, 0, 0, 0])
    with pytest.raises(ModelError, match="orthonormal"):
        m.timeline.key_head_pose(0.0, 2 * np.eye(3))
    with pytest.raises(ModelError, match="translation must be 3 finite numbers"):
        m.timeline.key_head_pose(0.0, translation=[1.0, 2.0])
    with pytest.raises(ModelError, match="time must be finite"):
        m.timeline.key_head_pose(float("inf"))


def test_expressions_are_saved_without_the_head_pose(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.timeline.key_head_pose(0.0, QZ90, [5.0, 0.0, 0.0])
    m.set_weight("up", 1.0)
    m.expressions.save("lifted")
    expect = np.zeros((9, 3), np.float32)
    expect[4, 2] = 1.0
    np.testing.assert_array_equal(m.expressions["lifted"].displacement, expect)
    m.key_expression(1.0, "lifted")  # its recipe plays back: no baked shape
    assert m.shape_names == ["up", "left"]
