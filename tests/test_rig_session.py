"""The Rig tab's state (``workbench.rigging.RigSession``): landmarks, examples, stages, one undo step each.

Template: the committed ~5k sample head. Target: that head re-triangulated and
warped by a known smooth warp, in centimetres (:mod:`workbench.rigging.synthetic`);
its true shapes are ``warp(p + delta) - warp(p)``, so an "actor" made of them
gives example poses with known weights.
"""

from __future__ import annotations

import numpy as np
import pytest
from rig_faces import WARP, Actor

import workbench
from workbench.model import FaceModel, ModelMetadata
from workbench.rigging import RigSession


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def actor(head: FaceModel) -> Actor:
    return Actor(head)


@pytest.fixture(scope="module")
def transferred(head: FaceModel, actor: Actor) -> RigSession:
    s = RigSession(head, actor.model)
    s.transfer()
    return s


def _left_right(head: FaceModel) -> tuple[int, int]:
    """A left-cheek skin vertex and its exact mirror on the (symmetric) sample head."""
    V = head.vertices
    skin = np.flatnonzero(head.component_labels == 0)
    a = int(skin[np.argmax(V[skin, 0] - 0.1 * np.abs(V[skin, 1] - 7.0))])
    return a, int(skin[np.argmin(np.linalg.norm(V[skin] - V[a] * [-1, 1, 1], axis=1))])


# ------------------------------------------------------------------ landmarks


def test_landmarks_add_replace_remove_and_undo_one_step_each(head: FaceModel, actor: Actor) -> None:
    s = RigSession(head, actor.model)
    seen: list[str] = []
    s.events.landmarks.connect(lambda: seen.append("landmarks"))
    assert s.add_landmark(10, 20) == 1
    assert s.add_landmark(11, 21) == 1
    assert s.landmarks == ((10, 20), (11, 21))
    s.add_landmark(10, 25)  # the same template vertex gets a new partner
    assert s.landmarks == ((11, 21), (10, 25))
    s.remove_landmark(0)
    assert s.landmarks == ((10, 25),)
    assert s.history.undo_labels[-1].startswith("Remove landmark 11")
    s.undo()
    assert s.landmarks == ((11, 21), (10, 25))
    s.undo()
    assert s.landmarks == ((10, 20), (11, 21))
    s.redo()
    s.clear_landmarks()
    assert s.landmarks == ()
    s.undo()
    assert s.landmarks == ((11, 21), (10, 25))
    assert len(seen) == 9  # every edit, undo and redo


def test_mirrored_landmarks_pair_left_with_right(head: FaceModel, actor: Actor) -> None:
    s = RigSession(head, actor.model)
    a, a_mirror = _left_right(head)
    # the target vertex nearest the warped template point, and the one nearest its mirror
    b = int(np.argmin(np.linalg.norm(actor.model.vertices - WARP(head.vertices[a][None])[0], axis=1)))
    assert s.mirror_vertex("template", a) == a_mirror
    assert s.mirror_vertex("template", a_mirror) == a
    assert s.add_landmark(a, b, mirror=True) == 2
    (_, _), (ma, mb) = s.landmarks
    assert ma == a_mirror
    true_mb = WARP(head.vertices[a_mirror][None])[0]
    size = np.ptp(actor.model.vertices, axis=0).max()
    # the target's mirror plane is its own (the warp is not symmetric): within 3 % of the head
    assert np.linalg.norm(actor.model.vertices[mb] - true_mb) < 0.03 * size
    assert len(s.history.undo_labels) == 1 and "mirrored" in s.history.undo_labels[0]
    # a mid-plane vertex is its own mirror: one pair only
    skin = np.flatnonzero(head.component_labels == 0)
    mid = int(skin[np.argmax(head.vertices[skin, 2] - 50 * np.abs(head.vertices[skin, 0]))])
    assert s.mirror_vertex("template", mid) == mid
    assert s.add_landmark(mid, b, mirror=True) == 1


def test_bad_landmarks_name_the_side_and_change_nothing(head: FaceModel, actor: Actor) -> None:
    s = RigSession(head, actor.model)
    with pytest.raises(ValueError, match=rf"template vertex must be an integer in 0\.\.{head.n_vertices - 1}, got {head.n_vertices}"):
        s.add_landmark(head.n_vertices, 0)
    with pytest.raises(ValueError, match="target vertex"):
        s.add_landmark(0, -1)
    with pytest.raises(ValueError, match=r"landmarks\[1\]"):
        s.set_landmarks([(1, 2), (3,)])
    with pytest.raises(IndexError):
        s.remove_landmark(0)
    with pytest.raises(ValueError, match="side must be"):
        s.mirror_vertex("left", 0)
    assert s.landmarks == () and not s.can_undo


# ------------------------------------------------------------------ stages


def test_transfer_is_one_undo_step_and_goes_stale_when_landmarks_change(
    transferred: RigSession, actor: Actor
) -> None:
    s = transferred
    assert s.stages_done == ("transfer",)
    rig = s.rig
    assert rig is not None and rig.n_vertices == actor.model.n_vertices
    assert rig.shape_names == s.template.shape_names
    assert s.report is not None and len(s.report.shapes) == 52
    # the transfer is right: jawOpen against its ground truth
    true = actor.truth("jawOpen")
    got = rig.shapes[rig.shape_names.index("jawOpen")].delta.astype(np.float64)
    skin = actor.model.component_labels == 0
    top = np.linalg.norm(true[skin], axis=1).max()
    assert np.sqrt((np.linalg.norm(got - true, axis=1)[skin] ** 2).mean()) < 0.05 * top
    assert s.history.undo_labels == ["Transfer 52 shapes"]
    assert s.undo() == "Transfer 52 shapes"
    assert s.rig is None and s.report is None and s.stages_done == ()
    s.redo()
    assert s.rig is rig
    s.add_landmark(5, 7)
    assert s.stale == ("transfer",)
    s.undo()
    assert s.stale == ()


