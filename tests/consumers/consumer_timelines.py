"""Timelines shared by the consumer tests (a plain module: tests/ is not a package)."""

from __future__ import annotations

import math

import numpy as np

from workbench.animation.curves import HEAD_POSE
from workbench.animation.tracks import Timeline
from workbench.methods.handles.facet import HANDLES_TRACK as HANDLES


def expression_timeline(kind: str) -> Timeline:
    """Three keyed expressions over 2 s; key times are exact in float32 (glTF stores float32).

    ``kind``: "linear" (every key linear), "cubic" (auto-clamped Bézier, one key
    with user tangents, one linear and one step track mixed in).
    """
    interp = "linear" if kind == "linear" else "bezier"
    tl = Timeline(fps=30.0, start=0.0, end=2.0)
    tl = tl.add_key("weights/jawOpen", 0.0, 0.0, interpolation=interp)
    tl = tl.add_key("weights/jawOpen", 0.5, 1.0, interpolation=interp)
    tl = tl.add_key("weights/jawOpen", 1.25, 0.2, interpolation=interp)
    tl = tl.add_key("weights/jawOpen", 2.0, 0.6, interpolation=interp)
    tl = tl.add_key("weights/eyeBlinkLeft", 0.25, 0.0, interpolation=interp)
    tl = tl.add_key("weights/eyeBlinkLeft", 0.75, 1.0, interpolation=interp)
    tl = tl.add_key("weights/eyeBlinkLeft", 1.5, 0.5, interpolation=interp)
    tl = tl.add_key("weights/mouthSmileLeft", 0.0, 0.0, interpolation="linear")
    tl = tl.add_key("weights/mouthSmileLeft", 1.0, 0.8, interpolation="linear")
    tl = tl.add_key("weights/mouthSmileLeft", 2.0, 0.1, interpolation="linear")
    if kind == "cubic":
        tl = tl.set_tangents("weights/eyeBlinkLeft", 1, in_tangent=-1.0, out_tangent=2.5)
        tl = tl.add_key("weights/browInnerUp", 0.0, 0.3, interpolation="step")
        tl = tl.add_key("weights/browInnerUp", 1.0, 0.9, interpolation="step")
    return tl


def with_head_pose(tl: Timeline) -> Timeline:
    """Add linear head-pose keys: translate and turn 20 degrees about y, then tilt about x."""
    a, b = math.radians(10), math.radians(7.5)
    tl = tl.add_key(HEAD_POSE, 0.0, [0, 0, 0, 0, 0, 0, 1], interpolation="linear")
    tl = tl.add_key(HEAD_POSE, 1.0, [0.2, 0.1, 0, 0, math.sin(a), 0, math.cos(a)], interpolation="linear")
    return tl.add_key(HEAD_POSE, 2.0, [0, 0, -0.1, math.sin(b), 0, 0, math.cos(b)], interpolation="linear")


def with_handle_keys(tl: Timeline, interpolation: str = "bezier") -> Timeline:
    """Key the three handles: rest, pulled forward/up, partly back (model units, dm)."""
    o1 = np.array([[0.0, 0.05, 0.08], [0.03, 0.0, 0.05], [-0.02, -0.04, 0.02]])
    tl = tl.add_key(HANDLES, 0.0, np.zeros((3, 3)), interpolation=interpolation)  # type: ignore[arg-type]
    tl = tl.add_key(HANDLES, 1.0, o1, interpolation=interpolation)  # type: ignore[arg-type]
    return tl.add_key(HANDLES, 2.0, 0.5 * o1, interpolation=interpolation)  # type: ignore[arg-type]


#: sample times: on keys, between keys, on frames and off frames (none inside step ramps)
SAMPLE_TIMES = [0.0, 0.1, 0.25, 0.3, 0.5, 0.62, 0.75, 0.9, 0.99, 1.0, 1.1, 1.25, 1.4, 1.5, 1.77, 1.9, 2.0]


def played_weights(model, tl: Timeline, times) -> np.ndarray:
    """(F, k) weights the workbench plays (``FaceModel.set_time``): keyed values clamped to
    each shape's slider range, unkeyed shapes at their current weight, muted shapes 0."""
    out = np.zeros((len(times), len(model.shapes)))
    for i, t in enumerate(times):
        keyed = tl.evaluate(float(t)).weights
        for k, s in enumerate(model.shapes):
            w = min(max(keyed[s.name], s.slider_min), s.slider_max) if s.name in keyed else model.weights[s.name]
            out[i, k] = 0.0 if s.mute else w
    return out


def expected_points(model, tl: Timeline, times, *, head_pose: bool = True) -> np.ndarray:
    """(F, n, 3) metres: ``model.evaluate_at(t, tl)`` — what the workbench shows at each time."""
    if not head_pose and HEAD_POSE in tl.tracks:
        tl = tl.without_track(HEAD_POSE)
    mpu = model.metadata.metres_per_unit
    return np.stack([np.asarray(model.evaluate_at(float(t), tl), np.float64) * mpu for t in times])
