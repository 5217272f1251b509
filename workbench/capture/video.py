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
MediaPipe's depth is relative and approximate, its face's scale wobbles by
±2 % with the expression, and on the rendered head it reports only part of the
jaw's motion (the chin against a neck of the same colour). On a 30-frame take
with a jawOpen ramp 0 → 1, a blink and a head turn (yaw ±10°), jawOpen follows
the ramp with correlation 0.99 but reaches about 0.5 (the rest is taken by
``mouthLowerDown*``, and ``jawForward`` / ``mouthFrown*`` / ``mouthPucker``
wander up to 0.4–0.6); a full blink reads about 0.6 with the lids open ≤ 0.02;
the head's yaw is within 2°. Calibrating on a rest frame
(``track(..., neutral=0)``) removes the constant landmark ↔ vertex offsets.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.pose import PoseError, fit_rigid, fit_rigid_robust
from workbench.geometry.masks import eyeball_mask, skin_or_all_mask

if TYPE_CHECKING:
    from workbench.capture.result import TrackResult
    from workbench.core.state import FaceState

__all__ = [
    "ANCHORS",
    "IRIS",
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

#: how to install what this module needs
VIDEO_EXTRA = "pip install 'face-workbench[video]'"
#: the mediapipe release whose legacy FaceMesh solution (with its bundled models) this module drives
MEDIAPIPE_VERSION = "0.10.14"
#: landmarks per face with ``refine_landmarks=True`` (468 face mesh + 2 × 5 iris)
N_LANDMARKS = 478
#: the iris landmarks (centre and four rim points per eye)
IRIS = range(468, 478)
#: face-mesh landmarks (no iris): the ones registered onto the skin surface
_MESH = 468
#: FaceMesh landmark of each rig landmark (:func:`workbench.rigging.template_landmarks` names;
#: ``*_left`` is the subject's left, on the image's right). Checked on the sample head: each
#: FaceMesh point lies within 4 px (480 px render) of the rig landmark's vertex.
ANCHORS: Mapping[str, int] = {
    "nose_tip": 4,  # the most frontal nose point (FaceMesh 1 is the tip's underside)
    "chin": 199,  # the front of the chin (152 is its underside)
    "mouth_corner_left": 291,
    "mouth_corner_right": 61,
    "eyelid_left": 386,  # upper lid, middle
    "eyelid_right": 159,
    "brow_inner_left": 336,
    "brow_inner_right": 107,
    "upper_lip": 0,
    "lower_lip": 16,
}
#: a landmark's vertex moving less than this share of the head size under any shape is "still"
_STILL = 0.01

Progress = Callable[[float, str], Any]


class VideoExtraMissing(ImportError):
    """The optional ``video`` extra (mediapipe, OpenCV) is not installed; the message says how to install it."""


class VideoError(ValueError):
    """A video or frames that cannot be read, or landmarks that cannot be registered; names the input."""


# ----------------------------------------------------------------------------- the extra
def _mediapipe_face_mesh() -> Any:
    """``mediapipe.solutions.face_mesh`` or :class:`VideoExtraMissing`."""
    try:
        import mediapipe
    except ImportError as exc:
        raise VideoExtraMissing(
            f"video landmarks need the optional 'video' extra (mediapipe=={MEDIAPIPE_VERSION}, which "
            f"brings OpenCV): {VIDEO_EXTRA}  [import failed: {exc}]"
        ) from exc
    try:
        face_mesh = mediapipe.solutions.face_mesh  # mediapipe.python.solutions, the legacy API
    except (ImportError, AttributeError) as exc:
        version = getattr(mediapipe, "__version__", "?")
        raise VideoExtraMissing(
            f"video landmarks use mediapipe's FaceMesh solution, which mediapipe {version} lacks; "
            f"install mediapipe=={MEDIAPIPE_VERSION}: {VIDEO_EXTRA}  [{exc}]"
        ) from exc
    return face_mesh


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as exc:
        raise VideoExtraMissing(
            f"reading video files needs OpenCV, part of the optional 'video' extra: {VIDEO_EXTRA}  "
            f"[import failed: {exc}]"
        ) from exc
    return cv2


# ------------------------------------------------------------------------- the sequence
@dataclass(frozen=True, eq=False)
class LandmarkSequence:
    """FaceMesh landmarks per frame, as :func:`video_landmarks` returns them.

    Attributes
    ----------
    landmarks : (T, 478, 3) float64
        MediaPipe's normalized coordinates: ``x`` (right) and ``y`` (down) as
        shares of the image width and height, ``z`` the relative depth (smaller
        is nearer the camera, about the scale of ``x``). NaN in a frame where no
        face was found.
    image_size : (int, int)
        ``(width, height)`` of the frames in pixels.
    fps : float
        Frames per second of the sequence (after any sampling).
    frame_numbers : (T,) int
        The frame of the source each row comes from (0-based).
    source : str
        The file read, or ``"<frames>"``.
    """

    landmarks: NDArray[np.float64]
    image_size: tuple[int, int]
    fps: float
    frame_numbers: NDArray[np.int64]
    source: str = "<frames>"

    def __post_init__(self) -> None:
        L = np.asarray(self.landmarks, np.float64)
        if L.ndim != 3 or L.shape[1:] != (N_LANDMARKS, 3):
            raise ValueError(f"LandmarkSequence: landmarks must be (frames, {N_LANDMARKS}, 3), got {L.shape}")
        n = np.asarray(self.frame_numbers, np.int64)
        if n.shape != (L.shape[0],):
            raise ValueError(f"LandmarkSequence: frame_numbers must be ({L.shape[0]},), got {n.shape}")
        L.setflags(write=False)
        n.setflags(write=False)
        object.__setattr__(self, "landmarks", L)
        object.__setattr__(self, "frame_numbers", n)
        object.__setattr__(self, "image_size", (int(self.image_size[0]), int(self.image_size[1])))

    @property
    def n_frames(self) -> int:
        return int(self.landmarks.shape[0])

    @property
    def n_markers(self) -> int:
        """478 (named like :class:`~workbench.io.markers.MarkerSequence`)."""
        return N_LANDMARKS

    @property
    def names(self) -> tuple[str, ...]:
        """``"0" .. "477"``: the FaceMesh landmark indices."""
        return tuple(str(i) for i in range(N_LANDMARKS))

    @property
    def found(self) -> NDArray[np.bool_]:
        """(T,) True where a face was found."""
        return np.asarray(np.isfinite(self.landmarks).all(axis=(1, 2)))

    @property
    def gaps(self) -> NDArray[np.bool_]:
        """(T, 478) True where a landmark is missing (the whole frame, when no face was found)."""
        return np.asarray(~np.isfinite(self.landmarks).all(axis=2))

    @property
    def times(self) -> NDArray[np.float64]:
        """(T,) seconds from the first row."""
        return np.arange(self.n_frames, dtype=np.float64) / self.fps

    def points(self) -> NDArray[np.float64]:
        """(T, 478, 3) landmarks as 3-D points in pixels: +x right, +y up, +z toward the camera.

        ``X = x·W``, ``Y = (1 − y)·H``, ``Z = −z·W`` (MediaPipe's depth has the scale of
        ``x``); NaN where no face was found.
        """
        return _to_points(self.landmarks, self.image_size)


def _to_points(L: NDArray[np.float64], image_size: tuple[int, int]) -> NDArray[np.float64]:
    w, h = float(image_size[0]), float(image_size[1])
    out = np.empty(L.shape, np.float64)
    out[..., 0] = L[..., 0] * w
    out[..., 1] = (1.0 - L[..., 1]) * h
    out[..., 2] = -L[..., 2] * w
    return out


# ------------------------------------------------------------------------- frame sources
def _check_frame(frame: Any, t: int, src: str, size: tuple[int, int] | None) -> NDArray[np.uint8]:
    a = np.asarray(frame)
    if a.ndim == 3 and a.shape[2] == 4:
        a = a[..., :3]
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise VideoError(f"{src}: frame {t} must be an (H, W, 3) RGB image, got shape {a.shape}")
    if a.dtype != np.uint8:
        raise VideoError(f"{src}: frame {t} must be uint8 RGB (0..255), got dtype {a.dtype}")
    if size is not None and (a.shape[1], a.shape[0]) != size:
        raise VideoError(
            f"{src}: frame {t} is {a.shape[1]}×{a.shape[0]} px but frame 0 is {size[0]}×{size[1]}; "
            "all frames must have one size"
        )
    return np.ascontiguousarray(a)


def _keep(i: int, native: float, fps: float | None) -> bool:
    """Whether source frame ``i`` (at ``native`` fps) is sampled at ``fps`` (None: all)."""
    if fps is None or fps >= native:
        return True
    step = native / fps
    return math.floor(i / step) != math.floor((i - 1) / step) if i > 0 else True


def _video_frames(path: Path, fps: float | None) -> tuple[Iterator[tuple[int, NDArray[np.uint8]]], float, int, Any]:
    cv2 = _cv2()
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        cap.release()
        raise VideoError(f"{path}: OpenCV cannot open this file as a video")
    native = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    if not (math.isfinite(native) and native > 0):
        native = float(fps) if fps else 30.0
        warnings.warn(f"{path}: the video states no frame rate; using {native:g} fps", stacklevel=3)
    count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)

    def frames() -> Iterator[tuple[int, NDArray[np.uint8]]]:
        i = 0
        while True:
            ok, bgr = cap.read()
            if not ok:
                return
            if _keep(i, native, fps):
                yield i, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            i += 1

    return frames(), native, count, cap


