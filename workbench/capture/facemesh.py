"""MediaPipe FaceMesh landmarks of a video or of frames (the first step of :mod:`workbench.capture.video`).

The optional ``video`` extra brings mediapipe (its legacy FaceMesh solution,
with the models in the wheel) and OpenCV (to read files); without it
:func:`video_landmarks` raises :class:`VideoExtraMissing` naming the install
command. :class:`LandmarkSequence` holds the landmarks per frame in
MediaPipe's normalized image coordinates.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "IRIS",
    "MEDIAPIPE_VERSION",
    "N_LANDMARKS",
    "N_MESH",
    "VIDEO_EXTRA",
    "LandmarkSequence",
    "VideoError",
    "VideoExtraMissing",
    "landmark_points",
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
N_MESH = 468

Progress = Callable[[float, str], Any]


class VideoExtraMissing(ImportError):
    """The optional ``video`` extra (mediapipe, OpenCV) is not installed; the message says how to install it."""


class VideoError(ValueError):
    """A video or frames that cannot be read, or landmarks that cannot be registered; names the input."""


# ----------------------------------------------------------------------------- the extra
def mediapipe_face_mesh() -> Any:
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
    rest_frame : int or None
        A saved live take's frame the session last took the actor's neutral from
        (:attr:`LiveTracker.neutral_at_ <workbench.capture.LiveTracker>`); None otherwise.
        :func:`~workbench.capture.video.track_video` registers on it unless told another.
    """

    landmarks: NDArray[np.float64]
    image_size: tuple[int, int]
    fps: float
    frame_numbers: NDArray[np.int64]
    source: str = "<frames>"
    rest_frame: int | None = None

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
        if self.rest_frame is not None:
            r = int(self.rest_frame)
            if not 0 <= r < L.shape[0] or not np.isfinite(L[r]).all():
                raise ValueError(f"LandmarkSequence: rest_frame must be a frame with a face (0–{L.shape[0] - 1}), "
                                 f"got {self.rest_frame!r}")
            object.__setattr__(self, "rest_frame", r)

    @classmethod
    def load_take(cls, path: str | Path) -> LandmarkSequence:
        """A live take saved by :meth:`LiveTracker.save_take` (``.npz``: landmarks, timestamps, image size).

        ``fps`` is the take's achieved rate (its median frame interval); ``frame_numbers``
        count the frames pushed; ``rest_frame`` is the frame the session took the neutral
        from (``neutral_frame``; takes saved before it was written have none). No pickle is read.
        """
        p = Path(path)
        fields = ("landmarks", "timestamps", "image_size")
        try:
            with np.load(p, allow_pickle=False) as z:
                arrays = {k: np.asarray(z[k]) for k in (*fields, "neutral_frame") if k in z.files}
                missing = sorted(set(fields) - set(z.files))
        except (OSError, ValueError) as exc:
            raise VideoError(f"{p.name}: not a saved live take ({exc})") from None
        if missing:
            raise VideoError(f"{p.name}: a saved live take has landmarks, timestamps and image_size; "
                             f"missing {missing}")
        ts, size = arrays["timestamps"].astype(np.float64), arrays["image_size"]
        if ts.ndim != 1 or ts.size < 1 or not np.all(np.isfinite(ts)) or np.any(np.diff(ts) <= 0):
            raise VideoError(f"{p.name}: timestamps must be increasing seconds, got shape {ts.shape}")
        if size.shape != (2,) or not np.all(size > 0):
            raise VideoError(f"{p.name}: image_size must be (width, height) > 0, got {size.tolist()}")
        fps = 1.0 / float(np.median(np.diff(ts))) if ts.size > 1 else 30.0
        rest = arrays.get("neutral_frame")
        if rest is not None and (rest.shape != () or rest.dtype.kind not in "iu"):
            raise VideoError(f"{p.name}: neutral_frame must be one frame index, got {rest.tolist()!r}")
        try:
            return cls(arrays["landmarks"], (int(size[0]), int(size[1])), fps, np.arange(ts.size), str(p),
                       None if rest is None else int(rest))
        except ValueError as exc:
            raise VideoError(f"{p.name}: {exc}") from None

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
        return landmark_points(self.landmarks, self.image_size)


def landmark_points(L: NDArray[np.float64], image_size: tuple[int, int]) -> NDArray[np.float64]:
    """Normalized landmarks (..., 3) -> pixels: +x right, +y up, +z toward the camera (see :meth:`LandmarkSequence.points`)."""
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
        face_mesh = mediapipe_face_mesh()
        items, native, total, cap = _video_frames(path, fps)
        rate = float(fps) if fps is not None and fps < native else native
        if fps is not None and fps < native:
            total = math.ceil(total * fps / native)
    else:
        src = "<frames>"
        items, total = _array_frames(source)
        rate = float(fps) if fps is not None else 30.0
        face_mesh = mediapipe_face_mesh()
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
