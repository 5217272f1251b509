"""The paint layer: ``sum_e W_e (D_e - D_below)`` (Pighin et al. 1998 §4.2; see :mod:`.painting`).

``D_below`` is the displacement of the mesh it is handed (blend, region
correction and handle shell), so the painted remainder ``1 - sum_e W_e`` keeps
whatever the layers below make. While the mesh below and the expressions stay
the same objects (a brush stroke), only the rows whose paint changed are
recomputed; each row is computed by the same float32 operations either way.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.core.linear import LinearTerms
from workbench.methods.paint.expressions import expression_displacement

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView


class PaintLayer:
    """Pipeline layer ``"paint"``: reads the ``paint_layers`` and ``expressions`` slots."""

    name = "paint"
    reads = ("paint_layers", "expressions")
    linear = True

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._below: NDArray[np.float32] | None = None
        self._expressions: object = None
        self._base: NDArray[np.float32] | None = None
        self._cache: NDArray[np.float32] | None = None
        self._maps: dict[str, NDArray[np.float32]] = {}

    @staticmethod
    def _rows(view: StateView, maps: Mapping[str, NDArray[np.float32]], base: NDArray[np.float32],
              ids: NDArray[np.int64] | slice) -> NDArray[np.float32]:
        out = np.zeros_like(base[ids])
        for name, w in maps.items():
            out += w[ids, None] * (expression_displacement(view, name)[ids] - base[ids])
        return out

    def _changed(self, maps: Mapping[str, NDArray[np.float32]], n: int) -> NDArray[np.int64] | None:
        """Vertices whose weights differ from the cached maps (None: too many or other maps)."""
        if set(maps) != set(self._maps):
            return None
        changed = np.zeros(n, bool)
        for name, new in maps.items():
            old = self._maps[name]
            if new is not old:
                changed |= new != old
        ids = np.flatnonzero(changed)
        return ids if ids.size < n // 3 else None

    def displacement(self, view: StateView, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        mix = view.slot("paint_layers")
        if not len(mix):
            return None
        exprs = view.slot("expressions")
        with self._lock:
            ids = None
            if below is self._below and exprs is self._expressions and self._cache is not None:
                ids = self._changed(mix.maps, view.n_vertices)
            if ids is None or self._base is None or self._cache is None:
                self._base = below - view.vertices32
                self._cache = self._rows(view, mix.maps, self._base, slice(None))
            elif ids.size:
                cache = self._cache.copy()  # returned arrays are frozen by the pipeline
                cache[ids] = self._rows(view, mix.maps, self._base, ids)
                self._cache = cache
            self._below, self._expressions, self._maps = below, exprs, dict(mix.maps)
            return self._cache

    # -- linear description (workbench.core.linear): below + d = neutral + (1 − P)(below − neutral) + C_P
    def gain(self, view: StateView) -> NDArray[np.float64] | None:
        """``1 − P``, ``P = Σ_e W_e`` the painted weight (None when nothing is painted)."""
        mix = view.slot("paint_layers")
        if not len(mix):
            return None
        paint = np.zeros(view.n_vertices, np.float64)
        for w in mix.maps.values():
            paint += np.asarray(w, np.float64)
        return 1.0 - paint

    def controls(self, view: StateView, timeline: Any) -> None:
        return None

    def linear_terms(self, view: StateView, timeline: Any) -> LinearTerms:
        """Gain ``1 − P`` and the constant ``C_P = Σ_e W_e D_e``."""
        mix = view.slot("paint_layers")
        if not len(mix):
            return LinearTerms(detail="nothing painted")
        n = view.n_vertices
        paint = np.zeros(n, np.float64)
        const = np.zeros((n, 3), np.float64)
        for name, w in mix.maps.items():
            w64 = np.asarray(w, np.float64)
            paint += w64
            const += w64[:, None] * expression_displacement(view, name).astype(np.float64)
        return LinearTerms(gain=1.0 - paint, constant=const,
                           detail=f"{len(mix)} painted expressions on {int(np.count_nonzero(paint))} vertices: "
                                  "constant target + shape and handle targets scaled by (1 - painted weight)")
