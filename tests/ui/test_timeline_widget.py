"""Timeline widget (widgets/timeline/) without a browser: front-end messages -> model calls.

Each test sends the JSON a click or drag in the front end sends
(``TimelineWidget.handle_message``) and checks the model, its undo stack and
the state shipped back to the front end. Playback runs on a real asyncio loop.
"""

from __future__ import annotations

import asyncio
import itertools

import numpy as np
import pytest

from workbench.core.pipeline import FunctionLayer

pytest.importorskip("anywidget")

from kernel_loop import on_ui_thread

from widgets.timeline import TimelineWidget, curve_samples, timeline_state, view_range
from workbench.animation.tracks import Timeline

pytestmark = pytest.mark.ui

UP, LEFT = "weights/up", "weights/left"


@pytest.fixture
def keyed(tiny_model):
    """'up' keyed 0 at 0 s, 1 at 1 s, 0 at 2 s; 30 fps."""
    m = tiny_model
    for t, w in ((0.0, 0.0), (1.0, 1.0), (2.0, 0.0)):
        m.set_weight("up", w)
        m.timeline.key_weights(t, ["up"])
    m.set_weight("up", 0.0)
    return m


def send(w, **content):
    w.handle_message(content)
    assert w._error == "", w._error


def test_state_lists_tracks_keys_and_tangents(keyed):
    w = TimelineWidget(keyed)
    st = w._tracks
    assert st["fps"] == 30.0 and (st["start"], st["end"]) == (0.0, 2.0)
    (tr,) = st["tracks"]
    assert tr["name"] == UP and tr["label"] == "up"
    assert tr["times"] == [0.0, 1.0, 2.0] and tr["values"] == [0.0, 1.0, 0.0]
    # auto-clamped: flat ends, and the middle key is an extreme -> flat too
    assert tr["in"] == [0.0, 0.0, 0.0] and tr["out"] == [0.0, 0.0, 0.0]
    assert tr["interp"] == ["bezier"] * 3
    # the only weight track is shown in the curve view, sampled by the model
    assert w.selected_track == UP
    assert w._curve["track"] == UP
    i = w._curve["times"].index(1.0)
    assert w._curve["values"][i] == 1.0
    assert st["view"][0] == 0.0 and st["view"][1] > 2.0


def test_view_range_pads_past_the_end():
    assert view_range(Timeline()) == (0.0, 1.25)
    assert view_range(Timeline(start=-1.0, end=9.0)) == (-1.0, 10.0)


def test_curve_samples_of_a_step_key_jump_at_the_next_key(keyed):
    tl = keyed.tracks.set_interpolation(UP, 0, "step")
    c = curve_samples(tl, UP)
    ts, vs = c["times"], c["values"]
    j = ts.index(1.0)
    assert vs[j - 1] == 0.0  # just before the key: still the step's value
    assert vs[j] == 1.0
    assert curve_samples(tl, "weights/nope") == {"track": "weights/nope", "times": [], "values": []}


def test_scrub_sets_model_time_and_acks(keyed, monkeypatch):
    w = TimelineWidget(keyed)
    sent = []
    monkeypatch.setattr(w, "send", lambda content, buffers=None: sent.append(content))
    labels = list(keyed.history.undo_labels)
    send(w, type="scrub", time=1.0, seq=7)
    assert keyed.time == 1.0 and w.time == 1.0
    assert keyed.weights["up"] == 1.0
    assert sent == [{"type": "scrub_ack", "seq": 7}]
    assert keyed.history.undo_labels == labels  # changing the frame is not an undo step


def test_scrub_gesture_phases_set_the_time_and_ack_each_message(keyed, monkeypatch):
    """The playhead drag speaks the gesture protocol: start / move / end, each acked."""
    w = TimelineWidget(keyed)
    sent = []
    monkeypatch.setattr(w, "send", lambda content, buffers=None: sent.append(content))
    labels = list(keyed.history.undo_labels)
    w.playing = True
    send(w, type="scrub", phase="start", gesture="g1", seq=1, time=0.5)
    assert not w.playing  # scrubbing takes the playhead from playback
    assert keyed.time == 0.5
    send(w, type="scrub", phase="move", gesture="g1", seq=2, time=1.0)
    assert keyed.time == 1.0 and keyed.weights["up"] == 1.0
    send(w, type="scrub", phase="end", gesture="g1", seq=3, time=1.5)
    assert keyed.time == 1.5
    send(w, type="scrub", phase="cancel", gesture="g1", seq=4)
    assert keyed.time == 1.5  # a cancel keeps the time (nothing to put back)
    assert sent == [{"type": "scrub_ack", "seq": s} for s in (1, 2, 3, 4)]
    assert keyed.history.undo_labels == labels


