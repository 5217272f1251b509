"""``model.enhance``: the database, the *Enhanced* preview layer, enhanced frames at the database's resolution.

The model is the 5k sample head; the database is the procedural wrinkled
performance of its Loop subdivision (the 25k head), so the correspondence is
the subdivision operator, found by the facet itself.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.core.shapes import ModelError
from workbench.enhance import Correspondence, PerformanceDatabase
from workbench.enhance.bake import EnhancedTake
from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor, performance_weights

SMILE = {"mouthSmileLeft": 0.9, "mouthSmileRight": 0.9, "browInnerUp": 0.8}


@pytest.fixture(scope="module")
def database() -> PerformanceDatabase:
    fine = workbench.load_sample("head", "25k")
    sc = WrinkleSculptor(fine)
    poses = list(EXAMPLE_POSES.values()) + performance_weights(40)[:20]
    V = np.asarray(fine.vertices, np.float64)
    return PerformanceDatabase.from_frames(sc.detail_of(V), fine.faces.astype(np.int64),
                                           np.stack([sc.detailed(w) for w in poses]), metres_per_unit=0.1)


@pytest.fixture
def model(database: PerformanceDatabase) -> workbench.FaceModel:
    m = workbench.load_sample("head")
    m.enhance.set_database(database, source="procedural")
    return m


def test_the_correspondence_is_found_from_the_meshes(model: workbench.FaceModel, database: PerformanceDatabase) -> None:
    st = model.enhance.state
    assert st.correspondence is not None and st.correspondence.kind == "loop"
    assert (st.correspondence.n_in, st.correspondence.n_out) == (model.n_vertices, database.neutral_.shape[0])
    # a database on the model's own mesh: the identity
    fine = workbench.load_sample("head", "25k")
    fine.enhance.set_database(database)
    assert fine.enhance.state.correspondence.kind == "identity"  # type: ignore[union-attr]
    assert "database of 26 frames (procedural)" in repr(model.enhance)


def test_the_preview_adds_the_database_detail_and_is_one_undo_step(
    model: workbench.FaceModel, database: PerformanceDatabase
) -> None:
    model.set_weights(SMILE)
    below = np.array(model.evaluate(), np.float64)
    assert not model.enhance.preview
    assert np.abs(model.layer_displacement("enhance")).max() == 0
    model.enhance.set_preview(True)
    shown = np.array(model.evaluate(), np.float64)
    corr = model.enhance.state.correspondence
    assert corr is not None
    mapped = corr(below[None])
    expected = below + corr.restrict(database.enhance(mapped)[0] - mapped[0])
    np.testing.assert_allclose(shown, expected, atol=1e-5)
    # the detail is real: wrinkles of a few tenths of a millimetre
    assert np.abs(shown - below).max() * 0.1 * 1e3 > 0.2
    model.undo()
    assert not model.enhance.preview
    np.testing.assert_allclose(model.evaluate(), below, atol=1e-6)
    model.redo()
    assert model.enhance.preview


def test_removing_the_database_turns_the_preview_off_and_undo_brings_both_back(model: workbench.FaceModel) -> None:
    model.enhance.set_preview(True)
    model.enhance.set_database(None)
    assert model.enhance.database is None and not model.enhance.preview
    model.undo()
    assert model.enhance.database is not None and model.enhance.preview


def test_bad_states_are_refused_with_what_was_expected(database: PerformanceDatabase) -> None:
    m = workbench.load_sample("head")
    with pytest.raises(ModelError, match="needs a database"):
        m.enhance.set_preview(True)
    with pytest.raises(ModelError, match="maps 4 → 4 vertices, but the model has 5084"):
        m.enhance.set_database(database, correspondence=Correspondence.identity(4))
    with pytest.raises(ModelError, match="no database"):
        m.enhance.enhance_timeline()
    assert m.enhance.database is None and not m.history.can_undo


def test_enhanced_frames_at_the_database_resolution_replay_exactly(
    model: workbench.FaceModel, database: PerformanceDatabase, tmp_path: Path
) -> None:
    for t, w in ((0.0, dict.fromkeys(SMILE, 0.0)), (0.2, SMILE)):
        model.set_weights(w)
        model.timeline.key_weights(t, list(w))
    model.enhance.set_preview(True)  # the take is made from the face below the preview
    seen: list[float] = []
    take = model.enhance.enhance_timeline(progress=lambda f, msg: seen.append(f))
    assert isinstance(take, EnhancedTake)
    n_frames = len(model.tracks.frame_times())
    assert take.frames.shape == (n_frames, database.neutral_.shape[0], 3)
    assert seen[0] == 0 and seen[-1] == 1.0
    model.enhance.set_preview(False)
    corr = model.enhance.state.correspondence
    assert corr is not None
    for k in (0, n_frames - 1):
        below = np.asarray(model.evaluate_at(float(take.times[k])), np.float64)
        np.testing.assert_allclose(take.frames[k], database.enhance(corr(below[None]))[0], atol=1e-6)
    baked = take.to_model()
    assert baked.n_vertices == database.neutral_.shape[0]
    for k in range(n_frames):
        np.testing.assert_allclose(baked.evaluate_at(float(take.times[k])), take.frames[k], atol=2e-5)
    (pc2,) = take.export(tmp_path / "enhanced.pc2")
    data = pc2.read_bytes()
    _, _, points, _, _, samples = struct.unpack_from("<12siiffi", data, 0)
    assert (points, samples) == (database.neutral_.shape[0], n_frames)
    cache = np.frombuffer(data, "<f4", samples * points * 3, 32).reshape(samples, points, 3)
    np.testing.assert_allclose(cache, take.frames * 0.1, atol=1e-5)


def test_a_session_without_enhancement_pays_nothing() -> None:
    m = workbench.load_sample("head")
    m.set_weights(SMILE)
    ev = m.evaluation_at(0.0)
    assert ev.displacements.get("enhance") is None


def test_a_procedural_database_for_a_rig_with_other_names_and_units() -> None:
    """Shapes spelled ``mouth_smile_L`` style, in centimetres: the regions and the performance still find them."""
    import re

    from workbench.core.shapes import BlendShape, ModelMetadata
    from workbench.enhance.performance import procedural_database

    src = workbench.load_sample("head")

    def respell(name: str) -> str:
        side = {"Left": "_L", "Right": "_R"}
        m = re.match(r"(.*?)(Left|Right)?$", name)
        assert m is not None
        return re.sub(r"(?<!^)([A-Z])", r"_\1", m.group(1)).lower() + side.get(m.group(2) or "", "")

    shapes = [BlendShape(respell(s.name), np.asarray(s.delta) * 10.0) for s in src.shapes]
    rig = workbench.FaceModel(np.asarray(src.vertices) * 10.0, src.faces, shapes,
                              component_labels=src.component_labels, component_names=src.component_names,
                              metadata=ModelMetadata(name="respelled", units="cm"))
    assert "mouth_smile_L" in rig.shape_names
    perf = procedural_database(rig, n_frames=12, levels=0)
    db = perf.database
    assert db.region_names_ == ["brow_left", "brow_right", "mouth_left", "mouth_right"]
    assert perf.weights.shape == (12, len(rig.shape_names)) and perf.weights.max() > 0.4
    assert perf.weights[:, rig.shape_names.index("mouth_smile_L")].max() > 0
    assert db.metres_per_unit == pytest.approx(0.01)
    # the same detail as the decimetre head, ten times the numbers: the example smile's wrinkles
    rig.enhance.set_database(db)
    rig.enhance.set_preview(True)
    rig.set_weights({"mouth_smile_L": 1.0, "mouth_smile_R": 1.0, "cheek_squint_L": 0.5, "cheek_squint_R": 0.5})
    d = rig.layer_displacement("enhance")
    assert 0.02 < np.abs(d).max() < 1.0  # 0.2–10 mm in cm


def test_the_mesh_below_a_layer_is_evaluated_without_it(model: workbench.FaceModel) -> None:
    model.set_weights(SMILE)
    plain = np.array(model.evaluate())
    model.enhance.set_preview(True)
    np.testing.assert_array_equal(model.evaluation_at(0.0, below="enhance").mesh, plain)
    assert model.evaluation_at(0.0, below="enhance").displacements.get("enhance") is None
    with pytest.raises(KeyError, match="no layer named 'nope'"):
        model.evaluation_at(0.0, below="nope")
