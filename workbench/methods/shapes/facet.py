"""``model.shape_tools``: split, mirror and corrective shapes as undoable edits.

(``model.shapes`` is the tuple of blendshapes, hence the name.) Every edit is
one undo step, however many shapes, tracks and slots it touches::

    model.shape_tools.split("browInnerUp")               # -> ("browInnerUp_L", "browInnerUp_R")
    model.shape_tools.mirror("mouthSmileLeft")           # replaces/creates mouthSmileRight
    model.shape_tools.mirror_expression("smirk")         # a saved expression, mirrored
    model.shape_tools.mirror_paint("mouthSmileLeft")     # its paint, painted on the other side
    model.shape_tools.add_corrective("jawOpen_mouthSmileLeft", ["jawOpen", "mouthSmileLeft"])
    model.shape_tools.set_drivers("jawOpen_mouthSmileLeft", ["jawOpen", "mouthSmileLeft", "eyeBlinkLeft"])
    model.shape_tools.remove_corrective("jawOpen_mouthSmileLeft")

Reading: :attr:`ShapeToolsFacet.correctives` (name -> drivers),
:meth:`ShapeToolsFacet.symmetry` (the mirror map, cached per axes and
tolerance), :meth:`ShapeToolsFacet.split_weights` (the left share a split would
use, for a preview).

Shapes are added in the list next to the shape they come from (split halves
in its place, a new mirror right after it). Edits that add shapes are refused
while the timeline keys region weights (those tracks hold one weight per shape).
"""

from __future__ import annotations

import dataclasses
import threading
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import Track, weight_track_name
from workbench.arkit import mirror_name
from workbench.core.shapes import BlendShape, ModelError
from workbench.methods.paint.expressions import Expression
from workbench.methods.shapes import mirror as _mirror
from workbench.methods.shapes.correctives import Correctives, check_rules, normalize_drivers
from workbench.methods.shapes.split import (
    DEFAULT_FALLOFF_FRACTION,
    side_weights,
    split_delta,
    split_names,
)
from workbench.methods.shapes.symmetry import Symmetry, lateral_axis, symmetry_map

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["MAX_UNMATCHED", "ShapeToolsFacet"]

#: largest fraction of a mirrored field's moving vertices allowed without a mirror partner
MAX_UNMATCHED = 0.02


