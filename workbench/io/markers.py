"""Motion-capture marker tracks: :class:`MarkerSequence` (what :func:`workbench.io.c3d.read_markers` returns).

Markers are not a face, so they are not in the face registry: the capture step
reads them on their own and fits a face to them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["MarkerSequence"]


@dataclass(frozen=True)
class MarkerSequence:
    """Labelled 3-D marker positions per frame.

    Attributes
    ----------
    names : tuple of str
        Marker labels, one per column (as in the file, whitespace stripped).
    positions : (F, m, 3) float64
        Positions in **metres** (the file's unit converted); NaN where the
        marker is missing in that frame (a gap: C3D residual < 0).
    fps : float
        Frames per second.
    units : str
        The unit the file stated (C3D ``POINT:UNITS``, e.g. "mm").
    first_frame : int
        Number of the first frame in the file (C3D counts from 1).
    source : str
        The file read.
    """

    names: tuple[str, ...]
    positions: NDArray[np.float64]
    fps: float
    units: str
    first_frame: int = 1
    source: str = ""

    def __post_init__(self) -> None:
        P = np.asarray(self.positions, np.float64)
        if P.ndim != 3 or P.shape[2] != 3 or P.shape[1] != len(self.names):
            raise ValueError(
                f"MarkerSequence: positions must be (frames, {len(self.names)}, 3), got {P.shape}"
            )
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"MarkerSequence: fps must be > 0, got {self.fps!r}")
        P.setflags(write=False)
        object.__setattr__(self, "positions", P)
        object.__setattr__(self, "names", tuple(self.names))

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_markers(self) -> int:
        return int(self.positions.shape[1])

    @property
    def times(self) -> NDArray[np.float64]:
        """(F,) seconds from the first frame."""
        return np.arange(self.n_frames, dtype=np.float64) / self.fps

    @property
    def gaps(self) -> NDArray[np.bool_]:
        """(F, m) True where a marker is missing."""
        return np.asarray(~np.isfinite(self.positions).all(axis=2), dtype=bool)

    def marker(self, name: str) -> NDArray[np.float64]:
        """(F, 3) track of one marker (the first with that label)."""
        try:
            j = self.names.index(name)
        except ValueError:
            raise KeyError(f"no marker {name!r}; markers: {list(self.names)[:10]}") from None
        return self.positions[:, j]
