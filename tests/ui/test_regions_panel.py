"""RegionsPanel (widgets/regions/) without a browser: widget events -> model calls.

Buttons are clicked and sliders set from Python; region drags are the JSON
messages the viewport's front end sends for a marker drag, fed to
``Viewport._on_frontend_msg`` (which routes them to the panel's drag handler
through the viewport's ``drag_handler`` hook). Runs on the sample head
(5k vertices): segmentation takes ~0.2 s.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("anywidget")

from widgets.regions import BACKGROUND_GREY, RegionsPanel, region_colors, region_palette
from widgets.viewport import Viewport
from workbench import load_sample

pytestmark = pytest.mark.ui


@pytest.fixture
def setup():
    model = load_sample("head")
    vp = Viewport(model)
    sent: list[dict] = []
    vp.send = lambda content, buffers=None: sent.append(content)  # no front end
    panel = RegionsPanel(model, vp, idle_s=30.0)  # slider bursts end by flush() in the tests
    yield model, vp, panel, sent
    panel.close()
    vp.close()


def mouth_corner_pin(model, panel) -> tuple[int, int]:
    """(marker index, vertex) of the pin nearest the left mouth corner."""
    V = np.asarray(model.vertices)
    skin = model.component_labels == model.component_names.index("skin")
    d = np.linalg.norm(model.shape("mouthSmileLeft").delta, axis=1) * skin
    top = np.argsort(-d)[:40]
    corner = int(top[np.argmax(V[top, 0])])
    pins = panel.pins
    k = int(np.argmin(np.linalg.norm(V[pins] - V[corner], axis=1)))
    return k, int(pins[k])


def drag(vp, k, v, targets):
    msg = {"type": "drag", "index": k, "vertex": v}
    vp._on_frontend_msg(vp, {**msg, "phase": "start", "seq": 1}, [])
    for i, p in enumerate(targets[:-1]):
        vp._on_frontend_msg(vp, {**msg, "phase": "move", "position": list(p), "seq": 2 + i}, [])
    vp._on_frontend_msg(vp, {**msg, "phase": "end", "position": list(targets[-1]), "seq": 99}, [])


def test_find_regions_button_segments_and_colours_one_colour_per_region(setup):
    model, vp, panel, _ = setup
    before = np.full((model.n_vertices, 3), 0.3, np.float32)
    vp.vertex_colors = before
    panel.deactivate()
    panel.activate()  # the panel remembers the colours it covers
    assert model.regions.state is None and panel.drag_mode.disabled
    panel.find_button.click()
    st = model.regions.state
    assert st is not None and model.history.undo_labels[-1] == "Segment regions (t=0.25)"
    R, lv = st.regions, st.level
    assert [o[1] for o in panel.level.options] == list(range(R.n_levels - 1, -1, -1))
    assert [o[0] for o in panel.region.options] == list(R.names[lv])
    C = vp.vertex_colors
    np.testing.assert_allclose(C, region_colors(R, lv), atol=1e-6)
    pal = region_palette(R.n_regions(lv))
    W = R.weight_matrix(lv).toarray()
    for r in range(R.n_regions(lv)):
        pure = np.flatnonzero(W[:, r] == 1.0)
        assert pure.size, R.names[lv][r]
        np.testing.assert_allclose(C[pure], np.broadcast_to(pal[r], (pure.size, 3)), atol=1e-6)
    # one colour per region: all distinct, and none is the background grey
    uniq = {tuple(np.round(c, 4)) for c in pal}
    assert len(uniq) == R.n_regions(lv)
    assert tuple(np.round(BACKGROUND_GREY, 4)) not in uniq
    bg = np.flatnonzero(R.background[lv] == 1.0)
    np.testing.assert_allclose(C[bg], np.broadcast_to(BACKGROUND_GREY, (bg.size, 3)), atol=1e-6)
    # an overlap vertex is a blend of its regions' colours
    mixed = np.flatnonzero((W > 0).sum(axis=1) >= 2)[0]
    np.testing.assert_allclose(
        C[mixed], W[mixed] @ pal + R.background[lv][mixed] * np.array(BACKGROUND_GREY), atol=1e-5
    )
    assert "L0: " in panel.status.value and "segmentation" in panel.status.value
    # the level slider shows another level's colours; closing restores the old colours
    panel.level.value = R.n_levels - 1
    assert model.regions.level == R.n_levels - 1
    assert model.history.undo_labels[-1] == f"Region level {R.n_levels - 1}"
    np.testing.assert_allclose(vp.vertex_colors, region_colors(R, R.n_levels - 1), atol=1e-6)
    panel.close()
    np.testing.assert_array_equal(vp.vertex_colors, before)


def test_threshold_release_resegments_and_undo_moves_the_slider_back(setup):
    model, _, panel, _ = setup
    panel.find_button.click()
    n_fine = model.regions.regions.n_regions(0)
    panel.threshold.value = 0.6
    st = model.regions.state
    assert st.regions.threshold == pytest.approx(0.6)
    assert model.history.undo_labels[-1] == "Segment regions (t=0.6)"
    assert st.regions.n_regions(0) < n_fine  # higher t: fewer, smaller regions
    assert "t = 0.60" in panel.progress_row.label.value and "ms" in panel.progress_row.label.value
    panel.undo_button.click()
    assert model.regions.regions.threshold == pytest.approx(0.25)
    assert panel.threshold.value == pytest.approx(0.25)
    assert model.history.undo_labels[-1] == "Segment regions (t=0.25)"  # no re-segmentation


def test_weight_slider_drag_is_one_undo_step_on_that_region_only(setup):
    model, _, panel, _ = setup
    panel.find_button.click()
    st = model.regions.state
    R, lv = st.regions, st.level
    r = R.names[lv].index("mouth_L_2") if "mouth_L_2" in R.names[lv] else 0
    panel.region.value = r
    shape = R.drivers[lv][r][0]
    assert list(panel.sliders.weight_sliders)[: len(R.drivers[lv][r])] == list(R.drivers[lv][r])
    n_undo = len(model.history.undo_labels)
    X0 = np.array(model.evaluate())
    for v in (0.1, 0.3, 0.5, 0.7):  # one drag of the slider
        panel.sliders.weight_sliders[shape].value = v
    assert panel.grouper.active
    panel.grouper.flush()
    labels = model.history.undo_labels
    assert len(labels) == n_undo + 1 and labels[-1] == f"Region {R.names[lv][r]}: {shape}"
    rw = model.regions.weights
    assert rw.region(r)[shape] == pytest.approx(0.7)
    others = np.delete(rw.values, r, axis=0)
    assert np.abs(others).max() == 0.0  # every other region still on the global weights (0)
    moved = np.flatnonzero(np.abs(np.array(model.evaluate()) - X0).max(axis=1) > 0)
    assert moved.size and np.isin(moved, R.members(lv, r)).all()
    # reset region to global: back to the neutral face, one more undo step
    panel.sliders.reset_region_button.click()
    assert model.regions.weights.region(r)[shape] == 0.0
    np.testing.assert_allclose(model.evaluate(), X0, atol=1e-6)
    assert model.history.undo_labels[-1] == f"Reset region {R.names[lv][r]}"
    assert panel.sliders.weight_sliders[shape].value == 0.0
    model.undo()
    assert panel.sliders.weight_sliders[shape].value == pytest.approx(0.7)


def test_a_late_echo_of_a_solved_weight_is_no_edit(setup):
    """A region drag solves off-grid weights; the page's snapped echo of one may arrive after the next."""
    model, _, panel, _ = setup
    panel.find_button.click()
    st = model.regions.state
    R, lv = st.regions, st.level
    r = R.names[lv].index("mouth_L_2") if "mouth_L_2" in R.names[lv] else 0
    panel.region.value = r
    shape = R.drivers[lv][r][0]
    slider = panel.sliders.weight_sliders[shape]
    with model.interaction("Region drag"):  # what a pin drag does: several solves
        model.regions.set_region(r, {shape: 0.4321})
        model.regions.set_region(r, {shape: 0.6187})  # the model moved on
    n_undo = len(model.history.undo_labels)
    slider.value = 0.43  # the page's late echo of 0.4321, snapped
    panel.grouper.flush()
    assert len(model.history.undo_labels) == n_undo  # no "Region ...: shape" step
    assert model.regions.weights.region(r)[shape] == pytest.approx(0.6187)  # not pulled back
    assert slider.value == pytest.approx(0.62)  # and the page is sent the current value again
    slider.value = 0.6  # a person's drag still edits
    panel.grouper.flush()
    assert model.regions.weights.region(r)[shape] == pytest.approx(0.6)
    assert model.history.undo_labels[-1] == f"Region {R.names[lv][r]}: {shape}"


