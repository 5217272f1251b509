"""The Capture tab (``widgets.capture.CapturePanel``) in the kernel, on a generated take with known answer.

``workbench.capture.synthetic.synthetic_performance`` plays known weight curves
and head motion on the sample head and observes them as noisy, partly occluded
markers; the tab loads the take (from files, as a user would), tracks it, draws
the markers over the face, re-tracks a window when λ moves, and applies the
result to the timeline as one undo step. The browser test clicks the same
buttons with the mouse.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import workbench

pytestmark = pytest.mark.ui


@pytest.fixture(scope="module")
def take():
    from workbench.capture.synthetic import synthetic_performance

    model = workbench.load_sample("head")
    return model, synthetic_performance(model, 90, fps=30.0, seed=4, markers=60, noise=0.002, occlusion=0.05)


def _write_take(tmp_path, model, perf):
    """The take as a user's files: an NPZ-free CSV of markers (metres) and a JSON marker map."""
    names = [f"M{i:02d}" for i in range(perf.markers.shape[1])]
    scale = {"dm": 0.1, "cm": 0.01, "mm": 0.001, "m": 1.0}[model.metadata.units]
    cols = ["frame"] + [f"{n}_{a}" for n in names for a in "xyz"]
    rows = [",".join(cols)]
    for f, P in enumerate(perf.markers * scale):
        cells = [str(f)] + ["" if not np.isfinite(v) else f"{v:.6f}" for v in P.reshape(-1)]
        rows.append(",".join(cells))
    csv = tmp_path / "take.csv"
    csv.write_text("# units: m\n# fps: 30\n" + "\n".join(rows) + "\n")
    mapping = tmp_path / "markers.json"
    mapping.write_text(json.dumps({n: int(v) for n, v in zip(names, perf.marker_ids, strict=True)}))
    return csv, mapping


def test_load_track_scrub_retrack_and_apply(take, tmp_path) -> None:
    from widgets import Workbench

    _, perf = take
    model = workbench.load_sample("head")
    wb = Workbench(model, height=240)
    try:
        cap = wb.capture
        wb.tabs.selected_index = wb.tabs.titles.index("Capture")
        assert cap.track_button.disabled and cap.apply_button.disabled
        # no plot before a tracked take (an empty Image draws as a broken picture in the page)
        assert cap.plot.layout.display == "none" and not cap.plot.value
        csv, mapping = _write_take(tmp_path, model, perf)
        cap.path.value, cap.map_path.value = str(csv), str(mapping)
        cap.load_button.click()
        assert cap.take is not None and cap.take["kind"] == "markers", wb.errors.outputs
        assert "90 frames at 30 fps, 60 markers" in cap.info.value
        assert not cap.adapt.disabled and not cap.adapt.value  # markers: adaptation offered, off by default
        np.testing.assert_allclose(cap.take["frames"], perf.markers, atol=1e-5, equal_nan=True)
        # frame 0's visible markers are drawn over the face
        drawn = wb.viewport.overlay_points
        assert len(drawn) == int(np.isfinite(perf.markers[0]).all(axis=1).sum())
        cap.frame.value = 10
        np.testing.assert_allclose(wb.viewport.overlay_points,
                                   perf.markers[10][np.isfinite(perf.markers[10]).all(axis=1)], atol=1e-5)
        # track: weights close to the truth, a plot
        cap.track_button.click()
        res = cap.result
        assert res is not None and res.n_frames == 90
        assert "frames/s" in cap.progress.label.value
        rmse = np.sqrt(np.mean((res.weights - perf.weights) ** 2))
        assert rmse < 0.08, rmse
        assert cap.plot.value[:4] == b"\x89PNG" and cap.plot.layout.display is None
        # a stronger smoothness re-tracks the window around the current frame only
        before = np.array(res.weights)
        cap.frame.value = 45
        cap.temporal.value = 10.0
        after = np.array(cap.result.weights)
        assert cap.result.info["retracked"] == (0, 89) or cap.result.info["retracked"][0] <= 45
        assert not np.array_equal(before, after)
        jitter = lambda W: float(np.mean(np.diff(W, 2, axis=0) ** 2))  # noqa: E731
        assert jitter(after) < jitter(before)
        # apply: one undo step; the timeline then reproduces the weights; scrubbing it moves the frame
        n_undo = len(model.history.undo_labels)
        cap.apply_button.click()
        assert len(model.history.undo_labels) == n_undo + 1
        model.set_time(30 / 30.0)
        assert cap.frame.value == 30
        got = np.array([model.weights.get(n, 0.0) for n in res.shape_names])
        assert np.abs(got - cap.result.weights[30]).max() < 0.02
        wb.undo()
        assert len(model.history.undo_labels) == n_undo
        # leaving the tab hides the points
        wb.tabs.selected_index = 0
        assert len(wb.viewport.overlay_points) == 0
    finally:
        wb.close()


