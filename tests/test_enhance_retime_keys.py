"""``model.enhance.retime``: *Retime from performance* on the timeline (Bermano et al. 2014 §6.2).

Ground truth: takes in which the jaw opens along a known ease (slow start, fast
finish) and distractor takes; the timeline has only two keys (closed, open); after
retiming, the in-betweens follow the known ease, not the linear or Bézier
in-betweens the keys alone give — as one undo step.
"""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.core.shapes import ModelError


def _ease(u: np.ndarray) -> np.ndarray:
    return u**3  # slow start, fast finish: neither linear nor smoothstep


@pytest.fixture(scope="module")
def takes() -> tuple[list[str], list[np.ndarray]]:
    model = workbench.load_sample("head")
    names = list(model.shape_names)
    k, j = len(names), names.index("jawOpen")
    rng = np.random.default_rng(0)
    out = []
    for t in range(4):
        T = 40 + 5 * t
        W = np.zeros((T, k))
        u = np.clip((np.arange(T) - 5) / (T - 15), 0, 1)
        W[:, j] = 0.9 * _ease(u)
        out.append(W + rng.normal(0, 0.002, W.shape).clip(0))
    distractor = np.zeros((50, k))
    distractor[:, names.index("mouthSmileLeft")] = np.linspace(0, 1, 50)
    out.append(distractor)
    return names, out


def test_retimed_in_betweens_follow_the_take_and_are_one_undo_step(takes) -> None:
    _, db = takes
    model = workbench.load_sample("head")
    model.timeline.set_fps(30)
    model.timeline.add_key("weights/jawOpen", 0.0, 0.0)
    model.timeline.add_key("weights/jawOpen", 1.0, 0.9)
    n_undo = len(model.history.undo_labels)
    times = np.linspace(0, 1, 31)
    before = model.slot("tracks").weight_matrix(["jawOpen"], times)[:, 0]
    res = model.enhance.retime(0.0, 1.0, db)
    assert res.matched[0] < 4  # one of the jaw takes, not the smile
    assert len(model.history.undo_labels) == n_undo + 1
    assert model.history.undo_labels[-1] == "Retime 0–1 s from performance"
    after = model.slot("tracks").weight_matrix(["jawOpen"], times)[:, 0]
    truth = 0.9 * _ease(times)
    err_after = np.sqrt(np.mean((after - truth) ** 2))
    err_before = np.sqrt(np.mean((before - truth) ** 2))
    # (3.5x here: the takes hold the open jaw for 10 noisy frames, and the end key's match
    # drifts into that hold a little — the weak spot of the paper's Fig. 7)
    assert err_after < 0.4 * err_before, (err_after, err_before)
    assert after[0] == pytest.approx(0.0) and after[-1] == pytest.approx(0.9)
    assert np.all(np.diff(after) >= -1e-6)  # monotone like the take
    # only the shape that changes between the keys got keys
    assert set(model.slot("tracks").weight_tracks) == {"jawOpen"}
    model.undo()
    np.testing.assert_allclose(model.slot("tracks").weight_matrix(["jawOpen"], times)[:, 0], before)


def test_a_tracked_take_and_bad_input(takes) -> None:
    from workbench.capture import TrackResult

    names, db = takes
    model = workbench.load_sample("head")
    model.timeline.add_key("weights/jawOpen", 0.0, 0.0)
    model.timeline.add_key("weights/jawOpen", 1.0, 0.9)
    T = db[0].shape[0]
    take = TrackResult(db[0], np.tile(np.eye(4), (T, 1, 1)), np.zeros(T), ("",) * T, 30.0, tuple(names))
    model.enhance.retime(0.0, 1.0, [take])
    with pytest.raises(ModelError, match="t0 < t1"):
        model.enhance.retime(1.0, 0.5, db)
    with pytest.raises(ModelError, match="no takes"):
        model.enhance.retime(0.0, 1.0, [])
    with pytest.raises(ModelError, match=r"database\[0\] must be \(T, 52\)"):
        model.enhance.retime(0.0, 1.0, [np.zeros((10, 3))])
    with pytest.raises(ModelError, match="the same"):
        model.enhance.retime(2.0, 3.0, db)


