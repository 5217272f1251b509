"""§5.4 as printed: the fitted pose space carried to another face (``workbench.rigging.transfer_pose_space``; issue 29)."""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.animation.baked_frames import baked_frames_model
from workbench.core.shapes import BlendShape
from workbench.geometry.masks import skin_or_all_mask
from workbench.methods.handles.handle_set import HandleSet
from workbench.methods.wrinkles.family import fit_sample_wrinkles
from workbench.model import FaceModel
from workbench.rigging import DetailMap, RigTransfer, transfer_details, transfer_pose_space
from workbench.testing import random_warp, remeshed, renumbered, sample_head_warp, warped
from workbench.testing.takes import realistic_weights


def _bare(m: FaceModel, shapes=None) -> FaceModel:
    return FaceModel(m.vertices, m.faces, list(m.shapes if shapes is None else shapes), polygons=m.polygons,
                     component_labels=m.component_labels, component_names=list(m.component_names),
                     metadata=m.metadata)


def _details(m: FaceModel, names, w) -> np.ndarray:
    m.set_weights(dict(zip(names, w, strict=True)))
    d = m.wrinkles.details()
    return np.zeros((m.n_vertices, 3)) if d is None else np.asarray(d, np.float64)


def _corr(a, b, mask) -> float:
    return float(np.corrcoef(a[mask].ravel(), b[mask].ravel())[0, 1])


def _with_detail(D: FaceModel, names, W):
    """``(weights, D's details)`` at each pose of ``W`` where D has any detail."""
    for w in W:
        d = _details(D, names, w)
        if np.abs(d).max() > 0:
            yield w, d


@pytest.fixture(scope="module")
def setup():
    head = workbench.load_sample("head")
    fit_sample_wrinkles(head)
    face = renumbered(warped(head, random_warp(head.vertices, seed=3), shapes=True, retriangulate=True), seed=2)
    dm = DetailMap(RigTransfer(head, face.model))
    W = realistic_weights(head, 30, seed=4)[::5]
    return head, face, dm, W


def _direct(head, face, nodes, *, on_blend: bool = False) -> FaceModel:
    """The target's wrinkles fitted on it directly from the template's examples pushed through the known warp.

    ``on_blend``: each example is the target rig's own blend of its weights (the warped shapes
    summed) plus the example's detail pushed through the warp, as the template's examples are its
    blend plus detail; otherwise the whole warped example, whose large-scale shape the target's
    linear blend misses where the warp bends a large motion (that miss is then fitted as detail).
    """
    truth = {n: face.truth(n) for n in head.shape_names} if on_blend else {}
    D = _bare(face.model, [BlendShape(n, d.astype(np.float32)) for n, d in truth.items()] if on_blend else None)
    D.handles.set(HandleSet(nodes))
    fac = head.wrinkles
    ex = {}
    for n, w in zip(fac.example_names, fac.example_weights, strict=True):
        _, detailed = fac.example_detailed(n)
        example = face.displaced(detailed - head.vertices)
        if on_blend:
            blend = face.model.vertices + sum(float(v) * truth[k] for k, v in w.items())
            example = blend + (example - face.pose(w))
        ex[n] = (w, example)
    D.wrinkles.fit(ex)
    return D


def test_transferred_details_match_the_details_fitted_on_the_warped_face(setup) -> None:
    head, face, dm, W = setup
    A = _bare(face.model)
    n_undo = len(A.history.undo_labels)
    st = transfer_pose_space(head, A, dm)
    assert st.free_nodes and A.slot("wrinkles") is st and len(A.history.undo_labels) == n_undo + 1
    assert len(A.handles) == 0  # the graph's nodes need not be handles
    D = _direct(head, face, st.handles)
    E = _bare(face.model)
    transfer_details(head, E, dm)  # today's example-based refit, for comparison
    skin = skin_or_all_mask(face.model)
    names = list(head.shape_names)
    printed, refit = [], []
    for w, d in _with_detail(D, names, W):
        printed.append(_corr(_details(A, names, w), d, skin))
        refit.append(_corr(_details(E, names, w), d, skin))
    assert len(printed) >= 3
    assert np.median(printed) >= 0.9, printed
    assert np.median(refit) >= 0.9, refit


