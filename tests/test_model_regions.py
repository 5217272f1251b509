"""Regions stored in the model: segmentation is undoable, region weights act only in their region."""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.methods.regions.blend import RegionWeights
from workbench.model import ModelError


def test_region_weights_change_only_their_region_and_undo() -> None:
    m = workbench.load_sample("head")
    with pytest.raises(ModelError, match="segment_regions"):
        m.regions.set_level(0)
    st = m.segment_regions(0.25)
    np.testing.assert_array_equal(m.evaluate(), m.blended())  # segmentation alone changes nothing
    r = st.regions.region_index(0, "mouth_L_2")  # the left mouth corner
    rw = RegionWeights.from_global(m, st.regions, 0).with_region(r, {"mouthSmileLeft": 1.0})
    m.regions.set_weights(rw)
    moved = np.flatnonzero(np.linalg.norm(m.evaluate() - m.blended(), axis=1) > 1e-7)
    assert moved.size > 0
    assert np.isin(moved, st.regions.members(0, r)).all()
    m.undo()
    np.testing.assert_array_equal(m.evaluate(), m.blended())
    m.undo()
    assert m.regions.state is None


def _state_arrays(st):  # everything undo must restore bit-exactly
    R = st.regions
    out = [a.copy() for f in ("labels", "weight_rows", "weight_cols", "weight_vals", "background", "parents")
           for a in getattr(R, f)]
    return out, R.names, R.drivers, st.level, None if st.weights is None else st.weights.values.copy()


def _assert_state_equal(a, b) -> None:
    assert len(a[0]) == len(b[0]) and all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(a[0], b[0], strict=True))
    assert a[1:4] == b[1:4]
    assert (a[4] is None and b[4] is None) or np.array_equal(a[4], b[4])


def test_region_edits_are_undoable_and_restore_the_regions_bit_exactly() -> None:
    m = workbench.load_sample("head")
    with pytest.raises(ModelError, match="segment_regions"):
        m.regions.merge(0, 0, 1)
    st0 = m.segment_regions(0.25)
    R = st0.regions
    rw = RegionWeights.from_global(m, R, 0).with_region("mouth_L_2", {"mouthSmileLeft": 0.8})
    m.regions.set_weights(rw)
    st1 = m.regions
    snap = _state_arrays(st1)
    n_undo = len(m.history.undo_labels)

    # merge: one step, the larger region's weights
    st = m.regions.merge(0, "mouth_L_2", "mouth_L_1")
    assert m.history.undo_labels[-1] == "Merge regions mouth_L_2 + mouth_L_1"
    assert len(m.history.undo_labels) == n_undo + 1
    sizes = {nm: int((R.labels[0] == R.region_index(0, nm)).sum()) for nm in ("mouth_L_2", "mouth_L_1")}
    big = max(sizes, key=sizes.get)
    assert big in st.regions.names[0]
    k = st.regions.region_index(0, big)
    assert st.weights.region(k)["mouthSmileLeft"] == pytest.approx(0.8 if big == "mouth_L_2" else 0.0)
    m.undo()
    assert m.regions is st1
    _assert_state_equal(_state_arrays(m.regions), snap)

    # split: both halves inherit the weights
    from workbench.methods.regions.topology import region_topology

    topo = region_topology(m)
    core = R.core(0, "mouth_L_2")
    core = core[topo.skin[core]]
    y = topo.vertices[core, 1]
    sa, sb = int(core[np.argmin(y)]), int(core[np.argmax(y)])
    st = m.regions.split(0, "mouth_L_2", sa, sb)
    assert m.history.undo_labels[-1] == "Split region mouth_L_2"
    for half in ("mouth_L_2_a", "mouth_L_2_b"):
        assert st.weights.region(half)["mouthSmileLeft"] == pytest.approx(0.8)
    X_split = m.evaluate().copy()
    st = m.regions.merge(0, "mouth_L_2_a", "mouth_L_2_b", name="mouth_L_2")
    np.testing.assert_array_equal(st.regions.labels[0], R.labels[0])  # split + merge = the partition
    m.undo()
    np.testing.assert_array_equal(m.evaluate(), X_split)
    m.undo()
    assert m.regions is st1

    # rename: the weights follow the name
    st = m.regions.rename(0, "mouth_L_2", "lip_corner_L")
    assert st.weights.region("lip_corner_L")["mouthSmileLeft"] == pytest.approx(0.8)
    assert st.regions.labels[0] is R.labels[0]
    assert m.regions.rename(0, "lip_corner_L", "lip_corner_L") is st  # no-op: no undo step
    m.undo()
    assert m.regions is st1

    # paint: the face changes where the region grew; a no-op paint adds no step
    A = topo.adjacency
    c = np.zeros(m.n_vertices, bool)
    c[R.core(0, "mouth_L_2")] = True
    # on its side: the mid-plane column belongs to the -x regions
    ring = np.flatnonzero((A @ c.astype(np.int32) > 0) & ~c & topo.skin & (topo.vertices[:, 0] > 0))[:10]
    st = m.regions.paint(0, "mouth_L_2", ring)
    assert (st.regions.labels[0][ring] == R.region_index(0, "mouth_L_2")).all()
    assert m.history.undo_labels[-1] == "Paint region mouth_L_2"
    n = len(m.history.undo_labels)
    assert m.regions.paint(0, "mouth_L_2", ring) is st
    assert len(m.history.undo_labels) == n
    m.undo()
    assert m.regions is st1
    _assert_state_equal(_state_arrays(m.regions), snap)
    m.redo()
    assert (m.regions.regions.labels[0][ring] == R.region_index(0, "mouth_L_2")).all()


def test_region_edit_errors_leave_no_undo_step() -> None:
    from workbench.methods.regions.hierarchy import RegionError

    m = workbench.load_sample("head")
    m.segment_regions(0.25)
    n = len(m.history.undo_labels)
    with pytest.raises(RegionError, match="b: region 'jaw_R_1' does not touch"):
        m.regions.merge(0, "brow_nose_L", "jaw_R_1")
    with pytest.raises(RegionError, match="seeds_a"):
        m.regions.split(0, "brow_nose_L", 0, 1)
    with pytest.raises(RegionError, match="new_name"):
        m.regions.rename(0, "brow_nose_L", "brow_nose_R")
    with pytest.raises(RegionError, match="level"):
        m.regions.paint(9, "brow_nose_L", [0])
    assert len(m.history.undo_labels) == n


def test_edited_regions_save_and_load(tmp_path) -> None:
    m = workbench.load_sample("head")
    m.segment_regions(0.25)
    m.regions.set_weights(RegionWeights.from_global(m, m.regions.regions, 0).with_region("brow_nose_L", {"browInnerUp": 0.5}))
    m.regions.merge(0, "mouth_L_2", "mouth_L_1", name="mouth_corner_L")
    m.regions.rename(1, "jaw", "chin")
    st = m.regions.state
    m.save(tmp_path / "edited.fwb")
    g = workbench.load(tmp_path / "edited.fwb")
    for lv in range(st.regions.n_levels):
        np.testing.assert_array_equal(g.regions.regions.labels[lv], st.regions.labels[lv])
        np.testing.assert_array_equal(g.regions.regions.weight_vals[lv], st.regions.weight_vals[lv])
        assert g.regions.regions.names[lv] == st.regions.names[lv]
    np.testing.assert_array_equal(g.regions.weights.values, st.weights.values)
    assert g.regions.weights.region("brow_nose_L")["browInnerUp"] == pytest.approx(0.5)
