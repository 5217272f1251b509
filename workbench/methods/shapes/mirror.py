"""Mirror shapes, saved expressions and painted weights to the other side of the face.

With the symmetry map ``m`` and ``R`` the reflection of vectors (the
left/right component negated), see :mod:`workbench.methods.shapes.symmetry`:

* a **shape** (or an expression's displacement) becomes ``δ'(v) = R δ(m(v))``,
  its vertex mask ``mask'(v) = mask(m(v))``: ``mouthSmileLeft`` mirrored is a
  ``mouthSmileRight``. Mirroring twice gives the shape back bit for bit (``m``
  is an involution, taking values and negating are exact);
* a **saved expression** (:class:`workbench.methods.paint.expressions.Expression`)
  gets the mirrored displacement, its recipe's weights moved to the mirrored
  shape names (:func:`workbench.arkit.mirror_name`; unsided shapes keep
  theirs) and its handle offsets reflected onto the mirror handles;
* a **painted map** ``W`` (:class:`workbench.methods.paint.painting.PaintMix`) is
  painted over the other side as the brush's X-mirror would have painted it:
  ``M(v) = W(m(v))`` is composited alpha-over for the target expression
  (``W_t ← (1 − M) W_t + M``, every other map ``W_e ← (1 − M) W_e``), so the
  maps stay convex (``Σ_e W_e ≤ 1``) and what was painted on this side stays.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from workbench.arkit import mirror_name
from workbench.core.shapes import BlendShape, ModelError
from workbench.methods.paint.expressions import Expression
from workbench.methods.paint.painting import PaintMix
from workbench.methods.shapes.symmetry import Symmetry

__all__ = ["mirror_expression", "mirror_paint", "mirror_shape", "mirror_weight_names"]


def mirror_shape(sym: Symmetry, shape: BlendShape, name: str) -> BlendShape:
    """``shape`` reflected to the other side, named ``name`` (range and mute kept, mask mirrored)."""
    mask = shape.vertex_mask
    return BlendShape(
        name,
        sym.mirror_vectors(shape.delta),
        shape.slider_min,
        shape.slider_max,
        shape.mute,
        None if mask is None else sym.mirror_scalars(mask),
    )


def mirror_weight_names(weights: Mapping[str, float], shape_names: list[str] | None = None) -> dict[str, float]:
    """A recipe's weights with sided names swapped (``eyeBlink_L`` ↔ ``eyeBlink_R``).

    With ``shape_names``, a name whose mirror is not a shape keeps its own name.
    """
    known = None if shape_names is None else set(shape_names)
    out: dict[str, float] = {}
    for k, v in weights.items():
        mk = mirror_name(k)
        out[mk if mk is not None and (known is None or mk in known) else k] = float(v)
    return out


def mirror_expression(
    sym: Symmetry,
    expr: Expression,
    name: str,
    shape_names: list[str],
    handle_vertices: NDArray[np.int32] | None = None,
) -> Expression:
    """``expr`` mirrored (module docstring), named ``name``.

    Handle offsets move to the mirror vertices; when those are the handles of
    ``handle_vertices`` (the model's handle set, symmetric), they are stored in
    its order so the expression still matches the handle set.
    """
    hv = expr.handle_vertices.astype(np.int64)
    ho = expr.handle_offsets.astype(np.float32)
    mv = sym.map[hv]
    mo = ho.copy()
    mo[:, sym.axis] = -mo[:, sym.axis]
    if handle_vertices is not None and hv.size and np.array_equal(np.sort(mv), np.sort(hv)) \
            and np.array_equal(np.asarray(handle_vertices, np.int64), hv):
        pos = {int(v): i for i, v in enumerate(hv)}
        order = np.array([pos[int(v)] for v in mv])
        out_o = np.zeros_like(mo)
        out_o[order] = mo
        mv, mo = hv, out_o
    return Expression(
        name,
        sym.mirror_vectors(expr.displacement),
        mirror_weight_names(expr.weights, shape_names),
        mv.astype(np.int32),
        mo,
    )


def mirror_paint(sym: Symmetry, mix: PaintMix, source: str, target: str) -> PaintMix:
    """The paint of ``source`` mirrored and painted (alpha-over) as ``target`` (module docstring)."""
    if source not in mix:
        raise KeyError(f"mirror_paint: {source!r} is not painted; painted expressions are {list(mix)}")
    M = sym.mirror_scalars(mix[source]).astype(np.float32)
    if not np.any(M):
        return mix
    keep = (np.float32(1.0) - M).astype(np.float32)
    maps: dict[str, NDArray[np.float32]] = {}
    n = M.shape[0]
    for name in {**dict.fromkeys(mix), target: None}:
        w = mix[name] if name in mix else np.zeros(n, np.float32)
        new = keep * w + M if name == target else keep * w
        new = np.clip(new, 0.0, 1.0).astype(np.float32)
        new.setflags(write=False)
        maps[name] = new
    total = np.zeros(n, np.float64)
    for w in maps.values():
        total += w
    if total.max(initial=0.0) > 1.0 + 1e-5:  # pragma: no cover - convexity is kept by construction
        raise ModelError("mirror_paint: painted weights would sum to more than 1")
    return PaintMix(maps)
