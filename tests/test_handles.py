"""Handles as model state: the shell layer on top of the blend, undo, mirror, bake."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import workbench
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.handles.shell import ShellDeformer
from workbench.model import FaceModel, HandleSet, ModelError


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture
def face(head: FaceModel) -> FaceModel:
    m = FaceModel(
        head.vertices, head.faces, head.shapes,
        component_labels=head.component_labels, component_names=head.component_names,
    )
    m.handles.set(default_face_handles(m))
    m.history.clear()
    return m


def test_default_handles_are_symmetric_pairs_on_moving_skin(face: FaceModel) -> None:
    h = face.handles
    assert 40 <= len(h) <= 90
    V = face.vertices
    skin = face.component_vertices("skin")
    assert np.isin(h.vertices, skin).all()
    assert len(set(h.vertices.tolist())) == len(h)
    for i, m in enumerate(h.mirror):
        if m >= 0:
            assert h.mirror[m] == i
            np.testing.assert_allclose(V[h.vertices[m]] * [-1, 1, 1], V[h.vertices[i]], atol=0.02)
        else:
            assert abs(V[h.vertices[i], 0]) < 0.05 and h.names[i].split("_")[1] == "C"
    groups = {n.split("_")[0] for n in h.names}
    assert {"brows", "eyes", "mouth", "jaw"} <= groups


def test_handle_offsets_compose_on_top_of_the_blend(face: FaceModel) -> None:
    face.set_weight("jawOpen", 0.5)
    blended = face.evaluate().copy()
    j = 3
    face.move_handle(j, [0.0, 0.2, 0.1])
    out = face.evaluate()
    v = face.handles.vertices[j]
    np.testing.assert_allclose(out[v], blended[v] + [0.0, 0.2, 0.1], atol=1e-5)
    # every other handle stays exactly where the blend put it
    others = np.delete(face.handles.vertices, j)
    np.testing.assert_allclose(out[others], blended[others], atol=1e-5)
    # and the layer equals a fresh ShellDeformer on the neutral mesh
    d = ShellDeformer(
        face.vertices, face.faces, face.handles.vertices, *face.handles.stiffness,
        component_labels=face.component_labels, component_names=face.component_names,
    )
    np.testing.assert_allclose(face.handles.displacement(), d.displacement(face.handles.offsets), atol=1e-5)


def test_drag_is_one_undo_step_and_rank_one_updates_match(face: FaceModel) -> None:
    with face.interaction("Drag brows_L_1"):
        for t in np.linspace(0, 1, 12):
            face.move_handle(0, [0.0, 0.15 * t, 0.0], symmetric=True)
            face.evaluate()  # the view evaluates every frame: exercises the rank-1 path
    assert face.history.undo_labels == ["Drag brows_L_1"]
    m = face.handles.mirror[0]
    np.testing.assert_allclose(face.handles.offsets[m], [0.0, 0.15, 0.0], atol=1e-7)
    fresh = ShellDeformer(
        face.vertices, face.faces, face.handles.vertices, *face.handles.stiffness,
        component_labels=face.component_labels, component_names=face.component_names,
    ).displacement(face.handles.offsets)
    np.testing.assert_allclose(face.evaluate() - face.vertices, fresh, atol=1e-5)
    face.undo()
    np.testing.assert_array_equal(face.evaluate(), face.vertices.astype(np.float32))


def test_add_remove_handles_keep_mirror_links(face: FaceModel) -> None:
    n = len(face.handles)
    i = face.handles.add(100, "extra")
    j = face.handles.add(101, "extra_R", mirror=i)
    assert face.handles.mirror[i] == j and face.handles.mirror[j] == i
    face.handles.remove(i)
    assert len(face.handles) == n + 1
    assert face.handles.mirror[-1] == -1 and face.handles.names[-1] == "extra_R"
    face.undo()
    face.undo()
    face.undo()
    assert len(face.handles) == n
    with pytest.raises(ModelError, match="vertex must be in"):
        face.handles.add(10**9)


def test_bake_turns_the_layer_into_a_shape_without_changing_the_face(face: FaceModel) -> None:
    face.move_handle(5, [0.0, -0.1, 0.1])
    before = face.evaluate().copy()
    shape = face.handles.bake_to_shape("myEdit")
    assert face.weights["myEdit"] == 1.0
    assert not np.any(face.handles.offsets)
    np.testing.assert_allclose(face.evaluate(), before, atol=1e-5)
    assert face.history.undo_labels[-1] == "Bake handles to myEdit"
    assert np.abs(shape.delta).max() > 0.09
    face.undo()
    assert "myEdit" not in face.shape_names
    np.testing.assert_allclose(face.evaluate(), before, atol=1e-6)


def test_eyes_stay_fixed_and_lashes_follow_the_lids(face: FaceModel) -> None:
    lid = int(np.flatnonzero([n.startswith("eyes_L") for n in face.handles.names])[0])
    face.move_handle(lid, [0.0, -0.1, 0.0])
    u = face.handles.displacement()
    assert np.abs(u[face.component_vertices("eye_left")]).max() == 0.0
    assert np.abs(u[face.component_vertices("eyelashes_left")]).max() > 0.0
    assert np.isfinite(u).all()


def test_handles_survive_save_and_load(face: FaceModel, tmp_path) -> None:
    face.move_handle(1, [0.01, 0.02, 0.03])
    face.save(tmp_path / "f.fwb")
    g = workbench.load(tmp_path / "f.fwb")
    assert g.handles.names == face.handles.names
    np.testing.assert_array_equal(g.handles.mirror, face.handles.mirror)
    np.testing.assert_allclose(g.evaluate(), face.evaluate(), atol=1e-6)


def test_set_handles_validates(face: FaceModel) -> None:
    with pytest.raises(ModelError, match="expected"):
        face.handles.set_offsets(np.zeros((2, 3)))
    with pytest.raises(ModelError, match="finite"):
        face.handles.set_offsets(np.full((len(face.handles), 3), np.nan))
    with pytest.raises(ModelError, match="HandleSet"):
        face.handles.set([1, 2, 3])  # type: ignore[arg-type]
    assert isinstance(face.handles.value, HandleSet)


def test_basis_precompute_reports_progress_through_the_model(face: FaceModel) -> None:
    calls: list[tuple[float, str]] = []
    face.handles.set_progress(lambda f, m: calls.append((f, m)))
    face.handles.prepare()
    fractions = [f for f, _ in calls]
    assert len(calls) >= 4 and 0.0 < fractions[0]
    assert all(b >= a for a, b in itertools.pairwise(fractions)), fractions
    assert calls[-1] == (1.0, "done")
    h = len(face.handles)
    assert f"solving handle columns {h}/{h}" in [m for _, m in calls]
    # offsets alone never rebuild the basis: no more reports
    calls.clear()
    face.move_handle(0, [0.0, 0.05, 0.0])
    face.evaluate()
    assert calls == []
    face.handles.set_progress(None)