def test_drag_handler_solves_and_moves_the_dragged_point_toward_the_target(setup):
    model, vp, panel, sent = setup
    panel.find_button.click()
    panel.drag_mode.value = True
    assert vp.tool == "sculpt" and vp.drag_handler is panel.drag_handler
    np.testing.assert_array_equal(vp.markers, panel.pins)
    k, v = mouth_corner_pin(model, panel)
    st = model.regions.state
    R, lv = st.regions, st.level
    touched = sorted(R.regions_at(lv, v))
    inside = np.unique(np.concatenate([R.members(lv, r) for r in touched]))
    X0 = np.array(model.evaluate(), dtype=np.float64)
    mouse = np.array([0.08, 0.06, 0.0])  # up and out (subject's left), in the view plane
    targets = [X0[v] + mouse * f for f in (0.25, 0.5, 0.75, 1.0)]
    n_undo = len(model.history.undo_labels)
    drag(vp, k, v, targets)
    assert not model.interacting and not panel.drag_handler.dragging
    labels = model.history.undo_labels
    assert len(labels) == n_undo + 1 and labels[-1].startswith("Region drag ")
    X1 = np.array(model.evaluate(), dtype=np.float64)
    # motion damping: the goal is the mouse motion scaled by drag_damping at v
    from workbench.methods.regions.blend import drag_damping

    goal = X0[v] + mouse * drag_damping(model, [v])[0]
    assert np.linalg.norm(X1[v] - goal) < 0.5 * np.linalg.norm(X0[v] - goal)
    assert np.dot(X1[v] - X0[v], mouse) > 0
    # only the regions under the pin changed, so nothing outside them moved
    rw = model.regions.weights
    changed = np.flatnonzero(np.abs(rw.values).max(axis=1) > 0)
    assert set(changed.tolist()) <= set(touched) and changed.size
    outside = np.setdiff1d(np.arange(model.n_vertices), inside)
    assert np.abs(X1[outside] - X0[outside]).max() == 0.0
    # every message was acknowledged; the status shows the solve time
    acks = [c for c in sent if c.get("type") == "drag_ack"]
    assert [a["seq"] for a in acks] == [1, 2, 3, 4, 99]
    assert "solve" in panel.status.value and "ms" in panel.status.value
    assert panel.region.label == panel.drag_handler.last_drag["name"]
    # the weight sliders show the solved weights of the selected region
    r = int(panel.region.value)
    for nm, s in panel.sliders.weight_sliders.items():
        assert s.value == pytest.approx(rw.region(r)[nm], abs=0.005 + 1e-6)
    # the browser snaps them to the slider step and sends that back: not an edit
    n_undo = len(model.history.undo_labels)
    assert any(abs(v - round(v, 2)) > 1e-4 for v in rw.region(r).values())
    for nm in panel.sliders.weight_sliders:
        panel.sliders.on_slider(nm, round(rw.region(r)[nm], 2))
    assert not panel.grouper.active and len(model.history.undo_labels) == n_undo
    # one undo puts the face back
    panel.undo_button.click()
    np.testing.assert_allclose(model.evaluate(), X0, atol=1e-6)