def test_scene_key_names_the_model_for_the_playback_registry(keyed):
    from widgets.viewport.common import scene_key

    w = TimelineWidget(keyed)
    assert w._scene == scene_key(keyed) != ""
    w.close()


def test_missing_bundle_says_how_to_build_it(tmp_path):
    from widgets.timeline import load_timeline_bundle

    with pytest.raises(FileNotFoundError, match="npm --prefix widgets/js"):
        load_timeline_bundle(tmp_path / "timeline.js")
    (tmp_path / "timeline.js").write_text("export default {};")
    assert load_timeline_bundle(tmp_path / "timeline.js") == "export default {};"


def test_drag_key_is_one_undo_step(keyed):
    w = TimelineWidget(keyed)
    n_undo = len(keyed.history.undo_labels)
    send(w, type="move_key", track=UP, index=1, time=1.5)
    assert list(keyed.tracks.tracks[UP].times) == [0.0, 1.5, 2.0]
    assert len(keyed.history.undo_labels) == n_undo + 1
    assert w._tracks["tracks"][0]["times"] == [0.0, 1.5, 2.0]
    assert w.selected_keys == [[UP, 1]]
    keyed.undo()
    assert list(keyed.tracks.tracks[UP].times) == [0.0, 1.0, 2.0]
    assert w._tracks["tracks"][0]["times"] == [0.0, 1.0, 2.0]


def test_move_key_past_a_neighbour_reorders_and_selects_it(keyed):
    w = TimelineWidget(keyed)
    send(w, type="move_key", track=UP, index=0, time=1.5)
    tr = keyed.tracks.tracks[UP]
    assert list(tr.times) == [1.0, 1.5, 2.0]
    assert float(tr.keys[1].value) == 0.0
    assert w.selected_keys == [[UP, 1]]


def test_move_onto_another_key_reports_an_error_and_changes_nothing(keyed):
    w = TimelineWidget(keyed)
    before = keyed.tracks
    w.handle_message({"type": "move_key", "track": UP, "index": 0, "time": 1.0})
    assert keyed.tracks is before
    assert "already there" in w._error


def test_delete_selected_keys_in_one_step(keyed):
    w = TimelineWidget(keyed)
    n_undo = len(keyed.history.undo_labels)
    send(w, type="delete_keys", keys=[[UP, 0], [UP, 2]])
    assert list(keyed.tracks.tracks[UP].times) == [1.0]
    assert len(keyed.history.undo_labels) == n_undo + 1
    assert w.selected_keys == []
    send(w, type="delete_keys", keys=[[UP, 0]])
    assert UP not in keyed.tracks.tracks
    assert w._tracks["tracks"] == [] and w.selected_track == ""


def test_double_click_adds_key_with_current_value(keyed):
    w = TimelineWidget(keyed)
    keyed.set_weight("up", 0.25)
    send(w, type="add_key", track=UP, time=0.5)
    tr = keyed.tracks.tracks[UP]
    assert list(tr.times) == [0.0, 0.5, 1.0, 2.0]
    assert float(tr.keys[1].value) == 0.25
    assert w.selected_keys == [[UP, 1]]


