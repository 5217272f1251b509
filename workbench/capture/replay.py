"""Marker replay: markers drive the linear shell, their strain drives the wrinkles (Bickel et al. 2008, §3–5, Fig. 6).

Bickel et al.'s own pipeline (§6.3, "Animation from Mocap"): the motion-capture
markers are the *handle vertices* of the linear thin shell (§4), so the face
follows the actor even where no blendshape could (an asymmetric lip curl, a
cheek the rig never puffs), and the fine scale comes from weighted pose-space
deformation driven by the strain of the markers' own feature graph (§5.1–5.3).

:func:`replay`, per take:

1. **Head pose, robustly.** With a rig (shapes), :func:`~workbench.capture.track`
   solves the head pose and the blendshape weights (Tukey-weighted pose on the
   markers the shapes barely move); without shapes, a Tukey-weighted rigid fit of
   each frame's markers onto the neutral's (the expression is local, so the
   still majority wins).
2. **Base.** The rig's weights give the large-scale base (the neutral without a
   rig), evaluated by the model's own pipeline below its ``handles`` layer.
3. **Shell.** What the base leaves at each marker (pose removed) becomes that
   marker's handle offset; the shell (``B u_H``) spreads it over the face, so every
   marker lands on its vertex. Occluded samples are interpolated in time.
4. **Wrinkles.** WPSD details fitted for the marker handles on the markers'
   feature graph (each marker's four nearest markers), from the model's own
   wrinkle examples (or the procedural examples when it has none).

The meshes are evaluated by the model's pipeline on a scratch copy whose handles
are the markers and whose wrinkles are that fit, through the same timeline
``model.capture.apply_replay`` keys, so what the model plays after applying it is
what :attr:`ReplayResult.meshes` holds (bit for bit with ``tolerance=0``).

Hand-written glue: the shell, the pose, the tracker and the pose space are the
kept modules of :mod:`workbench.methods` and :mod:`workbench.capture`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves.keys import Key
from workbench.animation.curves.track import Track
from workbench.animation.importers.keys import reduce_keys_jointly
from workbench.animation.tracks import Timeline
from workbench.capture.pose import PoseError, fit_rigid_robust, pose_matrix
from workbench.capture.result import TrackError, TrackResult, pose_keys
from workbench.capture.rig import head_size
from workbench.capture.track import prepare_markers, track
from workbench.methods.handles.handle_set import HandleSet
from workbench.methods.wrinkles.layer import WrinkleState, fit_wrinkles

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["ReplayResult", "replay"]

logger = logging.getLogger(__name__)

Progress = Callable[[float, str], None]

#: a marker farther than this (head sizes) from its vertex in most frames sits on another vertex
_FAR = 0.2


@dataclass(frozen=True, eq=False)
class ReplayResult:
    """A replayed take: the shell carried by markers, with wrinkles (Bickel et al. 2008, Fig. 6).

    Attributes
    ----------
    meshes : (T, n, 3) float32
        The face per frame, head pose removed (model space).
    poses : (T, 4, 4) float
        Head pose per frame: ``observed ≈ R x + t``.
    offsets : (T, m, 3) float
        Handle offset of every marker per frame (model units), on top of the base.
    vertex_ids : (m,) int
        The marker vertices (the replay's handles, in marker order).
    fps : float
    weights : (T, k) float
        The rig's tracked weights (``shape_names`` order; k = 0 without shapes).
    shape_names, derived : tuple of str
    head_size : float
        Model units.
    handles : HandleSet
        The markers as a handle set (zero offsets), what ``apply_replay`` installs.
    wrinkles : WrinkleState or None
        The pose space fitted on the markers' feature graph (None: no wrinkles).
    tracked : TrackResult or None
        The blendshape tracking the base came from (None without shapes).
    info : mapping
        ``"wrinkles"`` (where the details came from, or why there are none), ``"pose"``.
    """

    meshes: NDArray[np.float32]
    poses: NDArray[np.float64]
    offsets: NDArray[np.float64]
    vertex_ids: NDArray[np.intp]
    fps: float
    weights: NDArray[np.float64]
    shape_names: tuple[str, ...]
    derived: tuple[str, ...]
    head_size: float
    handles: HandleSet
    wrinkles: WrinkleState | None
    tracked: TrackResult | None
    info: Mapping[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        return (f"ReplayResult({self.n_frames} frames at {self.fps:g} fps, {self.vertex_ids.size} markers, "
                f"{len(self.shape_names)} shapes, wrinkles {'on' if self.wrinkles is not None else 'off'})")

    @property
    def n_frames(self) -> int:
        return int(self.offsets.shape[0])

    def times(self, start: float = 0.0) -> NDArray[np.float64]:
        """(T,) seconds: ``start + f / fps``."""
        return float(start) + np.arange(self.n_frames) / self.fps

    def to_timeline(self, tolerance: float = 0.01, *, offset_tolerance: float | None = None, start: float = 0.0,
                    head_pose: bool = True) -> Timeline:
        """Reduced linear keys: the rig's weights, the ``handles`` offsets and the head pose.

        Parameters
        ----------
        tolerance : float
            ≥ 0: weights within this of every frame (0 keys every frame, and then the
            model plays :attr:`meshes` exactly).
        offset_tolerance : float, optional
            Handle offsets within this (model units) of every frame; default
            ``1e-3 · head_size`` (0 when ``tolerance`` is 0).
        start : float
            Seconds of frame 0.
        head_pose : bool
            Also key the head pose.
        """
        tol = float(tolerance)
        if not (np.isfinite(tol) and tol >= 0):
            raise ValueError(f"tolerance must be a number ≥ 0, got {tolerance!r}")
        otol = (1e-3 * self.head_size if tol > 0 else 0.0) if offset_tolerance is None else float(offset_tolerance)
        if not (np.isfinite(otol) and otol >= 0):
            raise ValueError(f"offset_tolerance must be a number ≥ 0 (model units), got {offset_tolerance!r}")
        times = self.times(start)
        if self.tracked is not None:
            tl = self.tracked.to_timeline(tol, start=start, head_pose=False)
        else:
            tl = Timeline(fps=self.fps, start=float(times[0]), end=float(times[-1]), tracks={})
        # tolerance 0 keys every frame (not only the non-collinear ones): the model then plays the meshes bit for bit
        idx = (reduce_keys_jointly(times, self.offsets.reshape(self.n_frames, -1), otol) if otol > 0
               else np.arange(self.n_frames))
        tl = tl.with_track(Track("handles", tuple(Key(float(times[i]), self.offsets[i], "linear") for i in idx)))
        if head_pose:
            if tol > 0:
                tl = tl.with_track(pose_keys(self.poses, times, 1e-3 * self.head_size, 0.1))
            else:
                tl = tl.with_track(pose_keys(self.poses, times, 0.0, 0.0))
        return tl

    def to_face(self, model: FaceModel, *, posed: bool = False) -> FaceModel:
        """A face playing :attr:`meshes` as baked frames (for any exporter: point cache, glb, USD).

        ``posed``: with the head pose applied. The face keeps ``model``'s mesh, parts and metadata.
        """
        from workbench.animation.baked_frames import baked_frames_model

        M = self.meshes.astype(np.float64)
        if posed:
            M = np.einsum("tij,tnj->tni", self.poses[:, :3, :3], M) + self.poses[:, None, :3, 3]
        return baked_frames_model(M, None, self.times(), self.fps, like=model, what="Marker replay")


def _fill_occluded(U: NDArray[np.float64], times: NDArray[np.float64]) -> NDArray[np.float64]:
    """Occluded (NaN) offsets linearly interpolated in time, held before the first / after the last sample."""
    out = U.copy()
    for j in range(U.shape[1]):
        ok = np.isfinite(U[:, j]).all(1)
        if ok.all():
            continue
        for c in range(3):
            out[:, j, c] = np.interp(times, times[ok], U[ok, j, c])
    return out


def _rigid_poses(V0: NDArray[np.float64], Y: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T, 4, 4) Tukey-robust rigid poses of the neutral's markers onto each frame's."""
    T = Y.shape[0]
    poses = np.empty((T, 4, 4))
    last = np.eye(4)
    for f in range(T):
        try:
            p = fit_rigid_robust(V0, Y[f])
            last = pose_matrix(p.rotation, p.translation)
        except PoseError:
            pass  # fewer than three markers seen: hold the last pose
        poses[f] = last
    return poses


def _wiener_gains(raw: NDArray[np.float64], smoothed: NDArray[np.float64], sigma_frames: float
                  ) -> NDArray[np.float64]:
    """(m,) per-marker gains ``s / (s + n)``: how much of a smoothed offset is signal rather than noise.

    The marker's noise variance comes from its second differences (white noise has
    ``var(Δ²n) = 6σ²``; a robust MAD, so real motion barely counts), reduced by the
    Gaussian's ``1 / (2 √π σ_t)``; the signal is the smoothed offset's power above it.
    Where the rig explains a marker, its offset is mostly noise and shrinks toward 0.
    """
    d2 = np.diff(raw, 2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) * 1.4826  # (m, 3)
    noise = (mad**2 / 6.0).sum(1) / (2.0 * np.sqrt(np.pi) * sigma_frames)
    signal = np.maximum((smoothed * smoothed).sum(2).mean(0) - noise, 0.0)
    gains: NDArray[np.float64] = signal / np.maximum(signal + noise, 1e-300)
    return gains


def _wrinkle_examples(model: FaceModel) -> tuple[dict[str, tuple[Mapping[str, float], NDArray]], str]:
    """Detailed examples ``{name: (weights, detailed)}`` and where they come from."""
    facet = model.wrinkles
    if facet.fitted:
        return ({name: (w, facet.example_detailed(name)[1])
                 for name, w in zip(facet.example_names, facet.example_weights, strict=True)},
                "the model's fitted wrinkle examples")
    if not model.shapes:
        return {}, "no wrinkles: the model has no shapes to pose wrinkle examples with"
    from workbench.methods.wrinkles.examples import WrinkleSculptor, example_poses_for

    on_rig, _ = example_poses_for(model.shape_names)
    if len(on_rig) < 2:
        return {}, f"no wrinkles: only {len(on_rig)} procedural example poses can be built on this rig"
    s = WrinkleSculptor(model)
    return {k: (w, s.detailed(w)) for k, w in on_rig.items()}, f"{len(on_rig)} procedural wrinkle examples"


def _scratch(model: FaceModel, handles: HandleSet, wrinkles: WrinkleState | None) -> FaceModel:
    """A copy of ``model`` (same shapes and slot values) whose handles are the markers."""
    from workbench.core.families import families
    from workbench.model import FaceModel

    slots = {s.name: model.slot(s.name) for f in families() for s in f.slots}
    slots["handles"] = handles
    slots["wrinkles"] = wrinkles if wrinkles is not None else WrinkleState()
    return FaceModel(model.vertices, model.faces, model.shapes, polygons=model.polygons,
                     component_labels=model.component_labels, component_names=list(model.component_names),
                     metadata=model.metadata, weights=dict(model.weights), **slots)


def replay(
    model: FaceModel,
    frames: ArrayLike,
    *,
    vertex_ids: ArrayLike,
    fps: float = 30.0,
    wrinkles: bool | WrinkleState = True,
    neutral_frame: int | None = None,
    smoothing: float = 2.0 / 30.0,
    denoise: bool = True,
    progress: Progress | None = None,
    **track_options: Any,
) -> ReplayResult:
    """Replay a marker take through the shell with pose-space wrinkles (Bickel et al. 2008, Fig. 6).

    Parameters
    ----------
    model : FaceModel
        The face (with or without shapes; its other layers play as they are).
    frames : (T, m, 3) float
        Marker positions per frame (NaN = occluded), model units.
    vertex_ids : (m,) int
        The vertex each marker sits on (distinct).
    fps : float
    wrinkles : bool or WrinkleState
        True: fit WPSD details on the markers' feature graph from the model's wrinkle
        examples (procedural ones when it has none); False: none; a state fitted for
        these marker vertices: used as given.
    neutral_frame : int, optional
        A frame where the actor holds the neutral face: what the markers leave there
        (markers glued above the skin, a different actor) is their rest offset and is
        subtracted from every frame. Default: none (markers sit on their vertices).
    smoothing : float
        Seconds (≥ 0): a Gaussian in time over the handle offsets. The shell puts
        the markers exactly where they were seen, so their noise would go straight
        into the face; the default (two frames at 30 fps) was chosen on realistic
        takes with 0.1–0.2 mm marker noise, where it halves the replay's error over
        exact interpolation and costs nothing on clean takes (benchmark). 0: none.
    denoise : bool
        With ``smoothing``: shrink each marker's offsets by its Wiener gain (signal power
        over signal + noise power, the noise measured from the marker's own second
        differences), so a marker the rig already explains adds its noise to nothing
        (at 0.5 mm noise the replay's error falls from 0.9× to 0.74–0.75× tracking's).
    progress : callable, optional
        ``progress(fraction, message)``.
    **track_options
        Passed to :func:`~workbench.capture.track` for the rig's base (``l1``, ``temporal``…).

    Returns
    -------
    ReplayResult

    Raises
    ------
    TrackError
        Bad input, naming the argument: wrong shapes, repeated vertex ids, a marker never
        seen, a marker that never comes near its vertex. The model is never changed.
    """
    say = progress or (lambda f, m: None)
    Y, ids = prepare_markers(model, frames, vertex_ids)
    T, m = Y.shape[:2]
    if not (np.isfinite(fps) and fps > 0):
        raise TrackError(f"fps must be a positive number, got {fps!r}")
    uniq, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        v = int(uniq[counts > 1][0])
        raise TrackError(f"vertex_ids: vertex {v} carries markers {np.flatnonzero(ids == v).tolist()}; "
                         "each marker drives its own handle vertex")
    seen = np.isfinite(Y).all(2)
    never = np.flatnonzero(~seen.any(0))
    if never.size:
        raise TrackError(f"frames: marker {int(never[0])} (vertex {int(ids[never[0]])}) is occluded in every frame "
                         f"({never.size} such markers); drop it from frames and vertex_ids")
    if m < 3:
        raise TrackError(f"frames: need at least 3 markers to remove the head pose, got {m}")
    if not (isinstance(smoothing, int | float) and np.isfinite(smoothing) and smoothing >= 0):
        raise TrackError(f"smoothing must be seconds ≥ 0, got {smoothing!r}")
    if neutral_frame is not None and not (0 <= int(neutral_frame) < T):
        raise TrackError(f"neutral_frame must be a frame index in 0..{T - 1}, got {neutral_frame!r}")
    size = head_size(model)
    times = np.arange(T) / float(fps)
    V0 = np.asarray(model.vertices, np.float64)
    has_rig = any(not s.mute for s in model.shapes)

    # 1. head pose (and the rig's weights)
    tracked: TrackResult | None = None
    if has_rig:
        tracked = track(model, Y, vertex_ids=ids, fps=fps, progress=lambda f, msg: say(0.5 * f, msg),
                        **track_options)
        poses = np.array(tracked.poses)
        W = np.array(tracked.weights)
    else:
        say(0.0, "head pose")
        poses = _rigid_poses(V0[ids], Y)
        W = np.zeros((T, len(model.shape_names)))
    R, t = poses[:, :3, :3], poses[:, :3, 3]
    Ym = np.einsum("tji,tmj->tmi", R, Y - t[:, None, :])  # Rᵀ (y − t): model space

    # 2. wrinkles on the markers' feature graph
    handles = HandleSet(ids.astype(np.int32), names=tuple(f"marker{i}" for i in range(ids.size)))
    info: dict[str, Any] = {"pose": "tracked with the rig" if has_rig else "robust rigid fit to the neutral"}
    ws: WrinkleState | None = None
    if isinstance(wrinkles, WrinkleState):
        if not wrinkles.made_for(handles.vertices):
            raise TrackError("wrinkles: the given WrinkleState was not fitted for these marker vertices")
        ws, info["wrinkles"] = wrinkles, "given"
    elif wrinkles:
        say(0.5, "fitting wrinkles on the marker graph")
        examples, info["wrinkles"] = _wrinkle_examples(model)
        if examples:
            ws = fit_wrinkles(_scratch(model, handles, None), examples)
        else:
            logger.warning("replay: %s", info["wrinkles"])
    else:
        info["wrinkles"] = "off"
    scratch = _scratch(model, handles, ws)

    # 3. base below the shell, the markers' offsets on it
    names = list(model.shape_names)
    derived = tuple(tracked.derived) if tracked is not None else ()
    weights_tl = (tracked.to_timeline(0.0, head_pose=False) if tracked is not None
                  else Timeline(fps=fps, start=0.0, end=float(times[-1]), tracks={}))
    base = np.empty((T, m, 3))
    for f in range(T):
        base[f] = scratch.evaluation_at(float(times[f]), weights_tl, below="handles").mesh[ids]
        if f % 32 == 0:
            say(0.6 + 0.15 * f / T, f"base {f} of {T}")
    U = Ym - base
    far = np.nanmedian(np.linalg.norm(U, axis=2), axis=0) > _FAR * size
    if far.any():
        j = int(np.flatnonzero(far)[0])
        raise TrackError(f"vertex_ids: marker {j} stays {float(np.nanmedian(np.linalg.norm(U[:, j], axis=1))):.3g} "
                         f"model units (> {_FAR:g} head sizes) from vertex {int(ids[j])} after the head pose is "
                         f"removed ({int(far.sum())} such markers): wrong vertex ids, or frames in other units?")
    if neutral_frame is not None:
        rest = U[int(neutral_frame)]
        if not np.isfinite(rest).all():
            raise TrackError(f"neutral_frame {neutral_frame}: every marker must be visible in the neutral frame")
        U = U - rest
    U = _fill_occluded(U, times)
    if smoothing > 0 and T > 2:
        from scipy.ndimage import gaussian_filter1d

        sig = float(smoothing) * float(fps)
        smoothed = gaussian_filter1d(U, sig, axis=0, mode="nearest")
        if denoise and T > 8:
            smoothed = smoothed * _wiener_gains(U, smoothed, sig)[None, :, None]
        U = smoothed

    # 4. the face: the model's pipeline through the very timeline apply_replay keys
    result = ReplayResult(np.empty((0, 0, 3), np.float32), poses, U, ids, float(fps), W, tuple(names), derived, size,
                          handles, ws, tracked, info)
    tl = result.to_timeline(0.0, head_pose=False)
    n = model.n_vertices
    meshes = np.empty((T, n, 3), np.float32)
    for f in range(T):
        meshes[f] = scratch.evaluation_at(float(times[f]), tl).mesh
        if f % 16 == 0 or f == T - 1:
            say(0.75 + 0.25 * (f + 1) / T, f"replayed {f + 1} of {T} frames")
    object.__setattr__(result, "meshes", meshes)
    return result
