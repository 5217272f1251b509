"""Marker replay through the shell with wrinkles (``workbench.capture.replay``; Bickel et al. 2008 Fig. 6; issue 29)."""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.capture import ReplayResult, TrackError, replay, track
from workbench.geometry.masks import skin_or_all_mask
from workbench.model import FaceModel
from workbench.testing import foreign_face
from workbench.testing.takes import realistic_take

T = 60


def _half_rig(m: FaceModel) -> FaceModel:
    """The rig without every other shape (its takes then lie partly outside its span)."""
    return FaceModel(m.vertices, m.faces, m.shapes[::2], polygons=m.polygons, component_labels=m.component_labels,
                     component_names=list(m.component_names), metadata=m.metadata)


def _plain(m: FaceModel) -> FaceModel:
    return FaceModel(m.vertices, m.faces, (), polygons=m.polygons, component_labels=m.component_labels,
                     component_names=list(m.component_names), metadata=m.metadata)


def _local_truth(perf):
    P = perf.poses
    return np.einsum("tji,tnj->tni", P[:, :3, :3], perf.meshes - P[:, None, :3, 3])


def _tracked_meshes(rig, perf):
    res = track(rig, perf.markers, vertex_ids=perf.marker_ids)
    tl = res.to_timeline(0.0, head_pose=False)
    return np.stack([rig.evaluation_at(f / perf.fps, tl).mesh for f in range(perf.markers.shape[0])])


@pytest.fixture(scope="module")
def head():
    return workbench.load_sample("head")