def test_double_click_on_a_family_row_keys_what_its_family_records_now(keyed):
    """The handles row asks the handle family (TrackSpec.current): the offsets the model has now."""
    import numpy as np

    from workbench.methods.handles.handle_set import HandleSet

    m = keyed
    m.handles.set(HandleSet([1], np.zeros((1, 3), np.float32)), label="Handles")
    m.handles.key(0.0)
    m.handles.move(0, [0.0, 0.0, 0.25])
    w = TimelineWidget(m)
    assert [d["label"] for d in w._tracks["tracks"] if d["name"] == "handles"] == ["handles (pose)"]
    send(w, type="add_key", track="handles", time=1.5)
    np.testing.assert_allclose(m.tracks.tracks["handles"].evaluate(1.5), [[0.0, 0.0, 0.25]])
    assert m.history.undo_labels[-1] == "Key handles (pose) at 1.5s"
    assert w.selected_keys == [["handles", 1]]
    # a row no family records "now" (the head pose) keys the value it has at the playhead
    m.timeline.key_head_pose(0.0, translation=[0.0, 0.1, 0.0])
    m.set_time(0.0)
    send(w, type="add_key", track="head_pose", time=0.5)
    np.testing.assert_allclose(m.tracks.tracks["head_pose"].evaluate(0.5)[:3], [0.0, 0.1, 0.0])


def test_key_button_keys_nonzero_weights_at_the_playhead(tiny_model):
    w = TimelineWidget(tiny_model)
    send(w, type="key")
    assert "nothing to key" in w.status and not tiny_model.tracks.tracks
    tiny_model.set_time(0.5)
    tiny_model.set_weight("left", -0.5)
    send(w, type="key")
    assert list(tiny_model.tracks.tracks) == [LEFT]
    assert list(tiny_model.tracks.tracks[LEFT].times) == [0.5]


def test_key_expression_drop_and_gallery_button(tiny_model):
    import ipywidgets
    import traitlets

    class FakeGallery(ipywidgets.Widget):
        selected = traitlets.Unicode(None, allow_none=True)

    gal = FakeGallery()
    w = TimelineWidget(tiny_model, gallery=gal)
    assert w.expressions == ["up", "left"]
    send(w, type="key_expression", name="up", time=0.0)
    assert float(tiny_model.tracks.tracks[UP].keys[0].value) == 1.0
    gal.selected = "left"
    assert w._gallery_selected == "left"
    tiny_model.set_time(1.0)
    send(w, type="key_gallery")
    tl = tiny_model.tracks
    # key_expression: the new expression shows exactly at its time, the older one is 0 there
    assert tl.evaluate(1.0).weights == {"up": 0.0, "left": 1.0}
    assert tl.evaluate(0.0).weights == {"up": 1.0, "left": 0.0}
    # saved expressions come first in the chip list
    tiny_model.set_weights({"up": 0.5, "left": 0.5})
    tiny_model.expressions.save("half")
    assert w.expressions == ["half", "up", "left"] and w._saved_expressions == ["half"]


def test_interpolation_of_selected_keys(keyed):
    w = TimelineWidget(keyed)
    n_undo = len(keyed.history.undo_labels)
    send(w, type="set_interpolation", keys=[[UP, 0], [UP, 1]], interpolation="linear")
    assert keyed.tracks.tracks[UP].interpolations == ("linear", "linear", "bezier")
    assert len(keyed.history.undo_labels) == n_undo + 1
    assert keyed.tracks.evaluate(0.5).weights["up"] == pytest.approx(0.5)


def test_tangent_drag_sets_user_slopes_and_double_click_restores_auto(keyed):
    w = TimelineWidget(keyed)
    send(w, type="set_tangent", track=UP, index=1, side="out", slope=-0.6, aligned=True)
    k = keyed.tracks.tracks[UP].keys[1]
    assert k.tangent_mode == "user"
    assert float(k.in_tangent) == float(k.out_tangent) == -0.6
    tr_state = w._tracks["tracks"][0]
    assert tr_state["mode"][1] == "user" and tr_state["out"][1] == -0.6
    # Alt-drag: one side only
    send(w, type="set_tangent", track=UP, index=1, side="in", slope=0.3, aligned=False)
    k = keyed.tracks.tracks[UP].keys[1]
    assert (float(k.in_tangent), float(k.out_tangent)) == (0.3, -0.6)
    send(w, type="auto_tangent", track=UP, index=1)
    k = keyed.tracks.tracks[UP].keys[1]
    assert k.tangent_mode == "auto_clamped" and float(k.out_tangent) == 0.0


