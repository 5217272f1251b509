"""Keys on the model: keying, scrubbing, evaluate_at, undo."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.model import FaceModel, HandleSet, ModelError


def test_key_scrub_and_evaluate_at(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weight("up", 0.0)
    m.key_weights(0.0, ["up"], interpolation="linear")
    m.set_weight("up", 1.0)
    m.key_weights(2.0, interpolation="linear")
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
    m.key_weights(1.0)
    assert "weights/up" in m.tracks.tracks
    m.undo()
    assert not m.tracks.tracks
    m.redo()
    m.move_key("weights/up", 0, 1.5)
    assert m.tracks.tracks["weights/up"].times.tolist() == [1.5]
    m.delete_key("weights/up", 0)
    assert not m.tracks.tracks
    m.undo()
    m.undo()
    assert m.tracks.tracks["weights/up"].times.tolist() == [1.0]


def test_key_expression_keys_its_weights_and_zeroes_other_keyed_shapes(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weight("left", 1.0)
    m.save_expression("west")
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
    m.paint_flood("left", 0.5)  # half of 'left' painted on the neutral: no slider moved
    painted = m.evaluate().copy()
    m.save_expression("half_west")
    m.clear_paint()
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
    m.set_handles(HandleSet([4], [[0, 0, 0]], ("c",), [-1]))
    m.move_handle(0, [0.0, 0.0, 0.4])
    m.key_handles(0.0, interpolation="linear")
    m.reset_handle_offsets()
    m.paint_flood("up", 0.25)
    painted = m.evaluate().copy()
    m.save_expression("quarter_up")
    m.clear_paint()
    m.key_expression(1.0, "quarter_up", interpolation="linear")
    assert m.tracks.evaluate(1.0).handle_offsets is not None
    np.testing.assert_array_equal(m.tracks.evaluate(1.0).handle_offsets, [[0.0, 0.0, 0.0]])
    np.testing.assert_allclose(m.evaluate_at(1.0), painted, rtol=0, atol=1e-7)


def test_a_plain_expression_keys_its_recipe_without_a_new_shape(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_weights({"up": 0.5, "left": 1.0})
    saved = m.evaluate().copy()
    m.save_expression("mix")
    m.reset_weights()
    m.key_expression(1.0, "mix")
    assert m.shape_names == ["up", "left"]
    assert m.tracks.evaluate(1.0).weights == {"up": 0.5, "left": 1.0}
    np.testing.assert_allclose(m.evaluate_at(1.0), saved, rtol=0, atol=1e-7)


def test_handle_keys_animate_the_shell_layer(tiny_model: FaceModel) -> None:
    m = tiny_model
    m.set_handles(HandleSet([4], [[0, 0, 0]], ("c",), [-1]))
    m.key_handles(0.0, interpolation="linear")
    m.move_handle(0, [0.0, 0.0, 0.4])
    m.key_handles(1.0, interpolation="linear")
    m.reset_handle_offsets()
    assert m.evaluate_at(0.5)[4, 2] == pytest.approx(0.2, abs=1e-6)
    m.set_time(1.0)
    assert m.handles.offsets[0, 2] == pytest.approx(0.4)


def test_bad_time_and_timeline(tiny_model: FaceModel) -> None:
    with pytest.raises(ModelError, match="finite"):
        tiny_model.set_time(float("nan"))
    with pytest.raises(ModelError, match="Timeline"):
        tiny_model.set_timeline({"x": 1})  # type: ignore[arg-type]
    with pytest.raises(ModelError, match="no handles"):
        tiny_model.key_handles(0.0)
