"""Live tracking: camera frames in as they come, weights and head pose out (Bouaziz et al. 2013, online).

:class:`LiveTracker` is the kernel side of the Live tab (issue 30): each
:meth:`~LiveTracker.push` of an RGB camera frame runs MediaPipe FaceMesh in its
tracking mode (the ``video`` extra), brings the landmarks into the model's frame
and solves that frame alone — the same step as the offline marker tracker
(:class:`~workbench.capture.frame_step.FrameStepper`: robust head pose, bounded
L1 + temporal weights, warm-started), so a take pushed frame by frame gives what
:func:`~workbench.capture.video.track_video` gives it offline with the same λ's.

* **Start.** The first frame with a face registers the landmarks onto the rig
  (:func:`~workbench.capture.video.register_landmarks`: the landmark → vertex map)
  and calibrates on it as the actor's rest face (``track(..., neutral=0)``).
  No calibration session is needed, but the actor must be relaxed then: a face that
  registers smiling or talking is read against that expression from then on
  (``bench_live.py`` table 8: the whole take started at its open jaw and blink reads at
  weight RMSE 0.356 against 0.104 started at rest; at its smile 0.246, at all four
  expressions at half 0.157). :meth:`~LiveTracker.set_neutral` takes the next face as the
  neutral instead (0.086-0.087 after those starts), and a calibration session takes it
  from its "relax" prompt.
  The weights are fitted with the landmarks on the
  lips, eyes, brows and nose weighing 1 and those on smooth skin and the face's outline
  0.03 (:func:`~workbench.capture.landmark_registration.landmark_weights`: FaceMesh places
  the latter from the former, and they follow an expression only part of the way), in the
  image plane only (FaceMesh's depth is its face model's guess and does not follow the
  jaw; ``depth=True`` fits it too); the head pose uses them all, in 3-D. With ``adapt`` the rig adapts to the actor as
  frames arrive (the dynamic expression model, §4 — identity from the rest frame,
  correctives every few solved frames, :mod:`.adapt`); off by default (measured
  below).
* **Distance.** The head pose is a similarity (``fit_scale``, on by default): each frame's
  uniform scale — the actor leaning in or sitting back — is fitted with the rotation on the
  landmarks no expression moves and taken off before the weights' fit. With a rigid pose a
  face 15 % larger in the frame read as every shape that widens it (table 9: RMSE 0.33
  against 0.10; a 5 % drift 0.127 / 0.187 on the sample head / a foreign face).
* **Calibrate** (optional; FaceMesh reads some expressions short and mixes other
  shapes into them): :meth:`~LiveTracker.begin_calibration` runs a guided
  session — a neutral face, then a few prompted expressions, two seconds each
  (:mod:`.expression_calibration`) — and fits a map from what was tracked to what was
  prompted, applied to every later frame. On the rendered takes of
  ``benchmarks/bench_live.py`` (table 6) it lowers the whole take's weight RMSE from 0.107 to
  0.079 (sample head) and from 0.112 to 0.086 (a foreign face). A free "make your
  extremes" range (a gain per shape, 1 / its peak), the way before, raised it (0.168 / 0.142):
  it scaled up every shape the solve brushed.
* **No face** in view: the frame holds the last weights and pose, ``ok`` is
  False and ``note`` says so. **Two faces**: the largest is tracked.
* :meth:`~LiveTracker.take` is everything pushed so far as a
  :class:`~workbench.capture.TrackResult` (timestamps kept); the take survives
  the camera stopping mid-way.

The λ's cannot be chosen from a take that has not happened, so they are fixed:
the marker tracker's temporal term (:data:`~workbench.capture.track.DEFAULT_TEMPORAL`)
and a sparsity of its own, :data:`LANDMARK_L1`, three times the markers' (see there).
Hand-written glue over the kept modules.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.expression_calibration import (
    SECONDS_PER_PROMPT,
    CalibrationPrompt,
    ExpressionCalibration,
)
from workbench.capture.facemesh import N_LANDMARKS, VideoError, mediapipe_face_mesh
from workbench.capture.frame_step import FrameStepper
from workbench.capture.landmark_registration import LANDMARK_L1
from workbench.capture.result import FLAG_HELD, TrackResult

if TYPE_CHECKING:
    from workbench.capture.landmark_registration import LandmarkRegistration
    from workbench.core.state import FaceState

__all__ = ["LiveFrame", "LiveTracker"]


@dataclass(frozen=True, eq=False)
class LiveFrame:
    """What one pushed camera frame gave.

    Attributes
    ----------
    weights : (k,) float
        Every shape's weight, in ``model.shape_names`` order (held when ``ok`` is False).
    pose : (4, 4) float
        Head pose: ``observed ≈ R x + t`` in the model's units (held when ``ok`` is False).
    landmarks : (478, 3) float or None
        MediaPipe's normalized landmarks of the tracked face; None without a face.
    ok : bool
        A face was found and solved.
    timestamp : float
        Seconds, as pushed.
    note : str
        Empty, or why the frame holds (``"no face in view"``), or what happened
        (``"registered: …"`` on the first face, ``"calibrated: …"`` when a session ends).
    seconds : mapping of str to float
        Time per stage: ``"landmarks"``, ``"solve"`` (and ``"register"`` on the first face).
    prompt : str
        During a calibration session (:meth:`LiveTracker.begin_calibration`), what the
        actor is asked to do now; empty otherwise.
    prompt_index : int
        That prompt's place in the session's ``prompts_`` (prompts may share an
        instruction); -1 when no prompt shows.
    scale : float
        The face's size over its size at the neutral (``fit_scale``; > 1: the actor is closer
        to the camera), held like the pose; 1 without ``fit_scale``.
    """

    weights: NDArray[np.float64]
    pose: NDArray[np.float64]
    landmarks: NDArray[np.float64] | None
    ok: bool
    timestamp: float
    note: str = ""
    seconds: dict[str, float] = field(default_factory=dict)
    prompt: str = ""
    prompt_index: int = -1
    scale: float = 1.0


def _check_image(image: Any) -> NDArray[np.uint8]:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.shape[0] < 16 or img.shape[1] < 16:
        raise VideoError(f"image must be an (h, w, 3) RGB frame, got shape {img.shape}")
    if img.dtype != np.uint8:
        raise VideoError(f"image must be uint8 RGB, got dtype {img.dtype}")
    return np.ascontiguousarray(img[..., :3])


class LiveTracker:
    """Track a face from camera frames as they arrive (see the module docstring).

    Parameters
    ----------
    model : FaceModel
        The rig (ARKit-named shapes: the registration finds its landmarks by them).
    adapt : bool or dict
        Adapt the rig to the actor while tracking (True: the default options; a dict:
        :class:`~workbench.capture.AdaptiveModel` options). Off by default: on FaceMesh
        landmarks of an actor who is not the rig (a warped head) it leaves the weight error
        over the first three seconds about as it was (RMSE 0.099 against 0.091) and drifts up
        over the next ones (0.181 against 0.093 without by the ninth second), and on the rig's
        own face it raises it (0.080 → 0.151); from loop to loop the landmark error falls 21 %
        (``benchmarks/bench_live.py``, tables 2-3).
    l1, temporal : float, optional
        The tracker's relative λ's (default: :data:`LANDMARK_L1` and the marker tracker's
        ``DEFAULT_TEMPORAL``).
    iterations : int
        Pose / weight alternations per frame.
    min_markers : int
        Fewer landmarks in the model's frame hold the frame.
    min_confidence : float
        FaceMesh's detection and tracking confidence, in (0, 1).
    adapt_every : int
        With ``adapt``: every this many solved frames refine the rig (an update costs
        ~70 ms at 478 landmarks on one core, a frame without one ~7 ms: the default keeps
        the kernel at ≥ 20 frames/s while the rig converges over the first seconds).
    depth : bool
        Fit the weights on FaceMesh's depth too. Off by default: the weights are fitted on
        each landmark's offset in the image plane (``depth_axis`` of
        :func:`~workbench.capture.track.track_markers`, the registration's
        :attr:`~workbench.capture.landmark_registration.LandmarkRegistration.view_axis`), since
        FaceMesh's depth is a guess that does not follow the jaw; the head pose uses all three.
    fit_scale : bool
        Follow the actor's distance to the camera: the head pose is a similarity whose uniform
        scale is fitted each frame and removed before the weights' fit
        (:class:`~workbench.capture.frame_step.FrameStepper`). On by default: without it, an actor
        leaning 15 % closer than at the neutral reads as every shape that widens the face (the
        whole take's weight RMSE 0.33 against 0.10), and a sway of ±8 % costs 0.16 against 0.10; at
        a distance that never changes it costs the sample head 0.094 → 0.104 and the foreign face
        nothing (``benchmarks/bench_live.py`` table 9; a rigid pose loses more than that once the
        actor moves by more than 2-3 %). :attr:`LiveFrame.scale` holds it.

    Attributes
    ----------
    registration_ : LandmarkRegistration or None
        The landmark → vertex map, made on the first face.
    adapted_ : AdaptiveModel or None
        The rig adapting to the actor (``.to_model()``).
    n_frames_ : int
        Frames pushed.
    calibration_ : ExpressionCalibration or None
        The last calibration session (:meth:`begin_calibration`); its ``weight_map_``
        applies to every frame after it ended.
    neutral_at_ : (float, float) or None
        The timestamps (first, last) of the frames the actor's neutral was taken from: the
        first face, the frame after :meth:`set_neutral`, or a calibration's relax prompt.
    """

    def __init__(self, model: FaceState, *, adapt: bool | dict[str, Any] = False, l1: float | None = None,
                 temporal: float | None = None, iterations: int = 2, min_markers: int = 4,
                 min_confidence: float = 0.5, adapt_every: int = 5, depth: bool = False,
                 fit_scale: bool = True) -> None:
        from workbench.capture.track import DEFAULT_TEMPORAL

        if not model.shapes:
            raise VideoError("model: it has no blendshapes to track")
        for name, v in (("l1", l1), ("temporal", temporal)):
            if v is not None and not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise VideoError(f"{name} must be a number ≥ 0 (or None), got {v!r}")
        if not (0.0 < float(min_confidence) < 1.0):
            raise VideoError(f"min_confidence must be in (0, 1), got {min_confidence!r}")
        self.model = model
        self.adapt = adapt
        self.l1 = LANDMARK_L1 if l1 is None else float(l1)
        self.temporal = DEFAULT_TEMPORAL if temporal is None else float(temporal)
        self.iterations = int(iterations)
        self.min_markers = int(min_markers)
        self.min_confidence = float(min_confidence)
        if isinstance(adapt_every, bool) or not isinstance(adapt_every, int) or adapt_every < 1:
            raise VideoError(f"adapt_every must be an int ≥ 1, got {adapt_every!r}")
        self.adapt_every = adapt_every
        self.depth = bool(depth)
        self.fit_scale = bool(fit_scale)
        self.registration_: LandmarkRegistration | None = None
        self.adapted_: Any = None
        self.n_frames_ = 0
        self.calibration_: ExpressionCalibration | None = None
        self.neutral_at_: tuple[float, float] | None = None
        self._neutral_next = False  # set_neutral: register again on the next face
        self._relax_pending = False  # the running session's relax prompt has not given the neutral yet
        self._pending: ExpressionCalibration | None = None  # the session running
        self._solved = 0
        self._mesh: Any = None
        self._stepper: FrameStepper | None = None
        self._image_size: tuple[int, int] | None = None
        self._times: list[float] = []
        self._weights: list[NDArray[np.float64]] = []
        self._poses: list[NDArray[np.float64]] = []
        self._errors: list[float] = []
        self._flags: list[str] = []
        self._landmarks: list[NDArray[np.float64]] = []
        self._last_w = np.zeros(len(model.shape_names))
        self._last_pose = np.eye(4)
        self._last_scale = 1.0
        self._scales: list[float] = []

    # ------------------------------------------------------------------ frames
    def _face_landmarks(self, img: NDArray[np.uint8]) -> NDArray[np.float64] | None:
        """The largest face's (478, 3) normalized landmarks, or None."""
        if self._mesh is None:
            fm = mediapipe_face_mesh()
            self._mesh = fm.FaceMesh(static_image_mode=False, max_num_faces=2, refine_landmarks=True,
                                     min_detection_confidence=self.min_confidence,
                                     min_tracking_confidence=self.min_confidence)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r"SymbolDatabase\.GetPrototype\(\) is deprecated")
            res = self._mesh.process(img)
        faces = res.multi_face_landmarks or []
        if not faces:
            return None
        h, w = img.shape[:2]
        best, area = None, -1.0
        for face in faces:
            L = np.array([(p.x, p.y, p.z) for p in face.landmark], np.float64)
            if L.shape[0] != N_LANDMARKS:
                continue
            a = float(np.ptp(L[:, 0]) * w * np.ptp(L[:, 1]) * h)
            if a > area:
                best, area = L, a
        return best

    def _start(self, L: NDArray[np.float64]) -> str:
        """Register on the first face (the actor at rest) and set the tracker up on it."""
        from workbench.capture.landmark_registration import landmark_weights, register_landmarks
        from workbench.capture.track import (
            MarkerSetup,
            adaptive_for_markers,
            check_marker_units,
            start_from_neutral,
        )

        assert self._image_size is not None
        reg = register_landmarks(self.model, L[None], frame=0, image_size=self._image_size)
        ids = np.asarray(reg.vertex_ids, np.intp)
        setup = MarkerSetup(self.model, ids, self.l1, self.temporal, None, landmark_weights(),
                            None if self.depth else reg.view_axis)
        Y0 = reg.to_model(L[None])
        check_marker_units(Y0, setup.X0, self.model)
        am, rows = adaptive_for_markers(self.adapt if self.adapt else None, self.model, ids, None)
        start_from_neutral(setup, Y0, 0, am, rows)
        self._stepper = FrameStepper(setup, self.iterations, am, rows, fit_scale=self.fit_scale)
        self.registration_, self.adapted_ = reg, am
        return f"registered: {ids.size} landmarks on the rig (rms {reg.rms:.3g})"

    def push(self, image: ArrayLike, timestamp: float) -> LiveFrame:
        """Track one camera frame: ``image`` (h, w, 3) uint8 RGB taken at ``timestamp`` seconds.

        Raises
        ------
        VideoError
            Not an RGB uint8 frame, a frame of another size than the first, a timestamp
            not after the last one, or no face to register on (no rig landmarks).
        """
        img = _check_image(image)
        t = float(timestamp)
        if not math.isfinite(t) or (self._times and t <= self._times[-1]):
            last = self._times[-1] if self._times else None
            raise VideoError(f"timestamp must be finite and after the last frame's ({last}), got {timestamp!r}")
        size = (img.shape[1], img.shape[0])
        if self._image_size is not None and size != self._image_size:
            raise VideoError(f"image: every frame must be {self._image_size[0]}×{self._image_size[1]} like the "
                             f"first, got {size[0]}×{size[1]}")
        self._image_size = size
        secs: dict[str, float] = {}
        t0 = time.perf_counter()
        L = self._face_landmarks(img)
        secs["landmarks"] = time.perf_counter() - t0
        note = ""
        ok = False
        err, flag = float("nan"), FLAG_HELD
        if L is not None:
            if self._stepper is None or self._neutral_next:
                t1 = time.perf_counter()
                again = self._stepper is not None
                note = self._start(L)
                if again:
                    note = "neutral set on this frame: " + note
                self._neutral_next = False
                self.neutral_at_ = (t, t)
                secs["register"] = time.perf_counter() - t1
            elif self._pending is not None and self._relax_over(self._pending, t):
                t1 = time.perf_counter()
                note = self._neutral_from_session(self._pending)
                secs["register"] = time.perf_counter() - t1
            assert self._stepper is not None and self.registration_ is not None
            t1 = time.perf_counter()
            Y = self.registration_.to_model(L[None])[0]
            vis = np.asarray(np.isfinite(Y).all(1))
            if int(vis.sum()) >= self.min_markers:
                self._solved += 1
                w, M, err, flag = self._stepper.step(Y, vis, adapt=(self._solved - 1) % self.adapt_every == 0)
                if self._pending is not None:
                    self._pending.add(t, w)
                self._last_w = self._calibrated(w)
                self._last_pose = M
                self._last_scale = self._stepper.scale
                ok = True
            else:
                self._stepper.hold(self._stepper.w)
                note = f"only {int(vis.sum())} landmarks on the face: holding the last pose"
            secs["solve"] = time.perf_counter() - t1
        else:
            note = "no face in view: holding the last pose"
            if self._stepper is not None:
                self._stepper.hold(self._stepper.w)
        prompt, prompt_index = "", -1
        cal = self._pending
        if cal is not None:
            if cal.done(t):
                note = self._finish_calibration()
            else:
                prompt_index = cal.prompt_index(t) or 0
                prompt = cal.prompts_[prompt_index].instruction
        self.n_frames_ += 1
        self._times.append(t)
        self._weights.append(self._last_w.copy())
        self._poses.append(self._last_pose.copy())
        self._scales.append(self._last_scale)
        self._errors.append(err)
        self._flags.append(flag)  # FLAG_HELD unless the frame was solved
        self._landmarks.append(L if L is not None else np.full((N_LANDMARKS, 3), np.nan))
        return LiveFrame(self._last_w.copy(), self._last_pose.copy(), L, ok, t, note, secs, prompt, prompt_index,
                         self._last_scale)

    # ------------------------------------------------------------------ the neutral
    def set_neutral(self) -> None:
        """Take the next frame with a face as the actor's neutral (relaxed face, eyes open).

        The tracker registers again on it (the landmark → vertex map and the rest offsets:
        see the module docstring's *Start*), as on the first face, and reads every later
        frame against it; with ``adapt`` the rig starts adapting again from it. A calibration's
        map stays (a session takes the neutral from its own relax prompt). Frames already
        pushed keep what they read.
        """
        self._neutral_next = True

    def _relax_over(self, cal: ExpressionCalibration, t: float) -> bool:
        """The session's relax prompt ended before ``t`` and the neutral was not yet taken from it."""
        window = cal.neutral_window()
        return self._relax_pending and window is not None and t >= window[1]

    def _neutral_from_session(self, cal: ExpressionCalibration) -> str:
        """Register again on the relax prompt's later half (the landmarks' median) and re-read its frames.

        The actor may have started the camera mid-expression; the session's first prompt is
        the relaxed face, held for seconds. Its frames read again against the new neutral go
        into the session, so its fit sees them as every later frame is read.
        """
        window = cal.neutral_window()
        assert window is not None and self._stepper is not None
        self._relax_pending = False
        ts = np.array(self._times)
        inside = np.flatnonzero((ts >= window[0]) & (ts < window[1]))
        faces = [i for i in inside if np.isfinite(self._landmarks[i]).all()]
        assert faces, "a session starts at its first solved frame, which is in its relax prompt"
        later = faces[len(faces) // 2:]
        note = self._start(np.median(np.array([self._landmarks[i] for i in later]), axis=0))
        assert self._stepper is not None and self.registration_ is not None
        self.neutral_at_ = (float(ts[later[0]]), float(ts[later[-1]]))
        reread = []
        for i in faces:
            Y = self.registration_.to_model(self._landmarks[i][None])[0]
            vis = np.asarray(np.isfinite(Y).all(1))
            if int(vis.sum()) >= self.min_markers:
                reread.append(self._stepper.step(Y, vis, adapt=False)[0])
        cal.reread(0, np.array(reread))
        return "neutral set from the relax prompt: " + note

    # ------------------------------------------------------------------ calibration
    def begin_calibration(self, prompts: list[CalibrationPrompt] | None = None, *,
                          seconds: float = SECONDS_PER_PROMPT) -> ExpressionCalibration:
        """Start a guided calibration session at the next frame (see :mod:`.expression_calibration`).

        Each pushed frame's :attr:`LiveFrame.prompt` says what the actor should do; the
        session ends by itself after ``seconds`` per prompt (by the frames' timestamps) and
        its map applies from then on (a frame's ``note`` says so), or earlier with
        :meth:`end_calibration`. A new session replaces the last one's map when it ends.
        When its first prompt is a still neutral face (the default's "Relax"), the tracker
        takes the actor's neutral from that prompt's later half as it ends (as
        :meth:`set_neutral` does from one frame), so a session also mends a start that was
        not relaxed.
        """
        from workbench.capture.rig import ExpressionSpace

        space = ExpressionSpace.from_model(self.model)
        cal = ExpressionCalibration([space.shape_names[i] for i in space.plain], prompts, seconds=seconds)
        self._pending = cal
        self._relax_pending = True
        return cal

    @property
    def calibrating(self) -> bool:
        """A calibration session is running."""
        return self._pending is not None

    def end_calibration(self) -> ExpressionCalibration:
        """End the session now and fit it on the prompts reached so far.

        Raises
        ------
        VideoError
            No session is running, or it saw no neutral face or no held expression
            (the last calibration, if any, stays).
        """
        if self._pending is None:
            raise VideoError("end_calibration: begin_calibration first")
        self._finish_calibration(raise_errors=True)
        assert self.calibration_ is not None
        return self.calibration_

    def cancel_calibration(self) -> None:
        """Stop the session without fitting (the last calibration, if any, stays)."""
        self._pending = None

    def _finish_calibration(self, raise_errors: bool = False) -> str:
        cal, self._pending = self._pending, None
        assert cal is not None
        try:
            cal.fit()
        except ValueError as exc:
            if raise_errors:
                raise VideoError(str(exc)) from None
            return f"calibration not used: {exc}"
        self.calibration_ = cal
        return cal.summary()

    def _calibrated(self, w: NDArray[np.float64]) -> NDArray[np.float64]:
        """The plain weights ``w`` through the calibration's map, clamped to the sliders, as full weights."""
        assert self._stepper is not None
        space = self._stepper.setup.space
        cal = self.calibration_
        if cal is not None and cal.weight_map_ is not None:
            w = np.clip(cal.apply(w), space.lo, space.hi)
        return space.full_weights(w)

    # ------------------------------------------------------------------ the take
    @property
    def image_size(self) -> tuple[int, int] | None:
        """``(width, height)`` of the frames (None before the first)."""
        return self._image_size

    def save_take(self, path: str | Path) -> Path:
        """Write the raw take — landmarks, timestamps, image size, the neutral's frame — as ``.npz`` (atomically).

        Re-track it offline with other settings: ``track_video(model, path)`` (through
        :meth:`~workbench.capture.LandmarkSequence.load_take`) registers on the frame the
        session last took the neutral from (``neutral_frame``: the first face's frame, the frame
        after :meth:`set_neutral`, or the middle of a calibration's relax prompt's later half).
        """
        from workbench.export.base import atomic_path

        if not self._times:
            raise VideoError("save_take: no frame was pushed")
        out = Path(path)
        if out.suffix.lower() != ".npz":
            raise VideoError(f"save_take: {out.name}: expected a .npz path")
        L, ts = self.landmarks, self.timestamps
        arrays: dict[str, Any] = {"landmarks": L, "timestamps": ts, "image_size": np.array(self._image_size, np.int64)}
        if self.neutral_at_ is not None:  # the frame with a face nearest the middle of the neutral's frames
            gap = np.where(np.isfinite(L).all(axis=(1, 2)), np.abs(ts - 0.5 * sum(self.neutral_at_)), np.inf)
            arrays["neutral_frame"] = np.array(int(np.argmin(gap)), np.int64)
        with atomic_path(out) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return out

    @property
    def timestamps(self) -> NDArray[np.float64]:
        """(T,) seconds of the frames pushed so far."""
        return np.array(self._times, np.float64)

    @property
    def landmarks(self) -> NDArray[np.float64]:
        """(T, 478, 3) normalized landmarks pushed so far (NaN without a face): the raw take."""
        return np.array(self._landmarks, np.float64).reshape(-1, N_LANDMARKS, 3)

    def take(self) -> TrackResult:
        """Everything pushed so far as a :class:`~workbench.capture.TrackResult` (``info["timestamps"]``).

        The keys go at the frames' own timestamps (``info["timestamps"]``: a camera drops
        frames); ``fps`` is the nominal 30 (the timeline's rate when it had none), and
        ``info["rate"]`` the rate achieved (the median interval's), ``info["scales"]`` each
        frame's :attr:`LiveFrame.scale` (None without ``fit_scale``). Frames before the first
        face take its values.
        """
        if not self._times:
            raise VideoError("take: no frame was pushed")
        if self._stepper is None:
            raise VideoError("take: no face was seen in any frame")
        T = len(self._times)
        ts = self.timestamps
        rate = 1.0 / float(np.median(np.diff(ts))) if T > 1 else float("nan")
        W, P, S = np.array(self._weights), np.array(self._poses), np.array(self._scales)
        flags = list(self._flags)
        solved = [i for i, f in enumerate(flags) if f != FLAG_HELD]
        if solved:
            W[: solved[0]], P[: solved[0]], S[: solved[0]] = W[solved[0]], P[solved[0]], S[solved[0]]
        space = self._stepper.setup.space
        derived = space.unsolved_names
        return TrackResult(W, P, np.array(self._errors), tuple(flags), 30.0, space.shape_names, derived,
                           space.size, "markers",
                           {"l1": self.l1, "temporal": self.temporal, "live": True, "timestamps": ts, "rate": rate,
                            "vertex_ids": None if self.registration_ is None else self.registration_.vertex_ids,
                            "adapted": self.adapted_,
                            "scales": S if self.fit_scale else None})

    def close(self) -> None:
        """Release FaceMesh (the take stays readable)."""
        if self._mesh is not None:
            self._mesh.close()
            self._mesh = None

    def __enter__(self) -> LiveTracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
