"""A marker fit (Joshi et al. 2003 §3) keyed on the timeline: region-weight tracks.

``model.regions.key_marker_fit`` keys the fitted global weights and every region's
weights per frame; the model then plays the fit (without its RBF residual) in
``evaluate_at``, ``set_time``/``evaluate``, the file and the exports.
"""

from __future__ import annotations

import numpy as np
import pytest

import workbench
from workbench.animation.curves import TrackError
from workbench.export import ExportError, export
from workbench.export.encoding import MeshEncoding
from workbench.fileformat import load_model
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.regions.marker_fit import (
    MarkerFit,
    fit_markers,
    generate_synthetic_marker_performance,
)
from workbench.methods.regions.tracks import region_level, region_track_name, region_tracks
from workbench.model import FaceModel, ModelError

FRAMES = 8
LEVEL = 1  # not the level segment_regions shows (0): keying must switch to it in the same step
ATOL = 5e-6  # float32 round-off of a ~1 dm head (evaluate is float32, the fit float64)


def fitted_head() -> tuple[FaceModel, MarkerFit]:
    m = workbench.load_sample("head")
    st = m.segment_regions(0.25)
    markers = np.asarray(default_face_handles(m).vertices)
    perf = generate_synthetic_marker_performance(m, markers, n_frames=FRAMES, seed=3, noise=0.001)
    fit = fit_markers(m, st.regions, perf.markers, perf.marker_positions, LEVEL)
    return m, fit


@pytest.fixture
def fitted() -> tuple[FaceModel, MarkerFit]:
    return fitted_head()


def test_keyed_fit_plays_back_the_fit_at_every_frame(fitted):
    m, fit = fitted
    regions = m.regions.regions
    times = m.regions.key_marker_fit(fit)
    fps = m.tracks.fps
    np.testing.assert_array_equal(times, np.arange(FRAMES) / fps)
    assert m.regions.level == LEVEL
    assert len(region_tracks(m.tracks)) == len(fit.region_names) and region_level(m.tracks) == LEVEL
    assert (m.tracks.start, m.tracks.end) == (0.0, (FRAMES - 1) / fps)
    for f in (0, 2, 5, FRAMES - 1):
        ours = m.evaluate_at(f / fps)
        np.testing.assert_allclose(ours, fit.positions(m, regions, f, residual=False), atol=ATOL, rtol=0)
        # the regions matter: the global weights alone give another face
        global_only = m.evaluate_at(f / fps, m.tracks.replace(
            tracks={n: tr for n, tr in m.tracks.tracks.items() if not n.startswith("regions/")}))
        assert np.abs(ours - global_only).max() > 1e-3
    # linear keys, everything linear in the weights: half-way is the mean of the two frames
    mid = m.evaluate_at(2.5 / fps)
    expect = 0.5 * (fit.positions(m, regions, 2, residual=False) + fit.positions(m, regions, 3, residual=False))
    np.testing.assert_allclose(mid, expect, atol=ATOL, rtol=0)


def test_set_time_puts_the_keyed_region_weights_in_the_model(fitted):
    m, fit = fitted
    m.regions.key_marker_fit(fit)
    fps = m.tracks.fps
    seen: list[str] = []
    m.events.regions.connect(lambda: seen.append("regions"))
    m.set_time(4 / fps)
    assert seen == ["regions"]
    np.testing.assert_array_equal(m.regions.weights.values, fit.region_weights[4])
    assert m.weights["jawOpen"] == pytest.approx(float(fit.global_weights[4, m.shape_names.index("jawOpen")]))
    np.testing.assert_array_equal(m.evaluate(), m.evaluate_at(4 / fps))
    # evaluate_at elsewhere does not disturb the live state
    live = m.evaluate().copy()
    m.evaluate_at(1 / fps)
    np.testing.assert_array_equal(m.evaluate(), live)


def test_key_marker_fit_is_one_undo_step(fitted):
    m, fit = fitted
    before = m.regions
    n_steps = len(m.history.undo_labels)
    m.regions.key_marker_fit(fit, start=0.5)
    assert len(m.history.undo_labels) == n_steps + 1
    assert m.history.undo_labels[-1] == f"Key marker fit ({FRAMES} frames from 0.5s)"
    assert m.undo() == m.history.redo_labels[-1]
    assert not m.tracks.tracks and m.regions is before and m.regions.level == 0
    m.redo()
    assert len(region_tracks(m.tracks)) == len(fit.region_names) and m.regions.level == LEVEL
    np.testing.assert_allclose(
        m.evaluate_at(0.5 + 3 / m.tracks.fps), fit.positions(m, m.regions.regions, 3, residual=False),
        atol=ATOL, rtol=0,
    )


