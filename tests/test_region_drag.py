"""``model.regions.begin_drag``: Joshi et al.'s drag-to-sculpt as one undo step (or none, cancelled)."""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.methods.regions.drag import brush_vertices, spread_vertices
from workbench.methods.regions.hierarchy import RegionError


@pytest.fixture(scope="module")
def segmented() -> workbench.FaceModel:
    m = workbench.load_sample("head")
    m.segment_regions(0.25)
    return m


def corner_vertex(m: workbench.FaceModel) -> int:
    st = m.regions.state
    lab = st.regions.labels[st.level]
    inside = np.flatnonzero(lab >= 0)
    d = m.shape("mouthSmileLeft").delta
    return int(inside[np.argmax(np.linalg.norm(d[inside], axis=1))])


def test_a_drag_pulls_the_pin_toward_the_mouse_in_one_undo_step(segmented: workbench.FaceModel) -> None:
    m = segmented
    v = corner_vertex(m)
    before = m.evaluate().copy()
    steps = len(m.history.undo_labels)
    drag = m.regions.begin_drag(v, damping=False)
    target = before[v] + np.array([0.05, 0.05, 0.0])
    for s in (0.25, 0.5, 1.0):
        drag.move(before[v] + s * (target - before[v]))
    stats = drag.end()
    after = m.evaluate()
    # the solved blend moves the pin most of the way (bounded weights: not always all of it)
    assert np.linalg.norm(after[v] - target) < 0.5 * np.linalg.norm(before[v] - target)
    assert len(m.history.undo_labels) == steps + 1 and stats["moves"] == 3
    assert m.history.undo_labels[-1].startswith("Region drag")
    m.undo()
    np.testing.assert_array_equal(m.evaluate(), before)


def test_cancel_leaves_no_trace(segmented: workbench.FaceModel) -> None:
    m = segmented
    v = corner_vertex(m)
    before = m.evaluate().copy()
    steps = len(m.history.undo_labels)
    drag = m.regions.begin_drag(v, damping=False)
    drag.move(before[v] + [0.04, 0.0, 0.0])
    assert not np.array_equal(m.evaluate(), before)
    drag.cancel()
    np.testing.assert_array_equal(m.evaluate(), before)
    assert len(m.history.undo_labels) == steps and not m.interacting


def test_background_and_closed_drags_are_refused(segmented: workbench.FaceModel) -> None:
    m = segmented
    st = m.regions.state
    cover = np.asarray(st.regions.weight_matrix(st.level).sum(axis=1)).ravel()
    background = int(np.flatnonzero(cover == 0)[0])
    with pytest.raises(RegionError, match="background"):
        m.regions.begin_drag(background)
    drag = m.regions.begin_drag(corner_vertex(m))
    assert m.close_interaction()  # a discrete edit elsewhere closes it
    assert not drag.open
    with pytest.raises(RegionError, match="ended"):
        drag.move([0.0, 0.0, 0.0])


def test_brush_and_spread_pick_skin_vertices(segmented: workbench.FaceModel) -> None:
    m = segmented
    v = corner_vertex(m)
    ids = brush_vertices(m, v, 0.2)
    assert v in ids and np.all(m.regions.topology.skin[ids])
    assert np.all(np.linalg.norm(m.vertices[ids] - m.vertices[v], axis=1) <= 0.2)
    picks = spread_vertices(ids, m.vertices, 4)
    assert picks.size == min(4, ids.size) and len(set(picks.tolist())) == picks.size


def test_drag_closed_elsewhere_tells_the_owner_and_keeps_one_step(segmented: workbench.FaceModel) -> None:
    m = segmented
    v = corner_vertex(m)
    before = m.regions.state
    steps = len(m.history.undo_labels)
    told: list[bool] = []
    drag = m.regions.begin_drag(v, damping=False, on_close=lambda: told.append(True))
    drag.move(m.evaluate()[v] + [0.03, 0.02, 0.0])
    assert m.close_interaction()
    assert told == [True] and not drag.open
    assert drag.end()["moves"] == 1  # a late release: no second step, no error
    drag.cancel()  # nor does a late cancel undo what was kept
    assert len(m.history.undo_labels) == steps + 1 and m.regions.state is not before
    m.undo()
    assert m.regions.state is before


