"""Kernel-side behaviour of the widgets, without a browser.

What goes over the wire (binary full buffer vs sparse patch), that the viewport
only observes the model (two viewports agree, closing disconnects), that errors
in callbacks land in the Output widget, and that a slider drag is one undo step.
Hand-checked on a tiny 3x3 grid model.
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

pytest.importorskip("anywidget")
pytest.importorskip("ipywidgets")

from kernel_loop import in_kernel_loop

import widgets
from widgets.panels.expressions import layout_rows
from widgets.viewport import BUNDLE
from workbench.model import BlendShape, FaceModel
from workbench.testing import grid_polygons

pytestmark = pytest.mark.skipif(
    not BUNDLE.exists(), reason="viewport bundle not built (npm --prefix widgets/js run build)"
)


def _grid() -> FaceModel:
    V, quads = grid_polygons(2, 2)  # 3 x 3 vertices, 4 quads
    one = np.zeros((9, 3), np.float32)
    one[4, 2] = 1.0  # moves 1 of 9 vertices: a sparse update
    allv = np.zeros((9, 3), np.float32)
    allv[:, 0] = 0.5  # moves every vertex: a full update
    shapes = [
        BlendShape("jawOpen", one),
        BlendShape("shift", allv),
        BlendShape("eyeBlinkRight", one),
        BlendShape("eyeBlinkLeft", one),
    ]
    return FaceModel(V, None, shapes, polygons=quads)


class _Spy:
    """Records custom messages a viewport sends (content, buffer sizes, buffers)."""

    def __init__(self, vp: widgets.Viewport) -> None:
        self.messages: list[tuple[dict, list[bytes]]] = []
        orig = vp.send

        def send(content, buffers=None):
            self.messages.append((content, [bytes(b) for b in buffers or []]))
            return orig(content, buffers)

        vp.send = send  # type: ignore[method-assign]


def test_first_frame_is_full_binary_then_sparse_patches():
    m = _grid()
    vp = widgets.Viewport(m)
    spy = _Spy(vp)
    assert isinstance(vp._positions, bytes) and len(vp._positions) == 9 * 3 * 4
    assert len(vp._faces) == 8 * 3 * 4  # 4 quads -> 8 triangles, uint32
    np.testing.assert_array_equal(np.frombuffer(vp._faces, "<u4").reshape(-1, 3), m.faces)
    assert vp.updates_sent == {"full": 1, "patch": 0}

    m.set_weight("jawOpen", 0.5)  # one vertex moves
    assert vp.updates_sent == {"full": 1, "patch": 1}
    content, (ids, values) = spy.messages[-1]
    assert content["type"] == "patch" and content["count"] == 1
    assert np.frombuffer(ids, "<u4").tolist() == [4]
    np.testing.assert_array_equal(np.frombuffer(values, "<f4"), [1.0, 1.0, 0.5])
    # the stored full state follows silently, so a reloaded page gets the current mesh
    np.testing.assert_array_equal(np.frombuffer(vp._positions, "<f4").reshape(-1, 3), m.evaluate())
    assert vp._version == content["version"]

    m.set_weight("shift", 1.0)  # every vertex moves: full buffer
    assert vp.updates_sent == {"full": 2, "patch": 1}
    np.testing.assert_array_equal(np.frombuffer(vp._positions, "<f4").reshape(-1, 3), m.evaluate())

    m.set_weight("shift", 1.0)  # no change: nothing sent
    assert vp.updates_sent == {"full": 2, "patch": 1}


def test_two_viewports_follow_the_model_and_close_disconnects():
    m = _grid()
    a, b = widgets.Viewport(m), widgets.Viewport(m)
    m.set_weight("shift", 0.3)
    assert a._positions == b._positions
    b.close()
    m.set_weight("shift", 0.6)
    assert a.updates_sent["full"] == 3 and b.updates_sent["full"] == 2
    np.testing.assert_array_equal(np.frombuffer(a._positions, "<f4").reshape(-1, 3), m.evaluate())


def test_overlay_and_handles_are_binary_and_validated():
    m = _grid()
    vp = widgets.Viewport(m)
    vp.vertex_colors = np.full((9, 3), 0.5)
    assert isinstance(vp._vertex_colors, bytes) and len(vp._vertex_colors) == 9 * 3 * 4
    vp.vertex_colors = None
    assert vp._vertex_colors is None
    with pytest.raises(ValueError, match=r"\(9, 3\)"):
        vp.vertex_colors = np.zeros((8, 3))
    vp.markers = [0, 8]
    assert vp.markers.tolist() == [0, 8]
    with pytest.raises(ValueError, match=r"0\.\.8"):
        vp.markers = [9]


def test_callback_errors_go_to_the_output_widget():
    m = _grid()
    vp = widgets.Viewport(m)

    def broken(*_a, **_kw):
        raise RuntimeError("boom")

    vp.sync.push_geometry = broken  # type: ignore[method-assign]
    m.set_weight("jawOpen", 0.2)  # must not raise into the model's emit
    assert vp.errors.count == 1
    assert "boom" in vp.errors.output.outputs[-1]["text"]
    assert "boom" in vp._error


def test_panel_groups_pairs_left_first():
    rows = layout_rows(["jawOpen", "eyeBlinkRight", "eyeBlinkLeft", "custom"])
    assert rows == {
        "eyes": [("eyeBlinkLeft", "eyeBlinkRight")],
        "jaw": [("jawOpen",)],
        "other": [("custom",)],
    }


def test_slider_burst_is_one_undo_step_and_model_edits_move_sliders():
    m = _grid()

    async def drag():
        panel = widgets.ExpressionPanel(m, idle_s=0.1)
        for v in (0.1, 0.2, 0.3):  # what a keyboard nudge sends (no pointer press reported)
            panel.sliders["jawOpen"].value = v
        assert m.interacting and m.weights["jawOpen"] == pytest.approx(0.3)
        deadline = time.monotonic() + 5
        while m.interacting and time.monotonic() < deadline:
            await asyncio.sleep(0.02)  # the idle timer runs on the kernel's loop
        return panel

    panel = in_kernel_loop(drag)
    assert m.history.undo_labels == ["Drag jawOpen"]
    assert not panel.undo_button.disabled and panel.redo_button.disabled

    panel.undo()
    assert m.weights["jawOpen"] == 0.0 and panel.sliders["jawOpen"].value == 0.0
    assert panel.undo_button.disabled and not panel.redo_button.disabled

    m.set_weight("eyeBlinkLeft", 0.7)  # from Python: slider follows, no extra step
    assert panel.sliders["eyeBlinkLeft"].value == pytest.approx(0.7)
    assert m.history.undo_labels == ["Set eyeBlinkLeft"]

    panel.mutes["shift"].value = True
    assert m.shape("shift").mute and m.history.undo_labels[-1] == "Mute shift"
    m.undo()
    assert panel.mutes["shift"].value is False

    panel.search.value = "blink"
    shown = [row for row, box in panel._rows if box.layout.display != "none"]
    assert shown == [("eyeBlinkLeft", "eyeBlinkRight")]
    panel.close()
    m.set_weight("jawOpen", 0.4)
    assert panel.sliders["jawOpen"].value == 0.0  # disconnected


def test_missing_bundle_error_names_the_build_command(tmp_path):
    from widgets.viewport import load_bundle

    with pytest.raises(FileNotFoundError, match="npm --prefix widgets/js"):
        load_bundle(tmp_path / "viewport.js")


# --------------------------------------------------------------------------- handle drags
# The kernel side of the sculpt tool, driven with the messages the front end sends.


def _head_with_handles():
    from workbench import load_sample
    from workbench.methods.handles.presets import default_face_handles

    m = load_sample("head")
    m.handles.set(default_face_handles(m))
    return m


def _drag_msg(vp, phase, index, position=None, seq=0):
    vertex = int(vp.model.handles.vertices[index]) if index < len(vp.model.handles) else -1
    content = {"type": "drag", "phase": phase, "index": index, "vertex": vertex, "seq": seq}
    content["position"] = None if position is None else [float(x) for x in position]
    vp._on_frontend_msg(vp, content, [])


def test_handle_drag_is_one_undo_step_and_every_message_is_acknowledged():
    m = _head_with_handles()
    vp = widgets.Viewport(m)
    spy = _Spy(vp)
    i = m.handles.names.index("mouth_L_1")
    v = int(m.handles.vertices[i])
    p0 = m.evaluate()[v].astype(float)
    _drag_msg(vp, "start", i, p0, seq=1)
    assert m.interacting and vp.dragging and vp.selected_marker == i
    targets = [p0 + np.array([0.01 * k, 0.005 * k, 0.0]) for k in range(1, 5)]
    for k, p in enumerate(targets):
        _drag_msg(vp, "move", i, p, seq=2 + k)
        # the handle vertex is exactly where the pointer put it (handles are interpolated)
        np.testing.assert_allclose(m.evaluate()[v], p, atol=1e-5)
    _drag_msg(vp, "end", i, targets[-1] + [0.01, 0, 0], seq=9)
    assert not m.interacting and not vp.dragging
    assert m.history.undo_labels == ["Edit handles", "Drag handle mouth_L_1"]
    offsets = np.asarray(m.handles.offsets)
    np.testing.assert_allclose(offsets[i], targets[-1] + [0.01, 0, 0] - p0, atol=1e-5)
    assert np.abs(np.delete(offsets, i, axis=0)).max() == 0.0
    acks = [c for c, _ in spy.messages if c["type"] == "drag_ack"]
    assert [a["seq"] for a in acks] == [1, 2, 3, 4, 5, 9]
    # drag-frame patches carry the seq of their move (the front end's early ack)
    patch_seqs = [c.get("seq") for c, _ in spy.messages if c["type"] == "patch"]
    assert set(patch_seqs) - {None} <= {2, 3, 4, 5}
    # after the final (exact) update the front end's copy equals the model
    np.testing.assert_array_equal(vp._last, m.evaluate())
    assert vp.last_drag["moves"] == 5 and len(vp.drag_ms) == 5
    m.undo()
    assert np.abs(np.asarray(m.handles.offsets)).max() == 0.0


def test_a_drag_on_a_turned_head_follows_the_pointer():
    """With a head pose keyed, the pointer's (posed) position is mapped back to model space."""
    from workbench.animation.curves import head_rotation_from_euler

    m = _head_with_handles()
    yaw = head_rotation_from_euler(35.0, 10.0, 0.0)
    m.timeline.key_head_pose(0.0, yaw, [0.1, 0.0, 0.0])
    m.set_time(0.0)
    assert not np.allclose(m.head_matrix(), np.eye(4))
    vp = widgets.Viewport(m)
    i = m.handles.names.index("mouth_L_1")
    v = int(m.handles.vertices[i])
    p0 = m.evaluate()[v].astype(float)  # where the view draws the marker
    _drag_msg(vp, "start", i, p0, seq=1)
    target = p0 + np.array([0.03, 0.02, 0.0])  # a move in the view (world) frame
    _drag_msg(vp, "move", i, target, seq=2)
    np.testing.assert_allclose(m.evaluate()[v], target, atol=1e-5)  # under the pointer
    _drag_msg(vp, "end", i, target, seq=3)
    # the stored offset is the model-space one: the pose's rotation undone
    R = m.head_matrix()[:3, :3]
    np.testing.assert_allclose(R @ np.asarray(m.handles.offsets)[i], target - p0, atol=1e-5)


