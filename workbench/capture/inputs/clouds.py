"""Point clouds per frame, without correspondences: :class:`PointCloudSequence`.

What :func:`~workbench.capture.inputs.cloud_files.read_point_clouds` and
:func:`~workbench.capture.inputs.depth.read_depth_frames` return: frames of
possibly different sizes, in metres, with optional unit normals. A folder's
frame files are sorted *naturally* (``f2`` before ``f10``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.io.units import unit_name

__all__ = ["PointCloudSequence"]


@dataclass(frozen=True)
class PointCloudSequence:
    """Point clouds per frame, without correspondences.

    Attributes
    ----------
    frames : tuple of (p_t, 3) float64
        Points of each frame in **metres**, finite, read-only; ``p_t`` may differ
        between frames (and be 0 for an empty frame).
    fps : float
        Frames per second.
    units : str
        The unit the data were in ("mm", "m", ...); positions are in metres.
    normals : tuple of (p_t, 3) float64 or None
        Unit normals per point (zero where the file's normal was zero), or None.
    labels : tuple of str
        What each frame was read from (file names), or empty.
    source : str
        The file or folder read.
    first_frame : int
        Number of the first frame.
    """

    frames: tuple[NDArray[np.float64], ...]
    fps: float
    units: str
    normals: tuple[NDArray[np.float64], ...] | None = None
    labels: tuple[str, ...] = ()
    source: str = ""
    first_frame: int = 0

    def __post_init__(self) -> None:
        frames = []
        for t, f in enumerate(self.frames):
            F = np.array(f, dtype=np.float64)
            if F.shape == (0,):
                F = F.reshape(0, 3)
            if F.ndim != 2 or F.shape[1] != 3:
                raise ValueError(f"PointCloudSequence: frame {t} must be (p, 3), got {F.shape}")
            if not np.isfinite(F).all():
                raise ValueError(f"PointCloudSequence: frame {t} has non-finite points")
            F.setflags(write=False)
            frames.append(F)
        object.__setattr__(self, "frames", tuple(frames))
        if self.normals is not None:
            if len(self.normals) != len(frames):
                raise ValueError(
                    f"PointCloudSequence: {len(self.normals)} normal sets for {len(frames)} frames"
                )
            ns = []
            for t, (n, F) in enumerate(zip(self.normals, frames, strict=True)):
                N = np.array(n, np.float64)
                if N.shape == (0,):
                    N = N.reshape(0, 3)
                if N.shape != F.shape or not np.isfinite(N).all():
                    raise ValueError(
                        f"PointCloudSequence: frame {t} normals must be finite {F.shape}, got {N.shape}"
                    )
                N.setflags(write=False)
                ns.append(N)
            object.__setattr__(self, "normals", tuple(ns))
        if self.labels and len(self.labels) != len(frames):
            raise ValueError(
                f"PointCloudSequence: {len(self.labels)} labels for {len(frames)} frames"
            )
        object.__setattr__(self, "labels", tuple(self.labels))
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"PointCloudSequence: fps must be > 0, got {self.fps!r}")
        object.__setattr__(self, "units", unit_name(self.units))

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def counts(self) -> NDArray[np.int64]:
        """(T,) points per frame."""
        return np.array([f.shape[0] for f in self.frames], np.int64)

    @property
    def empty(self) -> NDArray[np.bool_]:
        """(T,) True where a frame has no points."""
        return np.asarray(self.counts == 0)

    @property
    def times(self) -> NDArray[np.float64]:
        """(T,) seconds from the first frame."""
        return np.arange(self.n_frames, dtype=np.float64) / self.fps


def _natural_key(name: str) -> tuple[tuple[int, int, str], ...]:
    return tuple(
        (0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", name.lower()) if t
    )