# ---------------------------------------------------------------- the region brush
@pytest.fixture
def fresh() -> workbench.FaceModel:
    m = workbench.load_sample("head")
    m.segment_regions(0.25)
    return m


def _grow_path(m: workbench.FaceModel, region: str) -> tuple[int, list[np.ndarray]]:
    """A background-or-neighbour skin vertex next to ``region`` and points into the region."""
    st = m.regions.state
    R, topo = st.regions, m.regions.topology
    r = R.region_index(0, region)
    core = np.flatnonzero((R.labels[0] == r) & topo.skin)
    V = topo.vertices
    side = np.sign(np.median(V[core, 0]))  # the mid-plane column belongs to the -x regions
    ring = np.flatnonzero((topo.adjacency @ np.isin(np.arange(m.n_vertices), core).astype(np.int32) > 0)
                          & topo.skin & (R.labels[0] != r) & (V[:, 0] * side > 0))
    start = int(ring[0])
    toward = V[core][np.argmin(np.linalg.norm(V[core] - V[start], axis=1))]
    return start, [V[start] + f * (toward - V[start]) for f in (0.5, 1.0)]


def test_a_brush_stroke_is_one_undo_step_and_undo_restores_the_object(fresh: workbench.FaceModel) -> None:
    m = fresh
    st0 = m.regions.state
    steps = len(m.history.undo_labels)
    start, path = _grow_path(m, "mouth_L_2")
    r = st0.regions.region_index(0, "mouth_L_2")
    stroke = m.regions.begin_paint(0, "mouth_L_2", radius=0.03)
    assert m.interacting
    assert stroke.dab(start) > 0, stroke.last_error
    for p in path:
        stroke.move(p)
    stats = stroke.end()
    assert not m.interacting and not stroke.open
    assert stats["name"] == "mouth_L_2" and stats["dabs"] >= 1 and stats["changed"] > 0
    assert m.history.undo_labels[-1] == "Paint region mouth_L_2"
    assert len(m.history.undo_labels) == steps + 1
    assert m.regions.regions.labels[0][start] == r
    m.undo()
    assert m.regions.state is st0
    m.redo()
    assert m.regions.regions.labels[0][start] == r


def test_a_cancelled_stroke_restores_the_regions_bit_exactly(fresh: workbench.FaceModel) -> None:
    m = fresh
    m.regions.set_region("mouth_L_2", {"mouthSmileLeft": 0.7})
    st0 = m.regions.state
    labels0 = [a.copy() for a in st0.regions.labels]
    X0 = m.evaluate().copy()
    steps = len(m.history.undo_labels)
    start, path = _grow_path(m, "mouth_L_2")
    stroke = m.regions.begin_paint(0, "mouth_L_2", radius=0.03)
    stroke.dab(start)
    for p in path:
        stroke.move(p)
    assert m.regions.state is not st0 and not np.array_equal(m.evaluate(), X0)
    stroke.cancel()
    assert m.regions.state is st0 and not m.interacting
    assert all(np.array_equal(a, b) for a, b in zip(m.regions.regions.labels, labels0, strict=True))
    np.testing.assert_array_equal(m.evaluate(), X0)
    assert len(m.history.undo_labels) == steps