def test_drag_frames_skip_invisible_changes_and_the_final_update_is_exact():
    m = _head_with_handles()
    vp = widgets.Viewport(m)
    i = m.handles.names.index("brows_L_1")
    p0 = m.evaluate()[int(m.handles.vertices[i])].astype(float)
    _drag_msg(vp, "start", i, p0)
    _drag_msg(vp, "move", i, p0 + np.array([0.0, 0.05, 0.0]))
    patches = vp.updates_sent["patch"]
    _drag_msg(vp, "move", i, p0 + np.array([0.0, 0.051, 0.0]))  # a small step: a sparse patch
    assert vp.updates_sent["patch"] == patches + 1
    # mid-drag the front end may lag by at most the tolerance ...
    lag = np.abs(vp._last - m.evaluate()).max()
    assert 0 < lag <= vp._tolerance
    _drag_msg(vp, "end", i)
    # ... and is exact once the drag ends, including the buffer a reloaded page gets
    np.testing.assert_array_equal(vp._last, m.evaluate())
    np.testing.assert_array_equal(np.frombuffer(vp._positions, "<f4").reshape(-1, 3), m.evaluate())


def test_symmetric_drag_moves_the_mirror_handle_with_x_reflected():
    m = _head_with_handles()
    vp = widgets.Viewport(m)
    vp.symmetric = True
    i = m.handles.names.index("mouth_L_1")
    j = int(m.handles.mirror[i])
    p0 = m.evaluate()[int(m.handles.vertices[i])].astype(float)
    _drag_msg(vp, "start", i, p0)
    _drag_msg(vp, "end", i, p0 + np.array([0.03, 0.02, 0.01]))
    o = np.asarray(m.handles.offsets)
    np.testing.assert_array_equal(o[j], o[i] * [-1, 1, 1])
    assert m.history.undo_labels[-1] == "Drag handle mouth_L_1"


