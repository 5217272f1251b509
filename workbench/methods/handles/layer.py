"""The handle-editing layer of a FaceModel: shell deformation of the handle offsets.

The model's handles (:class:`workbench.model.HandleSet`) carry offsets that sit
*on top of* the current blendshape expression. This layer turns them into a
smooth displacement of the whole face with a :class:`~workbench.methods.handles.shell.ShellDeformer`
built on the neutral mesh, and caches it:

* the basis is rebuilt only when the handle *vertex set* or the stiffness
  changes (offsets alone never trigger a precompute);
* when one or a few handles moved since the last evaluation, the displacement
  is updated by rank-1 column updates instead of the full ``B @ u_H`` product.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.methods.handles.shell import DEFAULT_K_B, DEFAULT_K_S, ShellDeformer

if TYPE_CHECKING:
    from workbench.model import FaceModel

#: more changed handles than this since the last evaluation -> full product
_RANK1_LIMIT = 4


class HandleLayer:
    """Callable displacement layer ``layer(model) -> (n, 3) float32 | None``.

    Parameters
    ----------
    k_s, k_b : float
        Shell stiffness (see :mod:`workbench.methods.handles.shell`).
    progress : callable, optional
        ``progress(fraction, message)`` during basis precomputes.
    """

    def __init__(
        self,
        k_s: float = DEFAULT_K_S,
        k_b: float = DEFAULT_K_B,
        progress: Callable[[float, str], None] | None = None,
    ) -> None:
        self.k_s = k_s
        self.k_b = k_b
        self.progress = progress
        self._lock = threading.Lock()
        self._deformer: ShellDeformer | None = None
        self._key: tuple[bytes, float, float] | None = None
        self._offsets: NDArray[np.float32] | None = None

    def deformer(self, model: FaceModel) -> ShellDeformer:
        """The shell deformer for the model's current handle vertices (built on demand)."""
        h = model.handles
        key = (h.vertices.tobytes(), self.k_s, self.k_b)
        with self._lock:
            if self._deformer is None or self._key != key:
                self._deformer = ShellDeformer(
                    model.vertices,
                    model.faces,
                    h.vertices,
                    self.k_s,
                    self.k_b,
                    component_labels=model.component_labels,
                    component_names=model.component_names,
                    progress=self.progress,
                )
                self._key = key
                self._offsets = None
            return self._deformer

    def __call__(self, model: FaceModel) -> NDArray[np.float32] | None:
        h = model.handles
        if len(h) == 0 or not np.any(h.offsets):
            return None
        d = self.deformer(model)
        with self._lock:
            prev = self._offsets
            if prev is not None and prev.shape == h.offsets.shape:
                moved = np.flatnonzero(np.any(prev != h.offsets, axis=1))
                if moved.size <= _RANK1_LIMIT:
                    for j in moved:
                        d.update(int(j), h.offsets[j])
                    self._offsets = h.offsets
                    return d.current_displacement
            d.reset(h.offsets)
            self._offsets = h.offsets
            return d.current_displacement