def test_examples_are_checked_and_undoable(transferred: RigSession, actor: Actor) -> None:
    s = RigSession(transferred.template, actor.model)
    n = actor.model.n_vertices
    with pytest.raises(ValueError, match=rf"expected \({n}, 3\) vertices"):
        s.add_example(np.zeros((n - 1, 3)))
    with pytest.raises(ValueError, match="no template shape 'smile'"):
        s.add_example(actor.model.vertices, {"smile": 1.0})
    with pytest.raises(ValueError, match="finite"):
        s.add_example(np.full((n, 3), np.nan))
    name = s.add_example(actor.pose({"jawOpen": 0.7}), {"jawOpen": 0.5}, name="open")
    assert name == "open"
    assert s.add_example(actor.model.vertices, name="open") == "open 1"
    s.set_example_weights("open", {"mouthSmileLeft": 0.2})
    assert dict(s.example("open").weights) == {"jawOpen": 0.5, "mouthSmileLeft": 0.2}
    s.set_example_weights("open", {"mouthSmileLeft": 0.0})
    assert dict(s.example("open").weights) == {"jawOpen": 0.5}
    s.undo()
    assert dict(s.example("open").weights) == {"jawOpen": 0.5, "mouthSmileLeft": 0.2}
    s.remove_example("open 1")
    assert s.example_names == ["open"]
    with pytest.raises(KeyError, match="no example 'x'"):
        s.example("x")
    # a model in millimetres is scaled to the target's centimetres
    mm = FaceModel(actor.model.vertices * 10.0, actor.model.faces, metadata=ModelMetadata(name="mm pose", units="mm"))
    s.add_example(mm)
    np.testing.assert_allclose(s.example("mm pose").vertices, actor.model.vertices, atol=1e-9)
    with pytest.raises(ValueError, match="read-only"):
        s.example("mm pose").vertices[0, 0] = 1.0
    with pytest.raises(RuntimeError, match="transfer"):
        s.refine()


def test_refine_and_details_are_one_step_each_and_rerunning_the_transfer_drops_them(
    transferred: RigSession, actor: Actor
) -> None:
    s = RigSession(transferred.template, actor.model)
    s.add_landmark(*_left_right(transferred.template)[:1], 0)
    s.clear_landmarks()
    s.transfer()
    transferred_rig = s.rig
    with pytest.raises(ValueError, match="example"):
        s.refine()
    poses = [{"jawOpen": 0.8}, {"mouthSmileLeft": 0.9, "mouthSmileRight": 0.9}, {"browInnerUp": 1.0}]
    for w in poses:
        rough = {k: v - 0.2 for k, v in w.items()}
        s.add_example(actor.pose(w), rough)
    res = s.refine(iterations=3)
    assert s.stages_done == ("transfer", "refine")
    assert s.rig is res.model
    assert res.errors[:, -1].mean() < res.initial_errors.mean()
    assert s.history.undo_labels[-1] == "Refine from 3 examples"
    s.set_example_weights("example 1", {"jawOpen": 0.9})
    assert s.stale == ("refine",)
    s.undo()
    detailed = s.carry_details()
    assert s.stages_done == ("transfer", "refine", "details")
    assert detailed.wrinkles.fitted and len(detailed.handles) > 0
    assert not res.model.wrinkles.fitted  # the refined rig is not touched
    assert not detailed.history.can_undo
    out = s.result()
    assert out is not detailed and out.wrinkles.fitted and out.shape_names == detailed.shape_names
    out.set_weight("jawOpen", 1.0)
    assert s.rig.weights.get("jawOpen", 0.0) == 0.0
    s.undo()
    assert s.rig is res.model
    # a second transfer drops the refinement (same step); undo brings it back
    s.redo()
    s.transfer()
    assert s.stages_done == ("transfer",)
    s.undo()
    assert s.stages_done == ("transfer", "refine", "details")
    assert transferred_rig is s.state.transferred


def test_session_rejects_bad_arguments(head: FaceModel, actor: Actor, tmp_path) -> None:
    with pytest.raises(TypeError, match="template must be a FaceModel"):
        RigSession("head", actor.model)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="target must be a FaceModel or a path"):
        RigSession(head, 3)  # type: ignore[arg-type]
    bare = FaceModel(head.vertices, head.faces)
    with pytest.raises(ValueError, match="no blendshapes"):
        RigSession(bare, actor.model)
    path = tmp_path / "actor.obj"
    actor.model.to_trimesh(evaluated=False).export(path)
    s = RigSession(head, path)
    assert s.target.n_vertices == actor.model.n_vertices
    with pytest.raises(RuntimeError, match="transfer"):
        s.result()


def test_moving_a_landmark_is_one_step_and_keeps_template_vertices_unique(head: FaceModel, actor: Actor) -> None:
    s = RigSession(head, actor.model)
    s.set_landmarks([(1, 2), (3, 4), (5, 6)])
    s.move_landmark(1, "target", 40)
    assert s.landmarks == ((1, 2), (3, 40), (5, 6))
    s.move_landmark(0, "template", 5)  # pair 2 held template vertex 5: it goes
    assert s.landmarks == ((5, 2), (3, 40))
    assert s.history.undo_labels[-2:] == ["Move landmark 2 (target)", "Move landmark 1 (template)"]
    s.undo()
    assert s.landmarks == ((1, 2), (3, 40), (5, 6))
    with pytest.raises(ValueError, match="side must be"):
        s.move_landmark(0, "other", 1)
    with pytest.raises(IndexError):
        s.move_landmark(3, "target", 1)