def test_a_failed_move_ends_the_interaction_and_cancels_the_drag():
    m = _head_with_handles()
    vp = widgets.Viewport(m)
    spy = _Spy(vp)
    p0 = m.evaluate()[int(m.handles.vertices[0])].astype(float)
    _drag_msg(vp, "start", 0, p0)
    _drag_msg(vp, "move", 0, p0 + np.array([0.02, 0, 0]))
    _drag_msg(vp, "move", 0, [np.nan, 0.0, 0.0])
    assert not m.interacting and not vp.dragging
    assert vp.errors.count == 1 and "finite" in vp._error
    assert [c["type"] for c, _ in spy.messages][-2:] == ["drag_cancel", "drag_ack"]
    assert len(m.history.undo_labels) == 2  # the part of the drag before the error
    _drag_msg(vp, "move", 0, p0)  # stray moves after the cancel are ignored
    assert not m.interacting


def test_handle_set_edited_while_dragging_and_close_mid_drag():
    m = _head_with_handles()
    vp = widgets.Viewport(m)
    spy = _Spy(vp)
    i = 10
    v = int(m.handles.vertices[i])
    p0 = m.evaluate()[v].astype(float)
    _drag_msg(vp, "start", i, p0)
    m.handles.remove(0)  # the dragged handle is now index 9: found again by its vertex
    vp._on_frontend_msg(
        vp,
        {
            "type": "drag",
            "phase": "move",
            "index": i,
            "vertex": v,
            "position": list(p0 + np.array([0, 0.03, 0])),
        },
        [],
    )
    assert int(m.handles.vertices[9]) == v
    np.testing.assert_allclose(m.evaluate()[v], p0 + np.array([0, 0.03, 0]), atol=1e-5)
    m.handles.remove(9)  # the dragged handle itself goes: the drag is cancelled
    vp._on_frontend_msg(
        vp, {"type": "drag", "phase": "move", "index": 9, "vertex": v, "position": list(p0)}, []
    )
    assert not m.interacting and "drag_cancel" in [c["type"] for c, _ in spy.messages]
    # closing the widget mid-drag never leaves the model inside an interaction
    p1 = m.evaluate()[int(m.handles.vertices[3])].astype(float)
    _drag_msg(vp, "start", 3, p1)
    _drag_msg(vp, "move", 3, p1 + np.array([0.01, 0, 0]))
    vp.close()
    assert not m.interacting
    assert m.history.undo_labels[-1].startswith("Drag handle")


