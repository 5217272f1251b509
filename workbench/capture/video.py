"""Video → face landmarks with MediaPipe FaceMesh, and the landmark → vertex map (issue 17, item 6).

An optional extra: ``pip install 'face-workbench[video]'`` brings ``mediapipe==0.10.14``
(and OpenCV, which reads the video files). The wheel ships the FaceMesh models
(``mediapipe/modules/face_landmark/face_landmark_with_attention.tflite``, 478
landmarks with the irises, and the face detector); nothing is downloaded at run
time. Without the extra, :func:`video_landmarks` raises :class:`VideoExtraMissing`
(an ``ImportError``) naming the install command. The blendshape model
(``face_landmarker.task``) is in no wheel and is not used: the weights come from
:func:`workbench.capture.track` on the landmarks.

The pipeline::

    seq = video_landmarks("take.mp4")                  # (T, 478, 3), NaN without a face
    reg = register_landmarks(model, seq, frame=0)      # frame 0: the actor at rest
    result = track(model, reg.to_model(seq), vertex_ids=reg.vertex_ids, neutral=0)
    # or, all at once: track_video(model, "take.mp4")

* :func:`video_landmarks` — per frame the 478 FaceMesh landmarks in MediaPipe's
  normalized image coordinates: ``x`` right and ``y`` down in [0, 1] of the
  width / height, ``z`` MediaPipe's *relative* depth (smaller is nearer the
  camera, roughly the scale of ``x``, origin at the head's centre). A video file
  is read with ``cv2.VideoCapture``; an array or list of RGB frames is used as is.
  FaceMesh runs in its tracking mode by default (each frame's search starts from
  the last frame's face: steadier, and on the rendered test head it reports
  about 25 % more of the jaw's motion than per-image detection).
* :meth:`LandmarkSequence.points` — the landmarks as 3-D points in pixels:
  ``X = x·W``, ``Y = (1 − y)·H``, ``Z = −z·W`` (+x right, **+y up, +z toward the
  camera**, the workbench's frame, as :func:`~workbench.capture.inputs.depth_to_points`).
* :func:`register_landmarks` — the landmark → vertex map by registration, on a
  frame of the actor at rest: (1) a similarity (scale, rotation, translation)
  from anchor landmarks to the rig's named landmarks
  (:func:`workbench.rigging.template_landmarks`; :data:`ANCHORS`), robust (Huber);
  (2) trimmed similarity ICP of the 468 face-mesh landmarks onto the skin surface
  (closest points on the triangles, a libigl AABB tree; pairs beyond 3 median
  distances dropped); (3) each landmark's vertex: the nearest front-facing skin
  vertex, with the distance along the camera's axis counted at ``depth_weight``
  (MediaPipe's depth is its least reliable coordinate); the iris landmarks
  (468–477) go to the eyeballs when the rig has eyeball parts.
  :func:`landmark_vertex_map` returns just the ids.
* :meth:`LandmarkRegistration.to_model` — every frame's landmarks in the model's
  frame and units (the registration's similarity), optionally with each frame's
  scale change relative to the rest frame removed (a head moving toward the
  camera grows in the image; the tracker's head pose is rigid).

Accuracy (measured on the sample head rendered by ``widgets.render.render_png``
at 480×480, ``camera="front"``, where the true camera is known;
``tests/test_capture_video.py``): the landmarks of the neutral face lie a median
0.9 mm from the skin surface after registration; the assigned vertices project a
median 2.6 px (p90 7.4 px; 1 px ≈ 0.64 mm on the face) from their landmarks,
against 1.5 px for the best vertex one could pick knowing the camera. The
largest misses are on the face's outline (the jaw contour), where MediaPipe's
depth is weakest. Landmarks take about 15 ms per frame on one CPU core, the
registration 0.2 s.

Weights tracked from video landmarks are **coarser** than from markers:
MediaPipe's depth is its face model's guess (an opening jaw's lower lip comes
2 mm toward the camera where the lip goes 14 mm back), its face's scale wobbles
by ±2 % with the expression, and on the rendered head its chin and jaw outline
follow the jaw half-way while its lips follow it (the chin against a neck of the
same colour). So the weights are fitted across the camera's axis
(``depth_axis=reg.view_axis``; the head pose uses all three coordinates) and the
lips, eyes, brows and nose weigh more than the outline
(:func:`~workbench.capture.landmark_registration.landmark_weights`). On a 30-frame
take with a jawOpen ramp 0 → 1, a blink and a head turn (yaw ±10°), jawOpen
follows the ramp with correlation 0.99 and reaches 0.95 (0.56 with the depth in
the fit and the inner lips on one vertex); ``mouthShrugUpper``, ``mouthPucker``,
``mouthLowerDown*`` and ``browInnerUp`` wander up to 0.3–0.6; a full blink reads
about 0.8 with the lids open ≤ 0.04; the head's yaw is within 2°. Calibrating on a
rest frame (``track(..., neutral=0)``) removes the constant landmark ↔ vertex offsets.
"""


