"""The handle set: which vertices are handles, their offsets, names and mirror partners."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from workbench.core.shapes import ModelError, readonly


@dataclass(frozen=True, eq=False)
class HandleSet:
    """Handle vertices for shell editing (filled by the handle-editing tool).

    Parameters
    ----------
    vertices : (h,) int
        Vertex ids of the handles, in handle order.
    offsets : (h, 3) float
        Displacement of each handle on top of the current blend (the edit layer).
    names : tuple of str
        One label per handle.
    mirror : (h,) int
        Index of the mirror handle, or -1.
    """

    vertices: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, np.int32))
    offsets: NDArray[np.float32] = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    names: tuple[str, ...] = ()
    mirror: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, np.int32))

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.int32).reshape(-1)
        o = np.asarray(self.offsets, dtype=np.float32).reshape(-1, 3)
        mi = np.asarray(self.mirror, dtype=np.int32).reshape(-1)
        if mi.size == 0:
            mi = np.full(v.size, -1, np.int32)
        if o.shape[0] == 0:
            o = np.zeros((v.size, 3), np.float32)
        names = tuple(self.names) or tuple(f"h{i}" for i in range(v.size))
        if not (o.shape[0] == v.size == mi.size == len(names)):
            raise ModelError(
                "handles: vertices, offsets, names and mirror need one entry per handle, got "
                f"{v.size}, {o.shape[0]}, {len(names)}, {mi.size}"
            )
        for name, arr in (("vertices", v), ("offsets", o), ("mirror", mi)):
            object.__setattr__(self, name, readonly(arr))
        object.__setattr__(self, "names", names)

    def __len__(self) -> int:
        return int(self.vertices.size)