def test_drag_in_the_background_is_refused_without_an_open_interaction(setup):
    model, vp, panel, sent = setup
    panel.find_button.click()
    panel.drag_mode.value = True
    st = model.regions.state
    bg = np.flatnonzero(st.regions.background[st.level] == 1.0)
    v = int(bg[0])
    n_err = panel.errors.count + vp.errors.count
    vp._on_frontend_msg(
        vp, {"type": "drag", "phase": "start", "index": 0, "vertex": v, "seq": 5}, []
    )
    assert not model.interacting
    assert {"type": "drag_cancel"} in sent and sent[-1]["type"] == "drag_ack"
    assert panel.errors.count + vp.errors.count == n_err + 1


def test_leaving_drag_mode_gives_the_viewport_back(setup):
    from workbench.methods.handles.presets import default_face_handles

    model, vp, panel, _ = setup
    model.handles.set(default_face_handles(model, per_side=5), label="few handles")
    model_handles = np.asarray(model.handles.vertices)
    panel.find_button.click()
    panel.drag_mode.value = True
    assert len(vp.markers) == len(panel.pins) > len(model_handles)
    # a handle added in drag mode (Shift-click) becomes a pin as well
    free = int(np.setdiff1d(np.arange(model.n_vertices), panel.pins)[0])
    model.handles.add(free)
    assert free in panel.pins and free in vp.markers
    panel.drag_mode.value = False
    assert vp.tool == "orbit" and vp.drag_handler is None
    np.testing.assert_array_equal(vp.markers, np.asarray(model.handles.vertices))


