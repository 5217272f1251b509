"""Point-cloud tracking (Bouaziz et al. 2013 §3.1) with online adaptation (§2, §3.2), on generated ground truth.

The truth is made here: known weight curves and head motion on the sample head
(:func:`workbench.capture.synthetic_performance`) sampled into noisy clouds with
outliers, and — for the adaptation — a face that is *not* the template: the
sample head under a known smooth warp (three bumps and an anisotropic scale,
same topology), whose shapes are the warped template's, so its posed meshes
are known vertex for vertex.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import workbench
from workbench.capture import synthetic_performance, track
from workbench.capture.adapt import AdaptiveModel
from workbench.capture.clouds import (
    CLOUD_L1,
    CLOUD_L1_REFINE,
    STABLE_MOTION,
    CloudTrackError,
    sample_vertices,
    track_clouds,
)
from workbench.capture.rig import ExpressionSpace
from workbench.model import BlendShape, FaceModel
from workbench.rigging.synthetic import SmoothWarp

POINTS = 3000


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


def visible_shapes(model: FaceModel) -> list[str]:
    """Shapes a depth camera sees on the skin (the eyeball and tongue shapes move no skin to speak of)."""
    return [n for n in model.shape_names if not n.startswith("eyeLook") and n != "tongueOut"]


def warped(model: FaceModel) -> FaceModel:
    """The sample head under a smooth warp (about 1.3 % of the head size RMS, up to 0.08 dm): another actor."""
    V = model.vertices
    D = np.asarray(model.effective_deltas, np.float64)
    centre = 0.5 * (V.min(0) + V.max(0))
    scale = np.array([1.05, 0.96, 1.03])
    warp = SmoothWarp(
        centres=np.array([[0.0, 7.0, 1.5], [0.35, 7.4, 1.2], [-0.3, 6.3, 1.2]]),
        radii=np.array([0.35, 0.3, 0.35]),
        amplitudes=np.array([[0.0, 0.0, 0.06], [0.03, 0.03, 0.03], [-0.03, -0.02, 0.03]]),
        scale=scale, translation=centre - scale * centre,
    )
    Va = warp(V)
    shapes = [BlendShape(s.name, warp(V + D[i]) - Va, slider_min=s.slider_min, slider_max=s.slider_max)
              for i, s in enumerate(model.shapes)]
    return FaceModel(Va, model.faces, shapes, polygons=model.polygons, component_labels=model.component_labels,
                     component_names=model.component_names, metadata=model.metadata)


def sample_cloud(model: FaceModel, X: np.ndarray, rng: np.random.Generator, noise: float, outliers: float
                 ) -> np.ndarray:
    """Area-weighted samples of the front-facing skin of the posed mesh ``X``, noise, outliers in its box."""
    F = np.asarray(model.faces, np.int64)
    V0 = model.vertices
    skin = model.component_labels == 0
    fn = np.cross(V0[F[:, 1]] - V0[F[:, 0]], V0[F[:, 2]] - V0[F[:, 0]])
    area = 0.5 * np.linalg.norm(fn, axis=1)
    ok = np.flatnonzero(skin[F].all(1) & (fn[:, 2] > 0.4 * area))
    n_out = round(outliers * POINTS)
    tri = ok[rng.choice(ok.size, POINTS - n_out, p=area[ok] / area[ok].sum())]
    s, r2 = np.sqrt(rng.random(tri.size)), rng.random(tri.size)
    b = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    P = np.einsum("pc,pcd->pd", b, X[F[tri]]) + rng.normal(0.0, noise, (tri.size, 3))
    lo, hi = X.min(0), X.max(0)
    return np.concatenate([P, lo + rng.random((n_out, 3)) * (hi - lo)])


def pose_errors(poses: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Mean rotation error (degrees) and mean translation error (model units)."""
    R = np.einsum("tji,tjk->tik", poses[:, :3, :3], truth[:, :3, :3])
    deg = np.degrees(Rotation.from_matrix(R).magnitude())
    return float(deg.mean()), float(np.linalg.norm(poses[:, :3, 3] - truth[:, :3, 3], axis=1).mean())


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


# ------------------------------------------------------------------ the template's own face
@pytest.fixture(scope="module")
def take(head: FaceModel):
    return synthetic_performance(head, 60, seed=3, markers=0, landmarks=0, points=POINTS, noise=0.004,
                                 outliers=0.05, head_motion=1.0, shapes=visible_shapes(head))


