"""One way to evaluate the mesh: ``evaluate``, ``evaluate_at`` and the exports agree bit for bit.

A hypothesis property test drives random edit sequences through every method
family (weights, handle drags, region weights, paint strokes, saved
expressions, keys of weights / handles / head pose, undo and redo) and then
checks, at random times, that

* ``set_time(t)`` then ``evaluate()`` equals ``evaluate_at(t)``,
* the per-frame exports (``MeshEncoding.points``, and the PC2 file in metres) hold exactly
  ``evaluate_at(t)``,
* the cached live evaluation equals a fresh, uncached run of the pipeline.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import workbench
from workbench.animation.curves import head_rotation_from_euler
from workbench.export import export
from workbench.export.encoding import MeshEncoding
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.paint.painting import Brush
from workbench.methods.regions.blend import RegionWeights
from workbench.model import FaceModel

SHAPES = ["jawOpen", "mouthSmileLeft", "browInnerUp", "eyeBlinkLeft", "mouthPucker"]


@pytest.fixture(scope="module")
def base() -> FaceModel:
    full = workbench.load_sample("head")
    m = FaceModel(
        full.vertices, full.faces, [full.shape(n) for n in SHAPES], polygons=full.polygons,
        component_labels=full.component_labels, component_names=full.component_names,
        metadata=full.metadata,
    )
    m.handles.set(default_face_handles(m))
    m.handles.prepare()
    m.segment_regions(0.25)
    return m


def fresh_copy(base: FaceModel) -> FaceModel:
    m = FaceModel(
        base.vertices, base.faces, base.shapes, polygons=base.polygons,
        component_labels=base.component_labels, component_names=base.component_names,
        metadata=base.metadata, handles=base.handles.value,
    )
    m.restore_slots({"regions": base.regions.state})
    return m


unit = st.floats(0.0, 1.0, allow_nan=False, width=32)
edit = st.one_of(
    st.tuples(st.just("weight"), st.sampled_from(SHAPES), unit),
    st.tuples(st.just("drag"), st.integers(0, 60), st.floats(-0.05, 0.05)),
    st.tuples(st.just("region"), st.integers(0, 5), st.sampled_from(SHAPES), unit),
    st.tuples(st.just("paint"), st.sampled_from([*SHAPES, "saved"]), st.integers(0, 4000), unit),
    st.tuples(st.just("save"), st.just("saved"), st.just(0)),
    st.tuples(st.just("key"), st.sampled_from(["weights", "handles", "head", "expression"]),
              st.floats(0.0, 2.0)),
    st.tuples(st.just("undo"), st.integers(1, 3), st.just(0)),
    st.tuples(st.just("redo"), st.integers(1, 2), st.just(0)),
)


def apply(m: FaceModel, e: tuple) -> None:
    kind = e[0]
    if kind == "weight":
        m.set_weight(e[1], e[2])
    elif kind == "drag":
        i = e[1] % len(m.handles)
        tok = m.begin_interaction("drag")
        for s in (0.3, 0.7, 1.0):  # a drag: rank-1 updates while it lasts, exact on release
            m.handles.move(i, [0.0, s * e[2], 0.5 * s * e[2]], symmetric=True)
            m.evaluate()
        m.end_interaction(tok)
    elif kind == "region":
        st_ = m.regions.state
        rw = st_.weights
        if rw is None or tuple(rw.shape_names) != tuple(m.shape_names):  # none yet, or stale after a bake
            rw = RegionWeights.from_global(m, st_.regions, st_.level)
        r = e[1] % len(rw.region_names)
        m.regions.set_weights(rw.with_region(rw.region_names[r], {e[2]: e[3]}))
    elif kind == "paint":
        name = e[1] if e[1] in m.expressions or e[1] in m.shape_names else SHAPES[0]
        skin = np.flatnonzero(m.component_labels == m.component_names.index("skin"))
        m.paint_stroke(name, [int(skin[e[2] % skin.size])], Brush(radius=0.4, opacity=max(e[3], 0.05)))
    elif kind == "save":
        m.expressions.save(e[1])
    elif kind == "key":
        t = float(e[2])
        if e[1] == "weights":
            m.timeline.key_weights(t, names=SHAPES[:3])
        elif e[1] == "handles":
            m.handles.key(t)
        elif e[1] == "head":
            m.timeline.key_head_pose(t, head_rotation_from_euler(20 * t - 15, 5 * t, 0), [0, 0.05 * t, 0])
        elif "saved" in m.expressions:
            m.key_expression(t, "saved")
    elif kind == "undo":
        for _ in range(e[1]):
            m.undo()
    elif kind == "redo":
        for _ in range(e[1]):
            m.redo()


def read_pc2(path: Path) -> np.ndarray:
    data = path.read_bytes()
    _, _, n, _, _, F = struct.unpack("<12siiffi", data[:32])
    return np.frombuffer(data[32:], "<f4").reshape(F, n, 3)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(edit, min_size=1, max_size=12), times=st.lists(st.floats(0.0, 2.5), min_size=1, max_size=3))
def test_every_path_gives_the_same_bits(base: FaceModel, edits: list, times: list, tmp_path_factory) -> None:
    m = fresh_copy(base)
    for e in edits:
        apply(m, e)
    # the cached live evaluation is what a fresh pipeline run gives
    np.testing.assert_array_equal(m.evaluate(posed=False), m.pipeline.run(m.view(), cache=False).mesh)
    for t in times:
        at = m.evaluate_at(t)
        m.set_time(t)
        np.testing.assert_array_equal(m.evaluate(), at, err_msg=f"evaluate after set_time({t})")
        np.testing.assert_array_equal(MeshEncoding(m, m.tracks).points([t])[0], at)
    if m.tracks.tracks:
        out = tmp_path_factory.mktemp("pc2") / "take.pc2"
        export(m, m.tracks, out)
        frames = read_pc2(out)
        mpu = np.float32(m.metadata.metres_per_unit)
        for f, t in enumerate(m.tracks.frame_times()[:3]):
            np.testing.assert_array_equal(frames[f], m.evaluate_at(float(t)) * mpu)


def test_a_drag_is_exact_once_released(base: FaceModel) -> None:
    """Rank-1 updates are for the drag; the release settles on the full product ``B u``."""
    m = fresh_copy(base)
    tok = m.begin_interaction("drag")
    for s in np.linspace(0.1, 1.0, 7):
        m.handles.move(3, [0.0, 0.04 * s, 0.0])
        m.evaluate()
    m.end_interaction(tok)
    d = m.handles.deformer()
    want = m.vertices32 + np.asarray(d.displacement(m.handles.offsets), np.float32)
    np.testing.assert_array_equal(m.evaluate(), want)


def test_cancel_puts_everything_back(base: FaceModel) -> None:
    m = fresh_copy(base)
    before = m.evaluate().copy()
    steps = len(m.history.undo_labels)
    tok = m.begin_interaction("drag")
    m.handles.move(5, [0.0, 0.05, 0.0])
    m.set_weight("jawOpen", 0.8)
    assert not np.array_equal(m.evaluate(), before)
    m.cancel_interaction(tok)
    np.testing.assert_array_equal(m.evaluate(), before)
    assert len(m.history.undo_labels) == steps  # no undo step
    with pytest.raises(workbench.ModelError, match="not the open one"):
        m.end_interaction(tok)  # a stale token is refused


def test_close_interaction_by_kind(base: FaceModel) -> None:
    m = fresh_copy(base)
    closed = []
    tok = m.begin_interaction("slider", on_close=lambda: closed.append("burst"), kind="burst")
    assert tok.kind == "burst"
    assert not m.close_interaction(kind="gesture") and m.interacting
    assert m.close_interaction(kind="burst") and closed == ["burst"] and not m.interacting
    m.begin_interaction("drag")
    assert not m.close_interaction(kind="burst") and m.close_interaction()