def test_add_and_remove_handles_by_click_messages():
    m = _head_with_handles()
    vp = widgets.Viewport(m)
    n0 = len(m.handles)
    skin = m.component_vertices("skin")
    v = int(skin[np.argmax(m.vertices[skin, 0])])  # far off the mid-plane
    vp._on_frontend_msg(vp, {"type": "pick", "vertex": v}, [])
    assert len(m.handles) == n0 + 1 and int(m.handles.vertices[-1]) == v
    assert vp.markers.tolist() == m.handles.vertices.tolist()  # markers follow the model
    vp.symmetric = True
    vp._on_frontend_msg(vp, {"type": "pick", "vertex": v}, [])  # a mirrored pair
    h = m.handles
    assert len(h) == n0 + 3 and m.history.undo_labels[-1].startswith("Add handle pair")
    a, b = n0 + 1, n0 + 2
    assert h.mirror[a] == b and h.mirror[b] == a
    assert m.vertices[h.vertices[b], 0] < 0 < m.vertices[h.vertices[a], 0]
    assert np.frombuffer(vp._marker_mirror, "<i4").tolist() == h.mirror.tolist()
    vp._on_frontend_msg(vp, {"type": "unpick", "index": a, "vertex": int(h.vertices[a])}, [])
    assert len(m.handles) == n0 + 1  # the pair went in one step
    m.undo()
    assert len(m.handles) == n0 + 3
    with pytest.raises(Exception, match="tool"):
        vp.tool = "brush"


