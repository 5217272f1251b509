"""``model.timeline``'s named edits: add_key, delete_keys, set_interpolation(s), set_tangents, set_fps.

Each is one undo step; undo gives back the very Timeline object it replaced (so
every key, tangent, fps and range bit for bit) and redo the edited one; a bad
argument raises a ModelError naming the method and the argument before
anything changes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.animation.curves import HEAD_POSE
from workbench.methods.regions.tracks import region_level, region_track_name
from workbench.model import FaceModel, HandleSet, ModelError

UP, LEFT = "weights/up", "weights/left"


@pytest.fixture
def keyed(tiny_model: FaceModel) -> FaceModel:
    """'up' keyed 0 / 1 / 0 at 0, 1, 2 s; 'left' keyed at 0 and 2 s; range 0..2 s."""
    m = tiny_model
    for t, up, left in ((0.0, 0.0, 0.0), (1.0, 1.0, None), (2.0, 0.0, 0.5)):
        m.set_weight("up", up)
        names = ["up"] if left is None else ["up", "left"]
        if left is not None:
            m.set_weight("left", left)
        m.timeline.key_weights(t, names)
    return m


def _dump(tl) -> str:
    return json.dumps(tl.to_json(), sort_keys=True)


def _one_step(m: FaceModel, edit, label: str | None = None):
    """Run ``edit``; check it was one undo step that undo/redo reverse exactly; the new timeline."""
    before, depth = m.tracks, len(m.history.undo_labels)
    dumped = _dump(before)
    edit()
    after = m.tracks
    assert after is not before
    assert len(m.history.undo_labels) == depth + 1
    if label is not None:
        assert m.history.undo_labels[-1] == label
    after_dump = _dump(after)
    m.undo()
    assert m.tracks is before and _dump(m.tracks) == dumped
    m.redo()
    assert m.tracks is after and _dump(m.tracks) == after_dump
    return after


def _refused(m: FaceModel, edit, match: str) -> None:
    before, depth = m.tracks, len(m.history.undo_labels)
    with pytest.raises(ModelError, match=match):
        edit()
    assert m.tracks is before and len(m.history.undo_labels) == depth


# ------------------------------------------------------------------ add_key
def test_add_key_with_a_value_extends_the_range(keyed: FaceModel) -> None:
    m = keyed
    tl = _one_step(m, lambda: m.timeline.add_key(UP, 3.0, 0.25, interpolation="linear"),
                   "Key up at 3s")
    tr = tl.tracks[UP]
    assert tr.times.tolist() == [0.0, 1.0, 2.0, 3.0]
    assert float(tr.keys[-1].value) == 0.25 and tr.keys[-1].interpolation == "linear"
    assert (tl.start, tl.end) == (0.0, 3.0)
    tl = _one_step(m, lambda: m.timeline.add_key(LEFT, -0.5, 1.0))
    assert (tl.start, tl.end) == (-0.5, 3.0)
    # a key at an existing time replaces it
    tl = _one_step(m, lambda: m.timeline.add_key(UP, 1.0, 0.75))
    assert tl.tracks[UP].times.tolist() == [0.0, 1.0, 2.0, 3.0]
    assert float(tl.tracks[UP].keys[1].value) == 0.75


def test_add_key_of_the_head_pose(keyed: FaceModel) -> None:
    m = keyed
    half = np.sqrt(0.5)
    pose = [0.1, 0.2, 0.3, 0.0, 0.0, half, half]
    tl = _one_step(m, lambda: m.timeline.add_key(HEAD_POSE, 4.0, pose), "Key head pose at 4s")
    np.testing.assert_allclose(tl.head_pose.evaluate(4.0), pose)
    assert tl.end == 4.0


def test_add_key_of_handles(keyed: FaceModel) -> None:
    m = keyed
    _refused(m, lambda: m.timeline.add_key("handles", 0.0, np.zeros((1, 3))), "no handles")
    m.handles.set(HandleSet([4], np.zeros((1, 3), np.float32)), label="Handles")
    tl = _one_step(m, lambda: m.timeline.add_key("handles", 0.5, [[0.0, 0.0, 0.1]]))
    np.testing.assert_array_equal(tl.tracks["handles"].evaluate(0.5), [[0.0, 0.0, 0.1]])


def test_add_key_refuses_bad_arguments(keyed: FaceModel) -> None:
    m = keyed
    add = m.timeline.add_key
    _refused(m, lambda: add("weights/ghost", 0.0, 1.0), r"add_key: track 'weights/ghost' names no shape")
    _refused(m, lambda: add("nonsense", 0.0, 1.0), r"add_key: track must be .* got 'nonsense'")
    _refused(m, lambda: add(UP, float("nan"), 1.0), r"add_key: time must be finite")
    _refused(m, lambda: add(UP, "soon", 1.0), r"add_key: time must be a number")
    _refused(m, lambda: add(UP, 0.5, [1.0, 2.0]), r"add_key: value for track 'weights/up' must have shape \(\)")
    _refused(m, lambda: add(UP, 0.5, np.inf), r"add_key: value .* must be finite")
    _refused(m, lambda: add(UP, 0.5, "high"), r"add_key: value must be numbers")
    _refused(m, lambda: add(HEAD_POSE, 0.5, [0.0] * 6), r"'head_pose' must have shape \(7,\)")
    _refused(m, lambda: add(HEAD_POSE, 0.5, [0.0] * 7), r"zero quaternion")
    _refused(m, lambda: add(UP, 0.5, 1.0, interpolation="cubic"),
             r"add_key: interpolation must be one of \['step', 'linear', 'bezier'\], got 'cubic'")


def test_add_key_of_a_region_track() -> None:
    import workbench

    m = workbench.load_sample("head")
    st = m.segment_regions(0.25)
    k = len(m.shape_names)
    name = region_track_name(0, st.regions.names[0][0])
    _refused(m, lambda: m.timeline.add_key(name, 0.0, np.zeros(k - 1)), rf"must have shape \({k},\)")
    values = np.linspace(0.0, 1.0, k)
    tl = _one_step(m, lambda: m.timeline.add_key(name, 0.5, values))
    np.testing.assert_array_equal(tl.tracks[name].evaluate(0.5), values)
    assert region_level(tl) == 0 and tl.end == 0.5


# ------------------------------------------------------------------ delete_keys
def test_delete_keys_is_one_step_and_each_key_once(keyed: FaceModel) -> None:
    m = keyed
    # (up, -1) is (up, 2): deleted once; the highest index goes first
    tl = _one_step(
        m, lambda: m.timeline.delete_keys([(UP, 0), (UP, 2), (UP, -1), (LEFT, 1)]), "Delete 3 keys"
    )
    assert tl.tracks[UP].times.tolist() == [1.0]
    assert tl.tracks[LEFT].times.tolist() == [0.0]
    assert m.timeline.delete_keys([]) == 0 and m.tracks is tl  # nothing: no step
    tl = _one_step(m, lambda: m.timeline.delete_keys([(LEFT, 0)]), "Delete key 0 of weights/left")
    assert LEFT not in tl.tracks  # its last key: the track goes


def test_delete_keys_checks_every_key_first(keyed: FaceModel) -> None:
    m = keyed
    d = m.timeline.delete_keys
    _refused(m, lambda: d([(UP, 0), ("weights/ghost", 0)]), r"delete_keys: track 'weights/ghost' has no keys")
    _refused(m, lambda: d([(UP, 0), (UP, 3)]),
             r"delete_keys: index 3 is out of range for track 'weights/up' \(3 keys\)")
    _refused(m, lambda: d([(UP, -4)]), r"index -4 is out of range")
    _refused(m, lambda: d([(UP, 1.0)]), r"delete_keys: index must be an int, got 1.0")
    _refused(m, lambda: d([(UP, True)]), r"index must be an int, got True")
    _refused(m, lambda: d([UP]), r"delete_keys: keys must be \(track, index\) pairs")
    _refused(m, lambda: m.timeline.delete_key(UP, 7), r"delete_key: index 7 is out of range")


# ------------------------------------------------------------------ interpolation
def test_set_interpolation_of_one_key_or_a_whole_track(keyed: FaceModel) -> None:
    m = keyed
    tl = _one_step(m, lambda: m.timeline.set_interpolation(UP, 0, "linear"), "Set interpolation linear (up)")
    assert tl.tracks[UP].interpolations == ("linear", "bezier", "bezier")
    assert tl.evaluate(0.5).weights["up"] == pytest.approx(0.5)
    tl = _one_step(m, lambda: m.timeline.set_interpolation(UP, None, "step"))
    assert tl.tracks[UP].interpolations == ("step", "step", "step")
    assert tl.evaluate(0.99).weights["up"] == 0.0
    depth = len(m.history.undo_labels)
    m.timeline.set_interpolation(UP, -1, "step")  # already: no step
    assert m.tracks is tl and len(m.history.undo_labels) == depth


def test_set_interpolations_of_several_keys_is_one_step(keyed: FaceModel) -> None:
    m = keyed
    n = 0

    def edit() -> None:
        nonlocal n
        n = m.timeline.set_interpolations([(UP, 0), (UP, 1), (LEFT, 0)], "linear")

    tl = _one_step(m, edit, "Set interpolation linear")
    assert n == 3
    assert tl.tracks[UP].interpolations == ("linear", "linear", "bezier")
    assert tl.tracks[LEFT].interpolations == ("linear", "bezier")


def test_set_interpolation_refuses_bad_arguments(keyed: FaceModel) -> None:
    m = keyed
    si = m.timeline.set_interpolation
    _refused(m, lambda: si(UP, 0, "cubic"), r"set_interpolation: interpolation must be one of .* got 'cubic'")
    _refused(m, lambda: si("weights/ghost", 0, "linear"),
             r"set_interpolation: track 'weights/ghost' has no keys; the keyed tracks are \['weights/left', 'weights/up'\]")
    _refused(m, lambda: si(UP, 3, "linear"), r"set_interpolation: index 3 is out of range")
    _refused(m, lambda: m.timeline.set_interpolations([(UP, 0), (LEFT, 2)], "linear"),
             r"set_interpolations: index 2 is out of range for track 'weights/left' \(2 keys\)")


# ------------------------------------------------------------------ tangents
def test_set_tangents_user_one_side_then_auto(keyed: FaceModel) -> None:
    m = keyed
    auto = m.tracks.tracks[UP].keys[1]
    tl = _one_step(m, lambda: m.timeline.set_tangents(UP, 1, in_tangent=-0.6, out_tangent=-0.6),
                   "Edit tangent of up")
    k = tl.tracks[UP].keys[1]
    assert k.tangent_mode == "user" and float(k.in_tangent) == float(k.out_tangent) == -0.6
    tl = _one_step(m, lambda: m.timeline.set_tangents(UP, 1, in_tangent=0.3))  # one side
    k = tl.tracks[UP].keys[1]
    assert (float(k.in_tangent), float(k.out_tangent)) == (0.3, -0.6)
    tl = _one_step(m, lambda: m.timeline.set_tangents(UP, 1, mode="auto_clamped"), "Auto tangent of up")
    k = tl.tracks[UP].keys[1]
    assert k.tangent_mode == "auto_clamped"
    np.testing.assert_array_equal(k.out_tangent, auto.out_tangent)


def test_set_tangents_refuses_bad_arguments(keyed: FaceModel) -> None:
    m = keyed
    st = m.timeline.set_tangents
    _refused(m, lambda: st("weights/ghost", 0, in_tangent=1.0), r"set_tangents: track 'weights/ghost' has no keys")
    _refused(m, lambda: st(UP, 5, in_tangent=1.0), r"set_tangents: index 5 is out of range")
    _refused(m, lambda: st(UP, 1, in_tangent=np.nan), r"set_tangents: in_tangent must be finite")
    _refused(m, lambda: st(UP, 1, out_tangent=[1.0, 2.0]),
             r"set_tangents: out_tangent for track 'weights/up' must be a number or shape \(\)")
    _refused(m, lambda: st(UP, 1, mode="smooth"), r"set_tangents: mode must be one of")
    _refused(m, lambda: st(UP, 1, in_tangent=1.0, mode="auto_clamped"), r"give no in/out_tangent")


# ------------------------------------------------------------------ fps
def test_set_fps(keyed: FaceModel) -> None:
    m = keyed
    tl = _one_step(m, lambda: m.timeline.set_fps(24), "Set fps 24")
    assert tl.fps == 24.0 and tl.tracks is not None
    depth = len(m.history.undo_labels)
    m.timeline.set_fps(24.0)  # unchanged: no step
    assert m.tracks is tl and len(m.history.undo_labels) == depth
    for bad, match in ((0, "a positive"), (-1, "a positive"), (float("inf"), "finite"), ("fast", "a number")):
        _refused(m, lambda bad=bad: m.timeline.set_fps(bad), rf"set_fps: fps must be {match}")


def test_edits_inside_an_interaction_are_part_of_its_step(keyed: FaceModel) -> None:
    m = keyed
    before, depth = m.tracks, len(m.history.undo_labels)
    with m.interaction("Timeline edits"):
        m.timeline.set_fps(25)
        m.timeline.add_key(UP, 3.0, 0.5)
        m.timeline.delete_keys([(LEFT, 0)])
    assert len(m.history.undo_labels) == depth + 1
    assert m.history.undo_labels[-1] == "Timeline edits"
    m.undo()
    assert m.tracks is before