def test_fps_field_is_undoable(keyed):
    w = TimelineWidget(keyed)
    send(w, type="set_fps", fps=24)
    assert keyed.tracks.fps == 24.0 and w._tracks["fps"] == 24.0
    keyed.undo()
    assert keyed.tracks.fps == 30.0
    w.handle_message({"type": "set_fps", "fps": -1})
    assert "fps must be a positive number" in w._error


def test_unknown_message_is_reported(keyed):
    w = TimelineWidget(keyed)
    w.handle_message({"type": "frobnicate"})
    assert "frobnicate" in w._error


def fake_frontend(w, delay=0.0):
    """Patch ``w.send``: answer each playback "frame" message with a ``frame_ack`` after ``delay``.

    Returns a log of ("frame" | "ack", seq) events in order.
    """
    log = []

    def ack(seq):
        log.append(("ack", seq))
        w.handle_message({"type": "frame_ack", "seq": seq})

    def send(content, buffers=None):
        if content.get("type") == "frame":
            log.append(("frame", content["seq"]))
            asyncio.get_running_loop().call_later(delay, ack, content["seq"])

    w.send = send
    return log


def test_playback_sets_times_and_stops_at_the_end(keyed):
    keyed.timeline.set(keyed.tracks.replace(end=0.2), "short range")
    w = TimelineWidget(keyed)
    fake_frontend(w)
    seen: list[float] = []
    keyed.events.time.connect(seen.append)

    async def main():
        task = w.play(loop=False)
        assert w.playing
        return await task

    stats = on_ui_thread(lambda: asyncio.run(main()))
    assert not w.playing
    assert keyed.time == 0.2
    assert seen[0] == 0.0 and seen[-1] == 0.2
    assert all(b > a for a, b in itertools.pairwise(seen))
    # every time set is a frame of the 30 fps grid (frames may be dropped, never invented)
    assert all(abs(s * 30 - round(s * 30)) < 1e-9 for s in seen)
    assert stats["frames"] == len(seen) and stats["frames"] + stats["dropped"] >= 7
    assert "played" in w.status


def test_pause_stops_looping_playback(keyed):
    w = TimelineWidget(keyed)
    fake_frontend(w)
    seen: list[float] = []
    keyed.events.time.connect(seen.append)

    async def main():
        task = w.play(loop=True)
        await asyncio.sleep(0.25)
        w.pause()
        await asyncio.wait_for(task, 5)

    on_ui_thread(lambda: asyncio.run(main()))
    assert not w.playing
    n = len(seen)
    assert n >= 2
    assert w.playback_stats["frames"] == n