def test_sculpt_panel_buttons_and_workbench_tabs():
    m = _grid()
    wb = widgets.Workbench(m)
    assert wb.viewport.tool == "orbit"
    wb.tabs.selected_index = 1
    assert wb.viewport.tool == "sculpt"
    wb.viewport.tool = "orbit"
    assert wb.tabs.selected_index == 0
    sp = wb.sculpt
    sp.symmetric.value = True
    assert wb.viewport.symmetric
    # the 3x3 grid's blendshapes move only vertex 4 and everything: handles by hand
    m.handles.add(4, name="centre")
    assert "<b>1</b> handles" in sp.status.value
    m.move_handle(0, [0.0, 0.0, 0.5])
    sp.bake_name.value = "bump"
    sp._on_bake()
    assert m.shape_names[-1] == "bump" and sp.bake_name.value == "bump_1"
    assert np.abs(np.asarray(m.handles.offsets)).max() == 0.0
    sp.undo()
    assert "bump" not in m.shape_names and m.handles.offsets[0, 2] == pytest.approx(0.5)
    sp._on_reset()
    assert np.abs(np.asarray(m.handles.offsets)).max() == 0.0
    sp._on_clear()
    assert len(m.handles) == 0
    sp.k_s.value, sp.k_b.value = 0.1, 100.0
    assert m.handles.stiffness == (pytest.approx(0.1), pytest.approx(100.0))
    sp.progress_row(0.4, "solving")
    assert sp.progress.layout.visibility == "visible" and "solving" in sp.progress_label.value
    sp.progress_row(1.0, "done")
    assert sp.progress.layout.visibility == "hidden"
    wb.close()
    m.handles.add(4)
    assert "<b>0</b> handles" in sp.status.value  # disconnected