def test_mesh_space_takes_time_the_keys_like_their_weights(takes) -> None:
    """Point caches of the same takes (the blend of their weights) retime the keys the same way.

    By default they are projected onto the model's shapes and matched in those weights: the
    timing is the weight takes' own. Matched as raw vertices (``space="mesh"``) the jaw dominates
    the distance, and on these takes (noise on every other weight) that follows the ease closely.
    """
    names, weight_takes = takes
    model = workbench.load_sample("head")
    j = names.index("jawOpen")
    deltas = np.stack([s.delta for s in model.shapes]).astype(np.float64)
    caches = [np.asarray(model.vertices) + np.einsum("tk,kvc->tvc", W, deltas) for W in weight_takes[:2]]
    for t, w in ((0.0, 0.0), (1.0, 0.9)):
        model.set_weights({"jawOpen": w})
        model.timeline.key_weights(t, ["jawOpen"])
    by_weights = model.enhance.retime(0.0, 1.0, weight_takes[:2])
    model.undo()
    res = model.enhance.retime(0.0, 1.0, caches)
    assert res.space == "rig" and res.choice == by_weights.choice and res.matched == by_weights.matched
    np.testing.assert_allclose(res.s, by_weights.s, atol=1e-4)  # the keys are faces evaluated in float32
    u = np.linspace(0, 1, len(res.s))
    played = model.tracks.weight_matrix(names, u)[:, j]
    np.testing.assert_allclose(played, 0.9 * res.s, atol=1e-6)
    model.undo()
    res = model.enhance.retime(0.0, 1.0, caches, space="mesh")
    assert res.space == "mesh"
    assert np.abs(res.s - _ease(u)).max() < np.abs(u - _ease(u)).max() / 2  # follows the ease, not the line
    played = model.tracks.weight_matrix(names, u)[:, j]
    np.testing.assert_allclose(played, 0.9 * res.s, atol=1e-6)
    with pytest.raises(ModelError, match="must be \\(40, 5084, 3\\) on the model's mesh"):
        model.enhance.retime(0.0, 1.0, [caches[0][:, :10]])


def test_point_cache_retime_follows_shape_edits(takes) -> None:
    """The rig basis point caches are matched in is kept between calls, never stale: after a
    shape edit the retiming is the one a model made with that edit gives."""
    names, weight_takes = takes

    def keyed(jaw_scale: float) -> workbench.FaceModel:
        model = workbench.load_sample("head")
        if jaw_scale != 1.0:
            model.set_shape_delta("jawOpen", jaw_scale * np.asarray(model.shape("jawOpen").delta))
        for t, w in ((0.0, 0.0), (1.0, 0.9)):
            model.set_weights({"jawOpen": w})
            model.timeline.key_weights(t, ["jawOpen"])
        return model

    model = keyed(1.0)
    deltas = np.stack([s.delta for s in model.shapes]).astype(np.float64)
    caches = [np.asarray(model.vertices) + np.einsum("tk,kvc->tvc", W, deltas) for W in weight_takes[:2]]
    first = model.enhance.retime(0.0, 1.0, caches)
    model.undo()
    again = model.enhance.retime(0.0, 1.0, caches)
    model.undo()
    np.testing.assert_array_equal(again.s, first.s)
    # a jaw half as strong: the caches' jaw needs weights past the slider (1.8), so the projection
    # and the timing change; the edit is seen exactly as a model built with it sees it
    model.set_shape_delta("jawOpen", 0.5 * deltas[names.index("jawOpen")])
    edited = model.enhance.retime(0.0, 1.0, caches)
    fresh = keyed(0.5).enhance.retime(0.0, 1.0, caches)
    assert np.abs(edited.s - first.s).max() > 1e-3
    np.testing.assert_allclose(edited.s, fresh.s, atol=1e-12)


def test_takes_at_another_rate_are_resampled_to_the_timelines() -> None:
    """A 60 fps tracked take times a 30 fps timeline by seconds, not by frames."""
    from types import SimpleNamespace

    from workbench.enhance.facet import weight_takes

    t60 = np.arange(61) / 60.0
    take = SimpleNamespace(shape_names=["a", "b"], weights=np.stack([t60, t60**2], axis=1), fps=60.0)
    (W,) = weight_takes([take], ["b", "a"], 30.0)
    assert W.shape == (31, 2)
    t30 = np.arange(31) / 30.0
    np.testing.assert_allclose(W[:, 1], t30, atol=1e-12)
    np.testing.assert_allclose(W[:, 0], t30**2, atol=3e-4)  # linear interpolation of t² between 60 fps samples
    (W_native,) = weight_takes([take], ["a", "b"])
    assert W_native.shape == (61, 2)
