"""Keys, tracks and the timeline: hand-worked interpolation cases and edit functions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from workbench import load_sample
from workbench.animation.curves import (
    HEAD_POSE,
    Key,
    Track,
    TrackError,
    auto_clamped_slopes,
    head_euler_from_rotation,
    head_rotation_from_euler,
    quat_slerp,
    quaternion_to_matrix,
)
from workbench.animation.tracks import (
    Timeline,
    add_key,
    add_keys,
    delete_key,
    move_key,
    set_interpolation,
    set_tangents,
)
from workbench.core.shapes import ModelError
from workbench.methods.handles.facet import HANDLES_TRACK as HANDLES
from workbench.methods.regions.tracks import (
    check_region_tracks,
    parse_region_track,
    region_level,
    region_track_name,
    region_tracks,
    sampled_region_weights,
)

W = "weights/up"


def track(times, values, interp="bezier", name=W):
    return Track(name, tuple(Key(t, v, interp) for t, v in zip(times, values, strict=True)))


def at(tr: Track, t):
    return tr.sample(np.atleast_1d(t))[:, 0]


# ------------------------------------------------------------------ interpolation
def test_linear_midpoint_and_quarter():
    tr = track([0.0, 2.0], [0.0, 1.0], "linear")
    assert at(tr, [1.0, 0.5]) == pytest.approx([0.5, 0.25])


def test_step_holds_until_next_key_and_extrapolates_constant():
    tr = track([0.0, 1.0, 2.0], [0.2, 0.8, 0.4], "step")
    assert at(tr, [-1.0, 0.0, 0.999, 1.0, 1.5, 2.0, 5.0]) == pytest.approx(
        [0.2, 0.2, 0.2, 0.8, 0.8, 0.4, 0.4]
    )


def test_segment_uses_the_interpolation_of_its_first_key():
    keys = (Key(0.0, 0.0, "step"), Key(1.0, 1.0, "linear"), Key(2.0, 0.0, "step"))
    tr = Track(W, keys)
    assert at(tr, [0.5, 1.5]) == pytest.approx([0.0, 0.5])


def test_hermite_with_flat_tangents_is_smoothstep():
    # v = 3u^2 - 2u^3 between 0 and 1 with zero slopes
    tr = track([0.0, 1.0], [0.0, 1.0])
    assert at(tr, [0.25, 0.5]) == pytest.approx([0.15625, 0.5])


def test_user_tangent_hand_worked():
    # v(u) = (u^3 - 2u^2 + u) * Δ * m0 with v0 = v1 = 0, m0 = 2, Δ = 1 -> v(0.5) = 0.25
    keys = (Key(0.0, 0.0, "bezier", 0.0, 2.0, "user"), Key(1.0, 0.0, "bezier", 0.0, 0.0, "user"))
    assert at(Track(W, keys), 0.5) == pytest.approx([0.25])


def test_tangents_are_per_second_not_per_segment():
    # same curve on a segment twice as long: slope 1/s over 2 s, v(u)=(u^3-2u^2+u)*2*1
    keys = (Key(0.0, 0.0, "bezier", 0.0, 1.0, "user"), Key(2.0, 0.0, "bezier", 0.0, 0.0, "user"))
    assert at(Track(W, keys), 1.0) == pytest.approx([0.25])


# ---------------------------------------------------------------- auto clamped
def test_auto_clamped_extremes_and_ends_are_flat():
    tr = track([0.0, 1.0, 2.0], [0.0, 1.0, 0.0])
    assert [float(k.out_tangent) for k in tr.keys] == [0.0, 0.0, 0.0]
    assert tr.derivatives([1.0], "left")[0, 0] == pytest.approx(0.0)
    assert tr.derivatives([1.0], "right")[0, 0] == pytest.approx(0.0)
    v = at(tr, np.linspace(0, 2, 201))
    assert v.max() == pytest.approx(1.0)
    assert v.min() >= 0.0


def test_no_overshoot_between_equal_keys():
    tr = track([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 1.0, 0.0])
    assert at(tr, np.linspace(1.0, 2.0, 51)) == pytest.approx(np.ones(51))
    assert at(tr, np.linspace(0, 3, 301)).max() <= 1.0


def test_collinear_keys_give_a_straight_line_between_interior_keys():
    tr = track([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 2.0, 3.0])
    t = np.linspace(1.0, 2.0, 11)
    assert at(tr, t) == pytest.approx(t, abs=1e-12)


def test_collinear_keys_with_uneven_spacing():
    # secants both 1 -> slope 1 at the middle key; ends flat
    assert auto_clamped_slopes([0.0, 1.0, 3.0], [[0.0], [1.0], [3.0]])[:, 0] == pytest.approx(
        [0.0, 1.0, 0.0]
    )


def test_auto_clamped_slope_hand_worked_clamp():
    # s_a = 1, s_b = 0.1: mean 0.55 is capped at 3 * 0.1 = 0.3
    tr = track([0.0, 1.0, 2.0], [0.0, 1.0, 1.1])
    assert float(tr.keys[1].in_tangent) == pytest.approx(0.3)
    assert float(tr.keys[1].out_tangent) == pytest.approx(0.3)
    v = at(tr, np.linspace(0, 2, 401))
    assert np.all(np.diff(v) >= -1e-12)  # monotone data stays monotone
    assert v.max() <= 1.1 + 1e-12


def test_auto_clamped_never_leaves_segment_range_on_random_data():
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.uniform(0.1, 1.0, 12))
    values = rng.uniform(-1, 1, 12)
    tr = track(times, values)
    for i in range(11):
        v = at(tr, np.linspace(times[i], times[i + 1], 64))
        lo, hi = sorted((values[i], values[i + 1]))
        assert v.min() >= lo - 1e-12 and v.max() <= hi + 1e-12


def test_derivatives_left_and_right_of_linear_key():
    tr = track([0.0, 1.0, 3.0], [0.0, 1.0, 0.0], "linear")
    assert tr.derivatives([1.0], "left")[0, 0] == pytest.approx(1.0)
    assert tr.derivatives([1.0], "right")[0, 0] == pytest.approx(-0.5)


# ------------------------------------------------------------------ vector tracks
def test_handle_track_interpolates_each_component():
    a = np.zeros((2, 3))
    b = np.array([[1.0, 2.0, -1.0], [0.0, 0.0, 4.0]])
    tr = Track(HANDLES, (Key(0.0, a, "linear"), Key(2.0, b, "linear")))
    assert tr.evaluate(1.0) == pytest.approx(b / 2)
    assert tr.value_shape == (2, 3)


def test_head_pose_slerp_and_translation():
    half = math.sqrt(0.5)
    k0 = Key(0.0, [0, 0, 0, 0, 0, 0, 1], "linear")
    k1 = Key(1.0, [2, 0, 0, 0, half, 0, half], "linear")  # 90 degrees about +y
    tl = Timeline(tracks={HEAD_POSE: Track(HEAD_POSE, (k0, k1))})
    s = tl.evaluate(0.5)
    assert s.head_translation == pytest.approx([1, 0, 0])
    angle = math.radians(22.5)  # half of 45 degrees
    assert s.head_rotation == pytest.approx([0, math.sin(angle), 0, math.cos(angle)])
    M = s.head_matrix()
    assert M[:3, :3] @ [1, 0, 0] == pytest.approx([half, 0, -half])


def test_slerp_takes_the_short_arc():
    q = quat_slerp([0, 0, 0, 1], [0, 0, 0, -1], 0.5)
    assert abs(q[3]) == pytest.approx(1.0)


def test_head_pose_quaternion_is_normalized_and_zero_rejected():
    tr = Track(HEAD_POSE, (Key(0.0, [0, 0, 0, 0, 0, 0, 2]),))
    assert tr.keys[0].value[3:] == pytest.approx([0, 0, 0, 1])
    with pytest.raises(TrackError, match="zero quaternion"):
        Track(HEAD_POSE, (Key(0.0, [0, 0, 0, 0, 0, 0, 0]),))


# --------------------------------------------------------------------- errors
def test_non_increasing_times_are_rejected_with_the_key_index():
    with pytest.raises(TrackError, match=r"strictly increasing.*key 2 \(t=1\).*key 1 \(t=1\)"):
        track([0.0, 1.0, 1.0], [0, 1, 2])


def test_nan_values_and_tangents_are_rejected():
    with pytest.raises(TrackError, match="finite"):
        Key(0.0, float("nan"))
    with pytest.raises(TrackError, match="out_tangent"):
        Key(0.0, 0.0, "bezier", 0.0, float("inf"), "user")
    with pytest.raises(TrackError, match="time must be finite"):
        Key(float("nan"), 0.0)


def test_bad_names_interpolations_and_shapes():
    for bad in ("weights/", "regions/0/", "jaw open", "/x", ""):
        with pytest.raises(TrackError, match="track name"):
            Track(bad, (Key(0.0, 0.0),))
    # a bare name is a method family's own track: the model refuses it unless a family keys it
    tl = Timeline(tracks={"jawOpen": Track("jawOpen", (Key(0.0, 0.0),))})
    with pytest.raises(TrackError, match="'jawOpen': no method family of this model keys it"):
        tl.check_model(load_sample("head"))
    with pytest.raises(TrackError, match="interpolation"):
        Key(0.0, 0.0, "cubic")  # type: ignore[arg-type]
    with pytest.raises(TrackError, match="value shape"):
        Track(HANDLES, (Key(0.0, np.zeros((2, 3))), Key(1.0, np.zeros((3, 3)))))
    # a family track's name is the family's to judge, against the model
    tl = Timeline().add_key("regions/one/a", 0.0, [1.0, 2.0])
    with pytest.raises(TrackError, match=r"'regions/one/a': a region track is named 'regions/<level>/<region>'"):
        tl.check_model(load_sample("head"))
    with pytest.raises(TrackError, match="values must have shape"):
        Track(W, (Key(0.0, [1.0, 2.0]),))


def test_unknown_shape_names_are_reported(tiny_model):
    tl = Timeline().add_key("weights/nope", 0.0, 1.0).add_key(W, 0.0, 1.0)
    with pytest.raises(TrackError, match=r"unknown shape names \['nope'\]"):
        tl.check_model(tiny_model)
    with pytest.raises(TrackError, match="unknown shape name 'nope'"):
        tl.weight_matrix(["up"], [0.0])


def test_handle_count_must_match_model(tiny_model):
    tl = Timeline().add_key(HANDLES, 0.0, np.zeros((2, 3)))
    with pytest.raises(TrackError, match="'handles': the model has no handles"):
        tl.check_model(tiny_model)


def test_timeline_arguments_checked():
    with pytest.raises(TrackError, match="fps"):
        Timeline(fps=0)
    with pytest.raises(TrackError, match="start <= end"):
        Timeline(start=2, end=1)


# ---------------------------------------------------------------------- edits
def test_add_key_returns_new_objects_and_replaces_same_time():
    tl0 = Timeline()
    tl1 = add_key(tl0, W, 1.0, 0.5, interpolation="linear")
    tl2 = add_key(tl1, W, 0.0, 0.0, interpolation="linear")
    tl3 = add_key(tl2, W, 1.0, 0.9, interpolation="linear")
    assert len(tl0.tracks) == 0 and len(tl1.tracks[W]) == 1
    assert [k.time for k in tl3.tracks[W].keys] == [0.0, 1.0]
    assert tl3.tracks[W].keys[1].scalar == 0.9
    assert tl2.tracks[W].keys[1].scalar == 0.5  # old object unchanged


def test_delete_key_and_empty_track_goes():
    tl = Timeline().add_key(W, 0.0, 0.0).add_key(W, 1.0, 1.0)
    tl = delete_key(tl, W, 0)
    assert [k.time for k in tl.tracks[W].keys] == [1.0]
    assert W not in delete_key(tl, W, 0).tracks
    with pytest.raises(TrackError, match="out of range"):
        delete_key(tl, W, 5)


def test_move_key_resorts_and_refuses_collisions():
    tl = Timeline().add_key(W, 0.0, 0.0).add_key(W, 1.0, 1.0).add_key(W, 2.0, 0.0)
    moved = move_key(tl, W, 0, 3.0)
    assert [k.time for k in moved.tracks[W].keys] == [1.0, 2.0, 3.0]
    with pytest.raises(TrackError, match="already there"):
        move_key(tl, W, 0, 2.0)


def test_moving_a_key_recomputes_auto_tangents():
    tl = Timeline().add_key(W, 0.0, 0.0).add_key(W, 1.0, 1.0).add_key(W, 2.0, 2.0)
    assert float(tl.tracks[W].keys[1].out_tangent) == pytest.approx(1.0)
    tl = move_key(tl, W, 2, 2.0, value=1.0)  # now an extreme plateau -> flat
    assert float(tl.tracks[W].keys[1].out_tangent) == 0.0


def test_set_tangents_user_then_back_to_auto():
    tl = Timeline().add_key(W, 0.0, 0.0).add_key(W, 1.0, 1.0).add_key(W, 2.0, 2.0)
    tl_user = set_tangents(tl, W, 1, in_tangent=5.0, out_tangent=-1.0)
    k = tl_user.tracks[W].keys[1]
    assert (k.tangent_mode, float(k.in_tangent), float(k.out_tangent)) == ("user", 5.0, -1.0)
    k_auto = set_tangents(tl_user, W, 1, mode="auto_clamped").tracks[W].keys[1]
    assert float(k_auto.in_tangent) == pytest.approx(1.0)


def test_set_interpolation_all_keys():
    tl = Timeline().add_key(W, 0.0, 0.0).add_key(W, 2.0, 1.0)
    tl = set_interpolation(tl, W, None, "linear")
    assert tl.tracks[W].interpolations == ("linear", "linear")
    assert tl.evaluate(1.0).weights["up"] == pytest.approx(0.5)


def test_frame_times_and_fit_range():
    tl = Timeline(fps=4).add_key(W, 0.5, 0.0).add_key(W, 1.5, 1.0).fit_range()
    assert (tl.start, tl.end) == (0.5, 1.5)
    assert tl.frame_times() == pytest.approx([0.5, 0.75, 1.0, 1.25, 1.5])


# --------------------------------------------------------------- mesh evaluation
def test_evaluate_mesh_matches_the_model_with_the_same_weights(tiny_model):
    tl = (
        Timeline()
        .add_key(W, 0.0, 0.0)
        .add_key(W, 1.0, 1.0)
        .add_key("weights/left", 0.0, 0.5, interpolation="linear")
        .add_key("weights/left", 1.0, -0.5, interpolation="linear")
    )
    for t in (0.0, 0.3, 1.0):
        tiny_model.set_weights(tl.evaluate(t).weights)
        assert tiny_model.evaluate_at(t, tl) == pytest.approx(tiny_model.evaluate(), abs=1e-6)


def test_head_pose_moves_points_rigidly(tiny_model):
    half = math.sqrt(0.5)
    tl = Timeline().add_key(HEAD_POSE, 0.0, [1, 2, 3, 0, 0, half, half])  # 90 deg about z
    P = tiny_model.evaluate_at(0.0, tl)
    V = tiny_model.vertices
    expect = np.stack([-V[:, 1], V[:, 0], V[:, 2]], axis=1) + np.array([1.0, 2.0, 3.0])
    assert P == pytest.approx(expect, abs=1e-6)


def test_muted_shape_contributes_nothing(tiny_model):
    tiny_model.set_shape_mute("up", True)
    tl = Timeline().add_key(W, 0.0, 1.0)
    assert tiny_model.evaluate_at(0.0, tl) == pytest.approx(tiny_model.vertices)


def test_json_round_trip_is_exact():
    import json

    tl = (
        Timeline(fps=24, start=0.0, end=2.0)
        .add_key(W, 0.0, 0.1)
        .add_key(W, 1.0 / 3.0, 0.7, in_tangent=0.25, out_tangent=-1.5)
        .add_key(HANDLES, 0.5, np.arange(6.0).reshape(2, 3) / 7, interpolation="step")
        .add_key(HEAD_POSE, 0.0, [0.1, 0, 0, 0, 0, 0, 1], interpolation="linear")
    )
    back = Timeline.from_json(json.loads(json.dumps(tl.to_json())))
    assert (back.fps, back.start, back.end, list(back.tracks)) == (24, 0.0, 2.0, list(tl.tracks))
    t = np.linspace(-0.5, 2.5, 37)
    for name, tr in tl.tracks.items():
        assert np.array_equal(back.tracks[name].sample(t), tr.sample(t))
        assert [k.tangent_mode for k in back.tracks[name].keys] == [k.tangent_mode for k in tr.keys]
    with pytest.raises(TrackError, match="malformed"):
        Timeline.from_json({"tracks": {W: [{"value": 1.0}]}})


# ------------------------------------------------------------------ region tracks
def test_region_track_names_round_trip_and_are_validated():
    assert region_track_name(1, "mouth/L") == "regions/1/mouth/L"
    assert parse_region_track("regions/1/mouth/L") == (1, "mouth/L")
    for bad in ("regions/x/a", "regions/1/", "regions/-1/a", "regions/1", "weights/a"):
        assert parse_region_track(bad) is None
    with pytest.raises(TrackError, match="level must be an int >= 0"):
        region_track_name(-1, "a")
    # the timeline keeps any family track; the regions family judges name and shape on a model
    Track("regions/0/a", (Key(0.0, 1.0),))


def test_region_tracks_interpolate_per_shape_and_stay_on_one_level():
    tl = Timeline().add_key("regions/0/a", 0.0, [0.0, 1.0], interpolation="linear")
    tl = tl.add_key("regions/0/a", 2.0, [1.0, 0.0], interpolation="linear")
    tl = tl.add_key("regions/0/b", 0.0, [0.5, 0.5])
    s = tl.evaluate(0.5)
    level, keyed = sampled_region_weights(s.others)
    assert level == 0 and sorted(keyed) == ["a", "b"]
    np.testing.assert_allclose(keyed["a"], [0.25, 0.75])
    np.testing.assert_allclose(keyed["b"], [0.5, 0.5])
    assert region_level(tl) == 0 and sorted(region_tracks(tl)) == ["a", "b"]
    assert tl.tracks["regions/0/a"].is_family_track and tl.tracks["regions/0/a"].shape_name is None
    check_region_tracks(None, tl.tracks)  # type: ignore[arg-type]
    with pytest.raises(ModelError, match=r"one region level, got levels \[0, 1\]"):
        check_region_tracks(None, tl.add_key("regions/1/a", 0.0, [0.0, 0.0]).tracks)  # type: ignore[arg-type]
    assert region_level(Timeline()) is None
    assert sampled_region_weights(Timeline().evaluate(0.0).others) == (None, {})
    back = Timeline.from_json(tl.to_json())
    np.testing.assert_array_equal(back.tracks["regions/0/a"].values, tl.tracks["regions/0/a"].values)


def test_add_keys_equals_add_key_one_by_one():
    tl = Timeline().add_key(W, 0.5, 0.3).add_key(W, 3.0, 0.9)
    times, values = [2.0, 0.5 + 1e-12, 1.0], [0.1, 0.7, 0.4]  # 0.5 is replaced (within tol)
    one = tl
    for t, v in zip(times, values, strict=True):
        one = one.add_key(W, t, v, interpolation="linear")
    many = add_keys(tl, W, times, values, interpolation="linear")
    assert many.tracks[W].times.tolist() == one.tracks[W].times.tolist() == pytest.approx([0.5, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(many.tracks[W].values, one.tracks[W].values)
    np.testing.assert_array_equal(many.tracks[W]._out, one.tracks[W]._out)
    with pytest.raises(TrackError, match="one row per time"):
        add_keys(tl, W, [0.0, 1.0], [0.0])
    with pytest.raises(TrackError, match="distinct"):
        add_keys(tl, W, [1.0, 1.0], [0.0, 1.0])


# ------------------------------------------------------------------ head pose angles
def test_yaw_pitch_roll_turn_the_model_axes_by_hand():
    front, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    R = quaternion_to_matrix(head_rotation_from_euler(90, 0, 0))
    np.testing.assert_allclose(R @ front, [1, 0, 0], atol=1e-12)  # toward the subject's left (+x)
    R = quaternion_to_matrix(head_rotation_from_euler(0, 30, 0))
    np.testing.assert_allclose(R @ front, [0, -0.5, math.sqrt(0.75)], atol=1e-12)  # nods down
    R = quaternion_to_matrix(head_rotation_from_euler(0, 0, 90))
    np.testing.assert_allclose(R @ up, [-1, 0, 0], atol=1e-12)  # top of the head to the subject's right
    # a z-up model facing -y: yaw is about +z
    R = quaternion_to_matrix(head_rotation_from_euler(90, 0, 0, up_axis="+z", front_axis="-y"))
    np.testing.assert_allclose(R @ [0, -1, 0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, 1], atol=1e-12)


@pytest.mark.parametrize("axes", [("+y", "+z"), ("+z", "-y"), ("-x", "+y")])
def test_euler_angles_round_trip(axes):
    up, front = axes
    for ypr in ((25.0, -10.0, 5.0), (-170.0, 80.0, 120.0), (0.0, 0.0, 0.0)):
        q = head_rotation_from_euler(*ypr, up_axis=up, front_axis=front)
        assert q[3] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
        assert head_euler_from_rotation(q, up_axis=up, front_axis=front) == pytest.approx(ypr, abs=1e-9)
    with pytest.raises(TrackError, match="perpendicular"):
        head_rotation_from_euler(0, 0, 0, up_axis="+y", front_axis="-y")
    with pytest.raises(TrackError, match="signed axis name"):
        head_rotation_from_euler(0, 0, 0, up_axis="y")


def test_prefetched_weights_are_the_same_bits_as_sampling_each_time() -> None:
    from workbench.animation.curves import Key, Track, weight_track_name
    from workbench.animation.tracks import Timeline

    rng = np.random.default_rng(7)
    tracks = {}
    for i, kind in enumerate(["bezier", "linear", "step", "bezier"]):
        name = weight_track_name(f"s{i}")
        times = np.sort(rng.uniform(0, 3, 6))
        tracks[name] = Track(name, tuple(Key(float(t), float(rng.uniform(-0.2, 1.2)), kind) for t in times))
    tl = Timeline(fps=30.0, tracks=tracks).fit_range()
    ts = np.concatenate([tl.frame_times(), rng.uniform(-1, 4, 50)])
    alone = [tl.evaluate(float(t)).weights for t in ts]
    tl.prefetch_weights(ts)
    try:
        together = [tl.evaluate(float(t)).weights for t in ts]
    finally:
        tl.forget_prefetched()
    for a, b in zip(alone, together, strict=True):
        assert a.keys() == b.keys()
        assert all(np.float64(a[k]).tobytes() == np.float64(b[k]).tobytes() for k in a)
    # an edit makes a new timeline that does not carry the table
    tl.prefetch_weights(ts[:3])
    assert "_prefetched" not in tl.add_key("weights/s0", 5.0, 0.5).__dict__
    tl.forget_prefetched()
    assert "_prefetched" not in tl.__dict__