@pytest.mark.parametrize("which", ["sample head", "foreign face"])
def test_replay_beats_blendshape_tracking_where_the_rig_lacks_shapes(head, which) -> None:
    face = head if which == "sample head" else foreign_face(head, seed=3).model
    # a realistic take of the full rig with mocap-grade noise, replayed on a rig with half the shapes
    perf = realistic_take(face, T, seed=11, markers=120, noise_mm=0.15)
    rig = _half_rig(face)
    truth = _local_truth(perf)
    skin = skin_or_all_mask(face)

    def err(M):
        return float(np.linalg.norm(M - truth, axis=2)[:, skin].mean())

    e_track = err(_tracked_meshes(rig, perf))
    rep = replay(rig, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps, wrinkles=False)
    e_replay = err(rep.meshes)
    assert e_replay <= 0.75 * e_track, (e_replay, e_track)
    # and the head pose was removed: the replay's poses are the take's within a fraction of a degree
    dR = np.einsum("tij,tik->tjk", rep.poses[:, :3, :3], perf.poses[:, :3, :3])
    angles = np.degrees(np.arccos(np.clip((np.trace(dR, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert np.median(angles) < 0.5, np.median(angles)


def test_without_shapes_the_markers_land_on_their_vertices_after_pose_removal(head) -> None:
    perf = realistic_take(head, 30, seed=2, markers=80, noise_mm=0.0)
    plain = _plain(head)
    rep = replay(plain, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps, smoothing=0.0, wrinkles=False)
    assert rep.tracked is None and rep.weights.shape == (30, 0)
    R, t = rep.poses[:, :3, :3], rep.poses[:, :3, 3]
    seen = np.einsum("tji,tmj->tmi", R, perf.markers - t[:, None])
    size = float(np.linalg.norm(np.ptp(head.vertices, axis=0)))
    np.testing.assert_allclose(rep.meshes[:, perf.marker_ids], seen, atol=1e-5 * size)
    # the rigid fit found the head motion (the expression is local)
    assert np.abs(rep.poses - perf.poses).max() < 0.02 * size


def test_wrinkles_appear_where_the_marker_graph_compresses(head) -> None:
    perf = realistic_take(head, 40, seed=4, markers=100, noise_mm=0.0)
    plain = replay(head, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps, wrinkles=False)
    rep = replay(head, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps)
    assert rep.wrinkles is not None and "procedural" in rep.info["wrinkles"]
    detail = np.linalg.norm(rep.meshes - plain.meshes, axis=2)  # (T, n)
    g = rep.wrinkles.graph
    strain = np.stack([g.strain(m[rep.vertex_ids].astype(np.float64)) for m in plain.meshes])  # (T, F)
    f = int(np.argmin(strain.min(1)))  # the frame of the strongest compression
    assert strain[f].min() < -0.02 and detail[f].max() > 0
    # the detail sits around the most compressed edge, not elsewhere
    i, j = g.edges[int(np.argmin(strain[f]))]
    mid = 0.5 * (head.vertices[rep.vertex_ids[i]] + head.vertices[rep.vertex_ids[j]])
    near = np.linalg.norm(head.vertices - mid, axis=1) < 0.1 * float(np.linalg.norm(np.ptp(head.vertices, 0)))
    assert detail[f][near].mean() > 3 * detail[f][~near].mean()


def test_apply_replay_is_one_undo_step_and_the_model_plays_the_replay(head) -> None:
    model = workbench.load_sample("head")
    perf = realistic_take(model, 20, seed=6, markers=60, noise_mm=0.1)
    rep = model.capture.replay(perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps)
    assert isinstance(rep, ReplayResult) and rep.meshes.shape == (20, model.n_vertices, 3)
    before = (model.handles.value, model.slot("wrinkles"), model.slot("tracks"))
    labels = model.history.undo_labels
    model.capture.apply_replay(rep, tolerance=0.0)
    assert len(model.history.undo_labels) == len(labels) + 1, model.history.undo_labels[-3:]
    assert np.array_equal(model.handles.vertices, rep.vertex_ids)
    for f in (0, 7, 19):
        np.testing.assert_allclose(model.evaluation_at(f / perf.fps).mesh, rep.meshes[f], atol=1e-6)
        # the exported, posed frame carries the head pose
        posed = model.evaluate_at(f / perf.fps)
        np.testing.assert_allclose(posed, rep.meshes[f] @ rep.poses[f, :3, :3].T + rep.poses[f, :3, 3], atol=1e-5)
    model.undo()
    after = (model.handles.value, model.slot("wrinkles"), model.slot("tracks"))
    assert all(a is b for a, b in zip(after, before, strict=True))
    assert model.history.undo_labels == labels


def test_a_replayed_face_exports_as_baked_frames(head, tmp_path) -> None:
    from workbench.export import export

    perf = realistic_take(head, 8, seed=1, markers=60, noise_mm=0.0)
    rep = replay(head, perf.markers, vertex_ids=perf.marker_ids, fps=perf.fps, wrinkles=False)
    face = rep.to_face(head)
    for f in (0, 5):
        np.testing.assert_allclose(face.evaluate_at(f / perf.fps), rep.meshes[f], atol=1e-5)
    out = export(face, face.tracks, tmp_path / "replay.glb")
    assert out and out[0].stat().st_size > 0


@pytest.mark.parametrize(("change", "match"), [
    (lambda Y, ids: (Y, ids[:-1]), "vertex_ids has"),
    (lambda Y, ids: (Y, np.r_[ids[:-1], ids[0]]), "carries markers"),
    (lambda Y, ids: (np.where(np.arange(Y.shape[1])[None, :, None] == 3, np.nan, Y), ids), "occluded in every frame"),
    (lambda Y, ids: (Y, np.roll(ids, 7)), "from vertex"),
    (lambda Y, ids: (Y[:, :2], ids[:2]), "at least 3 markers"),
])
def test_bad_input_is_named(head, change, match) -> None:
    perf = realistic_take(head, 6, seed=0, markers=40, noise_mm=0.0)
    Y, ids = change(perf.markers, perf.marker_ids)
    with pytest.raises(TrackError, match=match):
        replay(_plain(head), Y, vertex_ids=ids)
    with pytest.raises(TrackError, match="smoothing"):
        replay(_plain(head), perf.markers, vertex_ids=perf.marker_ids, smoothing=-1.0)


def test_wiener_gains_keep_a_clean_offset_and_drop_pure_noise() -> None:
    from scipy.ndimage import gaussian_filter1d

    from workbench.capture.replay import _wiener_gains

    rng = np.random.default_rng(0)
    t = np.linspace(0, 3, 90)[:, None]
    clean = np.stack([np.sin(2 * t + k) * 0.01 for k in range(4)], axis=1).repeat(3, 2)  # (T, 4, 3) smooth
    noise = rng.normal(0, 0.003, (90, 4, 3))
    raw = np.concatenate([clean, noise], axis=1)
    g = _wiener_gains(raw, gaussian_filter1d(raw, 2.0, axis=0, mode="nearest"), 2.0)
    assert (g[:4] > 0.95).all(), g
    assert (g[4:] < 0.5).all() and g[4:].mean() < 0.35, g


def test_a_neutral_frame_takes_markers_glued_above_the_skin_as_rest(head) -> None:
    """Markers 2 mm off their vertices (glued on the skin's surface, another actor): with ``neutral_frame`` the
    constant offsets are the rest, not an expression."""
    rng = np.random.default_rng(3)
    plain = _plain(head)
    ids = np.sort(rng.choice(np.flatnonzero(skin_or_all_mask(head)), 50, replace=False))
    glued = head.vertices[ids] + rng.normal(0, 0.02, (50, 3))  # 2 mm in dm
    ang = np.radians(np.linspace(0, 8, 10))
    frames = np.stack([glued @ np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]).T
                       + [0.01 * k, 0, 0] for k, a in enumerate(ang)])
    off = replay(plain, frames, vertex_ids=ids, wrinkles=False, smoothing=0.0)
    rest = replay(plain, frames, vertex_ids=ids, wrinkles=False, smoothing=0.0, neutral_frame=0)
    moved = np.abs(off.meshes - head.vertices).max()
    assert moved > 0.01  # without: the glue offsets deform the face
    assert np.abs(rest.meshes - head.vertices).max() < 0.05 * moved
    with pytest.raises(TrackError, match="neutral_frame"):
        replay(plain, frames, vertex_ids=ids, neutral_frame=10)