# --------------------------------------------------------------- region edits
def select(panel, name: str) -> int:
    st = panel.model.regions.state
    r = st.regions.names[st.level].index(name)
    panel.region.value = r
    return r


def click_marker(vp, k: int, v: int, seq: int) -> None:
    """A press and release on marker ``k`` (no motion), as the front end sends it."""
    msg = {"type": "drag", "index": k, "vertex": v}
    vp._on_frontend_msg(vp, {**msg, "phase": "start", "seq": seq}, [])
    vp._on_frontend_msg(vp, {**msg, "phase": "end", "seq": seq + 1}, [])


def test_rename_and_merge_controls_are_one_undo_step_each(setup):
    model, vp, panel, _ = setup
    panel.find_button.click()
    r = select(panel, "mouth_L_2")
    assert panel.edits.rename_text.placeholder == "mouth_L_2"
    n = len(model.history.undo_labels)
    colors0 = np.array(vp.vertex_colors)
    panel.edits.rename_text.value = "lip_corner_L"
    panel.edits.rename_button.click()
    R = model.regions.regions
    assert R.names[0][r] == "lip_corner_L" and panel.region.label == "lip_corner_L"
    np.testing.assert_array_equal(vp.vertex_colors, colors0)  # a rename keeps the colours
    assert model.history.undo_labels[-1] == "Rename region mouth_L_2 to lip_corner_L"
    # a taken name: the reason in the edit status, no undo step, no traceback
    panel.edits.rename_text.value = "mouth_L_1"
    panel.edits.rename_button.click()
    assert "already used" in panel.edits.status.value and "b00020" in panel.edits.status.value
    assert len(model.history.undo_labels) == n + 1 and panel.errors.count == 0
    # merge: the dropdown lists the touching regions only
    from workbench.methods.regions.topology import adjacent_regions, region_topology

    nb = adjacent_regions(R, region_topology(model), 0, r)
    assert [idx for _label, idx in panel.edits.merge_with.options] == nb
    b = nb[0]
    panel.edits.merge_with.value = b
    n_regions = R.n_regions(0)
    panel.edits.merge_button.click()
    R2 = model.regions.regions
    assert R2.n_regions(0) == n_regions - 1 and int(panel.region.value) == min(r, b)
    assert model.history.undo_labels[-1].startswith("Merge regions lip_corner_L + ")
    assert "merged" in panel.edits.status.value
    # the overlay: regions away from the merge keep their colours (no palette shift)
    far = R.core(0, "eye_R")
    np.testing.assert_array_equal(np.asarray(vp.vertex_colors)[far], colors0[far])
    panel.undo_button.click()
    assert model.regions.regions is R
    np.testing.assert_array_equal(vp.vertex_colors, colors0)
    panel.undo_button.click()
    assert model.regions.regions.names[0][r] == "mouth_L_2"


def test_split_mode_splits_between_two_clicked_markers(setup):
    model, vp, panel, sent = setup
    panel.find_button.click()
    r = select(panel, "cheek_eye_L")
    R = model.regions.regions
    panel.drag_mode.value = True
    panel.edits.split_mode.value = True
    assert not panel.drag_mode.value  # one pointer mode at a time
    assert vp.tool == "sculpt" and vp.drag_handler is panel.edits.seed_picker
    markers = np.asarray(vp.markers)
    assert markers.size >= 2 and (R.labels[0][markers] == r).all()
    V = np.asarray(model.vertices)[markers]
    ka, kb = int(np.argmin(V[:, 1])), int(np.argmax(V[:, 1]))
    n = len(model.history.undo_labels)
    click_marker(vp, ka, int(markers[ka]), 10)
    assert "click a second marker" in panel.edits.status.value
    assert len(model.history.undo_labels) == n
    click_marker(vp, kb, int(markers[kb]), 12)
    R2 = model.regions.regions
    assert R2.names[0][r : r + 2] == ("cheek_eye_L_a", "cheek_eye_L_b")
    assert R2.labels[0][markers[ka]] == r and R2.labels[0][markers[kb]] == r + 1
    assert model.history.undo_labels[-1] == "Split region cheek_eye_L"
    assert len(model.history.undo_labels) == n + 1
    assert not model.interacting and panel.errors.count + vp.errors.count == 0
    # the split ends split mode and gives the viewport back
    assert not panel.edits.split_mode.value and vp.drag_handler is None and vp.tool == "orbit"
    assert [c["seq"] for c in sent if c.get("type") == "drag_ack"] == [10, 11, 12, 13]
    panel.undo_button.click()
    assert model.regions.regions is R