def test_tracks_weights_and_pose_from_noisy_clouds(head: FaceModel, take) -> None:
    # a sparse take (a few shapes at a time): the stronger sparse prior suits it (the default is for dense takes)
    res = track_clouds(head, take.clouds, fps=take.fps, adapt=False, l1=CLOUD_L1_REFINE)
    assert res.kind == "clouds" and res.weights.shape == take.weights.shape
    assert not any(res.flags)
    assert rmse(res.weights, take.weights) < 0.045  # measured 0.025 (0.046 at the default l1)
    deg, trans = pose_errors(res.poses, take.poses)
    assert deg < 0.5  # measured 0.17°
    assert trans < 0.01 * take.head_size  # measured 0.56 % (the rotation error at the head's ~7 dm from the origin)
    # the fit error is the noise level (0.004 dm per coordinate) plus the cloud's sampling of a curved surface
    assert np.nanmedian(res.errors) < 2.0 * 0.004
    # a per-frame posed-vertex check on the face: the tracked face is where the true one is
    V = head.vertices
    D = np.asarray(head.effective_deltas, np.float64)
    ids = res.info["vertex_ids"]
    err = [np.linalg.norm(((V[ids] + np.tensordot(res.weights[f], D[:, ids], 1)) @ res.poses[f, :3, :3].T
                           + res.poses[f, :3, 3]) - take.meshes[f][ids], axis=1).mean() for f in range(take.n_frames)]
    assert np.mean(err) < 0.002 * take.head_size  # measured 0.08 %


def test_track_without_vertex_ids_is_the_cloud_tracker(head: FaceModel, take) -> None:
    res = track(head, take.clouds[:10], fps=take.fps, adapt=False)
    assert res.kind == "clouds" and res.n_frames == 10
    assert res.info["adapted"] is None


# ------------------------------------------------------------------ adaptation: a face that is not the template
@pytest.fixture(scope="module")
def actor_take(head: FaceModel):
    """8 neutral frames (the paper's start) then 60 frames of expressions and head motion, on the warped actor."""
    actor = warped(head)
    perf = synthetic_performance(actor, 60, seed=2, markers=0, landmarks=0, points=POINTS, noise=0.004,
                                 outliers=0.05, head_motion=0.5, shapes=visible_shapes(head))
    rng = np.random.default_rng(5)
    R0, t0 = perf.poses[0, :3, :3], perf.poses[0, :3, 3]
    rest = actor.vertices @ R0.T + t0
    lead = [sample_cloud(actor, rest, rng, 0.004, 0.05) for _ in range(8)]
    clouds = lead + list(perf.clouds)
    weights = np.concatenate([np.zeros((8, len(head.shape_names))), perf.weights])
    poses = np.concatenate([np.repeat(perf.poses[:1], 8, 0), perf.poses])
    meshes = np.concatenate([np.repeat(rest[None], 8, 0), perf.meshes])
    return actor, clouds, weights, poses, meshes