def _array_frames(source: Any) -> tuple[Iterator[tuple[int, Any]], int]:
    if isinstance(source, np.ndarray):
        if source.ndim != 4:
            raise VideoError(f"<frames>: expected (T, H, W, 3) uint8 RGB frames, got shape {source.shape}")
        return enumerate(source), int(source.shape[0])
    if isinstance(source, Sequence):
        return enumerate(source), len(source)
    if isinstance(source, Iterable):
        return enumerate(source), 0
    raise VideoError(
        f"source must be a video file path or (T, H, W, 3) uint8 RGB frames, got {type(source).__name__}"
    )


def video_landmarks(
    source: str | Path | ArrayLike | Iterable[ArrayLike],
    *,
    fps: float | None = None,
    max_frames: int | None = None,
    static: bool = False,
    min_confidence: float = 0.5,
    progress: Progress | None = None,
) -> LandmarkSequence:
    """The 478 MediaPipe FaceMesh landmarks of each frame of a video (the ``video`` extra).

    Parameters
    ----------
    source : path, (T, H, W, 3) uint8 array, or sequence of (H, W, 3) uint8 arrays
        A video file (anything OpenCV's ``VideoCapture`` reads: mp4, avi, mov, ...)
        or RGB frames (an alpha channel is dropped).
    fps : float, optional
        For a file: the rate to sample at (frames nearest that rate are kept; None or
        a rate ≥ the file's keeps every frame); for frames: their rate (default 30).
    max_frames : int, optional
        Stop after this many (kept) frames.
    static : bool
        Detect the face in every frame on its own (``static_image_mode=True``) instead
        of tracking it from frame to frame (the default; steadier on video).
    min_confidence : float
        FaceMesh's minimum detection (and tracking) confidence, in (0, 1).
    progress : callable, optional
        ``progress(fraction, message)`` as frames are processed.

    Returns
    -------
    LandmarkSequence
        NaN rows for frames where no face was found.

    Raises
    ------
    VideoExtraMissing
        mediapipe (or, for a file, OpenCV) is not installed: ``pip install 'face-workbench[video]'``.
    FileNotFoundError
        No such video file.
    VideoError
        A file OpenCV cannot open, a video without frames, frames of the wrong shape,
        dtype or of different sizes (naming the frame), bad arguments.
    """
    if fps is not None and not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise VideoError(f"fps must be a number > 0 (or None), got {fps!r}")
    if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, int | np.integer)
                                   or max_frames < 1):
        raise VideoError(f"max_frames must be an int ≥ 1 (or None), got {max_frames!r}")
    if not (0.0 < float(min_confidence) < 1.0):
        raise VideoError(f"min_confidence must be in (0, 1), got {min_confidence!r}")
    cap: Any = None
    if isinstance(source, str | Path):
        path = Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such video file")
        src = str(path)
        face_mesh = _mediapipe_face_mesh()
        items, native, total, cap = _video_frames(path, fps)
        rate = float(fps) if fps is not None and fps < native else native
        if fps is not None and fps < native:
            total = math.ceil(total * fps / native)
    else:
        src = "<frames>"
        items, total = _array_frames(source)
        rate = float(fps) if fps is not None else 30.0
        face_mesh = _mediapipe_face_mesh()
    if max_frames is not None:
        total = min(total, int(max_frames)) if total else int(max_frames)
    rows: list[NDArray[np.float64]] = []
    numbers: list[int] = []
    size: tuple[int, int] | None = None
    nan = np.full((N_LANDMARKS, 3), np.nan)
    try:
        with warnings.catch_warnings():
            # protobuf 4 warns about a deprecated call inside mediapipe on every frame
            warnings.filterwarnings("ignore", message=r"SymbolDatabase\.GetPrototype\(\) is deprecated")
            with face_mesh.FaceMesh(static_image_mode=bool(static), max_num_faces=1, refine_landmarks=True,
                                    min_detection_confidence=float(min_confidence),
                                    min_tracking_confidence=float(min_confidence)) as mesh:
                for i, frame in items:
                    if max_frames is not None and len(rows) >= int(max_frames):
                        break
                    img = _check_frame(frame, int(i), src, size)
                    size = (img.shape[1], img.shape[0])
                    res = mesh.process(img)
                    faces = res.multi_face_landmarks
                    if faces:
                        lm = faces[0].landmark
                        rows.append(np.array([(p.x, p.y, p.z) for p in lm], np.float64))
                    else:
                        rows.append(nan)
                    numbers.append(int(i))
                    if progress is not None:
                        n = len(rows)
                        progress(min(n / total, 1.0) if total else 0.0,
                                 f"landmarks of frame {n}" + (f" of {total}" if total else ""))
    finally:
        if cap is not None:
            cap.release()
    if not rows or size is None:
        raise VideoError(f"{src}: no frames to read")
    if rows[0].shape[0] != N_LANDMARKS and np.isfinite(rows[0]).all():  # pragma: no cover - mediapipe contract
        raise VideoError(f"{src}: FaceMesh returned {rows[0].shape[0]} landmarks, expected {N_LANDMARKS}")
    if progress is not None:
        progress(1.0, f"landmarks of {len(rows)} frames ({int(sum(np.isfinite(r).all() for r in rows))} with a face)")
    return LandmarkSequence(np.stack(rows), size, rate, np.asarray(numbers, np.int64), src)


