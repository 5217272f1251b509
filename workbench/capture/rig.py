"""The model's expression space as the tracker sees it: ``neutral + Σ w_i δ_i``, the unknowns, the head size.

Tracking (Bouaziz et al. 2013, §2–3) fits ``F(x) = b_0 + ΔB x`` to the input. On
a :class:`~workbench.model.FaceModel` that is the blend stage of
``model.evaluate()``: the neutral ``model.vertices`` plus the shapes'
``effective_deltas`` (vertex masks applied) times their played weights, a
muted shape playing 0 and a *derived* shape (a corrective / combination shape,
:class:`workbench.core.families.WeightProducts`) playing the clamped product of
its drivers' weights. The unknowns of the solve are the **plain** shapes
(not muted, not derived); derived shapes follow their drivers. The layers
after the blend (regions, handles, paint, wrinkles) are the model's edits, not
unknowns; a take is tracked against the blend.

:class:`ExpressionSpace` gathers this once per take; the marker tracker
(:mod:`.track`) and the point-cloud tracker (:mod:`.clouds`) share it. It is
kept apart from :mod:`.track` so that modules it calls never import the
tracker (no import cycle).

Shapes: ``(n, 3)`` vertices, ``(k, n, 3)`` deltas; weights ``(k,)`` in
``model.shape_names`` order, ``(kp,)`` over the plain shapes only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core import families as _families
from workbench.geometry.masks import skin_or_all_mask

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["ExpressionSpace", "head_size"]


def head_size(model: FaceState) -> float:
    """Diagonal of the bounding box of the model's skin (all vertices without a ``skin`` part), model units.

    The length the tracker measures errors and noise against (the sample head: 3.86 dm).
    """
    V = np.asarray(model.vertices, np.float64)[skin_or_all_mask(model)]
    if V.shape[0] == 0:
        return 1.0
    d = float(np.linalg.norm(V.max(0) - V.min(0)))
    return d if d > 0 else 1.0


@dataclass(frozen=True, eq=False)
class ExpressionSpace:
    """A model's linear expression space (see the module docstring); build with :meth:`from_model`.

    Attributes
    ----------
    shape_names : tuple of str
        All shapes, in model order (length ``k``).
    neutral : (n, 3) float
        ``model.vertices``.
    deltas : (k, n, 3) float32
        ``model.effective_deltas`` (read-only view, all shapes).
    plain : (kp,) int
        Indices of the unknowns: shapes neither muted nor derived.
    derived : dict of int to tuple of int
        Derived shape index → its drivers' indices (a missing driver is left out and makes the product 0).
    dead : (kd,) int
        Derived shapes with a missing or muted driver (they play 0).
    muted : (km,) int
        Muted shapes (they play 0).
    lo, hi : (kp,) float
        The plain shapes' slider ranges (the solver's box).
    lo_all, hi_all : (k,) float
        Every shape's slider range.
    size : float
        :func:`head_size`.
    """

    shape_names: tuple[str, ...]
    neutral: NDArray[np.float64]
    deltas: NDArray[np.float32]
    plain: NDArray[np.intp]
    derived: dict[int, tuple[int, ...]]
    dead: NDArray[np.intp]
    muted: NDArray[np.intp]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    lo_all: NDArray[np.float64]
    hi_all: NDArray[np.float64]
    size: float

    @classmethod
    def from_model(cls, model: FaceState) -> ExpressionSpace:
        shapes = model.shapes
        names = tuple(s.name for s in shapes)
        index = {n: i for i, n in enumerate(names)}
        muted = {i for i, s in enumerate(shapes) if s.mute}
        reads = _families.weight_product_reads()
        rules = _families.weight_products({r: model.slot(r) for r in reads}) if reads else {}
        derived: dict[int, tuple[int, ...]] = {}
        dead: set[int] = set()
        for name, drivers in rules.items():
            if name not in index:
                continue
            i = index[name]
            ids = tuple(index[d] for d in drivers if d in index)
            if len(ids) < len(drivers) or any(j in muted for j in ids):
                dead.add(i)
            derived[i] = ids
        plain = np.array([i for i in range(len(names)) if i not in muted and i not in derived], np.intp)
        lo_all = np.array([s.slider_min for s in shapes], np.float64)
        hi_all = np.array([s.slider_max for s in shapes], np.float64)
        return cls(
            names,
            np.asarray(model.vertices, np.float64),
            model.effective_deltas,
            plain,
            {i: d for i, d in derived.items() if i not in dead and i not in muted},
            np.array(sorted(dead | (muted & set(derived))), np.intp),
            np.array(sorted(muted), np.intp),
            lo_all[plain],
            hi_all[plain],
            lo_all,
            hi_all,
            head_size(model),
        )

    @property
    def k(self) -> int:
        return len(self.shape_names)

    @property
    def unsolved_names(self) -> tuple[str, ...]:
        """Names of the shapes that are not unknowns (derived ones follow their drivers, dead ones stay 0),
        in model order: a :class:`~workbench.capture.TrackResult`'s ``derived``."""
        return tuple(self.shape_names[i] for i in sorted(set(self.derived) | set(self.dead.tolist())))

    @property
    def n_vertices(self) -> int:
        return int(self.neutral.shape[0])

    def full_weights(self, w_plain: ArrayLike) -> NDArray[np.float64]:
        """Every shape's played weight from the plain ones: ``(kp,)`` → ``(k,)``, or ``(T, kp)`` → ``(T, k)``.

        Plain weights are clamped to their ranges; muted shapes get 0; derived shapes the clamped
        product of their drivers (as :func:`workbench.core.families.derive_weights`).
        """
        wp = np.asarray(w_plain, np.float64)
        if wp.shape[-1] != self.plain.size:
            raise ValueError(f"w_plain must end in {self.plain.size} (the plain shapes), got shape {wp.shape}")
        out = np.zeros((*wp.shape[:-1], self.k))
        out[..., self.plain] = np.clip(wp, self.lo, self.hi)
        for i, drivers in self.derived.items():
            prod = np.ones(wp.shape[:-1])
            for d in drivers:
                prod = prod * out[..., d]
            out[..., i] = np.clip(prod, self.lo_all[i], self.hi_all[i])
        return out

    def marker_basis(self, vertex_ids: NDArray[np.intp]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """At the given vertices: the neutral ``(m, 3)`` and the plain deltas as ``(m, 3, kp)`` float64."""
        X0 = self.neutral[vertex_ids]
        ids = np.asarray(vertex_ids, np.intp)
        D = np.ascontiguousarray(np.moveaxis(np.asarray(self.deltas[np.ix_(self.plain, ids)], np.float64), 0, -1))
        return X0, D

    def derived_offset(self, w_full: NDArray[np.float64], vertex_ids: NDArray[np.intp] | slice) -> NDArray[np.float64]:
        """``(m, 3)``: what the derived shapes add at the given vertices for the weights ``w_full : (k,)``."""
        X = np.zeros((len(self.neutral[vertex_ids]), 3))
        for i in self.derived:
            if w_full[i] != 0.0:
                X += w_full[i] * np.asarray(self.deltas[i][vertex_ids], np.float64)
        return X

    def positions(self, w_full: ArrayLike, vertex_ids: NDArray[np.intp] | slice | None = None) -> NDArray[np.float64]:
        """``(m, 3)`` model-space positions ``neutral + Σ w_i δ_i`` (``w_full : (k,)`` played weights)."""
        ids: Any = slice(None) if vertex_ids is None else vertex_ids
        w = np.asarray(w_full, np.float64)
        D = self.deltas[:, ids]
        return self.neutral[ids] + np.tensordot(w, D, axes=(0, 0))

    def motion(self, vertex_ids: NDArray[np.intp] | slice | None = None) -> NDArray[np.float64]:
        """``(m,)``: how far any one plain shape can move each vertex (``max_i |δ_i| · max(|lo_i|, |hi_i|)``)."""
        ids: Any = slice(None) if vertex_ids is None else vertex_ids
        if self.plain.size == 0:
            return np.zeros(len(self.neutral[ids]))
        reach = np.maximum(np.abs(self.lo), np.abs(self.hi))
        sub = self.deltas[self.plain] if isinstance(ids, slice) else self.deltas[np.ix_(self.plain, np.asarray(ids, np.intp))]
        mags = np.linalg.norm(np.asarray(sub, np.float64), axis=2)
        return (mags * reach[:, None]).max(0)