def test_a_refused_dab_is_skipped_and_the_stroke_goes_on(fresh: workbench.FaceModel) -> None:
    m = fresh
    R = m.regions.regions
    far = int(R.core(0, "brow_nose_R")[0])
    stroke = m.regions.begin_paint(0, "mouth_L_2", radius=0.01, erase=False)
    assert stroke.dab(far) == 0 and "do not touch region 'mouth_L_2'" in stroke.last_error
    start, _ = _grow_path(m, "mouth_L_2")
    assert stroke.dab(start) > 0 and stroke.last_error == ""
    assert stroke.end()["dabs"] == 1
    assert m.history.undo_labels[-1] == "Paint region mouth_L_2"
    with pytest.raises(RegionError, match="ended"):
        stroke.dab(start)
    told: list[bool] = []
    stroke = m.regions.begin_paint(0, "mouth_L_2", radius=0.01, erase=True, on_close=lambda: told.append(True))
    assert m.close_interaction() and told == [True] and not stroke.open
    with pytest.raises(RegionError, match="radius"):
        m.regions.begin_paint(0, "mouth_L_2", radius=0.0)


def test_brush_dab_is_one_undo_step_and_off_skin_is_refused(fresh: workbench.FaceModel) -> None:
    m = fresh
    st0 = m.regions.state
    start, _ = _grow_path(m, "mouth_L_2")
    steps = len(m.history.undo_labels)
    n = m.regions.brush(0, "mouth_L_2", start, 0.02)
    assert n > 0 and m.history.undo_labels[-1] == "Paint region mouth_L_2"
    assert m.regions.brush(0, "mouth_L_2", start, 0.02) == 0  # nothing left to do: no step
    assert len(m.history.undo_labels) == steps + 1
    m.undo()
    assert m.regions.state is st0
    topo = m.regions.topology
    off = int(np.flatnonzero(~topo.skin)[0])
    with pytest.raises(RegionError, match="not on the segmented skin"):
        m.regions.brush(0, "mouth_L_2", off, 0.02)
    assert m.regions.state is st0


def test_region_weights_of_one_region_and_reset_are_one_step_each(fresh: workbench.FaceModel) -> None:
    m = fresh
    st0 = m.regions.state
    g = m.regions.effective_weights
    assert m.regions.weights is None and g.values.shape == (st0.regions.n_regions(0), len(m.shape_names))
    assert m.regions.reset_region("mouth_L_2") is None  # nothing to reset: no step
    steps = len(m.history.undo_labels)
    rw = m.regions.set_region("mouth_L_2", {"mouthSmileLeft": 0.6})
    assert m.history.undo_labels[-1] == "Region mouth_L_2: mouthSmileLeft"
    assert m.regions.weights is rw and rw.region("mouth_L_2")["mouthSmileLeft"] == pytest.approx(0.6)
    others = np.delete(rw.values, rw.region_index("mouth_L_2"), axis=0)
    np.testing.assert_array_equal(others, np.delete(g.values, rw.region_index("mouth_L_2"), axis=0))
    st1 = m.regions.state
    m.regions.reset_region("mouth_L_2")
    assert m.history.undo_labels[-1] == "Reset region mouth_L_2"
    np.testing.assert_array_equal(m.regions.weights.values, g.values)
    np.testing.assert_array_equal(m.evaluate(), m.blended())
    assert len(m.history.undo_labels) == steps + 2
    m.undo()
    assert m.regions.state is st1
    m.undo()
    assert m.regions.state is st0


def test_region_markers_lie_on_the_region_or_its_band(fresh: workbench.FaceModel) -> None:
    from workbench.methods.regions.drag import region_markers

    m = fresh
    R, topo = m.regions.regions, m.regions.topology
    r = R.region_index(0, "cheek_eye_L")
    on = region_markers(m, 0, r, 24)
    assert 2 <= on.size <= 24 and (R.labels[0][on] == r).all() and topo.skin[on].all()
    band = region_markers(m, 0, "cheek_eye_L", 40, band=0.1)
    assert band.size <= 40 and topo.skin[band].all() and (R.labels[0][band] != r).any()
    V, core = topo.vertices, R.core(0, r)
    d = np.linalg.norm(V[band][:, None] - V[core][None], axis=2).min(axis=1)
    assert d.max() <= 0.1 + 1e-12
