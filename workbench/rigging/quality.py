"""How good the transferred shapes are: stretch, flipped and newly self-intersecting triangles, beside the template's.

The template's own shapes are measured once at set-up, on the template skin;
each transfer measures its shapes on the target skin, so the report can show a
shape that was already rough on the template apart from one the transfer
broke. Self-intersections (:mod:`.intersections`) are counted only with numba:
the numpy path takes ~0.5 s per shape on a 20k-vertex face.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.core.shapes import BlendShape
from workbench.rigging.report import ShapeQuality, StretchMeter
from workbench.rigging.sides import Side

if TYPE_CHECKING:
    from workbench.rigging.intersections import SelfIntersections

__all__ = ["NO_NUMBA_WARNING", "TransferQuality"]

#: in the report's warnings without numba, so a 0 in its table is not read as "none"
NO_NUMBA_WARNING = "self-intersections not checked: numba is not installed (pip install 'face-workbench[fast]')"


class TransferQuality:
    """Per-shape quality of a transfer; measures the template's shapes when built.

    Parameters
    ----------
    src : Side
        The template in the working frame.
    tgt : Side
        The target in the working frame.
    t_good : (m_t,) bool
        The target's usable skin triangles (the ones measured).
    """

    def __init__(self, src: Side, tgt: Side, t_good: NDArray[np.bool_]) -> None:
        from workbench.rigging.intersections import NUMBA, SelfIntersections

        self._numba = NUMBA
        self.src, self.tgt = src, tgt
        self.faces = tgt.skin_faces[t_good]
        self._crossing: SelfIntersections | None = None  # the target's rest pose, built on first use
        meter = StretchMeter(src.skin_X, src.skin_faces)
        crossing = SelfIntersections(src.skin_X, src.skin_faces) if NUMBA else None
        lin = src.frame.scale * src.frame.R
        #: (max stretch, flipped, new self-intersecting triangles) of every template shape
        self.source: list[tuple[float, int, int]] = []
        for s in src.model.shapes:
            d = s.delta[src.skin_ids].astype(np.float64) @ lin.T
            mx, _, fl, _ = meter.shape_quality(d)
            self.source.append((mx, fl, 0 if crossing is None else crossing.count_new(d)))

    def shapes(self, shapes: Sequence[BlendShape], work: NDArray[np.float64], warnings: list[str]
               ) -> list[ShapeQuality]:
        """Quality of transferred shapes ``work`` (k, n_target_skin, 3), working frame, in the template's order.

        Adds :data:`NO_NUMBA_WARNING` to ``warnings`` (once) when intersections cannot be counted.
        """
        from workbench.rigging.intersections import SelfIntersections

        meter = StretchMeter(self.tgt.skin_X, self.faces)
        if self._crossing is None and self._numba:
            self._crossing = SelfIntersections(self.tgt.skin_X, self.faces)
        elif self._crossing is None and NO_NUMBA_WARNING not in warnings:
            warnings.append(NO_NUMBA_WARNING)
        out = []
        for i, s in enumerate(shapes):
            mx, med, fl, moved = meter.shape_quality(work[i])
            smx, sfl, sx = self.source[i]
            out.append(ShapeQuality(name=s.name, max_stretch=mx, median_stretch=med, flipped=fl,
                                    source_max_stretch=smx, source_flipped=sfl, moved=moved,
                                    intersecting=0 if self._crossing is None else self._crossing.count_new(work[i]),
                                    source_intersecting=sx, triangles=int(self.faces.shape[0]),
                                    source_triangles=int(self.src.skin_faces.shape[0])))
        return out
