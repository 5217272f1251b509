"""The handle-editing layer: shell deformation of the handle offsets (Bickel et al. 2008, §4).

The handles' offsets sit on top of the mesh below (the expression). A
:class:`~workbench.methods.handles.shell.ShellDeformer` built on the neutral
turns them into a smooth displacement of the whole face:

* the basis is rebuilt only when the handle *vertex set* or the stiffness
  changes (offsets alone never trigger a precompute);
* during a drag (``view.interacting``) one or a few moved handles update the
  displacement by rank-1 column updates; outside a drag it is the full
  ``B @ u_H`` product, so the settled result depends only on the offsets
  (``evaluate`` and ``evaluate_at`` agree bit for bit).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.core.linear import Controls, LinearTerms
from workbench.geometry.parts import model_part_roles
from workbench.methods.handles.facet import HANDLES_TRACK
from workbench.methods.handles.shell import ShellDeformer

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView

#: more changed handles than this since the last evaluation -> full product
_RANK1_LIMIT = 4


class HandleLayer:
    """Pipeline layer ``"handles"``: reads the ``handles`` and ``shell_stiffness`` slots."""

    name = "handles"
    reads = ("handles", "shell_stiffness")
    linear = True
    uses_below = False

    def __init__(self) -> None:
        self.progress: Callable[[float, str], None] | None = None
        self._lock = threading.Lock()
        self._deformer: ShellDeformer | None = None
        self._key: tuple[bytes, float, float] | None = None
        self._offsets: NDArray[np.float32] | None = None

    def deformer(self, view: StateView) -> ShellDeformer:
        """The shell deformer for the view's handle vertices and stiffness (built on demand)."""
        h = view.slot("handles")
        k_s, k_b = view.slot("shell_stiffness")
        key = (h.vertices.tobytes(), k_s, k_b)
        with self._lock:
            if self._deformer is None or self._key != key:
                self._deformer = ShellDeformer(
                    view.vertices, view.faces, h.vertices, k_s, k_b,
                    component_labels=view.component_labels,
                    component_names=view.component_names,
                    component_roles=model_part_roles(view),
                    progress=self.progress,
                )
                self._key = key
                self._offsets = None
            return self._deformer

    def displacement(self, view: StateView, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        h = view.slot("handles")
        if len(h) == 0 or not np.any(h.offsets):
            return None
        d = self.deformer(view)
        with self._lock:
            prev = self._offsets
            if view.interacting and prev is not None and prev.shape == h.offsets.shape:
                moved = np.flatnonzero(np.any(prev != h.offsets, axis=1))
                if moved.size <= _RANK1_LIMIT:
                    for j in moved:
                        d.update(int(j), h.offsets[j])
                    self._offsets = h.offsets
                    return np.array(d.current_displacement)
            out = np.asarray(d.displacement(h.offsets), np.float32)
            if view.interacting:
                d.reset(h.offsets)
                self._offsets = h.offsets
            else:
                self._offsets = None  # the deformer's running state is not the settled one
            return out

    # -- linear description (workbench.core.linear): d = B u, linear in the offsets
    def gain(self, view: StateView) -> None:
        return None  # it adds to the mesh below and keeps all of it

    def controls(self, view: StateView, timeline: Any) -> Controls | None:
        """The handle offsets (keyed by the timeline's ``"handles"`` track); None without handles."""
        h = view.slot("handles")
        if len(h) == 0:
            return None
        H = len(h)

        def apply(o: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.asarray(self.deformer(view).displacement(np.asarray(o).reshape(H, 3)), np.float64)

        track = None if timeline is None else timeline.tracks.get(HANDLES_TRACK)
        return Controls(np.asarray(h.offsets, np.float64), track, apply, f"{H} handles", prefix="handle")

    def control_basis(self, view: StateView) -> tuple[Any, NDArray[np.float32], NDArray[np.int64]]:
        """``(key, B, columns)``: the shell basis (n, P) and each handle's column (for the GPU path)."""
        h = view.slot("handles")
        d = self.deformer(view)
        B = d.basis_.view()
        B.flags.writeable = False
        return (h.vertices.tobytes(), tuple(view.slot("shell_stiffness"))), B, d.handle_columns

    def linear_terms(self, view: StateView, timeline: Any) -> LinearTerms:
        c = self.controls(view, timeline)
        if c is None:
            return LinearTerms(detail="no handles")
        return LinearTerms(controls=c, detail=c.label)