# -------------------------------------------------------------------------- registration
@dataclass(frozen=True, eq=False)
class LandmarkRegistration:
    """The FaceMesh landmarks registered onto a rig; see :func:`register_landmarks`.

    Attributes
    ----------
    vertex_ids : (478,) int
        The rig vertex of each landmark (for ``track(..., vertex_ids=...)``).
    matrix : (4, 4) float
        The similarity from :meth:`LandmarkSequence.points` (pixels) to the model's
        frame and units: ``q = M @ [p, 1]``.
    scale : float
        Model units per pixel (at the face).
    image_size : (int, int)
        ``(width, height)`` the points were made with.
    surface_distance : (478,) float
        Each registered rest landmark's distance to the skin surface (model units).
    vertex_distance : (478,) float
        Each registered rest landmark's distance to its vertex (model units).
    inliers : (478,) bool
        The landmarks the final ICP step kept (iris landmarks are never used: False).
    still : (478,) bool
        Landmarks whose vertex no single shape moves by more than 1 % of the head size
        (the ones :meth:`to_model` measures a frame's scale on).
    rest : (478, 3) float
        The rest frame's landmarks in the model's frame.
    anchors : dict of str to int
        The rig landmarks and FaceMesh indices the start used.
    rms : float
        Root-mean-square surface distance of the inliers (model units).
    """

    vertex_ids: NDArray[np.intp]
    matrix: NDArray[np.float64]
    scale: float
    image_size: tuple[int, int]
    surface_distance: NDArray[np.float64]
    vertex_distance: NDArray[np.float64]
    inliers: NDArray[np.bool_]
    still: NDArray[np.bool_]
    rest: NDArray[np.float64]
    anchors: Mapping[str, int]
    rms: float

    def apply(self, points: ArrayLike) -> NDArray[np.float64]:
        """``(..., 3)`` pixel-frame points (:meth:`LandmarkSequence.points`) → the model's frame."""
        P = np.asarray(points, np.float64)
        return P @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    def to_model(self, landmarks: LandmarkSequence | ArrayLike, *, rescale: bool = False) -> NDArray[np.float64]:
        """Landmarks of every frame in the model's frame and units, for :func:`workbench.capture.track`.

        Parameters
        ----------
        landmarks : LandmarkSequence or (T, 478, 3) float
            MediaPipe's normalized landmarks (NaN rows where no face was found), from
            frames of :attr:`image_size`.
        rescale : bool
            Remove each frame's scale relative to the rest frame (a similarity fitted on
            the :attr:`still` landmarks, robustly), about their centre, for takes where
            the head moves toward or away from the camera. Off by default: MediaPipe's
            own scale wobbles by ±2 % with the expression (a blink shrinks the face), and
            on the test take removing it lowers jawOpen's correlation from 0.99 to 0.97.

        Returns
        -------
        (T, 478, 3) float
            NaN where no face was found.
        """
        if isinstance(landmarks, LandmarkSequence):
            if landmarks.image_size != self.image_size:
                raise VideoError(
                    f"{landmarks.source}: frames are {landmarks.image_size[0]}×{landmarks.image_size[1]} px but "
                    f"the registration was made on {self.image_size[0]}×{self.image_size[1]} px"
                )
            L = landmarks.landmarks
        else:
            L = np.asarray(landmarks, np.float64)
            if L.ndim == 2:
                L = L[None]
        if L.ndim != 3 or L.shape[1:] != (N_LANDMARKS, 3):
            raise VideoError(f"landmarks must be (frames, {N_LANDMARKS}, 3), got shape {L.shape}")
        Y = self.apply(_to_points(L, self.image_size))
        if not rescale:
            return Y
        s = self.still
        for t in range(Y.shape[0]):
            if not np.isfinite(Y[t]).all():
                Y[t] = np.nan
                continue
            try:
                pose = fit_rigid_robust(self.rest[s], Y[t, s], scale=True, max_iter=10)
            except PoseError:
                continue
            c = Y[t, s].mean(0)
            Y[t] = c + (Y[t] - c) / pose.scale
        return Y