def test_paint_stroke_messages_are_one_undo_step_with_overlay_patches_and_acks():
    m = _grid()
    vp = widgets.Viewport(m)
    vp.tool = "paint"
    spy = _Spy(vp)
    # a stroke with nothing picked is refused, acked, cancelled, and leaves no interaction
    vp._on_frontend_msg(vp, {"type": "stroke", "phase": "start", "vertices": [4], "seq": 1}, [])
    kinds = [c["type"] for c, _ in spy.messages]
    assert kinds == ["stroke_cancel", "stroke_ack"] and not m.interacting
    assert "pick an expression" in vp._error

    vp.tools["paint"].expression = "jawOpen"  # moves vertex 4 by +1 in z
    vp.brush_radius, vp.brush_opacity, vp.brush_falloff = 0.5, 1.0, "constant"
    assert vp._tint == b""  # nothing painted yet: empty overlay
    spy.messages.clear()
    vp._on_frontend_msg(vp, {"type": "stroke", "phase": "start", "vertices": [4], "seq": 2}, [])
    assert m.interacting and vp.stroking
    # the first paint of the picked expression goes as a full overlay buffer
    w = np.frombuffer(vp._tint, "<f4")
    assert w.tolist() == [0, 0, 0, 0, 1, 0, 0, 0, 0]
    (patch, (ids, vals)), (ack, _) = spy.messages
    assert patch["type"] == "patch" and patch["seq"] == 2  # the geometry patch carries the seq
    assert np.frombuffer(ids, "<u4").tolist() == [4]
    assert np.frombuffer(vals, "<f4").tolist() == [1.0, 1.0, 1.0]  # z: 0 + 1 * delta
    assert ack == {"type": "stroke_ack", "seq": 2, "phase": "start", "version": vp._version,
                   "tint_version": vp._tint_version, "kernel_ms": ack["kernel_ms"]}  # fmt: skip
    spy.messages.clear()
    vp._on_frontend_msg(vp, {"type": "stroke", "phase": "move", "vertices": [0], "seq": 3}, [])
    # vertex 0 and its grid neighbours within 0.5 (only itself): a sparse overlay patch
    (pp, (pids, pvals)), (ack, _) = spy.messages
    assert pp["type"] == "tint_patch" and pp["version"] == vp._tint_version
    assert np.frombuffer(pids, "<u4").tolist() == [0]
    assert np.frombuffer(pvals, "<f4").tolist() == [1.0]
    assert ack["type"] == "stroke_ack" and ack["seq"] == 3
    # the silent full state follows, so a reloaded page gets the current overlay
    assert np.frombuffer(vp._tint, "<f4")[[0, 4]].tolist() == [1.0, 1.0]
    vp._on_frontend_msg(vp, {"type": "stroke", "phase": "end", "vertices": [], "seq": 4}, [])
    assert not m.interacting and not vp.stroking
    assert m.history.undo_labels == ["Paint jawOpen"]
    assert vp.last_stroke["dabs"] == 2 and vp.last_stroke["messages"] == 2
    np.testing.assert_array_equal(np.frombuffer(vp._positions, "<f4").reshape(-1, 3), m.evaluate())

    # undo: the overlay goes back to empty, the geometry to the neutral
    m.undo()
    assert vp._tint == b"" and len(m.paint) == 0
    np.testing.assert_array_equal(np.frombuffer(vp._positions, "<f4").reshape(-1, 3), m.vertices)
    # overlay off: nothing is sent for the picked expression
    vp.tools["paint"].overlay = False
    m.paint.flood("jawOpen", 0.5)
    assert vp._tint == b""
    vp.tools["paint"].overlay = True
    assert np.frombuffer(vp._tint, "<f4").tolist() == [0.5] * 9

    # closing mid-stroke ends the interaction (one undo step)
    vp._on_frontend_msg(vp, {"type": "stroke", "phase": "start", "vertices": [8], "seq": 5}, [])
    assert m.interacting
    vp.close()
    assert not m.interacting and m.history.undo_labels[-1] == "Paint jawOpen"


