"""The blendshape list of the state: shapes stacked in one (k, n, 3) array, weights, shape edits.

A mixin of :class:`workbench.core.state.FaceState` (kept apart so each file
holds one concept). Shape deltas share the stacked memory, so the model holds
each delta once; undo steps of shape edits keep only what the edit changed
(the one added or removed shape, copied out of the stack, or the changed
fields), never a view into the whole stack.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core import families as _families
from workbench.core.history import Command, payload_nbytes
from workbench.core.shapes import BlendShape, ModelError, detached_shape, detached_value, readonly

if TYPE_CHECKING:
    from psygnal import SignalGroup

    from workbench.core.history import History


class ShapeStack:
    """Shapes, their stacked deltas and the weights (see the module docstring)."""

    _lock: threading.RLock
    _interaction: Any
    _version: dict[str, int]
    _slots: dict[str, Any]
    events: SignalGroup
    history: History

    def _bump(self, name: str) -> None:  # provided by FaceState
        raise NotImplementedError

    def push(self, cmd: Command) -> None:  # provided by FaceState
        raise NotImplementedError

    @property
    def n_vertices(self) -> int:  # provided by FaceState
        raise NotImplementedError

    def _init_shapes(self, shapes: tuple[BlendShape, ...]) -> None:
        self._shapes: tuple[BlendShape, ...] = ()
        self._stack: NDArray[np.float32] = np.zeros((0, self.n_vertices, 3), np.float32)
        self._effective: NDArray[np.float32] = self._stack
        self._index: dict[str, int] = {}
        self._weights: dict[str, float] = {}
        self._install_shapes(shapes, {})

    # ------------------------------------------------------------------ reading
    @property
    def shapes(self) -> tuple[BlendShape, ...]:
        return self._shapes

    @property
    def shape_names(self) -> list[str]:
        return [s.name for s in self._shapes]

    def shape(self, name: str) -> BlendShape:
        return self._shapes[self._shape_index(name)]

    @property
    def deltas(self) -> NDArray[np.float32]:
        """(k, n, 3) float32, read-only: every shape's delta (masks not applied)."""
        return self._stack

    @property
    def effective_deltas(self) -> NDArray[np.float32]:
        """(k, n, 3) float32, read-only: deltas with their vertex masks applied."""
        return self._effective

    @property
    def arkit_names(self) -> dict[str, str | None]:
        """Shape name → canonical ARKit-52 name (or None when not recognised)."""
        from workbench.arkit import canonical_arkit_name

        return {s.name: canonical_arkit_name(s.name) for s in self._shapes}

    @property
    def weights(self) -> Mapping[str, float]:
        """Read-only mapping shape name → current weight, as played.

        A derived shape (a combination / corrective shape,
        :class:`workbench.core.families.WeightProducts`) shows the product of
        its drivers' weights, whatever was set for it.
        """
        return MappingProxyType(self._played_weights())

    def weight_vector(self) -> NDArray[np.float32]:
        """(k,) float32 weights in shape order (as played), muted shapes as 0."""
        w = self._played_weights()
        return np.array([0.0 if s.mute else w[s.name] for s in self._shapes], np.float32)

    def _played_weights(self) -> dict[str, float]:
        slots = getattr(self, "_slots", None)  # None while the state is being built
        if slots is None:
            return dict(self._weights)
        return _families.derive_weights(self._shapes, self._weights, slots)

    def _shape_index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(
                f"no blendshape named {name!r}; the model has {len(self._shapes)} shapes"
                + (f", e.g. {self.shape_names[:5]}" if self._shapes else "")
            ) from None

    def _clamp(self, name: str, value: float) -> float:
        s = self._shapes[self._shape_index(name)]
        v = float(value)
        if not math.isfinite(v):
            raise ModelError(f"weight for {name!r} must be finite, got {value!r}")
        return min(max(v, s.slider_min), s.slider_max)

    # ------------------------------------------------------------------ install
    def _install_shapes(self, shapes: tuple[BlendShape, ...], weights: Mapping[str, float]) -> None:
        """Replace the shape list; rebuild the stacked delta matrix; no events, no history."""
        n = self.n_vertices
        names = [s.name for s in shapes]
        seen: set[str] = set()
        for s in shapes:
            if not isinstance(s, BlendShape):
                raise ModelError(f"shapes must be BlendShape objects, got {type(s).__name__}")
            if s.delta.shape[0] != n:
                raise ModelError(f"blendshape {s.name!r} has {s.delta.shape[0]} vertices, the neutral has {n}")
            if s.name in seen:
                raise ModelError(f"duplicate blendshape name {s.name!r}")
            seen.add(s.name)
        stack = np.empty((len(shapes), n, 3), np.float32)
        for i, s in enumerate(shapes):
            stack[i] = s.delta
        readonly(stack)
        self._shapes = tuple(s.replace(delta=stack[i]) for i, s in enumerate(shapes))
        self._stack = stack
        self._rebuild_effective()
        self._index = {nm: i for i, nm in enumerate(names)}
        self._weights = {nm: float(weights.get(nm, 0.0)) for nm in names}
        self._bump("shapes")
        self._bump("weights")

    def _rebuild_effective(self) -> None:
        if any(s.vertex_mask is not None for s in self._shapes):
            eff = self._stack.copy()
            for i, s in enumerate(self._shapes):
                if s.vertex_mask is not None:
                    eff[i] *= s.vertex_mask[:, None]
            self._effective = readonly(eff)
        else:
            self._effective = self._stack

    def _emit_shapes(self) -> None:
        self.events.shapes.emit()
        self.events.weights.emit(dict(self._weights))
        self.events.deformed.emit(True)

    def _apply_shapes(self, shapes: tuple[BlendShape, ...], weights: Mapping[str, float]) -> None:
        with self._lock:
            self._install_shapes(shapes, weights)
            self._emit_shapes()

    def _insert_shape(self, index: int, shape: BlendShape, weight: float) -> None:
        with self._lock:
            weights = dict(self._weights)
            weights[shape.name] = weight
            self._apply_shapes((*self._shapes[:index], shape, *self._shapes[index:]), weights)

    def _delete_shape(self, name: str) -> None:
        with self._lock:
            i = self._shape_index(name)
            weights = {k: v for k, v in self._weights.items() if k != name}
            self._apply_shapes(self._shapes[:i] + self._shapes[i + 1 :], weights)

    def _set_shape_props(self, name: str, props: Mapping[str, Any], weight: float) -> None:
        """Change fields of shape ``name`` other than its delta, and its weight; events, no history."""
        with self._lock:
            i = self._shape_index(name)
            new = self._shapes[i].replace(**props)
            self._shapes = (*self._shapes[:i], new, *self._shapes[i + 1 :])
            if new.name != name:
                self._index = {s.name: j for j, s in enumerate(self._shapes)}
                self._weights = {(new.name if k == name else k): v for k, v in self._weights.items()}
            self._weights[new.name] = weight
            if "vertex_mask" in props:
                self._rebuild_effective()
            self._bump("shapes")
            self._bump("weights")
            self._emit_shapes()

    # -------------------------------------------------------------------- edits
    def _refuse_in_interaction(self, label: str) -> None:
        if self._interaction is not None:
            raise ModelError(f"{label}: shape list edits are not allowed inside an interaction")

    def add_shape(
        self,
        name: str,
        delta: ArrayLike,
        *,
        slider_min: float = 0.0,
        slider_max: float = 1.0,
        mute: bool = False,
        vertex_mask: ArrayLike | None = None,
        weight: float = 0.0,
        index: int | None = None,
    ) -> BlendShape:
        """Add a blendshape (undoable). ``delta`` is a displacement, not an absolute shape.

        ``index``: its place in the shape list (default: the end).
        """
        shape = BlendShape(
            name, np.asarray(delta), slider_min, slider_max, mute,
            None if vertex_mask is None else np.asarray(vertex_mask),
        )
        label = f"Add shape {name}"
        with self._lock:
            self._refuse_in_interaction(label)
            if name in self._index:
                raise ModelError(f"a blendshape named {name!r} already exists")
            w = min(max(float(weight), shape.slider_min), shape.slider_max)
            if index is None:
                index = len(self._shapes)
            elif not (isinstance(index, int | np.integer) and 0 <= int(index) <= len(self._shapes)):
                raise ModelError(f"add_shape: index must be an int in 0..{len(self._shapes)}, got {index!r}")
            index = int(index)
            kept = detached_shape(shape)
            self._insert_shape(index, kept, w)
            self.push(Command(label, lambda: self._delete_shape(name),
                              lambda: self._insert_shape(index, kept, w), payload_nbytes(kept)))
            return self.shape(name)

    def remove_shape(self, name: str) -> None:
        """Remove a blendshape (undoable)."""
        label = f"Remove shape {name}"
        with self._lock:
            self._refuse_in_interaction(label)
            i = self._shape_index(name)
            kept = detached_shape(self._shapes[i])
            w = self._weights[name]
            self._delete_shape(name)
            self.push(Command(label, lambda: self._insert_shape(i, kept, w),
                              lambda: self._delete_shape(name), payload_nbytes(kept)))

    def _edit_shape_props(self, name: str, label: str, /, **changes: Any) -> None:
        with self._lock:
            self._refuse_in_interaction(label)
            old = self._shapes[self._shape_index(name)]
            new = old.replace(**changes)  # validates before anything changes
            new_name = new.name
            if new_name != name and new_name in self._index:
                raise ModelError(f"a blendshape named {new_name!r} already exists")
            before = {f: detached_value(getattr(old, f)) for f in changes}
            after = {f: detached_value(getattr(new, f)) for f in changes}
            w_before = self._weights[name]
            w_after = min(max(w_before, new.slider_min), new.slider_max)
            self._set_shape_props(name, after, w_after)
            self.push(
                Command(
                    label,
                    lambda: self._set_shape_props(new_name, before, w_before),
                    lambda: self._set_shape_props(name, after, w_after),
                    payload_nbytes([before, after]) + 64,
                )
            )

    def _replace_shape(self, index: int, shape: BlendShape) -> None:
        with self._lock:
            self._apply_shapes((*self._shapes[:index], shape, *self._shapes[index + 1 :]), self._weights)

    def set_shape_delta(self, name: str, delta: ArrayLike, label: str | None = None) -> None:
        """Replace the delta of shape ``name`` (undoable); its place, weight, range, mute and mask stay."""
        label = label or f"Edit {name}"
        with self._lock:
            self._refuse_in_interaction(label)
            i = self._shape_index(name)
            old = self._shapes[i]
            new = old.replace(delta=np.asarray(delta))  # validates before anything changes
            if new.delta.shape != old.delta.shape:
                raise ModelError(f"set_shape_delta: {name!r} needs a ({self.n_vertices}, 3) delta, got {new.delta.shape}")
            before, after = detached_shape(old), detached_shape(new)
            self._replace_shape(i, after)
            self.push(Command(label, lambda: self._replace_shape(i, before),
                              lambda: self._replace_shape(i, after), payload_nbytes([before, after])))

    def rename_shape(self, name: str, new_name: str) -> None:
        self._edit_shape_props(name, f"Rename {name} to {new_name}", name=new_name)

    def set_shape_mute(self, name: str, mute: bool) -> None:
        self._edit_shape_props(name, f"{'Mute' if mute else 'Unmute'} {name}", mute=bool(mute))

    def set_shape_range(self, name: str, slider_min: float, slider_max: float) -> None:
        self._edit_shape_props(name, f"Range of {name}", slider_min=slider_min, slider_max=slider_max)

    def set_shape_mask(self, name: str, vertex_mask: ArrayLike | None) -> None:
        self._edit_shape_props(
            name, f"Mask {name}", vertex_mask=None if vertex_mask is None else np.asarray(vertex_mask)
        )
