"""Baked frames as a face: frame 0 the neutral, every later frame a shape keyed on the timeline.

The layout point caches are read into (:mod:`workbench.io.alembic`) and that
enhanced takes and cloned performances are written from: shape ``frame_k``
holds frame k minus frame 0 and is keyed 1 at frame k's time and 0 at its
neighbours' (linear keys), so the timeline reproduces every frame exactly and
:func:`workbench.export.export` writes PC2, MDD, OBJ sequences, Alembic, glTF
(a morph target per frame) and USD from it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import Key, Track, weight_track_name
from workbench.animation.tracks import Timeline

if TYPE_CHECKING:
    from workbench.core.shapes import ModelMetadata
    from workbench.model import FaceModel

__all__ = ["baked_frames_model", "baked_frames_timeline", "frame_shape_name"]


def frame_shape_name(k: int) -> str:
    """The shape holding frame ``k`` of baked frames: ``frame_0001``."""
    return f"frame_{k:04d}"


def baked_frames_timeline(times: ArrayLike, fps: float) -> Timeline:
    """Linear keys that replay every frame at ``times`` (seconds) exactly: ``frame_k`` is 1 at frame k only."""
    t = np.asarray(times, np.float64).reshape(-1)
    tracks = {}
    for k in range(1, t.size):
        keys = [Key(float(t[k - 1]), 0.0, "linear"), Key(float(t[k]), 1.0, "linear")]
        if k + 1 < t.size:
            keys.append(Key(float(t[k + 1]), 0.0, "linear"))
        name = weight_track_name(frame_shape_name(k))
        tracks[name] = Track(name, tuple(keys))
    return Timeline(fps=fps, tracks=tracks).fit_range()


def baked_frames_model(frames: NDArray[np.float64], faces: ArrayLike | None, times: ArrayLike, fps: float, *,
                       metadata: ModelMetadata | None = None, component_labels: ArrayLike | None = None,
                       component_names: list[str] | None = None, what: str = "Baked frames",
                       like: Any = None) -> FaceModel:
    """A face whose neutral is ``frames[0]`` and whose timeline plays ``frames`` ((T, n, 3)) at ``times``.

    ``what`` names the timeline's undo step. ``like``: a model on the same mesh whose faces,
    metadata and parts the new face keeps (``faces`` None); the explicit arguments win.
    """
    from workbench.core.shapes import BlendShape
    from workbench.model import FaceModel

    if like is not None:
        faces = like.faces if faces is None else faces
        metadata = like.metadata if metadata is None else metadata
        if component_labels is None:
            component_labels, component_names = like.component_labels, list(like.component_names)
    if faces is None:
        raise ValueError("baked_frames_model: give the faces, or a model on the same mesh as like=")

    base = frames[0]
    shapes = [BlendShape(frame_shape_name(k), (frames[k] - base).astype(np.float32)) for k in range(1, len(frames))]
    kw: dict[str, Any] = {} if component_labels is None else {"component_labels": component_labels,
                                               "component_names": component_names}
    model = FaceModel(base, faces, shapes, metadata=metadata, **kw)
    if len(frames) > 1:
        model.timeline.set(baked_frames_timeline(times, fps), what)
    return model
