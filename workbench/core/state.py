"""The face-model state: mesh, shapes, weights, versioned slots, events, undo.

:class:`FaceState` is a small evented model in the style of napari's
components: views subscribe to its psygnal events (``model.events``) and change
it only through methods. It knows nothing of the methods built on it: each
method family (:mod:`workbench.core.families`) registers its slots, its facet
(``model.handles``, ``model.regions``…), its layer of the evaluation
:class:`~workbench.core.pipeline.Pipeline` and its part of the saved file.

Every edit is undoable (:mod:`workbench.core.history`). An interaction (a
drag, a stroke, a slider scrub) emits cheap ``*_changing`` events while it
lasts and one undo step plus ``changed`` events on release; interactions that
span several messages are held by an :class:`InteractionToken`.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from psygnal import Signal, SignalGroup

from workbench.core import families as _families
from workbench.core.evaluation import Evaluator
from workbench.core.history import Command, History, payload_nbytes
from workbench.core.interactions import Interactions, InteractionToken, _Interaction
from workbench.core.pipeline import Pipeline
from workbench.core.polygons import Polygons
from workbench.core.shape_stack import ShapeStack
from workbench.core.shapes import ModelError, ModelMetadata, readonly

__all__ = ["FaceState", "InteractionToken"]

#: versions of live values (a sampled view's are negative: never equal)
_versions = itertools.count(1)

_EVENT_CLASSES: dict[tuple[tuple[str, bool], ...], type[SignalGroup]] = {}


def _events_class(slots: Iterable[_families.SlotSpec]) -> type[SignalGroup]:
    """A SignalGroup with the core signals plus one (and ``<name>_changing``) per slot."""
    key = tuple((s.name, s.changing) for s in slots)
    cls = _EVENT_CLASSES.get(key)
    if cls is None:
        attrs: dict[str, Any] = {
            "weights": Signal(dict),
            "weights_changing": Signal(dict),
            "shapes": Signal(),
            "time": Signal(float),
            "metadata": Signal(),
            "deformed": Signal(bool),
            "history": Signal(),
        }
        for name, changing in key:
            attrs[name] = Signal()
            if changing:
                attrs[f"{name}_changing"] = Signal()
        cls = type("FaceModelEvents", (SignalGroup,), attrs)
        _EVENT_CLASSES[key] = cls
    return cls


class FaceState(ShapeStack, Evaluator, Interactions):
    """Neutral mesh, blendshapes, weights and method slots, with undo and events.

    Parameters
    ----------
    vertices : (n, 3) float
        Neutral vertex positions.
    faces : (m, 3) int or None
        Triangles; None to triangulate ``polygons``.
    shapes : iterable of BlendShape
    polygons : Polygons, optional
        Original faces (quads) kept for export; defaults to the triangles.
    component_labels : (n,) int, optional
    component_names : list of str, optional
    metadata : ModelMetadata, optional
    weights : mapping, optional
        Initial weights (default 0).
    **slots
        Initial values of family slots (e.g. ``handles=HandleSet(...)``).
    """

    def __init__(
        self,
        vertices: ArrayLike,
        faces: ArrayLike | None,
        shapes: Iterable[Any] = (),
        *,
        polygons: Polygons | None = None,
        component_labels: ArrayLike | None = None,
        component_names: Iterable[str] | None = None,
        metadata: ModelMetadata | None = None,
        weights: Mapping[str, float] | None = None,
        **slots: Any,
    ) -> None:
        V = np.array(vertices, dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] == 0:
            raise ModelError(f"vertices must be a non-empty (n, 3) array, got shape {V.shape}")
        if not np.isfinite(V).all():
            row = int(np.flatnonzero(~np.isfinite(V).all(axis=1))[0])
            raise ModelError(f"vertices: NaN/inf coordinate at vertex {row}")
        n = V.shape[0]
        if faces is None:
            if polygons is None:
                raise ModelError("give faces, polygons, or both")
            F, _ = polygons.triangulate()
        else:
            F = np.array(faces, dtype=np.int64)
            if F.ndim != 2 or F.shape[1] != 3:
                raise ModelError(f"faces must be (m, 3), got shape {F.shape}")
        if F.size and (F.min() < 0 or F.max() >= n):
            bad = int(np.flatnonzero((F < 0).any(1) | (F >= n).any(1))[0])
            raise ModelError(f"faces: face {bad} has a vertex index outside 0..{n - 1}")
        if polygons is not None and polygons.indices.size and polygons.indices.max() >= n:
            raise ModelError(f"polygons: vertex index outside 0..{n - 1}")
        self._vertices = readonly(V)
        self._vertices32 = readonly(V.astype(np.float32))
        self._faces = readonly(F.astype(np.int32))
        self._polygons = polygons if polygons is not None else Polygons.from_triangles(self._faces)
        if component_labels is None:
            labels = np.zeros(n, np.int32)
            names = list(component_names) if component_names is not None else ["mesh"]
        else:
            labels = np.asarray(component_labels, dtype=np.int32).reshape(-1)
            if labels.shape[0] != n:
                raise ModelError(f"component_labels has {labels.shape[0]} entries, expected {n}")
            names = (
                list(component_names)
                if component_names is not None
                else [f"component_{i}" for i in range(int(labels.max()) + 1)]
            )
            if labels.min() < 0 or labels.max() >= len(names):
                raise ModelError("component_labels must index into component_names")
        self._component_labels = readonly(labels)
        self._component_names = tuple(names)
        self._metadata = metadata or ModelMetadata()

        self._lock = threading.RLock()
        self.events: Any = None  # the SignalGroup of this model's slots, made below
        self.history = History()
        self._interaction: _Interaction | None = None
        self._time = 0.0
        self._version: dict[str, int] = {"shapes": next(_versions), "weights": next(_versions)}
        self._posed: tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float32]] | None = None
        self._init_shapes(tuple(shapes))
        if weights:
            unknown = set(weights) - set(self._index)
            if unknown:
                raise ModelError(f"weights: unknown shape names {sorted(unknown)}")
            for k, v in weights.items():
                self._weights[k] = self._clamp(k, v)

        fams = _families.families()
        self._specs = {s.name: s for f in fams for s in f.slots}
        self.events = _events_class(self._specs.values())()
        unknown_slots = set(slots) - set(self._specs)
        if unknown_slots:
            raise ModelError(f"unknown slots {sorted(unknown_slots)}; slots are {sorted(self._specs)}")
        self._slots: dict[str, Any] = {}
        for name, spec in self._specs.items():
            self._slots[name] = spec.default(self)
            self._version[name] = next(_versions)
        self.pipeline = Pipeline([f.layer() for f in fams if f.layer is not None])
        self._animators = [f.animate for f in fams if f.animate is not None]
        # facets after the slots and the pipeline exist: they may read both
        for f in fams:
            if f.facet is not None:
                setattr(self, f.name, f.facet(self))
        for name, value in slots.items():
            if value is not None:
                self._slots[name] = self._checked(name, value)

    # ------------------------------------------------------------------ basics
    def __repr__(self) -> str:
        return (
            f"<{type(self).__name__} {self._metadata.name or 'unnamed'}: {self.n_vertices} vertices, "
            f"{len(self._faces)} triangles, {len(self._shapes)} shapes, units={self._metadata.units}>"
        )

    @property
    def lock(self) -> threading.RLock:
        """Re-entrant lock held by every mutation; take it to read a consistent state."""
        return self._lock

    @property
    def n_vertices(self) -> int:
        return int(self._vertices.shape[0])

    @property
    def vertices(self) -> NDArray[np.float64]:
        """(n, 3) float64, read-only: the neutral positions."""
        return self._vertices

    @property
    def vertices32(self) -> NDArray[np.float32]:
        """(n, 3) float32, read-only: the neutral as the pipeline adds to it."""
        return self._vertices32

    @property
    def faces(self) -> NDArray[np.int32]:
        """(m, 3) int32, read-only: triangles (counter-clockwise seen from outside)."""
        return self._faces

    @property
    def polygons(self) -> Polygons:
        """The original polygon faces (quads) the triangles came from."""
        return self._polygons

    @property
    def component_labels(self) -> NDArray[np.int32]:
        """(n,) int32: component of each vertex, indexing :attr:`component_names`."""
        return self._component_labels

    @property
    def component_names(self) -> list[str]:
        return list(self._component_names)

    def component_vertices(self, name: str) -> NDArray[np.intp]:
        """Vertex ids of the named component."""
        if name not in self._component_names:
            raise ModelError(f"unknown component {name!r}; have {list(self._component_names)}")
        return np.flatnonzero(self._component_labels == self._component_names.index(name))

    @property
    def metadata(self) -> ModelMetadata:
        return self._metadata

    def set_metadata(self, metadata: ModelMetadata, label: str = "Set metadata") -> None:
        """Replace the metadata as one undoable step (emits ``metadata``); equal metadata records nothing."""
        if not isinstance(metadata, ModelMetadata):
            raise ModelError(f"set_metadata expects a ModelMetadata, got {type(metadata).__name__}")
        with self._lock:
            old = self._metadata
            if metadata == old:
                return

            def apply(m: ModelMetadata) -> None:
                with self._lock:
                    self._metadata = m
                    self.events.metadata.emit()

            apply(metadata)
            self.push(Command(label, lambda: apply(old), lambda: apply(metadata), payload_nbytes([old, metadata])))

    # ------------------------------------------------------------------- slots
    def slot(self, name: str) -> Any:
        """The current value of slot ``name`` (immutable; replaced, never mutated)."""
        try:
            return self._slots[name]
        except KeyError:
            raise ModelError(f"unknown slot {name!r}; slots are {sorted(self._slots)}") from None

    def version(self, name: str) -> int:
        """Version of ``"shapes"``, ``"weights"`` or a slot: changes whenever the value does."""
        return self._version[name]

    def _checked(self, name: str, value: Any) -> Any:
        spec = self._specs.get(name)
        if spec is None:
            raise ModelError(f"unknown slot {name!r}; slots are {sorted(self._specs)}")
        if isinstance(value, dict):
            value = MappingProxyType(dict(value))
        return value if spec.check is None else spec.check(self, value)

    def restore_slots(self, values: Mapping[str, Any]) -> None:
        """Install slot values as the starting point (a loaded file), not as an edit: no undo step.

        Each value is checked like :meth:`set_slot`'s; events are emitted.
        """
        with self._lock:
            for name, value in values.items():
                self._slots[name] = self._checked(name, value)
                self._bump(name)
            for name in values:
                getattr(self.events, name).emit()
            if values:
                self.events.deformed.emit(True)

    def _bump(self, name: str) -> None:
        self._version[name] = next(_versions)

    def _apply_slot(self, name: str, value: Any, final: bool) -> None:
        with self._lock:
            self._slots[name] = value
            self._bump(name)
            spec = self._specs[name]
            if final or not spec.changing:
                getattr(self.events, name).emit()
            else:
                getattr(self.events, f"{name}_changing").emit()
            if spec.deforms:
                self.events.deformed.emit(final)

    def set_slot(self, name: str, value: Any, label: str) -> None:
        """Replace slot ``name`` as one undoable edit (inside an interaction: part of its step).

        Values are immutable (new objects, never mutated old ones), so undo keeps
        the old object as it was.
        """
        with self._lock:
            value = self._checked(name, value)
            old = self._slots[name]
            if old is value:
                return
            inter = self._interaction
            if inter is not None:
                inter.slots_before.setdefault(name, old)
                self._apply_slot(name, value, final=False)
                return
            self._apply_slot(name, value, final=True)
            self.push(
                Command(
                    label,
                    lambda: self._apply_slot(name, old, True),
                    lambda: self._apply_slot(name, value, True),
                    payload_nbytes(value),
                )
            )

    # ----------------------------------------------------------------- weights
    def _apply_weights(self, values: Mapping[str, float], final: bool) -> None:
        with self._lock:
            self._weights.update(values)
            self._bump("weights")
            if final:
                self.events.weights.emit(dict(values))
            else:
                self.events.weights_changing.emit(dict(values))
            self.events.deformed.emit(final)

    def set_weight(self, name: str, value: float) -> None:
        """Set one weight (clamped to the shape's slider range); undoable."""
        self.set_weights({name: value}, label=f"Set {name}")

    def set_weights(self, values: Mapping[str, float], label: str | None = None) -> None:
        """Set several weights as one undoable edit."""
        with self._lock:
            new = {k: self._clamp(k, v) for k, v in values.items()}
            old = {k: self._weights[k] for k in new}
            changed = {k: v for k, v in new.items() if v != old[k]}
            if not changed:
                return
            inter = self._interaction
            if inter is not None:
                for k in changed:
                    inter.weights_before.setdefault(k, old[k])
                self._apply_weights(changed, final=False)
                return
            before = {k: old[k] for k in changed}
            self._apply_weights(changed, final=True)
            self.push(
                Command(
                    label or f"Set {len(changed)} weights",
                    lambda: self._apply_weights(before, True),
                    lambda: self._apply_weights(changed, True),
                    payload_nbytes([before, changed]),
                )
            )

    def reset_weights(self) -> None:
        """All weights to 0 (clamped into each slider range); one undo step."""
        self.set_weights({s.name: 0.0 for s in self._shapes}, label="Reset weights")

    # ------------------------------------------------------------------- undo
    def push(self, cmd: Command) -> None:
        """Record an already-applied edit as one undo step (facets' multi-part edits)."""
        self.history.push(cmd)
        self.events.history.emit()

    @contextmanager
    def undo_group(self, label: str) -> Iterator[None]:
        """Several edits as one undo step (emits ``history`` once at the end)."""
        with self._lock, self.history.group(label):
            yield
        self.events.history.emit()

    @property
    def can_undo(self) -> bool:
        return self.history.can_undo

    @property
    def can_redo(self) -> bool:
        return self.history.can_redo

    def undo(self) -> str | None:
        """Undo the last edit; returns its label, or None if there was nothing to undo."""
        with self._lock:
            if self._interaction is not None:
                raise ModelError("cannot undo during an interaction (finish the drag first)")
            cmd = self.history.undo()
            if cmd is not None:
                self.events.history.emit()
            return None if cmd is None else cmd.label

    def redo(self) -> str | None:
        """Redo the last undone edit; returns its label, or None."""
        with self._lock:
            if self._interaction is not None:
                raise ModelError("cannot redo during an interaction (finish the drag first)")
            cmd = self.history.redo()
            if cmd is not None:
                self.events.history.emit()
            return None if cmd is None else cmd.label
