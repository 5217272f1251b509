"""Enhanced frames at the database's resolution, as a face that every exporter writes.

:class:`EnhancedTake` holds what :meth:`workbench.enhance.facet.EnhanceFacet.enhance_timeline`
made: frames (T, n, 3) on the database's mesh at the timeline's frame times.
:meth:`EnhancedTake.to_model` turns them into a point-cache face — frame 0 the
neutral, every later frame a shape ``frame_NNNN`` keyed to 1 at its time and 0
at its neighbours' (the layout :mod:`workbench.io.alembic` reads) — so
:func:`workbench.export.export` writes baked PC2, MDD, OBJ sequences, Alembic,
glTF (a morph target per frame) and USD, each reproducing every frame exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from workbench.animation.tracks import Timeline
    from workbench.core.shapes import ModelMetadata
    from workbench.model import FaceModel

__all__ = ["EnhancedTake"]


@dataclass
class EnhancedTake:
    """Enhanced frames of an animation.

    Attributes
    ----------
    frames : (T, n, 3) float64
        On the database's mesh, in model units (head pose applied).
    times : (T,) float64
        Seconds.
    faces : (m, 3) int64
    weights : (T, R, D) float64
        Matched database weights per frame and region.
    fps : float
    metres_per_unit : float
    metadata : ModelMetadata
        The source model's (units, axes).
    name : str
    """

    frames: NDArray[np.float64]
    times: NDArray[np.float64]
    faces: NDArray[np.int64]
    weights: NDArray[np.float64]
    fps: float
    metres_per_unit: float
    metadata: ModelMetadata
    name: str = "face"

    def timeline(self) -> Timeline:
        """Linear keys that replay every frame exactly (shape ``frame_k`` is 1 at frame k only)."""
        from workbench.animation.baked_frames import baked_frames_timeline

        return baked_frames_timeline(self.times, self.fps)

    def to_model(self) -> FaceModel:
        """A face on the database's mesh that plays the enhanced frames on its timeline."""
        from workbench.animation.baked_frames import baked_frames_model

        return baked_frames_model(self.frames, self.faces, self.times, self.fps, metadata=self.metadata,
                                  what="Enhanced frames")

    def export(self, path: str | Path, *, format: str | None = None, **options: Any) -> Any:
        """Write the enhanced frames with :func:`workbench.export.export` (any format); returns its result."""
        from workbench.export import export

        model = self.to_model()
        return export(model, model.timeline.value, path, format=format, **options)