@pytest.mark.parametrize("refine", [False, True], ids=["identity", "refine"])
def test_adaptation_lowers_the_fit_error_on_a_face_that_is_not_the_template(head: FaceModel, actor_take,
                                                                            refine: bool) -> None:
    _, clouds, weights, poses, meshes = actor_take
    T = len(clouds)
    late = slice(T // 2, T)
    plain = track_clouds(head, clouds, adapt=False, l1=CLOUD_L1_REFINE if refine else CLOUD_L1)
    adapted = track_clouds(head, clouds, refine=refine)  # adaptation is on by default for clouds
    am = adapted.info["adapted"]
    # the identity is fitted on the first (neutral) frame; refinement then adds every frame
    assert isinstance(am, AdaptiveModel) and am.n_frames_ == (T if refine else 0)
    # the fit error (the tracker's own, RMS point-to-plane): 0.0166 dm against the template, ~0.0055 adapted
    e_plain, e_adapt = np.nanmean(plain.errors[late]), np.nanmean(adapted.errors[late])
    assert e_adapt < 0.5 * e_plain  # measured 0.0170 -> 0.0060 dm (identity), 0.0061 (refined)
    # where the tracked face is, against the truth, vertex for vertex (the last 10 frames, the fitted vertices)
    ids = adapted.info["vertex_ids"]

    def vertex_error(res, b0: np.ndarray, D: np.ndarray) -> float:
        out = []
        for f in range(T - 10, T):
            X = (b0 + np.tensordot(res.weights[f], D, 1)) @ res.poses[f, :3, :3].T + res.poses[f, :3, 3]
            out.append(np.linalg.norm(X[ids] - meshes[f][ids], axis=1).mean())
        return float(np.mean(out))

    v_plain = vertex_error(plain, head.vertices, np.asarray(head.effective_deltas, np.float64))
    v_adapt = vertex_error(adapted, am.neutral_, am.shapes_)
    size = ExpressionSpace.from_model(head).size
    assert v_adapt < 0.35 * v_plain  # measured 1.2 % -> 0.35 % of the head size (identity), 0.22 % (refined)
    assert v_adapt < 0.005 * size
    # the weights: the template compensates the identity with shapes; the adapted rig much less
    # measured 0.41 -> 0.047 (identity, l1 0.005), 0.31 -> 0.081 (refined, l1 0.02)
    assert rmse(adapted.weights, weights) < 0.5 * rmse(plain.weights, weights)
    assert rmse(adapted.weights, weights) < 0.12
    deg, _ = pose_errors(adapted.poses, poses)
    # measured 1.5° (identity), 0.31° (refined); 0.89° without adaptation. The head pose of a face that is not
    # the template is defined only up to a rigid part of its identity, which the richer identity basis takes
    # some of (the posed vertices above are where the truth is)
    assert deg < (1.0 if refine else 2.0)
    # the adapted rig is a model of its own
    rig = am.to_model(name="actor")
    assert rig.n_vertices == head.n_vertices and rig.shape_names == head.shape_names
    assert not np.allclose(rig.vertices, head.vertices)


def test_progress_covers_the_set_up_and_the_frames(head: FaceModel, actor_take) -> None:
    _, clouds, *_ = actor_take
    calls: list[tuple[float, str]] = []
    track_clouds(head, clouds[:6], adapt={"n_basis": 10}, progress=lambda f, msg: calls.append((f, msg)))
    fractions = [f for f, _ in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert any("Laplacian eigenvectors" in msg for _, msg in calls)  # the adaptive model's set-up is not silent
    assert sum("tracking cloud" in msg for _, msg in calls) == 6


def test_a_given_adaptive_model_is_updated_in_place(head: FaceModel, actor_take) -> None:
    _, clouds, *_ = actor_take
    ids, _ = sample_vertices(head)
    am = AdaptiveModel(head, vertex_ids=ids, n_basis=20)
    res = track_clouds(head, clouds[:12], adapt=am, refine=True)
    assert res.info["adapted"] is am
    assert am.n_frames_ == 12
    assert np.array_equal(res.info["vertex_ids"], am.vertex_ids_)


# ------------------------------------------------------------------ bad frames and bad input
def test_empty_and_all_outlier_frames_are_held_not_fatal(head: FaceModel, take) -> None:
    clouds = [np.asarray(c).copy() for c in take.clouds[:16]]
    clouds[0] = np.zeros((0, 3))  # empty before the first good frame: takes the first good frame's values
    clouds[5] = np.zeros((0, 3))  # empty
    size = take.head_size
    rng = np.random.default_rng(0)
    clouds[9] = take.poses[9, :3, 3] + size * (5.0 + rng.random((POINTS, 3)))  # all far away: no pair survives
    clouds[12] = np.full((40, 3), np.nan)  # only NaN rows: dropped, so empty
    res = track_clouds(head, clouds, adapt=True, refine=True)
    held = [0, 5, 9, 12]
    assert [f for f, fl in enumerate(res.flags) if fl] == held
    assert all(res.flags[f] == "held" for f in held)
    for f in (5, 9, 12):
        assert np.array_equal(res.weights[f], res.weights[f - 1])
        assert np.array_equal(res.poses[f], res.poses[f - 1])
        assert np.isnan(res.errors[f])
    assert np.array_equal(res.weights[0], res.weights[1])
    assert res.info["adapted"].n_frames_ == 16 - len(held)  # the rig does not adapt on a held frame
    assert np.isfinite(res.errors[[1, 2, 3, 4, 6]]).all()


def test_bad_input_names_the_argument(head: FaceModel, take) -> None:
    good = list(take.clouds[:4])
    with pytest.raises(CloudTrackError, match=r"clouds\[2\] must be \(p, 3\)"):
        track_clouds(head, [*good[:2], np.zeros((10, 2)), good[3]], adapt=False)
    bad = [c.copy() for c in good]
    bad[1][7, 2] = np.inf
    with pytest.raises(CloudTrackError, match=r"clouds\[1\]\[7\] is infinite"):
        track_clouds(head, bad, adapt=False)
    with pytest.raises(CloudTrackError, match="another unit"):
        track_clouds(head, [c * 100.0 for c in good], adapt=False)  # dm read as mm
    with pytest.raises(CloudTrackError, match="no frame could be tracked"):
        track_clouds(head, [np.zeros((0, 3))] * 3, adapt=False)
    with pytest.raises(CloudTrackError, match="no frames"):
        track_clouds(head, [], adapt=False)
    with pytest.raises(CloudTrackError, match="adapt must be"):
        track_clouds(head, good, adapt="yes")
    with pytest.raises(CloudTrackError, match="max_normal_angle"):
        track_clouds(head, good, adapt=False, max_normal_angle=120)
    with pytest.raises(CloudTrackError, match="sequence of"):
        track_clouds(head, 3.0, adapt=False)
    other = FaceModel(head.vertices, head.faces)
    with pytest.raises(CloudTrackError, match="no blendshapes"):
        track_clouds(other, good, adapt=False)


def test_sample_vertices_split_the_face_into_stable_and_moving(head: FaceModel) -> None:
    ids, stable = sample_vertices(head, samples=500, rigid_samples=200)
    assert ids.size == 700 and stable.sum() == 200
    space = ExpressionSpace.from_model(head)
    motion = space.motion(ids) / space.size
    assert motion[stable].max() <= STABLE_MOTION
    assert motion[~stable].min() > STABLE_MOTION
    # front-facing skin, off the border (the neck cut)
    assert (head.component_labels[ids] == 0).all()
    assert head.vertices[ids, 1].min() > head.vertices[head.component_labels == 0, 1].min() + 0.1


def test_cloud_errors_are_track_errors() -> None:
    """``track`` promises TrackError for input it cannot track, whichever tracker runs."""
    import workbench.capture as capture

    model = workbench.load_sample("head")
    with pytest.raises(capture.TrackError, match="no frames"):
        capture.track(model, [])
    assert issubclass(capture.CloudTrackError, capture.TrackError)


def test_on_a_dense_realistic_take_the_identity_fit_beats_online_refinement(head: FaceModel) -> None:
    """A take that looks real (~30 shapes active at once, a non-zero rest) on a face that is not the template.

    The default (the identity fitted at the start, a mild sparse prior) against the paper's online
    refinement (neutral and correctives on every frame, its stronger prior) and the template as it is.
    """
    from workbench.testing import capture_actor_warp, realistic_weights, warped

    actor = warped(head, capture_actor_warp(head.vertices), name=head.metadata.name).model
    T = 40
    W = realistic_weights(actor, T, seed=11)
    perf = synthetic_performance(actor, T, seed=12, markers=0, landmarks=0, points=POINTS, noise=0.005,
                                 outliers=0.01, head_motion=0.5, weights=W)
    assert (W > 0.05).sum(1).mean() > 20  # dense, as real takes are
    default = track_clouds(head, perf.clouds, fps=perf.fps)
    refined = track_clouds(head, perf.clouds, fps=perf.fps, refine=True)
    template = track_clouds(head, perf.clouds, fps=perf.fps, adapt=False)
    assert default.info["refine"] is False and default.info["l1"] == CLOUD_L1
    e_default, e_refined = rmse(default.weights, W), rmse(refined.weights, W)
    e_template = rmse(template.weights, W)
    # measured 0.146 (identity) vs 0.228 (refined) vs 0.375 (template)
    assert e_default < 0.9 * e_refined
    assert e_default < 0.6 * e_template


def test_refine_needs_a_bool_and_something_to_learn_from(head: FaceModel, take) -> None:
    with pytest.raises(CloudTrackError, match="refine"):
        track_clouds(head, take.clouds[:3], refine="yes")
    with pytest.raises(CloudTrackError, match="never adapt"):
        track_clouds(head, take.clouds[:3], neutral_start=False)
