"""Sample heads edited the way users edit them, for the consumer tests (a plain module).

Every builder returns a fresh base head (~5k vertices, decimetres) whose
``model.tracks`` holds three keys, edited through the public model API only:

* :func:`painted_head` — the default handles, six of them moved (not keyed),
  a saved "smile" expression painted onto both mouth corners, ``jawOpen``
  keyed three times;
* :func:`regions_head` — the same plus blend regions with their own weights
  and the handle offsets keyed three times (rest, brows up, half-way);
* :func:`wrinkled_head` — the pose-space wrinkle layer fitted and attached
  (a layer that is not linear in the weights: exports must bake it), with
  ``jawOpen`` and ``browInnerUp`` keyed.
"""

from __future__ import annotations

import numpy as np

from workbench import Brush, FaceModel, load_sample
from workbench.methods.handles.presets import default_face_handles

#: times inside and between the keys (0, 0.5, 1 s); 0.2 and 0.8 are frames at 30 fps, 0.37 is not
SAMPLE_TIMES = [0.0, 0.2, 0.37, 0.8, 1.0]


def _corners(m: FaceModel) -> tuple[int, int]:
    """The vertices the smile shapes move most (the mouth corners)."""
    left = int(np.argmax(np.linalg.norm(m.shape("mouthSmileLeft").delta, axis=1)))
    right = int(np.argmax(np.linalg.norm(m.shape("mouthSmileRight").delta, axis=1)))
    return left, right


def _brow_handles(m: FaceModel) -> list[int]:
    ids = [i for i, n in enumerate(m.handles.names) if n.startswith("brow")]
    return ids[:6] if ids else list(range(6))


def painted_head(interpolation: str = "bezier") -> FaceModel:
    m = load_sample("head")
    m.handles.set(default_face_handles(m), label="Default handles")
    with m.interaction("Drag brows"):
        for i in _brow_handles(m):
            m.move_handle(i, [0.0, 0.06, 0.02])
    m.set_weights({"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0, "cheekSquintLeft": 0.4, "cheekSquintRight": 0.4})
    m.expressions.save("smile")
    m.reset_weights()
    left, right = _corners(m)
    m.paint_stroke("smile", [left, right], Brush(radius=0.4, opacity=0.8))
    for t, w in ((0.0, 0.0), (0.5, 0.8), (1.0, 0.3)):
        m.set_weight("jawOpen", w)
        m.timeline.key_weights(t, ["jawOpen"], interpolation=interpolation)  # type: ignore[arg-type]
    return m


def regions_head(interpolation: str = "bezier") -> FaceModel:
    m = painted_head(interpolation)
    st = m.segment_regions(0.25)
    from workbench.methods.regions.blend import RegionWeights

    rw = RegionWeights.from_global(m, st.regions, st.level)
    m.regions.set_weights(rw.with_region(0, {"mouthPucker": 0.7, "jawOpen": 0.3}))
    rest = m.handles.offsets.copy()
    m.handles.key(0.0, interpolation)  # type: ignore[arg-type]
    up = rest.copy()
    up[_brow_handles(m)] += [0.0, 0.05, 0.0]
    m.handles.set_offsets(up)
    m.handles.key(0.5, interpolation)  # type: ignore[arg-type]
    m.handles.set_offsets(0.5 * up)
    m.handles.key(1.0, interpolation)  # type: ignore[arg-type]
    return m


def wrinkled_head() -> FaceModel:
    from workbench.methods.wrinkles.family import fit_sample_wrinkles

    m = load_sample("head")
    fit_sample_wrinkles(m)
    for t, w in ((0.0, {"jawOpen": 0.0, "browInnerUp": 0.0}), (0.5, {"jawOpen": 0.8, "browInnerUp": 1.0}),
                 (1.0, {"jawOpen": 0.1, "browInnerUp": 0.3})):
        m.set_weights(w)
        m.timeline.key_weights(t, list(w))
    return m


def fitted_head(n_frames: int = 10) -> FaceModel:
    """A synthetic marker performance fitted on region level 1 and keyed frame by frame
    (``key_marker_fit``: global weights + one region-weight track per region), with the
    head turning (head-pose keys) over the same frames."""
    from workbench.animation.curves import head_rotation_from_euler
    from workbench.methods.regions.marker_fit import (
        fit_markers,
        generate_synthetic_marker_performance,
    )

    m = load_sample("head")
    st = m.segment_regions(0.25)
    markers = np.asarray(default_face_handles(m).vertices)
    perf = generate_synthetic_marker_performance(m, markers, n_frames=n_frames, seed=5, noise=0.001)
    fit = fit_markers(m, st.regions, perf.markers, perf.marker_positions, 1)
    times = m.regions.key_marker_fit(fit)
    m.timeline.key_head_pose(float(times[0]), head_rotation_from_euler(0, 0, 0), [0, 0, 0], interpolation="linear")
    m.timeline.key_head_pose(float(times[-1]), head_rotation_from_euler(15, -5, 3), [0.05, 0.0, 0.02],
                    interpolation="linear")
    return m


def enhanced_head() -> FaceModel:
    """The *Enhanced* preview on (a layer that is not linear in the weights: exports bake it).

    The database is the procedural wrinkled performance of the head itself (its
    six example expressions and 12 frames of a generated performance), with
    ``browInnerUp`` and ``mouthSmileLeft`` keyed so that the detail changes.
    """
    from workbench.enhance import PerformanceDatabase
    from workbench.methods.wrinkles.examples import (
        EXAMPLE_POSES,
        WrinkleSculptor,
        performance_weights,
    )

    m = load_sample("head")
    sc = WrinkleSculptor(m)
    poses = list(EXAMPLE_POSES.values()) + performance_weights(24)[:12]
    V = np.asarray(m.vertices, np.float64)
    db = PerformanceDatabase.from_frames(sc.detail_of(V), m.faces.astype(np.int64),
                                         np.stack([sc.detailed(w) for w in poses]),
                                         metres_per_unit=m.metadata.metres_per_unit)
    m.enhance.set_database(db, source="procedural performance", preview=True)  # type: ignore[attr-defined]
    for t, w in ((0.0, {"browInnerUp": 0.0, "mouthSmileLeft": 0.0}), (0.5, {"browInnerUp": 1.0, "mouthSmileLeft": 0.9}),
                 (1.0, {"browInnerUp": 0.3, "mouthSmileLeft": 0.2})):
        m.set_weights(w)
        m.timeline.key_weights(t, list(w))
    return m


def replayed_head() -> FaceModel:
    """A marker take replayed through the shell (``capture.replay``): the markers are the handles,
    their offsets keyed with the weights and head pose, wrinkles on the marker graph (issue 29)."""
    from workbench.capture import synthetic_performance

    full = load_sample("head")
    perf = synthetic_performance(full, 31, fps=30.0, seed=7, markers=60)
    # replayed on a rig with every other shape: the shell carries what the rig cannot make
    m = FaceModel(full.vertices, full.faces, full.shapes[::2], polygons=full.polygons,
                  component_labels=full.component_labels, component_names=list(full.component_names),
                  metadata=full.metadata)
    rep = m.capture.replay(perf.markers, vertex_ids=perf.marker_ids, fps=30.0)
    m.capture.apply_replay(rep, tolerance=0.01)
    return m
