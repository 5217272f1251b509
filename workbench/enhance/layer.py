"""The *Enhanced* preview: spatial enhancement (§5) as the last layer of the evaluation pipeline.

The model's ``enhancement`` slot holds an :class:`EnhancementState` (a
:class:`~workbench.enhance.database.PerformanceDatabase`, the
:class:`~workbench.enhance.spatial.Correspondence` from the model's mesh to the
database's, and whether the preview is on). When it is on, the layer takes the
mesh below it (blend, regions, handles, paint, wrinkles), maps it onto the
database's mesh, enhances it and maps the result back
(:meth:`Correspondence.restrict`): the displacement is ``R (x − ā)``, the detail
the database adds, seen at the model's vertices. Every exporter bakes it per
frame like any nonlinear layer (PC2, MDD, OBJ sequences, Alembic, baked glTF
and USD frames); the full-resolution frames come from
:meth:`workbench.enhance.facet.EnhanceFacet.enhance_timeline`.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.core.shapes import ModelError

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState
    from workbench.enhance.database import PerformanceDatabase
    from workbench.enhance.spatial import Correspondence

__all__ = ["EnhanceLayer", "EnhancementState", "check_state"]


@dataclass(frozen=True, eq=False)
class EnhancementState:
    """What the ``enhancement`` slot holds (immutable: edits make a new one, so each is one undo step).

    Attributes
    ----------
    database : PerformanceDatabase or None
    correspondence : Correspondence or None
        Model mesh → database mesh (None: none set).
    enabled : bool
        The *Enhanced* preview is on.
    source : str
        Where the database came from (a file path, ``"sample performance"``), for panels.
    """

    database: PerformanceDatabase | None = None
    correspondence: Correspondence | None = None
    enabled: bool = False
    source: str = ""

    def replace(self, **changes: Any) -> EnhancementState:
        return dataclasses.replace(self, **changes)

    @property
    def ready(self) -> bool:
        return self.database is not None and self.correspondence is not None


def check_state(model: FaceState, value: Any) -> EnhancementState:
    """Validate a new slot value: a database whose correspondence fits the model's mesh."""
    if not isinstance(value, EnhancementState):
        raise ModelError(f"enhancement must be an EnhancementState, got {type(value).__name__}")
    if value.database is None:
        if value.enabled:
            raise ModelError("enhancement: the Enhanced preview needs a database (model.enhance.set_database)")
        return value
    corr = value.correspondence
    if corr is None:
        raise ModelError("enhancement: a database needs a correspondence from the model's mesh")
    n_db = value.database.neutral_.shape[0]
    if corr.n_in != model.n_vertices or corr.n_out != n_db:
        raise ModelError(
            f"enhancement: the correspondence maps {corr.n_in} → {corr.n_out} vertices, but the model has "
            f"{model.n_vertices} and the database {n_db}"
        )
    if corr.restriction is None:
        raise ModelError("enhancement: the correspondence has no map back to the model's mesh (for the preview)")
    return value


class EnhanceLayer:
    """Pipeline layer ``"enhance"``: reads the ``enhancement`` slot; silent unless the preview is on."""

    name = "enhance"
    reads = ("enhancement",)
    linear = False

    def __init__(self) -> None:
        # one database solve at a time (the factorizations are shared by every caller)
        self._lock = threading.Lock()

    def active(self, view: StateView) -> bool:
        st: EnhancementState = view.slot("enhancement")
        return st.enabled and st.ready

    def displacement(self, view: StateView, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        st: EnhancementState = view.slot("enhancement")
        if not (st.enabled and st.ready):
            return None
        assert st.database is not None and st.correspondence is not None
        corr = st.correspondence
        with self._lock:
            res = st.database.enhance_result(np.asarray(below, np.float64)[None], correspondence=corr)
        return corr.restrict(res.frames[0] - res.inputs[0]).astype(np.float32)