def _rest_landmarks(landmarks: Any, frame: int, image_size: tuple[int, int] | None
                    ) -> tuple[NDArray[np.float64], tuple[int, int], str]:
    if isinstance(landmarks, LandmarkSequence):
        if not -landmarks.n_frames <= int(frame) < landmarks.n_frames:
            raise VideoError(f"{landmarks.source}: frame {frame} is not in the sequence (0..{landmarks.n_frames - 1})")
        return landmarks.landmarks[int(frame)], image_size or landmarks.image_size, f"{landmarks.source} frame {frame}"
    L = np.asarray(landmarks, np.float64)
    where = "landmarks"
    if L.ndim == 3:
        if not -L.shape[0] <= int(frame) < L.shape[0]:
            raise VideoError(f"landmarks: frame {frame} is not in the sequence (0..{L.shape[0] - 1})")
        L = L[int(frame)]
        where = f"landmarks frame {frame}"
    if L.shape != (N_LANDMARKS, 3):
        raise VideoError(f"{where}: expected ({N_LANDMARKS}, 3) FaceMesh landmarks, got shape {L.shape}")
    return L, image_size or (1, 1), where


def register_landmarks(
    model: FaceState,
    landmarks: LandmarkSequence | ArrayLike,
    *,
    frame: int = 0,
    image_size: tuple[int, int] | None = None,
    anchors: Mapping[str, int] | None = None,
    iterations: int = 50,
    depth_weight: float = 0.5,
) -> LandmarkRegistration:
    """Register FaceMesh landmarks of the actor at rest onto a rig; the landmark → vertex map.

    Parameters
    ----------
    model : FaceModel
        A rig with ARKit-named shapes and ``metadata.up_axis`` / ``front_axis``
        (what :func:`workbench.rigging.template_landmarks` needs).
    landmarks : LandmarkSequence, (T, 478, 3) or (478, 3) float
        MediaPipe's normalized landmarks; ``frame`` picks the rest frame.
    frame : int
        The frame of the actor at rest (neutral face), ideally facing the camera.
    image_size : (int, int), optional
        ``(width, height)`` of the frames; a :class:`LandmarkSequence` knows it; for
        an array it defaults to (1, 1), right for square frames only.
    anchors : mapping of str to int, optional
        Rig landmark name → FaceMesh index for the start (default :data:`ANCHORS`);
        at least 4 that the rig has.
    iterations : int
        Most ICP iterations.
    depth_weight : float
        In (0, 1]: how much the distance along the camera's axis counts when picking
        each landmark's vertex (MediaPipe's depth is approximate).

    Returns
    -------
    LandmarkRegistration

    Raises
    ------
    VideoError
        No face in the rest frame, a rig lacking the anchors, bad arguments.
    """
    from scipy.spatial import cKDTree

    from workbench.capture.rig import ExpressionSpace
    from workbench.geometry.normals import vertex_normals
    from workbench.geometry.surface import SurfaceQuery
    from workbench.rigging.landmarks import template_landmarks

    if not (0.0 < float(depth_weight) <= 1.0):
        raise VideoError(f"depth_weight must be in (0, 1], got {depth_weight!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) or iterations < 1:
        raise VideoError(f"iterations must be an int ≥ 1, got {iterations!r}")
    L, size, where = _rest_landmarks(landmarks, frame, image_size)
    if not np.isfinite(L).all():
        raise VideoError(f"{where}: no face was found there; register on a frame with a face (see .found)")
    P = _to_points(L, size)

    V = np.asarray(model.vertices, np.float64)
    F = np.asarray(model.faces, np.int64)
    skin = skin_or_all_mask(model)
    tl = template_landmarks(model)  # type: ignore[arg-type]  # a FaceState is the FaceModel it needs
    use = {k: int(v) for k, v in (ANCHORS if anchors is None else anchors).items() if k in tl}
    if len(use) < 4:
        raise VideoError(
            f"model: the registration needs at least 4 of the rig landmarks {sorted(ANCHORS if anchors is None else anchors)} "
            f"(workbench.rigging.template_landmarks found {sorted(tl)})"
        )
    bad = [i for i in use.values() if not 0 <= i < _MESH]
    if bad:
        raise VideoError(f"anchors: FaceMesh indices must be in 0..{_MESH - 1}, got {bad}")
    names = list(use)
    start = fit_rigid_robust(P[[use[k] for k in names]], V[[tl[k] for k in names]], scale=True, loss="huber")
    M = start.matrix

    # trimmed similarity ICP of the face-mesh landmarks onto the skin surface
    Fs = F[skin[F].all(1)]
    if Fs.shape[0] == 0:
        Fs = F
    query = SurfaceQuery(V, Fs)
    Pm = P[:_MESH]
    ok = np.ones(_MESH, bool)
    dist = np.zeros(_MESH)
    for _ in range(int(iterations)):
        X = Pm @ M[:3, :3].T + M[:3, 3]
        dist, _face, C, _bary = query.closest(X)
        ok = dist <= 3.0 * float(np.median(dist))
        if int(ok.sum()) < 10:
            break
        new = fit_rigid(Pm[ok], C[ok], scale=True)
        change = float(np.abs(Pm @ new[:3, :3].T + new[:3, 3] - X).max())
        M = new
        if change < 1e-7 * float(np.ptp(V, axis=0).max()):
            break
    scale = float(np.cbrt(np.linalg.det(M[:3, :3])))
    R = M[:3, :3] / scale
    X = P @ M[:3, :3].T + M[:3, 3]
    sdist, *_ = query.closest(X)

    # each landmark's vertex: nearest front-facing one, the camera axis counted at depth_weight
    view = R @ np.array([0.0, 0.0, 1.0])  # toward the camera, in the model's frame
    N = vertex_normals(V, F)
    facing = (N @ view) > 0.0
    basis = np.linalg.svd(np.eye(3) - np.outer(view, view))[0][:, :2]  # the image plane's axes
    W = np.c_[basis, float(depth_weight) * view]

    def nearest(points: NDArray[np.float64], mask: NDArray[np.bool_]) -> NDArray[np.intp]:
        idx = np.flatnonzero(mask)
        _, j = cKDTree(V[idx] @ W).query(points @ W)
        return np.asarray(idx[j], np.intp)

    ids = np.empty(N_LANDMARKS, np.intp)
    skin_f = skin & facing if (skin & facing).any() else skin
    ids[:_MESH] = nearest(X[:_MESH], skin_f)
    eyes = eyeball_mask(model)
    eyes_f = eyes & facing if (eyes & facing).any() else eyes
    ids[_MESH:] = nearest(X[_MESH:], eyes_f if eyes_f.any() else skin_f)

    space = ExpressionSpace.from_model(model)
    still = space.motion(ids) / space.size <= _STILL
    still[_MESH:] = False
    if int(still.sum()) < 4:
        still = np.ones(N_LANDMARKS, bool)
        still[_MESH:] = False
    inliers = np.zeros(N_LANDMARKS, bool)
    inliers[:_MESH] = ok
    rms = float(np.sqrt(np.mean(dist[ok] ** 2))) if ok.any() else float("nan")
    return LandmarkRegistration(
        vertex_ids=ids,
        matrix=M,
        scale=scale,
        image_size=(int(size[0]), int(size[1])),
        surface_distance=np.asarray(sdist, np.float64),
        vertex_distance=np.linalg.norm(X - V[ids], axis=1),
        inliers=inliers,
        still=np.asarray(still, bool),
        rest=X,
        anchors=dict(use),
        rms=rms,
    )


def landmark_vertex_map(
    model: FaceState,
    landmarks_frame: LandmarkSequence | ArrayLike,
    **options: Any,
) -> NDArray[np.intp]:
    """``(478,)`` rig vertex ids of the FaceMesh landmarks, by registration on a rest frame.

    ``register_landmarks(model, landmarks_frame, **options).vertex_ids``: see
    :func:`register_landmarks` (options ``frame``, ``image_size``, ``anchors``,
    ``iterations``, ``depth_weight``). The landmarks must be brought into the model's
    frame and units before tracking: :meth:`LandmarkRegistration.to_model`.
    """
    return register_landmarks(model, landmarks_frame, **options).vertex_ids


def track_video(
    model: FaceState,
    source: str | Path | ArrayLike | LandmarkSequence,
    *,
    rest_frame: int = 0,
    fps: float | None = None,
    max_frames: int | None = None,
    static: bool = False,
    progress: Progress | None = None,
    **track_options: Any,
) -> TrackResult:
    """Video (or frames, or landmarks) → :class:`~workbench.capture.TrackResult`, all steps at once.

    :func:`video_landmarks` (unless ``source`` is a :class:`LandmarkSequence`), then
    :func:`register_landmarks` on ``rest_frame`` (the actor at rest), then
    :func:`workbench.capture.track` on :meth:`LandmarkRegistration.to_model` with
    ``neutral=rest_frame`` (the landmark ↔ vertex offsets calibrated away) unless
    ``track_options`` says otherwise. The registration is not kept: call the steps
    yourself to inspect it.
    """
    from workbench.capture.track import track

    def part(lo: float, hi: float) -> Progress | None:
        if progress is None:
            return None
        cb = progress
        return lambda f, msg: cb(lo + (hi - lo) * float(f), msg)

    if isinstance(source, LandmarkSequence):
        seq = source
    else:
        seq = video_landmarks(source, fps=fps, max_frames=max_frames, static=static, progress=part(0.0, 0.7))
    reg = register_landmarks(model, seq, frame=rest_frame)
    track_options.setdefault("neutral", int(rest_frame))
    return track(model, reg.to_model(seq), vertex_ids=reg.vertex_ids, fps=seq.fps, progress=part(0.7, 1.0),
                 **track_options)