from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from numpy.typing import ArrayLike

from workbench.capture.facemesh import (
    IRIS,
    MEDIAPIPE_VERSION,
    N_LANDMARKS,
    VIDEO_EXTRA,
    LandmarkSequence,
    VideoError,
    VideoExtraMissing,
    video_landmarks,
)
from workbench.capture.landmark_registration import (
    ANCHORS,
    LANDMARK_L1,
    LandmarkRegistration,
    landmark_vertex_map,
    landmark_weights,
    register_landmarks,
)

if TYPE_CHECKING:
    from workbench.capture.result import TrackResult
    from workbench.core.state import FaceState

__all__ = [
    "ANCHORS",
    "IRIS",
    "MEDIAPIPE_VERSION",
    "N_LANDMARKS",
    "VIDEO_EXTRA",
    "LandmarkRegistration",
    "LandmarkSequence",
    "VideoError",
    "VideoExtraMissing",
    "landmark_vertex_map",
    "register_landmarks",
    "track_video",
    "video_landmarks",
]

Progress = Callable[[float, str], Any]


def track_video(
    model: FaceState,
    source: str | Path | ArrayLike | LandmarkSequence,
    *,
    rest_frame: int | None = None,
    fps: float | None = None,
    max_frames: int | None = None,
    static: bool = False,
    progress: Progress | None = None,
    **track_options: Any,
) -> TrackResult:
    """Video (or frames, or landmarks, or a saved live take) → :class:`~workbench.capture.TrackResult`.

    ``source``: a video file, (T, h, w, 3) frames, a :class:`LandmarkSequence`, or a
    live take's ``.npz`` (:meth:`LiveTracker.save_take`, read by
    :meth:`LandmarkSequence.load_take`) to re-track with other settings.

    :func:`video_landmarks` (unless ``source`` is a :class:`LandmarkSequence`), then
    :func:`register_landmarks` on ``rest_frame`` (the actor at rest; default the sequence's own
    :attr:`LandmarkSequence.rest_frame` — a saved live take's neutral — or else 0), then
    :func:`workbench.capture.track` on :meth:`LandmarkRegistration.to_model` with
    ``neutral=rest_frame`` (the landmark ↔ vertex offsets calibrated away) and
    ``marker_weights=landmark_weights()`` (the lips, eyes, brows and nose weigh more than the
    landmarks on smooth skin), ``l1=LANDMARK_L1`` (the live tracker's sparsity) and
    ``depth_axis=reg.view_axis`` (the weights fitted across FaceMesh's depth; ``None`` fits
    them on it too) and ``fit_scale=True`` (the head pose a similarity: the actor moving toward or
    away from the camera is not read as expressions) unless ``track_options`` says otherwise. The sparsity is fixed, not chosen
    from the take as for markers (``l1="auto"``): held-out landmarks favour the weights that
    explain FaceMesh's misreadings best, the densest, and chose 0.003-0.01 on the rendered takes
    of ``benchmarks/bench_live.py`` (the issue's whole take 0.141 / 0.161 against 0.114 / 0.131 at
    ``LANDMARK_L1``, before the depth left the fit). With these defaults the whole take's second
    loop is 0.091 / 0.110 (sample head / a foreign face; 0.089 / 0.110 with a rigid pose; with the
    depth in the fit, measured before, 0.121 / 0.145; all-zero weights 0.112); dense takes and the held-out take of other expressions move by ≤ 0.004
    either way. ``temporal`` is still chosen from the take. The registration is not kept:
    call the steps yourself to inspect it.
    """
    from workbench.capture.track import track

    def part(lo: float, hi: float) -> Progress | None:
        if progress is None:
            return None
        cb = progress
        return lambda f, msg: cb(lo + (hi - lo) * float(f), msg)

    if isinstance(source, LandmarkSequence):
        seq = source
    elif isinstance(source, str | Path) and Path(source).suffix.lower() == ".npz":
        seq = LandmarkSequence.load_take(source)  # a live take saved by LiveTracker.save_take
    else:
        seq = video_landmarks(source, fps=fps, max_frames=max_frames, static=static, progress=part(0.0, 0.7))
    if rest_frame is None:
        rest_frame = 0 if seq.rest_frame is None else seq.rest_frame
    reg = register_landmarks(model, seq, frame=rest_frame)
    track_options.setdefault("neutral", int(rest_frame))
    track_options.setdefault("marker_weights", landmark_weights())  # the live tracker's weighting
    track_options.setdefault("l1", LANDMARK_L1)  # and its sparsity
    track_options.setdefault("depth_axis", reg.view_axis)  # and its fit across FaceMesh's depth
    track_options.setdefault("fit_scale", True)  # and its head pose with the actor's distance
    return track(model, reg.to_model(seq), vertex_ids=reg.vertex_ids, fps=seq.fps, progress=part(0.7, 1.0),
                 **track_options)