def test_paint_watchdog_ends_an_abandoned_stroke(monkeypatch):
    import widgets.viewport.gestures as vpmod

    monkeypatch.setattr(vpmod, "DRAG_WATCHDOG_S", 0.2)
    m = _grid()

    async def abandon():
        vp = widgets.Viewport(m)
        vp.tools["paint"].expression = "jawOpen"
        vp._on_frontend_msg(vp, {"type": "stroke", "phase": "start", "vertices": [4], "seq": 1}, [])
        assert m.interacting
        deadline = time.monotonic() + 5
        while m.interacting and time.monotonic() < deadline:
            await asyncio.sleep(0.05)  # the watchdog runs on the kernel's loop
        return vp

    vp = in_kernel_loop(abandon)
    assert not m.interacting and not vp.stroking
    assert m.history.undo_labels == ["Paint jawOpen"]
    vp.close()


def test_paint_panel_brush_links_blends_save_and_bake():
    m = _grid()
    wb = widgets.Workbench(m)
    assert not wb.panel_built("paint")  # built lazily
    wb.tabs.selected_index = widgets.TAB_TITLES.index("Paint")
    assert wb.viewport.tool == "paint" and wb.panel_built("paint")
    p, vp = wb.paint, wb.viewport
    # brush controls drive the viewport's brush
    p.radius.value, p.opacity.value, p.falloff.value = 0.6, 0.25, "linear"
    p.mode.value, p.mirror.value = "subtract", True
    brush = vp.tools["paint"].brush
    assert brush == type(brush)(0.6, 0.25, "linear", "subtract", True)
    assert p.brush == brush
    p.mode.value = "add"
    # picking in the palette sets the viewport's expression
    p.pick("jawOpen")
    assert vp.tools["paint"].expression == "jawOpen"
    p.overlay.value = False
    assert vp.tools["paint"].overlay is False
    p.overlay.value = True
    # global blend: one region, weight 0.5 everywhere, one undo step
    assert list(p.region_sliders) == ["all"]
    p.set_region_weight("all", 0.5)
    np.testing.assert_allclose(m.paint["jawOpen"], 0.5)
    assert m.history.undo_labels[-1] == "Global blend"
    np.testing.assert_allclose(m.evaluate()[4], [1.0, 1.0, 0.5], atol=1e-6)
    # a second expression in the same region is scaled so the sum stays <= 1
    p.set_region_weight("all", 0.8, expression="eyeBlinkLeft")
    total = m.paint.mix.total(m.n_vertices)
    assert total.max() <= 1.0 + 1e-6
    np.testing.assert_allclose(m.paint["jawOpen"], 0.2, atol=1e-6)
    # upper/lower preset: a slider per region; the mix is per preset
    p.preset.value = "upper_lower"
    assert list(p.region_sliders) == ["upper", "lower"]
    p.region_sliders["lower"].value = 1.0  # a slider drag: one undo step once it idles
    p.grouper.flush()
    assert m.history.undo_labels[-1] == "Blend jawOpen (upper_lower)"
    # flood / normalize / clear / undo
    p._on_clear()
    assert len(m.paint) == 0
    p.opacity.value = 0.5
    p._on_flood()
    np.testing.assert_allclose(m.paint["jawOpen"], 0.5)
    p._on_normalize()
    np.testing.assert_allclose(m.paint["jawOpen"], 1.0)
    # save as expression: appears first in the palette, name box moves on
    p.save_name.value = "open"
    p._on_save()
    assert "open" in m.expressions and p.gallery.names[0] == "open"
    assert p.save_name.value == "open_1"
    # bake: the paint becomes a shape at weight 1, paint cleared
    p.bake_name.value = "openBaked"
    p._on_bake()
    assert "openBaked" in m.shape_names and len(m.paint) == 0
    p.undo()
    assert "openBaked" not in m.shape_names and len(m.paint) == 1
    wb.close()
