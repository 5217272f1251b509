"""Keying an expression on the timeline (Pighin et al. 1998 §4-§5): by its recipe, or baked once.

A saved :class:`~workbench.methods.paint.expressions.Expression` records the
weights and handle offsets it was made with (its recipe) and the displacement
it shows. Keying it keys the recipe when that plays back the look; any other
expression (its look comes from painting, region weights, another handle set,
or shapes since removed or edited) becomes, as in the paper, a new expression
of its own: a ``<name>_baked`` blendshape keyed at 1. The timeline facet keys
weights and tracks; this module decides *what* an expression keys.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.animation.curves import Interpolation, weight_track_name
from workbench.animation.timeline import derived_shapes, grow_range
from workbench.core.families import families
from workbench.core.pipeline import StateView

if TYPE_CHECKING:
    from workbench.core.state import FaceState
    from workbench.methods.paint.expressions import Expression

#: Tolerance, relative to (1 + the largest neutral coordinate), within which a
#: saved expression's recipe counts as playing back its look (float32 round-off).
PLAYBACK_ATOL = 1e-6

#: the handle family's track (an expression's recipe records handle offsets)
_HANDLES_TRACK = "handles"


def key_expression(model: FaceState, time: float, expression: str,
                   interpolation: Interpolation = "bezier") -> None:
    """Key an expression at ``time`` (drop from the gallery onto the timeline); one undo step.

    A blendshape keys itself at 1. A saved expression whose recipe plays back
    its look keys its recipe weights and, when the handle set matches, its
    handle offsets. Any other saved expression is baked: its displacement
    becomes the blendshape ``<expression>_baked`` (added once in the same undo
    step, reused when it already holds exactly that displacement) keyed at 1;
    keyed handles are keyed at rest there.

    Every other already-keyed shape is keyed at 0, and a shape keyed for the
    first time gets 0-keys at the earlier key times, so at its time a keyed
    expression plays back exactly as saved, in ``evaluate_at`` and in every
    export, as long as the unkeyed state is at rest.
    """
    m = model
    with m.lock:
        label = f"Key {expression} at {time:g}s"
        with m.undo_group(label):
            handle_key: NDArray[np.float32] | None = None
            library = m.slot("expressions")
            handles = m.slot("handles")
            tl = m.slot("tracks")
            if expression in library:
                expr = library[expression]
                if recipe_plays_back(m, expr):
                    values = dict(expr.weights)
                    same = np.array_equal(expr.handle_vertices, handles.vertices)
                    if same and len(handles) and np.any(expr.handle_offsets):
                        handle_key = expr.handle_offsets
                else:
                    values = {baked_expression_shape(m, expr): 1.0}
                    if len(handles) and _HANDLES_TRACK in tl.tracks:
                        handle_key = np.zeros_like(handles.offsets)
            elif expression in m.shape_names:
                values = {expression: 1.0}
            else:
                raise KeyError(f"no expression named {expression!r}")
            tl = m.slot("tracks")  # baking may have added a shape, not keys
            keyed = set(tl.weight_tracks)
            earlier = sorted({float(t) for tr in tl.weight_tracks.values() for t in tr.times})
            for n in (keyed | {k for k, v in values.items() if v != 0.0}) - derived_shapes(m):
                if n not in keyed:  # a newly keyed shape was 0 in the expressions keyed before
                    for t in earlier:
                        tl = tl.add_key(weight_track_name(n), t, 0.0, interpolation=interpolation)
                tl = tl.add_key(weight_track_name(n), time, values.get(n, 0.0), interpolation=interpolation)
            if handle_key is not None:
                tl = tl.add_key(_HANDLES_TRACK, time, handle_key, interpolation=interpolation)
            m.set_slot("tracks", grow_range(tl, time), label)


def recipe_plays_back(model: FaceState, expr: Expression) -> bool:
    """True if keying ``expr``'s weights and handle offsets reproduces its displacement.

    Evaluated as the timeline plays it: its weights (0 for shapes it does not
    name), its handle offsets when the handle set is the one it was saved
    with, without what a recipe does not record (each family's
    ``recipe_slots``: no paint, no region weights), every other layer as it is
    — on a view of the state, so the model itself is untouched.
    """
    m = model
    if any(v != 0.0 and k not in m.shape_names for k, v in expr.weights.items()):
        return False  # a shape of the recipe is gone
    h = m.slot("handles")
    same = np.array_equal(expr.handle_vertices, h.vertices)
    if not same and np.any(expr.handle_offsets):
        return False
    weights = {s.name: min(max(expr.weights.get(s.name, 0.0), s.slider_min), s.slider_max) for s in m.shapes}
    slots = dict(m.view().slots)
    slots["handles"] = dataclasses.replace(h, offsets=expr.handle_offsets if same else np.zeros_like(h.offsets))
    for fam in families():
        if fam.recipe_slots is not None:
            slots.update(fam.recipe_slots(slots))
    versions = {name: -1 - i for i, name in enumerate(("shapes", "weights", *slots))}
    view = StateView(m, weights, slots, versions, m.time)
    played = m.pipeline.run(view, cache=False).mesh - m.vertices32
    atol = PLAYBACK_ATOL * (1.0 + float(np.abs(m.vertices32).max()))
    return bool(np.allclose(played, expr.displacement, rtol=0.0, atol=atol))


def baked_expression_shape(model: FaceState, expr: Expression) -> str:
    """Name of a blendshape holding exactly ``expr.displacement`` (added at weight 0 if none does)."""
    m = model
    stem = f"{expr.name}_baked"
    for i in itertools.count(1):
        name = stem if i == 1 else f"{stem}_{i}"
        if name not in m.shape_names:
            m.add_shape(name, expr.displacement)
            return name
        s = m.shape(name)
        if (s.vertex_mask is None and not s.mute and s.slider_min <= 1.0 <= s.slider_max
                and np.array_equal(s.delta, expr.displacement)):
            return name
    raise AssertionError("unreachable")  # itertools.count never ends