def test_paint_mode_brush_stroke_grows_the_region_in_one_undo_step(setup):
    from workbench.methods.regions.topology import region_topology

    model, vp, panel, _ = setup
    panel.find_button.click()
    r = select(panel, "mouth_L_2")
    R = model.regions.regions
    panel.edits.paint_mode.value = True
    assert vp.drag_handler is panel.edits.brush_handler and vp.tool == "sculpt"
    panel.edits.paint_radius.value = panel.edits.paint_radius.max / 2  # the markers follow the radius
    markers = np.asarray(vp.markers)
    topo = region_topology(model)
    outside = [i for i, v in enumerate(markers) if R.labels[0][v] != r]
    assert outside  # markers around the region too
    # the outside marker nearest the region's core
    core = R.core(0, r)
    core = core[topo.skin[core]]
    Vn = topo.vertices
    k = min(outside, key=lambda i: np.linalg.norm(Vn[core] - Vn[markers[i]], axis=1).min())
    v = int(markers[k])
    X = np.asarray(model.evaluate(), dtype=np.float64)
    toward = Vn[core][np.argmin(np.linalg.norm(Vn[core] - Vn[v], axis=1))]
    path = [X[v] + f * (toward - Vn[v]) for f in (0.5, 1.0)]  # drag from the marker into the region
    n = len(model.history.undo_labels)
    drag(vp, k, v, path)
    assert panel.edits.brush_handler.last_stroke["error"] == "", panel.edits.status.value
    assert not model.interacting and not panel.edits.brush_handler.dragging
    R2 = model.regions.regions
    assert R2.labels[0][v] == r
    grown = np.flatnonzero((R2.labels[0] == r) & ~(R.labels[0] == r) & topo.skin)
    assert grown.size > 1
    assert model.history.undo_labels[-1] == "Paint region mouth_L_2"
    assert len(model.history.undo_labels) == n + 1
    assert "painted into mouth_L_2" in panel.edits.status.value
    from scipy.sparse.csgraph import connected_components

    c2 = np.flatnonzero((R2.labels[0] == r) & topo.skin)
    assert connected_components(topo.adjacency[c2][:, c2], directed=False)[0] == 1
    # erase with a click-sized dab (paint_at), its own undo step
    panel.edits.paint_erase.value = True
    panel.edits.paint_radius.value = panel.edits.paint_radius.min
    assert panel.edits.paint_at(v) > 0, panel.edits.status.value
    assert model.regions.regions.labels[0][v] == -1
    assert model.history.undo_labels[-1] == "Erase from region mouth_L_2"
    panel.undo_button.click()
    panel.undo_button.click()
    assert model.regions.regions is R
    # a dab far from the region is refused with the reason, no undo step
    panel.edits.paint_erase.value = False
    far = int(R.core(0, "brow_nose_R")[0])
    n = len(model.history.undo_labels)
    assert panel.edits.paint_at(far) == 0
    assert "do not touch region 'mouth_L_2'" in panel.edits.status.value
    assert len(model.history.undo_labels) == n
    panel.edits.paint_mode.value = False
    assert vp.drag_handler is None and vp.tool == "orbit"


