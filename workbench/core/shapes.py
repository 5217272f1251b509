"""Blendshapes and metadata: the value objects the face-model state is made of.

:class:`BlendShape` is a named per-vertex displacement with Blender-like
fields (slider range, mute, vertex mask); :class:`ModelMetadata` says how to
read the coordinates (units, axes) and where the model came from. Both are
immutable; the state replaces them as a whole, which keeps undo steps exact.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray


class ModelError(ValueError):
    """An edit or construction argument the model cannot accept."""


def readonly(a: NDArray[Any]) -> NDArray[Any]:
    a.setflags(write=False)
    return a


def owned(a: NDArray[Any]) -> NDArray[Any]:
    """``a`` if it owns its memory, else a read-only copy.

    What undo steps keep goes through this so that a view (one row of the
    model's (k, n, 3) delta stack, a slice of a caller's array) does not keep
    the whole buffer it was cut from alive.
    """
    return a if a.base is None else readonly(a.copy())


def detached_value(value: Any) -> Any:
    """A field value safe to keep in an undo step (arrays own their memory)."""
    return owned(value) if isinstance(value, np.ndarray) else value


@dataclass(frozen=True, eq=False)
class BlendShape:
    """A named blendshape stored as a per-vertex displacement from the neutral.

    Parameters
    ----------
    name : str
        Unique within a model.
    delta : (n, 3) float
        Displacement of every vertex at weight 1 (stored float32, read-only).
    slider_min, slider_max : float
        Allowed weight range (Blender's "Range Min/Max"); weights are clamped to it.
    mute : bool
        A muted shape contributes nothing but keeps its weight.
    vertex_mask : (n,) float or None
        Optional per-vertex factor in [0, 1] (Blender's shape-key vertex group).
    """

    name: str
    delta: NDArray[np.float32]
    slider_min: float = 0.0
    slider_max: float = 1.0
    mute: bool = False
    vertex_mask: NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ModelError(f"blendshape name must be a non-empty string, got {self.name!r}")
        d = np.asarray(self.delta)
        if d.ndim != 2 or d.shape[1] != 3:
            raise ModelError(f"blendshape {self.name!r}: delta must be (n, 3), got {d.shape}")
        d32 = d if (d.dtype == np.float32 and not d.flags.writeable) else d.astype(np.float32)
        if not np.isfinite(d32).all():
            row = int(np.flatnonzero(~np.isfinite(d32).all(axis=1))[0])
            raise ModelError(f"blendshape {self.name!r}: delta has NaN/inf at vertex {row}")
        object.__setattr__(self, "delta", readonly(d32))
        lo, hi = float(self.slider_min), float(self.slider_max)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ModelError(
                f"blendshape {self.name!r}: need finite slider_min < slider_max, got {lo}, {hi}"
            )
        object.__setattr__(self, "slider_min", lo)
        object.__setattr__(self, "slider_max", hi)
        object.__setattr__(self, "mute", bool(self.mute))
        if self.vertex_mask is not None:
            m = np.asarray(self.vertex_mask, dtype=np.float32).reshape(-1)
            if m.shape[0] != d32.shape[0]:
                raise ModelError(
                    f"blendshape {self.name!r}: vertex_mask has {m.shape[0]} values, "
                    f"expected one per vertex ({d32.shape[0]})"
                )
            if not (np.isfinite(m).all() and m.min() >= 0.0 and m.max() <= 1.0):
                raise ModelError(f"blendshape {self.name!r}: vertex_mask values must be in [0, 1]")
            object.__setattr__(self, "vertex_mask", readonly(m))

    def replace(self, **changes: Any) -> BlendShape:
        """A copy with some fields changed (arrays are shared, not copied)."""
        return dataclasses.replace(self, **changes)

    def effective_delta(self) -> NDArray[np.float32]:
        """(n, 3) float32: the delta with the vertex mask applied."""
        if self.vertex_mask is None:
            return self.delta
        return self.delta * self.vertex_mask[:, None]


def detached_shape(shape: BlendShape) -> BlendShape:
    """``shape`` with a delta (n, 3) and mask (n,) that own their memory (for undo steps)."""
    mask = shape.vertex_mask
    return shape.replace(delta=owned(shape.delta), vertex_mask=None if mask is None else owned(mask))


@dataclass(frozen=True)
class ModelMetadata:
    """Where the model came from and how to read its coordinates.

    ``units`` is a length unit name ("m", "cm", "dm", "mm", "in"); ``up_axis`` and
    ``front_axis`` are signed axis names ("+y", "+z"): the face looks toward
    ``front_axis``. "Left" in shape names always means the subject's left.
    """

    name: str = ""
    units: str = "m"
    up_axis: str = "+y"
    front_axis: str = "+z"
    provenance: tuple[Mapping[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if self.units not in UNIT_TO_METRES:
            raise ModelError(f"metadata.units must be one of {sorted(UNIT_TO_METRES)}, got {self.units!r}")
        for ax_name in ("up_axis", "front_axis"):
            ax = getattr(self, ax_name)
            if ax not in AXES:
                raise ModelError(f"metadata.{ax_name} must be one of {AXES}, got {ax!r}")
        object.__setattr__(
            self, "provenance", tuple(MappingProxyType(dict(p)) for p in self.provenance)
        )

    @property
    def metres_per_unit(self) -> float:
        return UNIT_TO_METRES[self.units]

    def with_provenance(self, entry: Mapping[str, Any]) -> ModelMetadata:
        return dataclasses.replace(self, provenance=(*self.provenance, entry))

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "units": self.units,
            "up_axis": self.up_axis,
            "front_axis": self.front_axis,
            "provenance": [dict(p) for p in self.provenance],
        }


UNIT_TO_METRES = {"m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001, "in": 0.0254}
AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
