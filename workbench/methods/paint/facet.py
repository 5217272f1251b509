"""``model.paint`` and ``model.expressions``: painterly blending's undoable edits.

``model.expressions`` reads like a mapping name -> :class:`Expression` and
saves/removes expressions; ``model.paint`` reads like the :class:`PaintMix`
(name -> (n,) weights) and paints. Each edit replaces a slot: one undo step,
or part of the open interaction's (a stroke's) step.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.shapes import BlendShape, ModelError
from workbench.methods.paint.expressions import Expression
from workbench.methods.paint.painting import (
    Brush,
    PaintMix,
    PaintSurface,
    Stroke,
    apply_dab,
    flood,
    normalize,
)

if TYPE_CHECKING:
    from workbench.animation.curves import Interpolation
    from workbench.core.state import FaceState


class ExpressionsFacet(Mapping[str, Expression]):
    """Saved expressions of one model (a read-only mapping plus undoable edits)."""

    def __init__(self, model: FaceState) -> None:
        self._model = model

    @property
    def value(self) -> Mapping[str, Expression]:
        return self._model.slot("expressions")

    def __getitem__(self, name: str) -> Expression:
        return self.value[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.value)

    def __len__(self) -> int:
        return len(self.value)

    def __repr__(self) -> str:
        return f"<expressions: {list(self.value)}>"

    def save(self, name: str) -> Expression:
        """Save the current evaluated state as expression ``name`` (undoable); replaces a same-named one.

        Its displacement is ``evaluate(posed=False) - neutral``: the head pose is a
        rigid motion of the whole head, not part of an expression.
        """
        m = self._model
        with m.lock:
            try:
                h = m.slot("handles")
            except ModelError:  # no handle family registered
                h = None
            expr = Expression(
                name, m.evaluate(posed=False) - m.vertices32, dict(m.weights),
                h.vertices if h is not None else np.zeros(0, np.int32),
                h.offsets if h is not None else np.zeros((0, 3), np.float32),
            )
            lib = dict(self.value)
            lib[name] = expr
            m.set_slot("expressions", lib, f"Save expression {name}")
            return expr

    def key(self, time: float, name: str, interpolation: Interpolation = "bezier") -> None:
        """Key expression (or blendshape) ``name`` at ``time`` on the timeline; one undo step.

        By its recipe when that plays back its look, else baked once into a
        ``<name>_baked`` shape: :func:`workbench.methods.paint.keying.key_expression`.
        """
        from workbench.methods.paint.keying import key_expression

        key_expression(self._model, time, name, interpolation)

    def remove(self, name: str) -> None:
        """Remove a saved expression (undoable); its paint goes with it."""
        m = self._model
        with m.lock:
            if name not in self.value:
                raise KeyError(f"no saved expression named {name!r}; have {list(self.value)}")
            with m.undo_group(f"Remove expression {name}"):
                mix = m.slot("paint_layers")
                if name in mix:
                    m.set_slot("paint_layers", PaintMix({k: v for k, v in mix.items() if k != name}),
                               "Remove paint")
                m.set_slot("expressions", {k: v for k, v in self.value.items() if k != name},
                           f"Remove expression {name}")


def check_mix(model: FaceState, mix: Any) -> PaintMix:
    """Slot check: a PaintMix of known expressions with one weight per vertex."""
    if isinstance(mix, PaintFacet):
        mix = mix.mix
    if not isinstance(mix, PaintMix):
        raise ModelError(f"paint: expected a PaintMix, got {type(mix).__name__}")
    lib = model.slot("expressions")
    for name, w in mix.items():
        if name not in lib and name not in model.shape_names:
            raise KeyError(f"no expression named {name!r}: paint with a blendshape name or a saved expression")
        if w.shape != (model.n_vertices,):
            raise ModelError(f"paint map {name!r} must have shape ({model.n_vertices},), got {w.shape}")
    return mix


class PaintFacet(Mapping[str, NDArray[np.float32]]):
    """The painted blend functions of one model (reads like its PaintMix) and the brush edits."""

    def __init__(self, model: FaceState) -> None:
        self._model = model
        self._surface: PaintSurface | None = None
        self._lock = threading.Lock()

    @property
    def mix(self) -> PaintMix:
        return self._model.slot("paint_layers")

    def __getitem__(self, name: str) -> NDArray[np.float32]:
        return self.mix[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.mix)

    def __len__(self) -> int:
        return len(self.mix)

    def total(self, n: int | None = None) -> NDArray[np.float32]:
        """(n,) float32: the painted weights summed over expressions (<= 1 after normalize).

        ``n`` defaults to the model's vertex count.
        """
        return self.mix.total(self._model.n_vertices if n is None else int(n))

    def __repr__(self) -> str:
        return f"<paint: {list(self.mix)}>"

    @property
    def surface(self) -> PaintSurface:
        """Edge graph and mirror map of the mesh, mirrored about the skin's mid-plane (built once)."""
        with self._lock:
            if self._surface is None:
                from workbench.methods.regions.segmentation import component_roles

                m = self._model
                V = np.asarray(m.vertices, dtype=np.float64)
                skin = V[component_roles(m) == 0]
                # the plane and tolerance of the region segmentation's mirror
                mid = 0.5 * float(skin[:, 0].min() + skin[:, 0].max()) if len(skin) else 0.0
                tol = 1e-3 * float(np.linalg.norm(skin.max(0) - skin.min(0))) if len(skin) else 0.0
                self._surface = PaintSurface(V, m.faces, mirror_plane=mid, mirror_tolerance=tol)
            return self._surface

    def _check_expression(self, name: str) -> None:
        if name not in self._model.slot("expressions") and name not in self._model.shape_names:
            raise KeyError(f"no expression named {name!r}: paint with a blendshape name or a saved expression")

    def dab(self, expression: str, center: int, brush: Brush | None = None) -> None:
        """One brush dab of ``expression`` at vertex ``center``.

        Inside an interaction (a stroke) the dabs share one undo step and never
        paint beyond the brush opacity where they overlap (:class:`Stroke`).
        """
        m = self._model
        with m.lock:
            self._check_expression(expression)
            stroke = None
            scratch = m.interaction_scratch()
            if scratch is not None:
                cur = scratch.get("paint_stroke")
                if cur is None or cur[0] != expression:
                    cur = (expression, Stroke(self.mix, m.n_vertices))
                    scratch["paint_stroke"] = cur
                stroke = cur[1]
            mix = apply_dab(self.mix, expression, self.surface, brush or Brush(), int(center), stroke)
            m.set_slot("paint_layers", mix, f"Paint {expression}")

    def stroke(self, expression: str, centers: Iterable[int], brush: Brush | None = None) -> None:
        """A whole stroke (several dabs) as one undo step."""
        with self._model.interaction(f"Paint {expression}"):
            for c in centers:
                self.dab(expression, c, brush)

    def flood(self, expression: str, opacity: float = 1.0, vertices: ArrayLike | None = None) -> None:
        """Paint ``expression`` everywhere (or on ``vertices``) with strength ``opacity`` (undoable)."""
        m = self._model
        with m.lock:
            self._check_expression(expression)
            m.set_slot("paint_layers", flood(self.mix, expression, opacity, m.n_vertices, vertices),
                       f"Flood {expression}")

    def normalize(self) -> None:
        """Make painted weights sum to 1 wherever something is painted (undoable)."""
        m = self._model
        with m.lock:
            m.set_slot("paint_layers", normalize(self.mix, m.n_vertices), "Normalize paint")

    def set(self, mix: PaintMix, label: str = "Set paint") -> None:
        """Replace the whole paint layer (e.g. a regional blend); undoable."""
        self._model.set_slot("paint_layers", mix, label)

    def clear(self) -> None:
        """Remove all paint (undoable)."""
        self._model.set_slot("paint_layers", PaintMix(), "Clear paint")

    def displacement(self) -> NDArray[np.float32]:
        """(n, 3) float32 copy of what the paint layer adds on top of the layers below."""
        return self._model.layer_displacement("paint")

    def bake_to_shape(self, name: str) -> BlendShape:
        """Turn the paint layer into a new blendshape at weight 1 and clear the paint (one undo step)."""
        m = self._model
        with m.lock:
            if m.interacting:
                raise ModelError("bake_paint_to_shape: finish the stroke first")
            delta = self.displacement()
            with m.undo_group(f"Bake paint to {name}"):
                m.add_shape(name, delta, weight=1.0)
                self.clear()
            return m.shape(name)
