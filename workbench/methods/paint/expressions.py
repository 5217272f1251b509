"""Expressions as first-class items (Pighin et al. 1998, §4 inside the SIGGRAPH 2006 course).

An *expression* is a whole-face state the user can name, see in the gallery,
paint with, and key on the timeline. Two kinds exist side by side:

* every blendshape is an expression by itself (its delta at weight 1);
* :class:`Expression` objects saved from any state of the model: the recipe
  (weights and handle offsets, for re-editing) and the resulting displacement
  from the neutral, ``(n, 3)`` float32, which is what painting blends.

The library lives in the model's ``expressions`` slot (undoable, evented).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.core.shapes import ModelError

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState


@dataclass(frozen=True, eq=False)
class Expression:
    """A saved face state.

    Parameters
    ----------
    name : str
    displacement : (n, 3) float32
        Evaluated mesh minus the neutral when the expression was saved.
    weights : mapping
        Blendshape weights at save time (the recipe).
    handle_vertices : (h,) int
    handle_offsets : (h, 3) float32
        The handle layer at save time.
    """

    name: str
    displacement: NDArray[np.float32]
    weights: Mapping[str, float] = field(default_factory=dict)
    handle_vertices: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, np.int32))
    handle_offsets: NDArray[np.float32] = field(default_factory=lambda: np.zeros((0, 3), np.float32))

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ModelError(f"expression name must be a non-empty string, got {self.name!r}")
        d = np.array(self.displacement, dtype=np.float32)
        if d.ndim != 2 or d.shape[1] != 3 or not np.isfinite(d).all():
            raise ModelError(f"expression {self.name!r}: displacement must be a finite (n, 3) array")
        d.setflags(write=False)
        object.__setattr__(self, "displacement", d)
        object.__setattr__(self, "weights", MappingProxyType({k: float(v) for k, v in self.weights.items()}))
        hv = np.array(self.handle_vertices, dtype=np.int32).reshape(-1)
        ho = np.array(self.handle_offsets, dtype=np.float32).reshape(-1, 3)
        hv.setflags(write=False)
        ho.setflags(write=False)
        object.__setattr__(self, "handle_vertices", hv)
        object.__setattr__(self, "handle_offsets", ho)


def expression_names(state: FaceState | StateView) -> list[str]:
    """Every expression the palette offers: saved expressions first, then the blendshapes."""
    saved = list(state.slot("expressions"))
    return saved + [n for n in state.shape_names if n not in saved]


def expression_displacement(state: FaceState | StateView, name: str) -> NDArray[np.float32]:
    """(n, 3) float32 displacement from the neutral of expression ``name`` (read-only).

    ``state`` is the model or a pipeline view: a saved expression's displacement,
    else the blendshape's delta with its vertex mask.
    """
    lib = state.slot("expressions")
    if name in lib:
        return lib[name].displacement
    names = state.shape_names
    if name in names:
        return state.effective_deltas[names.index(name)]
    raise KeyError(
        f"no expression named {name!r}; saved expressions: {list(lib)}, "
        f"and the {len(names)} blendshapes"
    )


def expressions_to_json(expressions: Mapping[str, Expression]) -> list[dict[str, Any]]:
    """Manifest entries (arrays are stored separately by the file format)."""
    return [
        {"name": e.name, "weights": dict(e.weights), "n_handles": int(e.handle_vertices.size)}
        for e in expressions.values()
    ]