def test_escape_cancels_a_pin_drag_and_a_brush_stroke_bit_exactly(setup):
    model, vp, panel, sent = setup
    panel.find_button.click()
    panel.drag_mode.value = True
    k, v = mouth_corner_pin(model, panel)
    st0 = model.regions.state
    X0 = np.array(model.evaluate())
    n_undo = len(model.history.undo_labels)
    msg = {"type": "drag", "index": k, "vertex": v, "gesture": 7}
    vp._on_frontend_msg(vp, {**msg, "phase": "start", "seq": 1}, [])
    vp._on_frontend_msg(vp, {**msg, "phase": "move", "position": list(X0[v] + [0.05, 0.04, 0]), "seq": 2}, [])
    assert panel.drag_handler.dragging and model.regions.state is not st0
    vp._on_frontend_msg(vp, {**msg, "phase": "cancel", "seq": 3}, [])
    assert not panel.drag_handler.dragging and not model.interacting
    assert model.regions.state is st0 and len(model.history.undo_labels) == n_undo
    np.testing.assert_array_equal(model.evaluate(), X0)
    assert [c["seq"] for c in sent if c.get("type") == "drag_ack"] == [1, 2, 3]
    # the same for a brush stroke
    select(panel, "mouth_L_2")
    panel.edits.paint_mode.value = True
    markers = np.asarray(vp.markers)
    R = model.regions.regions
    kb = next(i for i, m in enumerate(markers) if R.labels[0][m] != R.region_index(0, "mouth_L_2"))
    msg = {"type": "drag", "index": kb, "vertex": int(markers[kb]), "gesture": 8}
    vp._on_frontend_msg(vp, {**msg, "phase": "start", "seq": 4}, [])
    vp._on_frontend_msg(vp, {**msg, "phase": "cancel", "seq": 5}, [])
    assert not panel.edits.brush_handler.dragging and not model.interacting
    assert model.regions.state is st0 and len(model.history.undo_labels) == n_undo
    assert panel.errors.count + vp.errors.count == 0


def test_another_widgets_edit_mid_drag_keeps_the_drag_as_one_step(setup):
    from widgets._threading import close_interactions

    model, vp, panel, _sent = setup
    panel.find_button.click()
    panel.drag_mode.value = True
    k, v = mouth_corner_pin(model, panel)
    X0 = np.array(model.evaluate())
    n_undo = len(model.history.undo_labels)
    msg = {"type": "drag", "index": k, "vertex": v}
    vp._on_frontend_msg(vp, {**msg, "phase": "start", "seq": 1}, [])
    vp._on_frontend_msg(vp, {**msg, "phase": "move", "position": list(X0[v] + [0.05, 0.04, 0]), "seq": 2}, [])
    st1 = model.regions.state
    close_interactions(model)  # e.g. the timeline's Key button
    assert not model.interacting and not panel.drag_handler.dragging
    assert model.history.undo_labels[-1].startswith("Region drag ")
    assert len(model.history.undo_labels) == n_undo + 1
    assert panel.drag_handler.last_drag["moves"] == 1 and "last drag" in panel.status.value
    # the front end's late messages change nothing
    vp._on_frontend_msg(vp, {**msg, "phase": "move", "position": list(X0[v] + [0.1, 0.1, 0]), "seq": 3}, [])
    vp._on_frontend_msg(vp, {**msg, "phase": "end", "seq": 4}, [])
    assert model.regions.state is st1 and len(model.history.undo_labels) == n_undo + 1
    assert panel.errors.count + vp.errors.count == 0
    panel.undo_button.click()
    np.testing.assert_array_equal(model.evaluate(), X0)


def test_every_offered_pin_lies_in_a_region_of_the_shown_level(setup):
    """A default marker in the background of the shown level is not offered (its drag could only refuse)."""
    from workbench.methods.handles.presets import default_face_handles

    model, vp, panel, _ = setup
    panel.find_button.click()
    panel.drag_mode.value = True
    defaults = np.asarray(default_face_handles(model).vertices)
    for level in range(model.regions.state.regions.n_levels):
        model.regions.set_level(level)
        st = model.regions.state
        np.testing.assert_array_equal(vp.markers, panel.pins)  # the viewport shows this level's pins
        assert all(st.regions.regions_at(st.level, int(v)) for v in panel.pins), level
        left_out = [int(v) for v in defaults if int(v) not in set(panel.pins.tolist())]
        assert all(not st.regions.regions_at(st.level, v) for v in left_out), level
    # and an offered pin drags: one undo step
    n = len(model.history.undo_labels)
    v = int(panel.pins[0])
    drag(vp, 0, v, [np.asarray(model.vertices[v]) + np.array([0.0, 0.01, 0.0])])
    assert len(model.history.undo_labels) == n + 1