def test_bad_take_files_say_what_is_wrong(tmp_path) -> None:
    from widgets import Workbench

    wb = Workbench(workbench.load_sample("head"), height=240)
    try:
        cap = wb.capture
        with pytest.raises(ValueError, match="type the path"):
            cap.load("")
        bad = tmp_path / "bad.csv"
        bad.write_text("frame,A_x,A_y\n0,1,2\n")
        with pytest.raises(Exception, match=r"bad\.csv"):
            cap.load(str(bad), None)
        assert cap.take is None and cap.track_button.disabled
        cap.path.value = str(bad)
        cap.load_button.click()  # through the button: reported, nothing loaded
        assert cap.take is None and cap.errors.count == 1
        assert "bad.csv" in wb.errors.outputs[-1]["text"]
    finally:
        wb.close()


def test_the_sliders_ignore_the_browsers_snapped_echo_of_off_grid_weights() -> None:
    """The browser snaps a weight it is sent to the 0.01 step and sends it back, maybe late."""
    from widgets.panels import ExpressionPanel

    model = workbench.load_sample("head")
    panel = ExpressionPanel(model)
    try:
        model.set_weights({"jawOpen": 0.2345})
        model.set_weights({"jawOpen": 0.2712})  # the model moved on (a playing timeline)
        n = len(model.history.undo_labels)
        panel.sliders["jawOpen"].value = 0.23  # the late echo of 0.2345, snapped
        panel.grouper.flush()
        assert model.weights["jawOpen"] == pytest.approx(0.2712)
        assert len(model.history.undo_labels) == n
        # ... and the slider is sent the model's value again: a page that dropped 0.2712 (it
        # waited for the echo of its own 0.23) would otherwise keep showing 0.23
        assert panel.sliders["jawOpen"].value == pytest.approx(0.2712)
        panel.sliders["jawOpen"].value = 0.27  # the page's echo of that: in step, nothing more
        assert panel.sliders["jawOpen"].value == 0.27 and model.weights["jawOpen"] == pytest.approx(0.2712)
        # a real drag still works, also back to a value the model sent before
        panel.sliders["jawOpen"].value = 0.5
        panel.sliders["jawOpen"].value = 0.23
        panel.grouper.flush()
        assert model.weights["jawOpen"] == pytest.approx(0.23)
        assert model.history.undo_labels[-1] == "Drag jawOpen"
    finally:
        panel.close()


def test_point_clouds_are_thinned_on_screen_tracked_and_the_adapted_rig_saved(take, tmp_path) -> None:
    from widgets import Workbench
    from widgets.capture.panel import MAX_DRAWN_POINTS
    from workbench.capture.synthetic import synthetic_performance

    model = workbench.load_sample("head")
    perf = synthetic_performance(model, 6, fps=30.0, seed=2, markers=20, points=4000, noise=0.001, head_motion=0.3)
    wb = Workbench(model, height=240)
    try:
        cap = wb.capture
        cap.set_take(perf.clouds, fps=30.0, name="clouds")
        assert "point clouds of ~4000 points" in cap.info.value
        assert not cap.adapt.disabled and cap.adapt.value  # adaptation on by default for clouds
        assert len(wb.viewport.overlay_points) == MAX_DRAWN_POINTS
        cap.adapt.value = False
        cap.track()
        assert cap.result.kind == "clouds" and cap.result.n_frames == 6
        assert np.sqrt(np.mean((cap.result.weights - perf.weights) ** 2)) < 0.15
        assert cap.save_adapted_button.disabled
        with pytest.raises(ValueError, match="Adapt the rig"):
            cap.save_adapted(str(tmp_path / "a.fwb"))
        cap.adapt.value = True
        cap.track()
        assert not cap.save_adapted_button.disabled
        with pytest.raises(ValueError, match=r"expected a \.fwb"):
            cap.save_adapted(str(tmp_path / "a.obj"))
        out = cap.save_adapted(str(tmp_path / "adapted.fwb"))
        rig = workbench.load(out)
        assert rig.shape_names == model.shape_names and rig.n_vertices == model.n_vertices
        assert not np.array_equal(rig.vertices, model.vertices)  # the neutral moved toward the actor
    finally:
        wb.close()


