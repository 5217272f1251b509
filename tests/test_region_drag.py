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