def test_details_carried_onto_a_remeshed_face_match_the_details_fitted_there(setup) -> None:
    """No target vertex where a template vertex was (4x the triangles), a stronger warp, cm."""
    head, W = setup[0], setup[3]
    face = remeshed(head, seed=1, warp=sample_head_warp(), shapes=True)
    dm = DetailMap(RigTransfer(head, face.model))
    A = _bare(face.model)
    st = transfer_pose_space(head, A, dm)
    D = _direct(head, face, st.handles, on_blend=True)
    skin = skin_or_all_mask(face.model)
    names = list(head.shape_names)
    r, amp = [], []
    for w, d in _with_detail(D, names, W):
        a = _details(A, names, w)
        r.append(_corr(a, d, skin))
        amp.append(np.linalg.norm(a[skin]) / np.linalg.norm(d[skin]))
    assert len(r) >= 3
    assert np.median(r) >= 0.9, r
    assert 0.75 <= np.median(amp) <= 1.25, amp


def test_a_plain_animation_of_the_target_gains_the_detail(setup) -> None:
    head, face, dm, W = setup
    names = list(head.shape_names)
    frames = np.stack([face.pose(dict(zip(names, w, strict=True))) for w in W])
    times = np.arange(len(frames)) / 30.0
    plain = baked_frames_model(frames, face.model.faces, times, 30.0, metadata=face.model.metadata,
                               component_labels=face.model.component_labels,
                               component_names=list(face.model.component_names), what="plain animation")
    for f in range(len(frames)):  # before: exactly the frames
        np.testing.assert_allclose(plain.evaluate_at(times[f]), frames[f], atol=1e-5)
    st = transfer_pose_space(head, plain, dm)
    D = _direct(head, face, st.handles)
    skin = skin_or_all_mask(face.model)
    shown = []
    for f, w in enumerate(W):
        d = _details(D, names, w)
        if np.abs(d).max() == 0:
            continue
        added = np.asarray(plain.evaluate_at(times[f]), np.float64) - frames[f]
        assert np.abs(added).max() > 0.2 * np.abs(d).max()
        shown.append(_corr(added, d, skin))
    assert shown and np.median(shown) >= 0.9, shown


def test_onto_the_template_itself_the_details_come_back(setup) -> None:
    head = setup[0]
    same = _bare(head)
    st = transfer_pose_space(head, same, RigTransfer(head, same))
    names = list(head.shape_names)
    skin = skin_or_all_mask(head)
    for w in setup[3][1:3]:
        a, b = _details(same, names, w), _details(head, names, w)
        assert _corr(a, b, skin) > 0.99
        assert np.abs(a - b).max() < 0.1 * np.abs(b).max()
    assert st.graph is not None and len(st.graph) == len(head.slot("wrinkles").graph)


def test_a_transferred_state_saves_and_loads(setup, tmp_path) -> None:
    head, face, dm, W = setup
    A = _bare(face.model)
    transfer_pose_space(head, A, dm)
    A.save(tmp_path / "t.fwb")
    B = workbench.load(tmp_path / "t.fwb")
    st = B.slot("wrinkles")
    assert st.free_nodes and np.array_equal(st.handles, A.slot("wrinkles").handles)
    names = list(head.shape_names)
    a, b = _details(A, names, W[2]), _details(B, names, W[2])
    assert _corr(a, b, skin_or_all_mask(face.model)) > 0.95


def test_a_correspondence_of_other_meshes_is_refused(setup) -> None:
    head, _, dm, _ = setup
    other = FaceModel(np.eye(3), [[0, 1, 2]])
    with pytest.raises(ValueError, match="correspondence maps"):
        transfer_pose_space(head, other, dm)
    assert not other.wrinkles.fitted