def test_retime_the_selected_key_pair_from_the_tracked_take(take) -> None:
    from widgets import Workbench

    model = workbench.load_sample("head")
    _, perf = take
    wb = Workbench(model, height=240)
    try:
        cap = wb.capture
        cap.set_take(perf.markers, vertex_ids=perf.marker_ids, fps=30.0)
        cap.track()
        W = cap.result.weights
        j = int(np.argmax(W.max(axis=0)))  # the busiest shape of the take
        name = cap.result.shape_names[j]
        f1 = int(np.argmax(W[:, j]))
        model.timeline.add_key(f"weights/{name}", 0.0, float(W[0, j]))
        model.timeline.add_key(f"weights/{name}", 1.0, float(W[f1, j]))
        with pytest.raises(ValueError, match="exactly two times"):
            cap.retime_selected()
        wb.timeline.selected_keys = [[f"weights/{name}", 0], [f"weights/{name}", 1]]
        n = len(model.history.undo_labels)
        cap.retime_button.click()
        assert len(model.history.undo_labels) == n + 1, wb.errors.outputs
        assert model.history.undo_labels[-1] == "Retime 0–1 s from performance"
        assert len(model.slot("tracks").tracks[f"weights/{name}"].keys) > 2
        assert "retimed 0–1 s" in cap.progress.label.value
    finally:
        wb.close()


def test_drive_handles_replays_the_markers_through_the_shell_and_applies_in_one_step(take) -> None:
    """Mode "drive handles (shell)": the markers become handles, the face follows them, one undo step."""
    from widgets import Workbench

    _, perf = take
    model = workbench.load_sample("head")
    wb = Workbench(model, height=240)
    try:
        cap = wb.capture
        assert cap.mode.disabled  # no take yet
        cap.set_take(perf.markers, vertex_ids=perf.marker_ids, fps=30.0, name="mocap")
        assert not cap.mode.disabled
        cap.mode.value = "shell"
        cap.track_button.click()
        rep = cap.replayed
        assert rep is not None and rep.n_frames == 90, wb.errors.outputs
        assert "through the shell" in cap.progress.label.value and "wrinkles" in cap.progress.label.value
        assert cap.result is rep.tracked and cap.plot.value[:4] == b"\x89PNG"
        n_undo = len(model.history.undo_labels)
        cap.apply_button.click()
        assert len(model.history.undo_labels) == n_undo + 1
        assert np.array_equal(model.handles.vertices, perf.marker_ids)
        model.set_time(45 / 30.0)
        # the face the viewport shows is the replay (within the key tolerance of the weights and offsets)
        size = float(np.linalg.norm(np.ptp(model.vertices, axis=0)))
        assert np.abs(model.evaluate(posed=False) - rep.meshes[45]).max() < 0.02 * size
        wb.undo()
        assert len(model.history.undo_labels) == n_undo and len(model.handles) != len(perf.marker_ids)
        # a point-cloud take cannot drive handles
        seen = perf.markers[0][np.isfinite(perf.markers[0]).all(axis=1)]
        cap.set_take([seen, seen], fps=30.0, name="clouds")
        assert cap.mode.disabled
    finally:
        wb.close()


def test_clone_a_performance_of_another_face_then_track_it_onto_this_rig(tmp_path) -> None:
    """The Capture tab's clone entry: a performance file of the sample head, played on a foreign face's own rig."""
    from widgets import Workbench
    from workbench.animation.importers.keys import timeline_from_samples
    from workbench.testing import foreign_face
    from workbench.testing.takes import realistic_weights

    head = workbench.load_sample("head")
    T = 20
    W = realistic_weights(head, T, seed=3)
    head.timeline.set(timeline_from_samples(np.arange(T) / 30.0, W, head.shape_names, fps=30.0), "performance")
    perf_path = tmp_path / "performance.fwb"
    head.save(perf_path)
    foreign = foreign_face(head, seed=3)
    model = foreign.model
    wb = Workbench(model, height=240)
    try:
        cap = wb.capture
        cap.clone_path.value = str(tmp_path / "missing.fwb")
        cap.clone_button.click()
        assert cap.take is None and "missing.fwb" in str(wb.errors.outputs)
        cap.clone_path.value = str(perf_path)
        cap.clone_button.click()
        assert cap.take is not None and cap.take["kind"] == "markers", wb.errors.outputs
        assert cap.take["frames"].shape == (T, 120, 3) and "clone of performance.fwb" in cap.info.value
        assert "cloned 20 frames" in cap.progress.label.value
        cap.auto.value = False
        cap.track_button.click()
        n_undo = len(model.history.undo_labels)
        cap.apply_button.click()
        assert len(model.history.undo_labels) == n_undo + 1
        # this face's own (split, renamed) rig now plays the performance: near the true clone
        names = list(head.shape_names)
        errs, motion = [], []
        for f in (5, 10, 15):
            truth = foreign.pose(dict(zip(names, W[f], strict=True)))
            model.set_time(f / 30.0)
            errs.append(np.linalg.norm(model.evaluate(posed=False) - truth, axis=1).mean())
            motion.append(np.linalg.norm(truth - model.vertices, axis=1).mean())
        assert np.median(errs) < 0.5 * np.median(motion), (errs, motion)
    finally:
        wb.close()