class ShapeToolsFacet:
    """Shape tools of one model: split, mirror, correctives (see the module docstring)."""

    def __init__(self, model: FaceState) -> None:
        self._model = model
        self._lock = threading.Lock()
        self._symmetry: dict[tuple[str, str, float | None], Symmetry] = {}
        self._skin: NDArray[np.bool_] | None = None

    def __repr__(self) -> str:
        return f"<shape_tools: {len(self.correctives)} correctives>"

    # ------------------------------------------------------------------ reading
    @property
    def correctives(self) -> Correctives:
        """Corrective shape name -> its drivers (its weight is the product of theirs)."""
        value: Correctives = self._model.slot("correctives")
        return value

    def is_corrective(self, name: str) -> bool:
        return name in self.correctives

    def drivers(self, name: str) -> tuple[str, ...]:
        """The drivers of corrective ``name``."""
        try:
            return self.correctives[name]
        except KeyError:
            raise KeyError(f"{name!r} is not a corrective shape; correctives are {list(self.correctives)}") from None

    def _skin_mask(self) -> NDArray[np.bool_]:
        if self._skin is None:
            from workbench.geometry.masks import skin_or_all_mask

            self._skin = skin_or_all_mask(self._model)
        return self._skin

    def plane(self) -> tuple[int, float, float, float]:
        """``(axis, left_sign, mid, width)``: the left/right axis (from the metadata's up and
        front axes), the mirror plane and the head's width (the skin's extent along the axis)."""
        m = self._model
        axis, sign = lateral_axis(m.metadata.up_axis, m.metadata.front_axis)
        x = m.vertices[self._skin_mask(), axis]
        lo, hi = float(x.min()), float(x.max())
        return axis, sign, 0.5 * (lo + hi), hi - lo

    def symmetry(self, tolerance: float | None = None) -> Symmetry:
        """The mirror map of the mesh (:func:`workbench.methods.shapes.symmetry.symmetry_map`).

        The plane is the middle of the skin's left/right extent; ``tolerance``
        (default ``1e-3`` of the skin's bounding-box diagonal) bounds position matches.
        Cached per axes and tolerance (the mesh never changes).
        """
        m = self._model
        meta = m.metadata
        key = (meta.up_axis, meta.front_axis, None if tolerance is None else float(tolerance))
        with self._lock:
            sym = self._symmetry.get(key)
            if sym is None:
                axis, sign, mid, _ = self.plane()
                skin = m.vertices[self._skin_mask()]
                tol = 1e-3 * float(np.linalg.norm(skin.max(0) - skin.min(0))) if tolerance is None else tolerance
                sym = symmetry_map(m.vertices, m.polygons, axis=axis, left_sign=sign, mid=mid, tolerance=tol)
                self._symmetry[key] = sym
            return sym

    def default_falloff(self) -> float:
        """The split band's default width: 5 % of the head's width (model units)."""
        return DEFAULT_FALLOFF_FRACTION * self.plane()[3]

    def split_weights(self, falloff: float | None = None) -> NDArray[np.float64]:
        """(n,) share of the left half a :meth:`split` with this ``falloff`` gives each vertex."""
        axis, sign, mid, width = self.plane()
        f = DEFAULT_FALLOFF_FRACTION * width if falloff is None else falloff
        return side_weights(sign * (self._model.vertices[:, axis] - mid), f)

    # ------------------------------------------------------------------ helpers
    def _shape(self, name: Any, what: str) -> BlendShape:
        if not isinstance(name, str):
            raise ModelError(f"{what}: shape name must be a string, got {name!r}")
        try:
            return self._model.shape(name)
        except KeyError as exc:
            raise KeyError(f"{what}: {exc.args[0]}") from None

    def _index(self, name: str) -> int:
        return self._model.shape_names.index(name)

    def _new_name(self, name: Any, what: str) -> str:
        if not isinstance(name, str) or not name.strip():
            raise ModelError(f"{what} must be a non-empty string, got {name!r}")
        if name in self._model.shape_names:
            raise ModelError(f"{what}: a blendshape named {name!r} already exists")
        return name

    def _refuse_region_tracks(self, what: str) -> None:
        from workbench.methods.regions.tracks import region_tracks

        keyed = region_tracks(self._model.slot("tracks"))
        if keyed:
            raise ModelError(
                f"{what}: the timeline keys region weights ({len(keyed)} region tracks, one "
                "weight per shape), which a new shape would not fit; delete the region tracks first"
            )

    def _refuse_references(self, name: str, what: str, correctives: Correctives) -> None:
        """Refuse to remove shape ``name`` while paint or another corrective uses it."""
        m = self._model
        if name in m.slot("paint_layers"):
            raise ModelError(f"{what}: {name!r} is painted (model.paint); remove its paint first or keep the shape")
        driven = correctives.driven_by(name)
        if driven:
            raise ModelError(f"{what}: {name!r} drives the corrective {driven[0]!r}; remove or re-drive it first")

    def _check_mirrorable(self, sym: Symmetry, moving: NDArray[np.bool_], what: str) -> None:
        """Refuse when too many of the moving vertices have no mirror partner."""
        moving = moving | moving[sym.map]
        count = int(np.count_nonzero(moving))
        bad = int(np.count_nonzero(moving & sym.unmatched))
        if count and bad > MAX_UNMATCHED * count:
            raise ModelError(
                f"{what}: the mesh is not symmetric where it moves: {bad} of its {count} moving vertices "
                f"({100 * bad / count:.1f} %) have no mirror partner within {sym.tolerance:.3g} "
                f"(mirror plane {'xyz'[sym.axis]} = {sym.mid:.4g}); pass a larger tolerance "
                f"(model.shape_tools.symmetry(tolerance=...).summary() shows the map)"
            )

    # ------------------------------------------------------------------ split
    def split(
        self,
        name: str,
        falloff: float | None = None,
        names: tuple[str, str] | None = None,
        keep: bool = False,
    ) -> tuple[str, str]:
        """Split shape ``name`` into left and right halves that sum to it exactly; one undo step.

        Parameters
        ----------
        name : str
        falloff : float, optional
            Width (model units) of the smooth band across the mirror plane where
            the halves blend (default :meth:`default_falloff`: 5 % of the head's width).
        names : (str, str), optional
            ``(left, right)``; default from :func:`workbench.methods.shapes.split.split_names`
            (``browInnerUp_L``/``_R``, ``mouthSmileLeft``/``Right``).
        keep : bool
            Keep the original (the halves are added at weight 0). Default: the
            halves replace it in the list, take its weight and its keys (the
            face looks the same), and inherit its drivers if it is a corrective.

        Returns
        -------
        (left, right) names.
        """
        m = self._model
        what = f"split({name!r})"
        with m.lock:
            shape = self._shape(name, what)
            if names is None:
                left, right = split_names(name)
            else:
                if isinstance(names, str) or len(tuple(names)) != 2:
                    raise ModelError(f"{what}: names must be (left, right), got {names!r}")
                left, right = tuple(names)
            self._new_name(left, f"{what}: names[0]")
            self._new_name(right, f"{what}: names[1]")
            if left == right:
                raise ModelError(f"{what}: names must differ, got {left!r} twice")
            self._refuse_region_tracks(what)
            cor = self.correctives
            if not keep:
                self._refuse_references(name, what, cor)
            f = self.split_weights(self.default_falloff() if falloff is None else falloff)
            dL, dR = split_delta(shape.delta, f)
            w = 0.0 if keep else float(m.weights[name])
            i = self._index(name)
            tl = m.slot("tracks")
            with m.undo_group(f"Split {name}"):
                for k, (nm, d) in enumerate(((left, dL), (right, dR))):
                    m.add_shape(nm, d, slider_min=shape.slider_min, slider_max=shape.slider_max, mute=shape.mute,
                                vertex_mask=shape.vertex_mask, weight=w, index=i + 1 + k)
                if not keep:
                    track = tl.tracks.get(weight_track_name(name))
                    if track is not None:
                        new = tl.without_track(track.name)
                        for nm in (left, right):
                            new = new.with_track(Track(weight_track_name(nm), track.keys))
                        m.set_slot("tracks", new, f"Split {name}")
                    m.remove_shape(name)
                    if name in cor:
                        rules = {k: v for k, v in cor.items() if k != name}
                        rules[left] = rules[right] = cor[name]
                        m.set_slot("correctives", Correctives(rules), f"Split {name}")
            return left, right

    # ------------------------------------------------------------------ mirror
    def mirror(self, name: str, target: str | None = None, tolerance: float | None = None) -> str:
        """Mirror shape ``name`` to the other side into ``target``; one undo step.

        ``target`` defaults to the mirrored name (``mouthSmileLeft`` ->
        ``mouthSmileRight``, ``eyeBlink_L`` -> ``eyeBlink_R``), or ``name`` itself
        for an unsided shape (flipped in place, as Blender's "Mirror Shape Key").
        An existing target gets the mirrored delta and mask (its place, weight
        and keys stay); a new one is added after ``name`` at weight 0 and, when
        ``name`` is a corrective, driven by the mirrored drivers. Returns the target.
        """
        m = self._model
        what = f"mirror({name!r})"
        with m.lock:
            shape = self._shape(name, what)
            if target is None:
                mn = mirror_name(name)
                target = mn if mn is not None else name
            if not isinstance(target, str) or not target.strip():
                raise ModelError(f"{what}: target must be a non-empty string, got {target!r}")
            sym = self.symmetry(tolerance)
            self._check_mirrorable(sym, np.any(shape.effective_delta() != 0, axis=1), what)
            new = _mirror.mirror_shape(sym, shape, target)
            label = f"Mirror {name}" if target == name else f"Mirror {name} to {target}"
            cor = self.correctives
            with m.undo_group(label):
                if target in m.shape_names:
                    m.set_shape_delta(target, new.delta, label)
                    old_mask = m.shape(target).vertex_mask
                    if not (old_mask is None and new.vertex_mask is None) and not (
                        old_mask is not None and new.vertex_mask is not None
                        and np.array_equal(old_mask, new.vertex_mask)
                    ):
                        m.set_shape_mask(target, new.vertex_mask)
                else:
                    self._refuse_region_tracks(what)
                    m.add_shape(target, new.delta, slider_min=new.slider_min, slider_max=new.slider_max,
                                mute=new.mute, vertex_mask=new.vertex_mask, index=self._index(name) + 1)
                    if name in cor:
                        names = set(m.shape_names)
                        drivers = tuple(
                            mn if (mn := mirror_name(d)) is not None and mn in names else d for d in cor[name]
                        )
                        if target not in drivers:
                            m.set_slot("correctives", cor.with_rule(target, drivers), label)
            return target

    def mirror_expression(self, name: str, target: str | None = None, tolerance: float | None = None) -> Expression:
        """Mirror the saved expression ``name`` (``model.expressions``) into ``target``; one undo step.

        ``target`` defaults to the mirrored name, else ``<name>_mirrored``; an
        existing expression of that name is replaced. The recipe's weights move
        to the mirrored shapes and the handle offsets to the mirror handles.
        """
        m = self._model
        what = f"mirror_expression({name!r})"
        with m.lock:
            lib = m.slot("expressions")
            if name not in lib:
                raise KeyError(f"{what}: no saved expression named {name!r}; saved: {list(lib)}")
            if target is None:
                mn = mirror_name(name)
                target = mn if mn is not None else f"{name}_mirrored"
            if not isinstance(target, str) or not target.strip():
                raise ModelError(f"{what}: target must be a non-empty string, got {target!r}")
            expr = lib[name]
            sym = self.symmetry(tolerance)
            self._check_mirrorable(sym, np.any(expr.displacement != 0, axis=1), what)
            handles = m.slot("handles")
            new = _mirror.mirror_expression(sym, expr, target, m.shape_names, handles.vertices)
            m.set_slot("expressions", {**lib, target: new}, f"Mirror expression {name} to {target}")
            return new

    def mirror_paint(self, expression: str, target: str | None = None, tolerance: float | None = None) -> None:
        """Paint the mirror image of ``expression``'s painted map on the other side; one undo step.

        ``target`` (the expression painted there) defaults to the mirrored name
        when that is a saved expression or a shape (``mouthSmileLeft`` ->
        ``mouthSmileRight``), else ``expression`` itself (a one-sided paint made
        symmetric). Composited like a brush (alpha-over), so the maps stay convex.
        """
        m = self._model
        what = f"mirror_paint({expression!r})"
        with m.lock:
            mix = m.slot("paint_layers")
            if expression not in mix:
                raise KeyError(f"{what}: {expression!r} is not painted; painted: {list(mix)}")
            known = set(m.slot("expressions")) | set(m.shape_names)
            if target is None:
                mn = mirror_name(expression)
                target = mn if mn is not None and mn in known else expression
            if target not in known:
                raise KeyError(f"{what}: target {target!r} is neither a saved expression nor a shape")
            sym = self.symmetry(tolerance)
            self._check_mirrorable(sym, np.asarray(mix[expression]) > 0, what)
            new = _mirror.mirror_paint(sym, mix, expression, target)
            if new is not mix:
                m.set_slot("paint_layers", new, f"Mirror paint of {expression}")

    # ------------------------------------------------------------------ correctives
    def _drivers(self, name: str, drivers: Any, what: str) -> tuple[str, ...]:
        out = normalize_drivers(name, drivers, f"{what}: drivers")
        names = set(self._model.shape_names)
        for d in out:
            if d not in names:
                raise KeyError(f"{what}: drivers: no blendshape named {d!r}")
            if d in self.correctives:
                raise ModelError(f"{what}: drivers: {d!r} is a corrective itself (drive it by its drivers)")
        return out

    def add_corrective(
        self, name: str | None, drivers: Any, delta: ArrayLike | str | None = None
    ) -> BlendShape:
        """Add a corrective shape ``name`` whose weight is the product of ``drivers``' weights; one undo step.

        Parameters
        ----------
        name : str or None
            The new shape (None: the drivers' names joined by ``_``, e.g.
            ``jawOpen_mouthSmileLeft``).
        drivers : list of str
            Two or more different shapes, none a corrective itself.
        delta : (n, 3) array, "handles" or None
            None (default): an empty corrective (zeros) to sculpt into, as a
            new Blender shape key. ``"handles"``: the handle layer's current
            displacement divided by the drivers' current product weight (so the
            face looks the same), the handle offsets reset — pose the drivers,
            sculpt the fix with the handles, then make it a corrective.
        """
        m = self._model
        with m.lock:
            what = "add_corrective"
            if name is None:
                name = "_".join(normalize_drivers("the new corrective", drivers, f"{what}: drivers"))
            name = self._new_name(name, f"{what}: name")
            drv = self._drivers(name, drivers, what)
            self._refuse_region_tracks(what)
            from_handles = isinstance(delta, str)
            if from_handles:
                if delta != "handles":
                    raise ModelError(f"{what}: delta must be an (n, 3) array, 'handles' or None, got {delta!r}")
                w = 1.0
                played = m.weights
                for dn in drv:
                    w *= played[dn]
                if w == 0.0:
                    raise ModelError(
                        f"{what}: delta='handles' needs the drivers posed (their weights multiply to 0 now: "
                        + ", ".join(f"{dn}={played[dn]:g}" for dn in drv) + ")"
                    )
                values = m.layer_displacement("handles").astype(np.float64) / w
            elif delta is None:
                values = np.zeros((m.n_vertices, 3), np.float64)
            else:
                values = np.asarray(delta, dtype=np.float64)
                if values.shape != (m.n_vertices, 3):
                    raise ModelError(f"{what}: delta must be ({m.n_vertices}, 3), got {values.shape}")
            with m.undo_group(f"Add corrective {name}"):
                m.add_shape(name, values.astype(np.float32))
                m.set_slot("correctives", self.correctives.with_rule(name, drv), f"Add corrective {name}")
                if from_handles:
                    h = m.slot("handles")
                    m.set_slot("handles", dataclasses.replace(h, offsets=np.zeros_like(h.offsets)), "Reset handles")
            return m.shape(name)

    def set_drivers(self, name: str, drivers: Any) -> None:
        """Make shape ``name`` a corrective driven by ``drivers`` (or change its drivers); one undo step."""
        m = self._model
        with m.lock:
            what = f"set_drivers({name!r})"
            self._shape(name, what)
            drv = self._drivers(name, drivers, what)
            cor = self.correctives
            driven = cor.driven_by(name)
            if driven:
                raise ModelError(f"{what}: {name!r} drives the corrective {driven[0]!r}, so it cannot be one")
            if cor.get(name) == drv:
                return
            new = cor.with_rule(name, drv)
            check_rules(new, m.shape_names)
            m.set_slot("correctives", new, f"Drive {name} by {' × '.join(drv)}")

    def remove_corrective(self, name: str, keep_shape: bool = False) -> None:
        """Remove corrective ``name``: its rule and (unless ``keep_shape``) its shape and keys; one undo step.

        With ``keep_shape`` it stays as an ordinary shape at its own weight.
        """
        m = self._model
        with m.lock:
            what = f"remove_corrective({name!r})"
            cor = self.correctives
            if name not in cor:
                raise KeyError(f"{what}: {name!r} is not a corrective; correctives are {list(cor)}")
            if not keep_shape and name in m.shape_names:
                self._refuse_references(name, what, cor)
                self._refuse_region_tracks(what)
            with m.undo_group(f"Remove corrective {name}"):
                m.set_slot("correctives", cor.without(name), f"Remove corrective {name}")
                if not keep_shape and name in m.shape_names:
                    tl = m.slot("tracks")
                    if weight_track_name(name) in tl.tracks:
                        m.set_slot("tracks", tl.without_track(weight_track_name(name)), f"Remove corrective {name}")
                    m.remove_shape(name)