def test_slow_browser_gets_one_frame_at_a_time_and_frames_are_dropped(keyed):
    # a browser that needs 0.2 s per frame, with the timeline at 30 fps
    w = TimelineWidget(keyed)
    log = fake_frontend(w, delay=0.2)

    async def main():
        task = w.play(loop=True)
        await asyncio.sleep(1.0)
        w.pause()
        await asyncio.wait_for(task, 5)

    on_ui_thread(lambda: asyncio.run(main()))
    in_flight = 0
    for kind, _seq in log:
        in_flight += 1 if kind == "frame" else -1
        assert in_flight <= 2, "a third frame was sent before the first one was drawn"
    shown, dropped = w.frames_shown, w.frames_dropped
    assert shown >= 3
    # frame k + 2 waits for the ack of frame k (>= 0.2 s = 6 frames at 30 fps later),
    # so every second frame shown comes after at least 4 skipped ones
    assert dropped >= 4 * ((shown - 1) // 2), (shown, dropped)


def test_playback_without_any_view_stops_waiting_for_acks(keyed):
    keyed.timeline.set(keyed.tracks.replace(end=0.3), "short range")
    w = TimelineWidget(keyed)
    w.frame_ack_timeout = 0.05
    w.send = lambda content, buffers=None: None  # nothing displayed: no acks ever

    async def main():
        return await asyncio.wait_for(w.play(loop=False), 5)

    stats = on_ui_thread(lambda: asyncio.run(main()))
    assert keyed.time == 0.3
    assert stats["frames"] >= 5  # only the first frame waited


def test_timeline_state_orders_weight_tracks_before_others(keyed):
    tl = keyed.tracks.add_key("head_pose", 0.0, [0, 0, 0, 0, 0, 0, 1])
    st = timeline_state(tl)
    assert [d["name"] for d in st["tracks"]] == [UP, "head_pose"]
    assert st["tracks"][1]["values"] is None and st["tracks"][1]["label"] == "head pose"


def test_region_tracks_are_vector_rows_with_a_readable_label(keyed):
    tl = keyed.tracks.add_key("regions/1/mouth_L", 0.0, [0.5, 0.0])
    st = timeline_state(tl)
    assert [d["name"] for d in st["tracks"]] == [UP, "regions/1/mouth_L"]
    row = st["tracks"][1]
    assert row["kind"] == "regions" and row["label"] == "region mouth_L (L1)" and row["values"] is None
    assert curve_samples(tl, "regions/1/mouth_L") == {"track": "regions/1/mouth_L", "times": [], "values": []}


# ------------------------------------------------------------------ head pose
def test_key_head_pose_message_turns_the_head_in_one_undo_step(keyed):
    m = keyed
    w = TimelineWidget(m)
    assert w.head_pose_angles == (0.0, 0.0, 0.0)
    m.set_time(1.0)
    send(w, type="key_head_pose", yaw=90.0, pitch=0.0, roll=0.0)
    assert m.history.undo_labels[-1] == "Key head pose at 1s"
    assert list(m.tracks.head_pose.times) == [1.0]
    # tiny model: y up, z front; yaw 90 turns +z (front) to +x and +x to -z
    np.testing.assert_allclose(m.evaluate()[1], [0.0, 0.0, -1.0], atol=1e-6)
    np.testing.assert_array_equal(m.evaluate(), m.evaluate_at(1.0))
    assert w.head_pose_angles == pytest.approx((90.0, 0.0, 0.0))
    assert "keyed head pose (yaw 90°" in w.status
    assert "head_pose" in [d["name"] for d in w._tracks["tracks"]]
    m.undo()
    assert m.tracks.head_pose is None and w.head_pose_angles == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(m.evaluate(), m.evaluate(posed=False))


def test_head_pose_sliders_follow_the_playhead(keyed):
    m = keyed
    w = TimelineWidget(m)
    send(w, type="key_head_pose", yaw=0.0, pitch=0.0, roll=0.0, time=0.0)
    send(w, type="key_head_pose", yaw=0.0, pitch=40.0, roll=0.0, time=2.0)
    send(w, type="scrub", time=1.0, seq=1)
    assert w.head_pose_angles == pytest.approx((0.0, 20.0, 0.0))  # slerp half-way about one axis
    send(w, type="scrub", time=2.0, seq=2)
    assert w.head_pose_angles == pytest.approx((0.0, 40.0, 0.0))
    w.handle_message({"type": "key_head_pose", "yaw": float("nan"), "pitch": 0.0, "roll": 0.0})
    assert "finite degrees" in w._error
    w.close()


# ------------------------------------------------------------------ export panel
def test_export_panel_writes_files_and_imports_csv_back(keyed, tmp_path):
    from widgets.panels.export import ExportPanel

    p = ExportPanel(keyed, path=str(tmp_path / "anim.glb"))
    written = p.do_export()
    assert written == [tmp_path / "anim.glb"] and written[0].stat().st_size > 0
    assert "anim.glb" in p.result.value and "Wrote 1 file" in p.result.value
    # the dropdown changes the suffix; the CSV re-imports as the same curve at the frames
    p.format.value = "CSV weights (.csv)"
    assert p.path.value == str(tmp_path / "anim.csv")
    p.fps.value = 10
    (csv_path,) = p.do_export()
    old = keyed.tracks
    n_undo = len(keyed.history.undo_labels)
    p.import_path.value = str(csv_path)
    assert p.do_import(), p.import_result.value
    assert len(keyed.history.undo_labels) == n_undo + 1
    new = keyed.tracks
    for s in (0.0, 0.3, 1.0, 1.7, 2.0):
        assert new.evaluate(s).weights["up"] == pytest.approx(
            old.evaluate(s).weights["up"], abs=1e-6
        )


def test_export_panel_obj_sequence_lists_files(keyed, tmp_path):
    from widgets.panels.export import ExportPanel

    p = ExportPanel(keyed, path=str(tmp_path / "seq.glb"))
    p.format.value = "OBJ sequence (one .obj per frame)"
    p.fps.value = 5
    written = p.do_export()
    assert len(written) == 11  # 0..2 s at 5 fps
    assert "Wrote 11 files" in p.result.value and "more" in p.result.value


def test_export_panel_shows_errors(keyed, tmp_path):
    from widgets.panels.export import ExportPanel

    p = ExportPanel(keyed)
    p.import_path.value = str(tmp_path / "missing.csv")
    assert not p.do_import()
    assert "Import failed" in p.import_result.value
    bad = tmp_path / "bad.csv"
    bad.write_text("time,notAShape\n0,1\n")
    p.import_path.value = str(bad)
    assert not p.do_import()
    assert "notAShape" in p.import_result.value
    p.path.value = str(tmp_path / "a_file_not_a_dir" / "x.glb")
    (tmp_path / "a_file_not_a_dir").write_text("")
    assert p.do_export() == []
    assert "Export failed" in p.result.value


def test_panels_without_a_workbench_close_each_others_slider_steps(tiny_model):
    """A timeline and two slider panels of one model, composed by hand (no Workbench)."""
    from widgets.panels.expressions import ExpressionPanel

    m = tiny_model
    a, b = ExpressionPanel(m, idle_s=30.0), ExpressionPanel(m, idle_s=30.0)
    w = TimelineWidget(m)
    a.sliders["up"].value = 0.5  # what a drag sends (the step stays open 30 s)
    b.sliders["left"].value = 1.5  # another panel's slider: a step of its own
    send(w, type="key", time=0.0)
    assert not m.interacting
    assert m.history.undo_labels == ["Drag up", "Drag left", "Key 2 weights at 0s"]
    for p in (a, b):
        p.close()
    w.close()


def test_export_panel_says_how_each_layer_was_written(keyed, tmp_path):
    from widgets.panels.export import ExportPanel

    def squared(m):  # not linear in the weights: the exporters must bake it
        d = np.zeros((9, 3), np.float32)
        d[4, 1] = m.weights["up"] ** 2
        return d

    keyed.register_layer(FunctionLayer("squared", squared))
    p = ExportPanel(keyed, path=str(tmp_path / "anim.glb"))
    assert p.do_export() == [tmp_path / "anim.glb"]
    assert "fwb-export-layers" in p.result.value
    assert "<b>squared</b>: baked frame by frame" in p.result.value
    assert "handles" not in p.result.value  # inactive layers are not listed
    p.format.value = "CSV weights (.csv)"
    assert p.do_export()
    assert "<b>squared</b>: not in this format" in p.result.value


def test_export_panel_fbx_without_blender_shows_the_reason(keyed, tmp_path, monkeypatch):
    from widgets.panels.export import ExportPanel

    monkeypatch.setenv("WORKBENCH_BPY_PYTHON", str(tmp_path / "missing-python"))
    p = ExportPanel(keyed, path=str(tmp_path / "anim.glb"))
    p.format.value = "FBX, shape keys (.fbx, through Blender)"
    assert p.path.value == str(tmp_path / "anim.fbx")
    assert p.do_export() == []
    assert "Export failed" in p.result.value and "WORKBENCH_BPY_PYTHON" in p.result.value
    assert not (tmp_path / "anim.fbx").exists()


# ------------------------------------------------------------ thumbnail chips
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def renders(monkeypatch):
    """Names the gallery renders (blendshapes and saved expressions), from an empty cache."""
    pytest.importorskip("pyvista")
    import widgets.gallery as gallery_mod

    gallery_mod.clear_thumbnail_cache()
    done: list[str] = []
    real_shapes, real_png = gallery_mod.expression_thumbnails, gallery_mod.render_png

    def shapes(model, names, **kw):
        done.extend(names)
        return real_shapes(model, names, **kw)

    def png(model, **kw):
        done.append("<expression>")
        return real_png(model, **kw)

    monkeypatch.setattr(gallery_mod, "expression_thumbnails", shapes)
    monkeypatch.setattr(gallery_mod, "render_png", png)
    yield done
    gallery_mod.clear_thumbnail_cache()


def test_chips_show_the_gallery_thumbnails_as_binary_and_follow_new_expressions(
    tiny_model, renders
):
    from ipywidgets.widgets.widget import _remove_buffers

    from widgets.gallery import ExpressionGallery

    gal = ExpressionGallery(tiny_model, size=(32, 32), expressions=True)
    assert sorted(renders) == ["left", "up"]
    w = TimelineWidget(tiny_model, gallery=gal)
    assert sorted(renders) == ["left", "up"]  # nothing rendered twice: the gallery's PNGs
    assert w.expressions == ["up", "left"]
    assert set(w._thumbnails) == set(w.expressions)
    for name in w.expressions:
        png = w._thumbnails[name]
        assert isinstance(png, bytes) and png.startswith(PNG_MAGIC)
        assert png == gal.thumbnails[name]
    # on the wire the pictures are binary buffers, one per chip, not JSON numbers
    state, paths, buffers = _remove_buffers(w.get_state())
    assert state["_thumbnails"] == {}
    assert sorted(paths) == [["_thumbnails", "left"], ["_thumbnails", "up"]]
    assert all(isinstance(b, bytes) and b.startswith(PNG_MAGIC) for b in buffers)

    # a newly saved expression gets a chip (first) with the gallery's picture of it
    tiny_model.set_weights({"up": 0.5, "left": 0.5})
    tiny_model.expressions.save("half")
    assert w.expressions == ["half", "up", "left"] and w._saved_expressions == ["half"]
    assert renders.count("<expression>") == 1  # rendered once, by the gallery
    assert w._thumbnails["half"] == gal.thumbnails["half"]
    assert w._thumbnails["half"].startswith(PNG_MAGIC)
    assert w._thumbnails["half"] not in (w._thumbnails["up"], w._thumbnails["left"])
    state, paths, _ = _remove_buffers(w.get_state())
    assert sorted(p[1] for p in paths) == ["half", "left", "up"]

    # dropping a picture chip sends the same message as a text chip: one undo step
    n_undo = len(tiny_model.history.undo_labels)
    send(w, type="key_expression", name="half", time=0.5)
    assert tiny_model.history.undo_labels[n_undo:] == ["Key half at 0.5s"]
    assert tiny_model.tracks.evaluate(0.5).weights == {"up": 0.5, "left": 0.5}

    # without the gallery the chips are text again; a closed timeline stops following
    w.set_gallery(None)
    assert w._thumbnails == {} and w.expressions == ["half", "up", "left"]
    w.set_gallery(gal)
    assert set(w._thumbnails) == {"half", "up", "left"}
    w.close()
    assert not any(o for o in gal._trait_notifiers.get("thumbnails", {}).values())


def test_standalone_timeline_has_text_chips(tiny_model):
    w = TimelineWidget(tiny_model)
    assert w.expressions == ["up", "left"] and w._thumbnails == {}
    tiny_model.expressions.save("same")
    assert w.expressions == ["same", "up", "left"] and w._thumbnails == {}


def test_workbench_shares_its_palette_with_the_timeline_chips(renders):
    from widgets import Workbench
    from workbench import load_sample

    model = load_sample("head")

    async def build_in_a_kernel_like_loop():
        wb = Workbench(model)
        assert wb._gallery is None and wb.timeline._thumbnails == {}  # text chips at first
        await asyncio.sleep(0)  # the app is shown; then the loop renders the palette
        return wb

    wb = on_ui_thread(asyncio.run, build_in_a_kernel_like_loop())
    try:
        assert wb._gallery is not None and wb.timeline.gallery is wb.gallery
        n = len(renders)
        assert n == len(model.shape_names)
        assert wb.paint.gallery is wb.gallery and len(renders) == n  # the Paint tab's palette
        tl = wb.timeline
        assert set(tl._thumbnails) == set(tl.expressions) == set(model.shape_names)
        assert all(tl._thumbnails[k] is wb.gallery.thumbnails[k] for k in tl.expressions)
        model.set_weights({"jawOpen": 1.0})
        model.expressions.save("open")
        assert tl.expressions[0] == "open" and tl._thumbnails["open"].startswith(PNG_MAGIC)
        assert renders.count("<expression>") == 1
    finally:
        wb.close()
    assert wb.errors.outputs == ()