def test_every_keys_some_frames_and_always_the_last(fitted):
    m, fit = fitted
    times = m.regions.key_marker_fit(fit, every=3)
    fps = m.tracks.fps
    np.testing.assert_allclose(times * fps, [0, 3, 6, 7])
    for tr in m.tracks.tracks.values():
        assert len(tr) == 4 and set(tr.interpolations) == {"linear"}
    np.testing.assert_allclose(m.evaluate_at(6 / fps), fit.positions(m, m.regions.regions, 6, residual=False),
                               atol=ATOL, rtol=0)


def test_bad_fits_and_arguments(fitted):
    m, fit = fitted
    with pytest.raises(ModelError, match="every must be an int >= 1"):
        m.regions.key_marker_fit(fit, every=0)
    with pytest.raises(ModelError, match="fit must be a MarkerFit"):
        m.regions.key_marker_fit(fit.region_weights)
    with pytest.raises(ModelError, match="start must be finite"):
        m.regions.key_marker_fit(fit, start=float("nan"))
    m.regions.set_level(0)
    m.regions.key_marker_fit(fit)  # switches to the fit's level
    other = fit_markers(m, m.regions.regions, fit.markers, np.zeros((2, fit.markers.size, 3)) + m.vertices[fit.markers], 0)
    with pytest.raises(ModelError, match="region keys on level 1"):
        m.regions.key_marker_fit(other)
    m.add_shape("extra", np.zeros((m.n_vertices, 3)))
    with pytest.raises(ModelError, match="fit was made for 52 shapes"):
        m.regions.key_marker_fit(fit)
    assert m.history.undo_labels[-1] == "Add shape extra"  # nothing recorded by the failures


def test_region_tracks_need_regions(tiny_model):
    m = tiny_model
    tl = m.tracks.add_key(region_track_name(0, "r0"), 0.0, [0.5, 0.0])
    with pytest.raises(ModelError, match="no regions"):
        m.timeline.set(tl)
    st = m.segment_regions(0.25, levels=1, min_region_size=0.0)
    name = st.regions.names[0][0]
    with pytest.raises(TrackError, match="level 0 has no region 'r0'"):
        m.timeline.set(tl)
    with pytest.raises(TrackError, match=r"values must have shape \(2,\), got \(3,\)"):
        m.timeline.set(m.tracks.add_key(region_track_name(0, name), 0.0, [0.5, 0.0, 1.0]))
    m.timeline.set(m.tracks.add_key(region_track_name(0, name), 0.0, [0.5, 0.0]))
    assert region_tracks(m.tracks)[name].value_shape == (2,)


def test_keyed_fit_survives_save_and_load(fitted, tmp_path):
    m, fit = fitted
    m.regions.key_marker_fit(fit, every=2)
    m.save(tmp_path / "fit.fwb")
    back = load_model(tmp_path / "fit.fwb")
    assert back.regions.state is not None and back.regions.level == LEVEL
    assert sorted(back.tracks.tracks) == sorted(m.tracks.tracks)
    for name, tr in m.tracks.tracks.items():
        np.testing.assert_array_equal(back.tracks.tracks[name].values, tr.values)
    for t in (0.0, 3 / 30, 0.2):
        np.testing.assert_array_equal(back.evaluate_at(t), m.evaluate_at(t))


def test_exports_bake_the_keyed_region_weights_and_say_so(fitted, tmp_path):
    m, fit = fitted
    m.regions.key_marker_fit(fit)
    enc = MeshEncoding(m, m.tracks)
    assert enc.baked_layers == ("regions",)
    frames = m.tracks.frame_times()
    assert frames.size == FRAMES
    np.testing.assert_allclose(enc.points(frames), np.stack([m.evaluate_at(t) for t in frames]),
                               atol=ATOL, rtol=0)
    result = export(m, m.tracks, tmp_path / "fit.glb")
    (rep,) = [r for r in result.layers if r.name == "regions"]
    assert rep.encoding == "baked"
    assert rep.detail.startswith(f"region weights keyed on level {LEVEL} ({len(fit.region_names)} region tracks)")
    assert f"({FRAMES} of {FRAMES} frames non-zero)" in rep.detail
    csv = export(m, m.tracks, tmp_path / "fit.csv")
    assert {r.name: r.encoding for r in csv.layers}["regions"] == "omitted"
    # a timeline with region keys on a model without regions cannot be exported
    bare = workbench.load_sample("head")
    with pytest.raises(ExportError, match="no regions"):
        export(bare, m.tracks, tmp_path / "bare.glb")
