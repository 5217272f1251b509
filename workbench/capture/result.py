"""What tracking gives: :class:`TrackResult` — weights, head poses, fit errors, per-frame flags — and its timeline.

``TrackResult.to_timeline(tolerance)`` turns the per-frame samples into a
:class:`~workbench.animation.tracks.Timeline` with linear keys reduced by
:func:`workbench.animation.importers.reduce_keys` (every frame's weight is
reproduced within ``tolerance``) and a ``head_pose`` track (translation +
quaternion, ``p -> R p + t`` as :meth:`TimelineFacet.key_head_pose`).
``model.capture.apply(result)`` puts it on the model's timeline as one undo
step (:mod:`.facet`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.animation.curves import HEAD_POSE, Key, Track
from workbench.animation.importers import reduce_keys_jointly, timeline_from_samples
from workbench.animation.tracks import Timeline

__all__ = ["FLAG_HELD", "FLAG_POSE_ALL", "TrackResult", "pose_keys"]

#: too few visible markers (or an empty cloud): the frame holds the previous frame's weights and pose
FLAG_HELD = "held"
#: the rigid markers were not usable (occluded or collinear): the pose was fitted on all visible markers
FLAG_POSE_ALL = "pose_all_markers"


def pose_keys(poses: NDArray[np.float64], times: NDArray[np.float64], translation_tol: float,
              rotation_tol_deg: float) -> Track:
    """A reduced linear ``head_pose`` track through ``(T, 4, 4)`` rigid poses at ``times``.

    Keys are the union of :func:`reduce_keys` over the three translation components
    (tolerance ``translation_tol``, model units) and the four quaternion components
    (``radians(rotation_tol_deg) / 4``, so the rotation between keys stays within about
    ``rotation_tol_deg``); quaternions are kept on one hemisphere so neighbours interpolate
    the short way.
    """
    from scipy.spatial.transform import Rotation

    P = np.asarray(poses, np.float64)
    q = np.asarray(Rotation.from_matrix(P[:, :3, :3]).as_quat(), np.float64)  # (x, y, z, w)
    for f in range(1, q.shape[0]):
        if q[f] @ q[f - 1] < 0:
            q[f] = -q[f]
    values = np.concatenate([P[:, :3, 3], q], axis=1)
    idx = reduce_keys_jointly(times, values, [translation_tol] * 3 + [np.radians(rotation_tol_deg) / 4.0] * 4)
    return Track(HEAD_POSE, tuple(Key(float(times[i]), values[i], "linear") for i in idx))


class TrackError(ValueError):
    """Input that cannot be tracked (wrong shape, wrong units, nothing visible); names the argument.

    Here, with the result, so every tracker (markers, clouds) raises one error type
    without importing :mod:`.track` (which imports them).
    """


class CloudTrackError(TrackError):
    """Point clouds that cannot be tracked (wrong shape, wrong units, nothing usable); names the argument."""


@dataclass(frozen=True, eq=False)
class TrackResult:
    """A tracked take (Bouaziz et al. 2013, §3.1: rigid pose + blendshape weights per frame).

    Attributes
    ----------
    weights : (T, k) float
        Played weights in ``shape_names`` order (the model's at tracking time); derived
        (corrective) shapes hold their drivers' product, muted shapes 0.
    poses : (T, 4, 4) float
        The head pose in the model's frame: ``observed ≈ R (neutral + Σ w δ) + t``.
    errors : (T,) float
        RMS distance between the input and the tracked face (model units); NaN where nothing
        was visible.
    flags : tuple of str
        Per frame: ``""`` when fine, else :data:`FLAG_HELD` (held: too few visible points) or
        :data:`FLAG_POSE_ALL` (pose from all markers).
    fps : float
    shape_names : tuple of str
    derived : tuple of str
        Shapes whose weight follows other shapes (not keyed by :meth:`to_timeline`).
    head_size : float
        The model's :func:`~workbench.capture.rig.head_size` (model units).
    kind : str
        ``"markers"`` or ``"clouds"``.
    info : mapping
        What the tracker used (λ's, rigid markers, iterations…), for reports.
    """

    weights: NDArray[np.float64]
    poses: NDArray[np.float64]
    errors: NDArray[np.float64]
    flags: tuple[str, ...]
    fps: float
    shape_names: tuple[str, ...]
    derived: tuple[str, ...] = ()
    head_size: float = 1.0
    kind: str = "markers"
    info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        W = np.array(self.weights, np.float64)  # copies: the result's arrays are read-only, the caller's stay as they were
        if W.ndim != 2 or W.shape[1] != len(self.shape_names):
            raise ValueError(f"weights must be (T, {len(self.shape_names)}), got {W.shape}")
        T = W.shape[0]
        P = np.array(self.poses, np.float64)
        if P.shape != (T, 4, 4):
            raise ValueError(f"poses must be ({T}, 4, 4), got {P.shape}")
        E = np.array(self.errors, np.float64)
        if E.shape != (T,):
            raise ValueError(f"errors must be ({T},), got {E.shape}")
        if len(self.flags) != T:
            raise ValueError(f"flags must have {T} entries, got {len(self.flags)}")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps must be a positive number, got {self.fps!r}")
        for name, a in (("weights", W), ("poses", P), ("errors", E)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "flags", tuple(str(f) for f in self.flags))
        object.__setattr__(self, "shape_names", tuple(self.shape_names))
        object.__setattr__(self, "derived", tuple(self.derived))

    def __repr__(self) -> str:
        held = int(self.held.sum())
        return (f"TrackResult({self.kind}, {self.n_frames} frames at {self.fps:g} fps, {len(self.shape_names)} shapes, "
                f"median error {np.nanmedian(self.errors) if np.isfinite(self.errors).any() else float('nan'):.3g}"
                f"{f', {held} held' if held else ''})")

    @property
    def n_frames(self) -> int:
        return int(self.weights.shape[0])

    @property
    def held(self) -> NDArray[np.bool_]:
        """(T,) bool: frames that hold the previous frame's values (:data:`FLAG_HELD`)."""
        return np.array([f == FLAG_HELD for f in self.flags], bool)

    def times(self, start: float = 0.0) -> NDArray[np.float64]:
        """(T,) seconds: ``start + f / fps``, or the frames' own timestamps (``info["timestamps"]``,
        a live take's, from its first frame) when the result has them."""
        ts = self.info.get("timestamps") if self.info else None
        if ts is not None and len(ts) == self.n_frames:
            t = np.asarray(ts, np.float64)
            return float(start) + (t - t[0])
        return float(start) + np.arange(self.n_frames) / self.fps

    def to_timeline(self, tolerance: float = 0.01, *, start: float = 0.0, head_pose: bool = True,
                    pose_tolerance: tuple[float, float] | None = None) -> Timeline:
        """A timeline of reduced linear keys: one weight track per non-derived shape, and the head pose.

        Parameters
        ----------
        tolerance : float
            ≥ 0: every frame's weight is reproduced within this (0 keys every frame).
        start : float
            Seconds of frame 0.
        head_pose : bool
            Also key the head pose.
        pose_tolerance : (float, float), optional
            Translation (model units) and rotation (degrees) tolerance of the pose keys;
            default ``(1e-3 · head_size, 0.1)``.
        """
        tol = float(tolerance)
        if not (np.isfinite(tol) and tol >= 0):
            raise ValueError(f"tolerance must be a number ≥ 0, got {tolerance!r}")
        t0 = float(start)
        if not np.isfinite(t0):
            raise ValueError(f"start must be finite seconds, got {start!r}")
        times = self.times(t0)
        derived = set(self.derived)
        cols = [j for j, n in enumerate(self.shape_names) if n not in derived]
        tl = timeline_from_samples(times, self.weights[:, cols], [self.shape_names[j] for j in cols],
                                   fps=self.fps, tolerance=tol)
        if head_pose:
            tt, rt = pose_tolerance if pose_tolerance is not None else (1e-3 * self.head_size, 0.1)
            if not (np.isfinite(tt) and tt >= 0 and np.isfinite(rt) and rt >= 0):
                raise ValueError(f"pose_tolerance must be two numbers ≥ 0, got {pose_tolerance!r}")
            tl = tl.with_track(pose_keys(self.poses, times, float(tt), float(rt)))
        return tl
