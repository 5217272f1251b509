"""The face-model state object shared by every tool and view.

:class:`FaceModel` is a pure-Python evented model in the style of napari's
``components``: views subscribe to its psygnal events and change it only
through its methods. Every edit is undoable (see :mod:`workbench.core.history`);
an *interaction* (a mouse drag, a slider scrub) emits cheap ``*_changing``
events while it lasts and one undo step plus one ``changed`` event on release.

Evaluation (:meth:`FaceModel.evaluate`) is ``neutral + sum_k w_k * delta_k``
plus the editing layers later tools add, computed in float32 with one BLAS
call (or per-shape axpy when few weights are non-zero) and cached until
something it depends on changes; then the head pose keyed on the timeline at
the current time (:attr:`FaceModel.head_pose`) moves it rigidly, so the
viewport shows what :meth:`FaceModel.evaluate_at` and the exports give.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from psygnal import Signal, SignalGroup

from workbench.converters import mesh_converter
from workbench.methods.paint.expressions import Expression
from workbench.methods.handles.layer import HandleLayer
from workbench.core.history import Command, History, payload_nbytes
from workbench.methods.paint.painting import Brush, PaintLayer, PaintMix, Stroke, apply_dab, flood, normalize
from workbench.core.polygons import Polygons
from workbench.methods.regions.blend import RegionState, RegionWeights, region_layer
from workbench.animation.tracks import (
    HEAD_POSE,
    IDENTITY_POSE,
    Interpolation,
    Timeline,
    TimelineSample,
    add_keys,
    quaternion_to_matrix,
    region_track_name,
    weight_track_name,
)


class ModelError(ValueError):
    """An edit or construction argument the model cannot accept."""


def _readonly(a: NDArray[Any]) -> NDArray[Any]:
    a.setflags(write=False)
    return a


def _owned(a: NDArray[Any]) -> NDArray[Any]:
    """``a`` if it owns its memory, else a read-only copy.

    What undo steps keep goes through this so that a view (one row of the
    model's (k, n, 3) delta stack, a slice of a caller's array) does not keep
    the whole buffer it was cut from alive.
    """
    return a if a.base is None else _readonly(a.copy())


def _detached_value(value: Any) -> Any:
    """A field value safe to keep in an undo step (arrays own their memory)."""
    return _owned(value) if isinstance(value, np.ndarray) else value


def _head_matrix_at(timeline: Timeline, time: float) -> NDArray[np.float64] | None:
    """(4, 4) head transform of ``timeline`` at ``time``, None when the head pose is not keyed."""
    hp = timeline.head_pose
    if hp is None:
        return None
    p = hp.sample([time])[0]
    M = np.eye(4)
    M[:3, :3] = quaternion_to_matrix(p[3:])
    M[:3, 3] = p[:3]
    return M


def _as_quaternion(rotation: ArrayLike, what: str) -> NDArray[np.float64]:
    """(4,) unit quaternion (x, y, z, w) from a quaternion or a (3, 3) rotation matrix."""
    r = np.asarray(rotation, np.float64)
    if r.shape == (4,) and np.isfinite(r).all() and np.linalg.norm(r) > 1e-12:
        return np.asarray(r / np.linalg.norm(r), np.float64)
    if r.shape == (3, 3) and np.isfinite(r).all():
        if np.allclose(r.T @ r, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0:
            from scipy.spatial.transform import Rotation

            return np.asarray(Rotation.from_matrix(r).as_quat(), np.float64)
        raise ModelError(f"{what}: rotation matrix must be orthonormal with determinant +1")
    raise ModelError(
        f"{what}: rotation must be a non-zero finite (4,) quaternion (x, y, z, w) or a (3, 3) "
        f"rotation matrix, got shape {r.shape}"
    )


def _posed_points(points: NDArray[np.float32], matrix: NDArray[np.float64]) -> NDArray[np.float32]:
    """(n, 3) float32 ``R p + t`` for a (4, 4) rigid ``matrix`` (the one rounding rule for both
    :meth:`FaceModel.evaluate` and :meth:`FaceModel.evaluate_at`)."""
    out: NDArray[np.float32] = (points @ matrix[:3, :3].T.astype(np.float32)) + matrix[:3, 3].astype(
        np.float32
    )
    return out


@dataclass(frozen=True, eq=False)
class BlendShape:
    """A named blendshape stored as a per-vertex displacement from the neutral.

    Parameters
    ----------
    name : str
        Unique within a model.
    delta : (n, 3) float
        Displacement of every vertex at weight 1 (stored float32, read-only).
    slider_min, slider_max : float
        Allowed weight range (Blender's "Range Min/Max"); weights are clamped to it.
    mute : bool
        A muted shape contributes nothing but keeps its weight.
    vertex_mask : (n,) float or None
        Optional per-vertex factor in [0, 1] (Blender's shape-key vertex group).
    """

    name: str
    delta: NDArray[np.float32]
    slider_min: float = 0.0
    slider_max: float = 1.0
    mute: bool = False
    vertex_mask: NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ModelError(f"blendshape name must be a non-empty string, got {self.name!r}")
        d = np.asarray(self.delta)
        if d.ndim != 2 or d.shape[1] != 3:
            raise ModelError(f"blendshape {self.name!r}: delta must be (n, 3), got {d.shape}")
        d32 = d if (d.dtype == np.float32 and not d.flags.writeable) else d.astype(np.float32)
        if not np.isfinite(d32).all():
            row = int(np.flatnonzero(~np.isfinite(d32).all(axis=1))[0])
            raise ModelError(f"blendshape {self.name!r}: delta has NaN/inf at vertex {row}")
        object.__setattr__(self, "delta", _readonly(d32))
        lo, hi = float(self.slider_min), float(self.slider_max)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ModelError(
                f"blendshape {self.name!r}: need finite slider_min < slider_max, got {lo}, {hi}"
            )
        object.__setattr__(self, "slider_min", lo)
        object.__setattr__(self, "slider_max", hi)
        object.__setattr__(self, "mute", bool(self.mute))
        if self.vertex_mask is not None:
            m = np.asarray(self.vertex_mask, dtype=np.float32).reshape(-1)
            if m.shape[0] != d32.shape[0]:
                raise ModelError(
                    f"blendshape {self.name!r}: vertex_mask has {m.shape[0]} values, "
                    f"expected one per vertex ({d32.shape[0]})"
                )
            if not (np.isfinite(m).all() and m.min() >= 0.0 and m.max() <= 1.0):
                raise ModelError(f"blendshape {self.name!r}: vertex_mask values must be in [0, 1]")
            object.__setattr__(self, "vertex_mask", _readonly(m))

    def replace(self, **changes: Any) -> BlendShape:
        """A copy with some fields changed (arrays are shared, not copied)."""
        return dataclasses.replace(self, **changes)

    def effective_delta(self) -> NDArray[np.float32]:
        """(n, 3) float32: the delta with the vertex mask applied."""
        if self.vertex_mask is None:
            return self.delta
        return self.delta * self.vertex_mask[:, None]


def _detached(shape: BlendShape) -> BlendShape:
    """``shape`` with a delta (n, 3) and mask (n,) that own their memory (for undo steps)."""
    mask = shape.vertex_mask
    return shape.replace(delta=_owned(shape.delta), vertex_mask=None if mask is None else _owned(mask))


@dataclass(frozen=True)
class ModelMetadata:
    """Where the model came from and how to read its coordinates.

    ``units`` is a length unit name ("m", "cm", "dm", "mm"); ``up_axis`` and
    ``front_axis`` are signed axis names ("+y", "+z"): the face looks toward
    ``front_axis``. "Left" in shape names always means the subject's left.
    """

    name: str = ""
    units: str = "m"
    up_axis: str = "+y"
    front_axis: str = "+z"
    provenance: tuple[Mapping[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if self.units not in UNIT_TO_METRES:
            raise ModelError(f"metadata.units must be one of {sorted(UNIT_TO_METRES)}, got {self.units!r}")
        for ax_name in ("up_axis", "front_axis"):
            ax = getattr(self, ax_name)
            if ax not in AXES:
                raise ModelError(f"metadata.{ax_name} must be one of {AXES}, got {ax!r}")
        object.__setattr__(
            self, "provenance", tuple(MappingProxyType(dict(p)) for p in self.provenance)
        )

    @property
    def metres_per_unit(self) -> float:
        return UNIT_TO_METRES[self.units]

    def with_provenance(self, entry: Mapping[str, Any]) -> ModelMetadata:
        return dataclasses.replace(self, provenance=(*self.provenance, entry))

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "units": self.units,
            "up_axis": self.up_axis,
            "front_axis": self.front_axis,
            "provenance": [dict(p) for p in self.provenance],
        }


#: Tolerance, relative to (1 + the largest neutral coordinate), within which a
#: saved expression's recipe counts as playing back its look (float32 round-off).
_PLAYBACK_ATOL = 1e-6

UNIT_TO_METRES = {"m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001}
AXES = ("+x", "-x", "+y", "-y", "+z", "-z")


@dataclass(frozen=True, eq=False)
class HandleSet:
    """Handle vertices for shell editing (filled by the handle-editing tool).

    Parameters
    ----------
    vertices : (h,) int
        Vertex ids of the handles, in handle order.
    offsets : (h, 3) float
        Displacement of each handle on top of the current blend (the edit layer).
    names : tuple of str
        One label per handle.
    mirror : (h,) int
        Index of the mirror handle, or -1.
    """

    vertices: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, np.int32))
    offsets: NDArray[np.float32] = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    names: tuple[str, ...] = ()
    mirror: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, np.int32))

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.int32).reshape(-1)
        o = np.asarray(self.offsets, dtype=np.float32).reshape(-1, 3)
        mi = np.asarray(self.mirror, dtype=np.int32).reshape(-1)
        if mi.size == 0:
            mi = np.full(v.size, -1, np.int32)
        if o.shape[0] == 0:
            o = np.zeros((v.size, 3), np.float32)
        names = tuple(self.names) or tuple(f"h{i}" for i in range(v.size))
        if not (o.shape[0] == v.size == mi.size == len(names)):
            raise ModelError(
                "handles: vertices, offsets, names and mirror need one entry per handle, got "
                f"{v.size}, {o.shape[0]}, {len(names)}, {mi.size}"
            )
        for name, arr in (("vertices", v), ("offsets", o), ("mirror", mi)):
            object.__setattr__(self, name, _readonly(arr))
        object.__setattr__(self, "names", names)

    def __len__(self) -> int:
        return int(self.vertices.size)


class FaceModelEvents(SignalGroup):
    """One signal per field; ``*_changing`` fire during interactions only."""

    weights = Signal(dict)
    weights_changing = Signal(dict)
    shapes = Signal()
    # no ``vertices`` signal: the neutral mesh and topology never change after
    # construction (another mesh is another model)
    handles = Signal()
    handles_changing = Signal()
    regions = Signal()
    paint_layers = Signal()
    paint_layers_changing = Signal()
    expressions = Signal()
    tracks = Signal()
    time = Signal(float)
    metadata = Signal()
    shell_stiffness = Signal()
    deformed = Signal(bool)
    history = Signal()


#: Fields stored in the generic slots, and whether they change ``evaluate()``.
_SLOTS: dict[str, bool] = {
    "handles": True,
    "regions": True,
    "paint_layers": True,
    "expressions": True,
    "tracks": False,
}


@dataclass
class _Interaction:
    label: str
    weights_before: dict[str, float] = field(default_factory=dict)
    slots_before: dict[str, Any] = field(default_factory=dict)
    paint_stroke: tuple[str, Stroke] | None = None
    token: InteractionToken | None = None
    on_close: Callable[[], None] | None = None


@dataclass(frozen=True)
class InteractionToken:
    """Names one open interaction (a drag, a stroke) across separate messages.

    Returned by :meth:`FaceModel.begin_interaction`; pass it back to
    :meth:`FaceModel.end_interaction` (one undo step) or
    :meth:`FaceModel.cancel_interaction` (everything put back, no undo step).
    A token of an interaction that was already closed is refused, so a late
    message of an old gesture can never close a newer one.
    """

    label: str
    serial: int


_token_serials = itertools.count(1)


class FaceModel:
    """Neutral mesh, blendshapes, weights and editing layers, with undo and events.

    Parameters
    ----------
    vertices : (n, 3) float
        Neutral vertex positions.
    faces : (m, 3) int
        Triangles. If ``polygons`` is given, pass ``faces=None`` to triangulate them.
    shapes : iterable of BlendShape
        Blendshapes, names unique, deltas (n, 3).
    polygons : Polygons, optional
        Original faces (quads) kept for export; defaults to the triangles.
    component_labels : (n,) int, optional
        Connected-component label of each vertex (eyes, teeth, skin...).
    component_names : list of str, optional
        One name per label value.
    metadata : ModelMetadata, optional
    weights : mapping, optional
        Initial weights (default 0 for every shape).
    handles : HandleSet, optional
        Initial handle set (default: none).
    """

    def __init__(
        self,
        vertices: ArrayLike,
        faces: ArrayLike | None,
        shapes: Iterable[BlendShape] = (),
        *,
        polygons: Polygons | None = None,
        component_labels: ArrayLike | None = None,
        component_names: Iterable[str] | None = None,
        metadata: ModelMetadata | None = None,
        weights: Mapping[str, float] | None = None,
        handles: HandleSet | None = None,
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
        self._vertices = _readonly(V)
        self._vertices32 = _readonly(V.astype(np.float32))
        self._faces = _readonly(F.astype(np.int32))
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
        self._component_labels = _readonly(labels)
        self._component_names = tuple(names)
        self._metadata = metadata or ModelMetadata()

        self._lock = threading.RLock()
        self.events = FaceModelEvents()
        self.history = History()
        self._interaction: _Interaction | None = None
        self._evaluated: NDArray[np.float32] | None = None
        self._blended: NDArray[np.float32] | None = None
        # (local mesh it was made from, head matrix, posed mesh): evaluate()'s posed cache
        self._posed: tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float32]] | None = None
        # (timeline, time, head matrix or None): the live head pose
        self._pose_cache: tuple[Timeline, float, NDArray[np.float64] | None] | None = None
        self._layer_providers: dict[str, Callable[[FaceModel], NDArray[np.float32] | None]] = {}
        # layer order: region blend (a correction of the blend), handles, paint
        self._layer_providers["regions"] = region_layer
        self._handle_layer = HandleLayer()
        self._layer_providers["handles"] = self._handle_layer
        self._paint_layer = PaintLayer()
        self._layer_providers["paint"] = self._paint_layer

        self._shapes: tuple[BlendShape, ...] = ()
        self._stack: NDArray[np.float32] = np.zeros((0, n, 3), np.float32)
        self._effective: NDArray[np.float32] = self._stack
        self._index: dict[str, int] = {}
        self._weights: dict[str, float] = {}
        self._install_shapes(tuple(shapes), {})
        if weights:
            unknown = set(weights) - set(self._index)
            if unknown:
                raise ModelError(f"weights: unknown shape names {sorted(unknown)}")
            for k, v in weights.items():
                self._weights[k] = self._clamp(k, v)
        handles = handles if handles is not None else HandleSet()
        if len(handles) and (handles.vertices.min() < 0 or handles.vertices.max() >= n):
            raise ModelError(f"handles: vertex ids must be in 0..{n - 1}")
        self._slots: dict[str, Any] = {
            "handles": handles,
            "regions": None,
            "paint_layers": PaintMix(),
            "expressions": MappingProxyType({}),
            "tracks": Timeline(),
        }
        self._time = 0.0

    # ------------------------------------------------------------------ basics
    def __repr__(self) -> str:
        return (
            f"<FaceModel {self._metadata.name or 'unnamed'}: {self.n_vertices} vertices, "
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

    # ------------------------------------------------------------------ shapes
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
    def arkit_names(self) -> dict[str, str | None]:
        """Shape name → canonical ARKit-52 name (or None when not recognised)."""
        from workbench.arkit import canonical_arkit_name

        return {s.name: canonical_arkit_name(s.name) for s in self._shapes}

    def _shape_index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(
                f"no blendshape named {name!r}; the model has {len(self._shapes)} shapes"
                + (f", e.g. {self.shape_names[:5]}" if self._shapes else "")
            ) from None

    def _install_shapes(self, shapes: tuple[BlendShape, ...], weights: Mapping[str, float]) -> None:
        """Replace the shape list; rebuild the stacked delta matrix; no events, no history."""
        n = self.n_vertices
        names = [s.name for s in shapes]
        seen: set[str] = set()
        for s in shapes:
            if not isinstance(s, BlendShape):
                raise ModelError(f"shapes must be BlendShape objects, got {type(s).__name__}")
            if s.delta.shape[0] != n:
                raise ModelError(
                    f"blendshape {s.name!r} has {s.delta.shape[0]} vertices, the neutral has {n}"
                )
            if s.name in seen:
                raise ModelError(f"duplicate blendshape name {s.name!r}")
            seen.add(s.name)
        stack = np.empty((len(shapes), n, 3), np.float32)
        for i, s in enumerate(shapes):
            stack[i] = s.delta
        _readonly(stack)
        # Shapes share the stacked memory so the model holds each delta once.
        self._shapes = tuple(s.replace(delta=stack[i]) for i, s in enumerate(shapes))
        self._stack = stack
        self._rebuild_effective()
        self._index = {nm: i for i, nm in enumerate(names)}
        self._weights = {nm: float(weights.get(nm, 0.0)) for nm in names}
        self._evaluated = None
        self._blended = None

    def _rebuild_effective(self) -> None:
        """Recompute the (k, n, 3) masked deltas from the stack and the shapes' masks."""
        if any(s.vertex_mask is not None for s in self._shapes):
            eff = self._stack.copy()
            for i, s in enumerate(self._shapes):
                if s.vertex_mask is not None:
                    eff[i] *= s.vertex_mask[:, None]
            self._effective = _readonly(eff)
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

    # Undo steps of shape edits keep only what the edit changed: the one added or
    # removed shape (with a delta that owns its memory) or the changed fields.
    # Never a shape of the live model: its delta is a view into the whole
    # (k, n, 3) stack and would keep that stack alive (1.2 MB per shape at 100k
    # vertices) while the step books a few bytes, defeating History.max_bytes.
    def _insert_shape(self, index: int, shape: BlendShape, weight: float) -> None:
        """Insert ``shape`` at position ``index`` with ``weight``; events, no history."""
        with self._lock:
            weights = dict(self._weights)
            weights[shape.name] = weight
            self._apply_shapes((*self._shapes[:index], shape, *self._shapes[index:]), weights)

    def _delete_shape(self, name: str) -> None:
        """Remove shape ``name`` and its weight; events, no history."""
        with self._lock:
            i = self._shape_index(name)
            weights = {k: v for k, v in self._weights.items() if k != name}
            self._apply_shapes(self._shapes[:i] + self._shapes[i + 1 :], weights)

    def _set_shape_props(self, name: str, props: Mapping[str, Any], weight: float) -> None:
        """Change fields of shape ``name`` other than its delta, and its weight; events, no history.

        The delta stays the same view of the current stack: nothing (k, n, 3) is copied.
        """
        with self._lock:
            i = self._shape_index(name)
            new = self._shapes[i].replace(**props)
            self._shapes = (*self._shapes[:i], new, *self._shapes[i + 1 :])
            if new.name != name:
                self._index = {s.name: j for j, s in enumerate(self._shapes)}
                # rebuilt in shape order so weights keep following the shape list
                self._weights = {(new.name if k == name else k): v for k, v in self._weights.items()}
            self._weights[new.name] = weight
            if "vertex_mask" in props:
                self._rebuild_effective()
            self._evaluated = None
            self._blended = None
            self._emit_shapes()

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
    ) -> BlendShape:
        """Add a blendshape (undoable). ``delta`` is a displacement, not an absolute shape."""
        shape = BlendShape(
            name,
            np.asarray(delta),
            slider_min,
            slider_max,
            mute,
            None if vertex_mask is None else np.asarray(vertex_mask),
        )
        label = f"Add shape {name}"
        with self._lock:
            self._refuse_in_interaction(label)
            if name in self._index:
                raise ModelError(f"a blendshape named {name!r} already exists")
            w = min(max(float(weight), shape.slider_min), shape.slider_max)
            index = len(self._shapes)
            kept = _detached(shape)  # the redo copy: the added delta is the step's new memory
            self._insert_shape(index, kept, w)
            self._push(
                Command(
                    label,
                    lambda: self._delete_shape(name),
                    lambda: self._insert_shape(index, kept, w),
                    payload_nbytes(kept),
                )
            )
            return self.shape(name)

    def remove_shape(self, name: str) -> None:
        """Remove a blendshape (undoable)."""
        label = f"Remove shape {name}"
        with self._lock:
            self._refuse_in_interaction(label)
            i = self._shape_index(name)
            kept = _detached(self._shapes[i])  # the one removed delta, copied out of the stack
            w = self._weights[name]
            self._delete_shape(name)
            self._push(
                Command(
                    label,
                    lambda: self._insert_shape(i, kept, w),
                    lambda: self._delete_shape(name),
                    payload_nbytes(kept),
                )
            )

    def _edit_shape_props(self, name: str, label: str, /, **changes: Any) -> None:
        with self._lock:
            self._refuse_in_interaction(label)
            old = self._shapes[self._shape_index(name)]
            new = old.replace(**changes)  # validates before anything changes
            new_name = new.name
            if new_name != name and new_name in self._index:
                raise ModelError(f"a blendshape named {new_name!r} already exists")
            before = {f: _detached_value(getattr(old, f)) for f in changes}
            after = {f: _detached_value(getattr(new, f)) for f in changes}
            w_before = self._weights[name]
            w_after = min(max(w_before, new.slider_min), new.slider_max)
            self._set_shape_props(name, after, w_after)
            self._push(
                Command(
                    label,
                    lambda: self._set_shape_props(new_name, before, w_before),
                    lambda: self._set_shape_props(name, after, w_after),
                    payload_nbytes([before, after]) + 64,
                )
            )

    def rename_shape(self, name: str, new_name: str) -> None:
        self._edit_shape_props(name, f"Rename {name} to {new_name}", name=new_name)

    def set_shape_mute(self, name: str, mute: bool) -> None:
        self._edit_shape_props(name, f"{'Mute' if mute else 'Unmute'} {name}", mute=bool(mute))

    def set_shape_range(self, name: str, slider_min: float, slider_max: float) -> None:
        self._edit_shape_props(
            name, f"Range of {name}", slider_min=slider_min, slider_max=slider_max
        )

    def set_shape_mask(self, name: str, vertex_mask: ArrayLike | None) -> None:
        self._edit_shape_props(
            name,
            f"Mask {name}",
            vertex_mask=None if vertex_mask is None else np.asarray(vertex_mask),
        )

    # ----------------------------------------------------------------- weights
    @property
    def weights(self) -> Mapping[str, float]:
        """Read-only mapping shape name → current weight."""
        return MappingProxyType(dict(self._weights))

    def weight_vector(self) -> NDArray[np.float32]:
        """(k,) float32 weights in shape order, muted shapes as 0."""
        return np.array(
            [0.0 if s.mute else self._weights[s.name] for s in self._shapes], np.float32
        )

    def _clamp(self, name: str, value: float) -> float:
        s = self._shapes[self._shape_index(name)]
        v = float(value)
        if not math.isfinite(v):
            raise ModelError(f"weight for {name!r} must be finite, got {value!r}")
        return min(max(v, s.slider_min), s.slider_max)

    def _apply_weights(self, values: Mapping[str, float], final: bool) -> None:
        with self._lock:
            self._weights.update(values)
            self._evaluated = None
            self._blended = None
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
            self._push(
                Command(
                    label or f"Set {len(changed)} weights",
                    lambda: self._apply_weights(before, True),
                    lambda: self._apply_weights(changed, True),
                    payload_nbytes([before, changed]),
                )
            )

    def reset_weights(self) -> None:
        """Set every weight to 0 (clamped into range) as one undoable edit."""
        self.set_weights({s.name: 0.0 for s in self._shapes}, label="Reset weights")

    # ------------------------------------------------------------------- slots
    @property
    def handles(self) -> HandleSet:
        """Handle vertices and their offsets (the handle-editing layer)."""
        return self._slots["handles"]

    @property
    def regions(self) -> RegionState | None:
        """Blend regions with the level shown and per-region weights (None until segmented)."""
        return self._slots["regions"]

    @property
    def paint_layers(self) -> PaintMix:
        """Painted blend functions, expression name -> (n,) weights (empty until painted)."""
        return self._slots["paint_layers"]

    @property
    def expressions(self) -> Mapping[str, Expression]:
        """Saved expressions (name -> :class:`~workbench.methods.paint.expressions.Expression`)."""
        return self._slots["expressions"]

    @property
    def tracks(self) -> Timeline:
        """The keyframe :class:`~workbench.animation.tracks.Timeline` (no tracks until something is keyed)."""
        return self._slots["tracks"]

    def _apply_slot(self, name: str, value: Any, final: bool) -> None:
        with self._lock:
            pose_before = self._live_head_matrix() if name == "tracks" else None
            self._slots[name] = value
            changing = getattr(self.events, f"{name}_changing", None)
            if final or changing is None:
                getattr(self.events, name).emit()
            else:
                changing.emit()
            if _SLOTS[name]:
                self._evaluated = None
                self.events.deformed.emit(final)
            elif name == "tracks":
                # the live head pose follows the timeline: a key edit (or its undo)
                # at the current time moves the shown head
                after = self._live_head_matrix()
                if (pose_before is None) != (after is None) or (
                    pose_before is not None and after is not None
                    and not np.array_equal(pose_before, after)
                ):
                    self.events.deformed.emit(final)

    def set_slot(self, name: str, value: Any, label: str) -> None:
        """Replace a layer slot (handles, regions, paint_layers, tracks) as one undoable edit.

        Tools call this with immutable values (new objects, not mutated old ones),
        so undo can keep the old object as it was.
        """
        if name not in _SLOTS:
            raise ModelError(f"unknown slot {name!r}; slots are {sorted(_SLOTS)}")
        if isinstance(value, dict):
            value = MappingProxyType(dict(value))
        with self._lock:
            old = self._slots[name]
            if old is value:
                return
            inter = self._interaction
            if inter is not None:
                inter.slots_before.setdefault(name, old)
                self._apply_slot(name, value, final=False)
                return
            self._apply_slot(name, value, final=True)
            self._push(
                Command(
                    label,
                    lambda: self._apply_slot(name, old, True),
                    lambda: self._apply_slot(name, value, True),
                    payload_nbytes(value),
                )
            )

    def set_handles(self, handles: HandleSet, label: str = "Edit handles") -> None:
        """Replace the handle set (undoable)."""
        if not isinstance(handles, HandleSet):
            raise ModelError(f"set_handles expects a HandleSet, got {type(handles).__name__}")
        if len(handles) and (handles.vertices.min() < 0 or handles.vertices.max() >= self.n_vertices):
            raise ModelError(f"handles: vertex ids must be in 0..{self.n_vertices - 1}")
        self.set_slot("handles", handles, label)

    def add_handle(self, vertex: int, name: str | None = None, mirror: int = -1) -> int:
        """Add a handle at ``vertex`` (undoable); returns its index.

        ``mirror`` is the index of an existing handle that mirrors this one (or -1);
        the link is made both ways.
        """
        with self._lock:
            h = self.handles
            v = int(vertex)
            if not 0 <= v < self.n_vertices:
                raise ModelError(f"add_handle: vertex must be in 0..{self.n_vertices - 1}, got {vertex}")
            idx = len(h)
            mir = np.append(h.mirror, np.int32(mirror))
            if mirror >= 0:
                if mirror >= idx:
                    raise ModelError(f"add_handle: mirror must index an existing handle, got {mirror}")
                mir[mirror] = idx
            self.set_handles(
                HandleSet(
                    np.append(h.vertices, v),
                    np.vstack([h.offsets, np.zeros((1, 3), np.float32)]),
                    (*h.names, name or f"h{idx}"),
                    mir,
                ),
                label=f"Add handle {name or idx}",
            )
            return idx

    def remove_handle(self, index: int) -> None:
        """Remove handle ``index`` (undoable); mirror links to it are cleared."""
        with self._lock:
            h = self.handles
            if not 0 <= index < len(h):
                raise ModelError(f"remove_handle: index must be in 0..{len(h) - 1}, got {index}")
            keep = np.arange(len(h)) != index
            remap = np.cumsum(keep) - 1
            mir = h.mirror[keep]
            mir = np.where(mir == index, -1, np.where(mir >= 0, remap[np.maximum(mir, 0)], -1))
            self.set_handles(
                HandleSet(
                    h.vertices[keep],
                    h.offsets[keep],
                    tuple(n for i, n in enumerate(h.names) if i != index),
                    mir,
                ),
                label=f"Remove handle {h.names[index]}",
            )

    def set_handle_offsets(self, offsets: ArrayLike, label: str = "Move handles") -> None:
        """Set every handle's offset, (h, 3), on top of the blend (undoable)."""
        with self._lock:
            h = self.handles
            o = np.asarray(offsets, dtype=np.float32).reshape(-1, 3)
            if o.shape[0] != len(h):
                raise ModelError(f"set_handle_offsets: expected ({len(h)}, 3) offsets, got {o.shape}")
            if not np.isfinite(o).all():
                raise ModelError("set_handle_offsets: offsets must be finite")
            self.set_slot("handles", dataclasses.replace(h, offsets=o), label)

    def move_handle(self, index: int, offset: ArrayLike, *, symmetric: bool = False) -> None:
        """Set one handle's offset (3,); with ``symmetric`` its mirror gets the x-reflected offset.

        The reflection assumes the face is symmetric about the plane x = 0 of
        model space (true for the sample head). Call inside ``model.interaction``
        while dragging so the drag is one undo step.
        """
        with self._lock:
            h = self.handles
            if not 0 <= index < len(h):
                raise ModelError(f"move_handle: index must be in 0..{len(h) - 1}, got {index}")
            o = h.offsets.copy()
            o[index] = np.asarray(offset, dtype=np.float32).reshape(3)
            m = int(h.mirror[index])
            if symmetric and m >= 0:
                o[m] = o[index] * np.array([-1.0, 1.0, 1.0], np.float32)
            self.set_handle_offsets(o, label=f"Move handle {h.names[index]}")

    def reset_handle_offsets(self) -> None:
        """Zero every handle offset (undoable)."""
        self.set_handle_offsets(np.zeros((len(self.handles), 3)), label="Reset handles")

    def prepare_handles(self) -> None:
        """Build the shell basis for the current handle set now (else on the first drag).

        Reports through the callback of :meth:`set_handle_progress`; takes ~0.3 s at
        20k vertices and ~2 s at 80k with CHOLMOD.
        """
        with self._lock:
            if len(self.handles):
                self._handle_layer.deformer(self)

    def handle_displacement(self) -> NDArray[np.float32]:
        """(n, 3) float32: the displacement the handle layer adds (a copy)."""
        with self._lock:
            d = self._handle_layer(self)
            return np.zeros((self.n_vertices, 3), np.float32) if d is None else d.copy()

    @property
    def shell_stiffness(self) -> tuple[float, float]:
        """``(k_s, k_b)`` of the handle layer's thin-shell energy."""
        return self._handle_layer.k_s, self._handle_layer.k_b

    def set_shell_stiffness(self, k_s: float, k_b: float) -> None:
        """Change the stiffness of the handle layer as one undoable step.

        The shell basis is rebuilt on the next evaluation. Emits
        ``shell_stiffness`` and ``deformed``; setting the current values records nothing.
        """
        ks, kb = float(k_s), float(k_b)
        if not (math.isfinite(ks) and math.isfinite(kb)) or ks < 0 or kb < 0 or (ks == 0 and kb == 0):
            raise ModelError(f"need finite k_s >= 0, k_b >= 0, not both zero; got {k_s}, {k_b}")
        with self._lock:
            old, new = self.shell_stiffness, (ks, kb)
            if new == old:
                return
            self._apply_shell_stiffness(new)
            self._push(
                Command(
                    "Shell stiffness",
                    lambda: self._apply_shell_stiffness(old),
                    lambda: self._apply_shell_stiffness(new),
                    payload_nbytes([old, new]),
                )
            )

    def _apply_shell_stiffness(self, stiffness: tuple[float, float]) -> None:
        with self._lock:
            self._handle_layer.k_s, self._handle_layer.k_b = stiffness
            self._evaluated = None
            self.events.shell_stiffness.emit()
            self.events.deformed.emit(True)

    def set_handle_progress(self, progress: Callable[[float, str], None] | None) -> None:
        """Callback ``progress(fraction, message)`` for long basis precomputes (a progress bar)."""
        self._handle_layer.progress = progress

    def bake_handles_to_shape(self, name: str) -> BlendShape:
        """Turn the handle layer into a new blendshape ``name`` at weight 1, and zero the offsets.

        One undo step. The new shape's delta is the handle layer's displacement,
        so the face looks the same before and after.
        """
        with self._lock:
            if self._interaction is not None:
                raise ModelError("bake_handles_to_shape: finish the drag first")
            delta = self.handle_displacement()
            with self.history.group(f"Bake handles to {name}"):
                self.add_shape(name, delta, weight=1.0)
                self.reset_handle_offsets()
            self.events.history.emit()
            return self.shape(name)

    # --------------------------------------------------- expressions, painting
    def save_expression(self, name: str) -> Expression:
        """Save the current evaluated state as expression ``name`` (undoable); replaces a same-named one.

        The displacement is ``evaluate(posed=False) - neutral``: the head pose is
        a rigid motion of the whole head, not part of an expression.
        """
        with self._lock:
            # the expression is a deformation of the face: without the head pose
            expr = Expression(
                name,
                self.evaluate(posed=False) - self._vertices32,
                dict(self._weights),
                self.handles.vertices,
                self.handles.offsets,
            )
            lib = dict(self.expressions)
            lib[name] = expr
            self.set_slot("expressions", lib, f"Save expression {name}")
            return expr

    def remove_expression(self, name: str) -> None:
        """Remove a saved expression (undoable); its paint is removed with it."""
        with self._lock:
            if name not in self.expressions:
                raise KeyError(f"no saved expression named {name!r}; have {list(self.expressions)}")
            with self.history.group(f"Remove expression {name}"):
                if name in self.paint_layers:
                    maps = {k: v for k, v in self.paint_layers.items() if k != name}
                    self.set_slot("paint_layers", PaintMix(maps), "Remove paint")
                self.set_slot(
                    "expressions", {k: v for k, v in self.expressions.items() if k != name},
                    f"Remove expression {name}",
                )
            self.events.history.emit()

    @property
    def paint_surface(self) -> Any:
        """The :class:`~workbench.methods.paint.painting.PaintSurface` (edge graph, mirror map) of this mesh."""
        return self._paint_layer.surface(self)

    def _check_expression(self, name: str) -> None:
        if name not in self.expressions and name not in self._index:
            raise KeyError(
                f"no expression named {name!r}: paint with a blendshape name or a saved expression"
            )

    def paint_dab(self, expression: str, center: int, brush: Brush | None = None) -> None:
        """One brush dab of ``expression`` at vertex ``center``.

        Undoable; call inside ``model.interaction("Paint ...")`` so that a
        stroke (press, move, release) is one undo step — and so that the stroke
        never paints beyond the brush opacity where its dabs overlap
        (:class:`~workbench.methods.paint.painting.Stroke`).
        """
        with self._lock:
            self._check_expression(expression)
            stroke = None
            inter = self._interaction
            if inter is not None:
                if inter.paint_stroke is None or inter.paint_stroke[0] != expression:
                    inter.paint_stroke = (expression, Stroke(self.paint_layers, self.n_vertices))
                stroke = inter.paint_stroke[1]
            mix = apply_dab(
                self.paint_layers, expression, self.paint_surface, brush or Brush(), int(center), stroke
            )
            self.set_slot("paint_layers", mix, f"Paint {expression}")

    def paint_stroke(self, expression: str, centers: Iterable[int], brush: Brush | None = None) -> None:
        """A whole stroke (several dabs) as one undo step."""
        with self.interaction(f"Paint {expression}"):
            for c in centers:
                self.paint_dab(expression, c, brush)

    def paint_flood(self, expression: str, opacity: float = 1.0, vertices: ArrayLike | None = None) -> None:
        """Paint ``expression`` everywhere (or on ``vertices``) with strength ``opacity`` (undoable)."""
        with self._lock:
            self._check_expression(expression)
            mix = flood(self.paint_layers, expression, opacity, self.n_vertices, vertices)
            self.set_slot("paint_layers", mix, f"Flood {expression}")

    def paint_normalize(self) -> None:
        """Make painted weights sum to 1 wherever something is painted (undoable)."""
        with self._lock:
            self.set_slot("paint_layers", normalize(self.paint_layers, self.n_vertices), "Normalize paint")

    def set_paint(self, mix: PaintMix, label: str = "Set paint") -> None:
        """Replace the whole paint layer (e.g. a regional blend); undoable."""
        if not isinstance(mix, PaintMix):
            raise ModelError(f"set_paint expects a PaintMix, got {type(mix).__name__}")
        for name, w in mix.items():
            self._check_expression(name)
            if w.shape != (self.n_vertices,):
                raise ModelError(f"paint map {name!r} must have shape ({self.n_vertices},), got {w.shape}")
        self.set_slot("paint_layers", mix, label)

    def clear_paint(self) -> None:
        """Remove all paint (undoable)."""
        self.set_slot("paint_layers", PaintMix(), "Clear paint")

    def paint_displacement(self) -> NDArray[np.float32]:
        """(n, 3) float32: what the paint layer adds on top of blend, regions and handles (a copy)."""
        with self._lock:
            d = self._paint_layer(self)
            return np.zeros((self.n_vertices, 3), np.float32) if d is None else d.copy()

    def bake_paint_to_shape(self, name: str) -> BlendShape:
        """Turn the paint layer into a new blendshape at weight 1 and clear the paint (one undo step)."""
        with self._lock:
            if self._interaction is not None:
                raise ModelError("bake_paint_to_shape: finish the stroke first")
            delta = self.paint_displacement()
            with self.history.group(f"Bake paint to {name}"):
                self.add_shape(name, delta, weight=1.0)
                self.clear_paint()
            self.events.history.emit()
            return self.shape(name)

    # ------------------------------------------------------------------ regions
    def segment_regions(self, threshold: float = 0.25, **options: Any) -> RegionState:
        """Find local blend regions (Joshi et al. 2003) and store them (undoable).

        ``options`` go to :func:`workbench.methods.regions.segmentation.segment_blend_regions`. The
        region weights start equal to the global weights (the face does not change).
        """
        from workbench.methods.regions.segmentation import segment_blend_regions

        with self._lock:
            regions = segment_blend_regions(self, threshold, **options)
            old = self.regions
            level = min(old.level, regions.n_levels - 1) if isinstance(old, RegionState) else 0
            state = RegionState(regions, level, None)
            self.set_slot("regions", state, f"Segment regions (t={threshold:g})")
            return state

    def set_region_level(self, level: int) -> None:
        """Show/edit hierarchy ``level`` (weights are carried over to it); undoable."""
        with self._lock:
            st = self._require_regions("set_region_level")
            lv = st.regions.check_level(level)
            self.set_slot("regions", RegionState(st.regions, lv, st.weights), f"Region level {lv}")

    def set_region_weights(self, weights: RegionWeights | None, label: str = "Region weights") -> None:
        """Set per-region blend weights (None: regions follow the global sliders); undoable."""
        with self._lock:
            st = self._require_regions("set_region_weights")
            if weights is not None and tuple(weights.shape_names) != tuple(self.shape_names):
                raise ModelError("set_region_weights: weights were made for other shapes")
            self.set_slot("regions", RegionState(st.regions, st.level, weights), label)

    def _require_regions(self, what: str) -> RegionState:
        st = self.regions
        if not isinstance(st, RegionState):
            raise ModelError(f"{what}: no regions yet; call model.segment_regions() first")
        return st

    # ------------------------------------------- region edits (merge/split/rename/paint)
    # Thin undoable wrappers of the pure edits in workbench.methods.regions.segmentation: each is one
    # set_slot("regions", ...) step (undo restores the previous RegionState object,
    # so the regions come back bit-exact). The per-region blend weights follow the
    # edit's ``origins``: a merged region keeps the weights of the larger region,
    # both halves of a split inherit the split region's, painting keeps everyone's.
    def _apply_region_edit(self, edit: Any, label: str) -> RegionState:
        st = self._require_regions(label)
        if edit.regions is st.regions:
            return st
        rw = st.weights
        if rw is not None:
            rw = RegionWeights(
                rw.level, rw.shape_names, edit.regions.names[rw.level], rw.values[edit.origins[rw.level]]
            )
        state = RegionState(edit.regions, st.level, rw)
        self.set_slot("regions", state, label)
        return state

    def merge_regions(self, level: int, a: int | str, b: int | str, name: str | None = None) -> RegionState:
        """Merge two touching regions of ``level`` (undoable); see :func:`workbench.methods.regions.segmentation.merge_regions`.

        The merged region keeps the lower index and the name and blend weights of
        the larger region (or ``name``); coarser levels merge too if needed to stay nested.
        """
        from workbench.methods.regions.segmentation import merge_regions, region_topology

        with self._lock:
            st = self._require_regions("merge_regions")
            R = st.regions
            edit = merge_regions(R, region_topology(self), level, a, b, name=name)
            lv = R.check_level(level)
            na, nb = R.names[lv][R.region_index(lv, a)], R.names[lv][R.region_index(lv, b)]
            return self._apply_region_edit(edit, f"Merge regions {na} + {nb}")

    def split_region(
        self, level: int, region: int | str, seeds_a: ArrayLike, seeds_b: ArrayLike,
        names: tuple[str, str] | None = None,
    ) -> RegionState:
        """Split a region around two clicked vertices (undoable); see :func:`workbench.methods.regions.segmentation.split_region`.

        Geodesic Voronoi of the seeds on level 0; on coarser levels whole children
        are grouped. Both halves inherit the region's blend weights.
        """
        from workbench.methods.regions.segmentation import region_topology, split_region

        with self._lock:
            st = self._require_regions("split_region")
            R = st.regions
            edit = split_region(R, region_topology(self), level, region, seeds_a, seeds_b, names=names)
            lv = R.check_level(level)
            return self._apply_region_edit(edit, f"Split region {R.names[lv][R.region_index(lv, region)]}")

    def rename_region(self, level: int, region: int | str, name: str) -> RegionState:
        """Rename a region of ``level`` (undoable; labels and weights unchanged)."""
        from workbench.methods.regions.segmentation import rename_region

        with self._lock:
            st = self._require_regions("rename_region")
            R = st.regions
            lv = R.check_level(level)
            old = R.names[lv][R.region_index(lv, region)]
            if old == name:
                return st
            return self._apply_region_edit(rename_region(R, lv, region, name), f"Rename region {old} to {name}")

    def paint_region(self, level: int, region: int | str, vertices: ArrayLike, add: bool = True) -> RegionState:
        """Assign skin vertices to a region (``add``) or return them to the background (undoable).

        See :func:`workbench.methods.regions.segmentation.paint_region`; a paint that changes nothing adds no undo step.
        """
        from workbench.methods.regions.segmentation import paint_region, region_topology

        with self._lock:
            st = self._require_regions("paint_region")
            R = st.regions
            edit = paint_region(R, region_topology(self), level, region, vertices, add=add)
            lv = R.check_level(level)
            verb = "Paint region" if add else "Erase from region"
            return self._apply_region_edit(edit, f"{verb} {R.names[lv][R.region_index(lv, region)]}")

    # ----------------------------------------- end of region edits (merge/split/rename/paint)

    # ----------------------------------------------------------------- timeline
    @property
    def time(self) -> float:
        """Current time in seconds (set by :meth:`set_time`)."""
        return self._time

    def set_timeline(self, timeline: Timeline, label: str = "Edit keys") -> None:
        """Replace the timeline (undoable); it is checked against the model's shapes/handles/regions.

        Raises
        ------
        ModelError
            ``timeline`` is not a Timeline, or it has region tracks and the model
            has no regions.
        TrackError
            The tracks do not fit the model (:meth:`Timeline.check_model`).
        """
        if not isinstance(timeline, Timeline):
            raise ModelError(f"set_timeline expects a Timeline, got {type(timeline).__name__}")
        with self._lock:
            if timeline.region_tracks and not isinstance(self.regions, RegionState):
                raise ModelError(
                    "set_timeline: the timeline keys region weights "
                    f"({len(timeline.region_tracks)} region tracks) but the model has no regions; "
                    "call segment_regions() first"
                )
            timeline.check_model(self)
            self.set_slot("tracks", timeline, label)

    def _grow_range(self, tl: Timeline, time: float) -> Timeline:
        return tl.replace(start=min(tl.start, time), end=max(tl.end, time))

    def key_weights(
        self,
        time: float,
        names: Iterable[str] | None = None,
        interpolation: Interpolation = "bezier",
    ) -> None:
        """Key the current weights at ``time`` (one undo step).

        ``names`` default: every shape that has a non-zero weight or is already keyed.
        """
        with self._lock:
            tl = self.tracks
            if names is None:
                keyed = set(tl.weight_tracks)
                names = [n for n in self.shape_names if self._weights[n] != 0.0 or n in keyed]
            names = list(names)
            for n in names:
                self._shape_index(n)
                tl = tl.add_key(weight_track_name(n), time, self._weights[n], interpolation=interpolation)
            self.set_timeline(self._grow_range(tl, time), f"Key {len(names)} weights at {time:g}s")

    def key_expression(self, time: float, expression: str, interpolation: Interpolation = "bezier") -> None:
        """Key an expression at ``time`` (drop from the gallery onto the timeline); one undo step.

        A blendshape keys itself at 1. A saved expression whose recipe plays
        back its look keys its recipe weights and, when the handle set matches,
        its handle offsets. Any other saved expression (its look comes from
        painting, region weights, handles of another handle set, or shapes
        since removed or edited) is, as in Pighin et al. 1998 §4, a new
        expression of its own: its displacement becomes the blendshape
        ``<expression>_baked`` (added once in the same undo step, reused when
        it already holds exactly that displacement) keyed at 1; keyed handles
        are keyed at rest there, since the bake already holds their effect.

        Every other already-keyed shape is keyed at 0, and a shape keyed for
        the first time gets 0-keys at the earlier key times, so at its time a
        keyed expression plays back exactly as saved, in :meth:`evaluate_at`
        and in every export, as long as the unkeyed state (shapes never keyed,
        live paint and region weights, which the timeline does not animate)
        is at rest.
        """
        with self._lock:
            label = f"Key {expression} at {time:g}s"
            with self.history.group(label):
                handle_key: NDArray[np.float32] | None = None
                if expression in self.expressions:
                    expr = self.expressions[expression]
                    if self._recipe_plays_back(expr):
                        values = dict(expr.weights)
                        same_handles = np.array_equal(expr.handle_vertices, self.handles.vertices)
                        if same_handles and len(self.handles) and np.any(expr.handle_offsets):
                            handle_key = expr.handle_offsets
                    else:
                        values = {self._baked_expression_shape(expr): 1.0}
                        if len(self.handles) and self.tracks.handles is not None:
                            handle_key = np.zeros_like(self.handles.offsets)
                elif expression in self._index:
                    values = {expression: 1.0}
                else:
                    raise KeyError(f"no expression named {expression!r}")
                tl = self.tracks
                keyed = set(tl.weight_tracks)
                earlier = sorted({float(t) for tr in tl.weight_tracks.values() for t in tr.times})
                for n in keyed | {k for k, v in values.items() if v != 0.0}:
                    if n not in keyed:
                        # a newly keyed shape was 0 in the expressions keyed before
                        for t in earlier:
                            tl = tl.add_key(weight_track_name(n), t, 0.0, interpolation=interpolation)
                    tl = tl.add_key(
                        weight_track_name(n), time, values.get(n, 0.0), interpolation=interpolation
                    )
                if handle_key is not None:
                    tl = tl.add_key("handles", time, handle_key, interpolation=interpolation)
                self.set_timeline(self._grow_range(tl, time), label)
            self.events.history.emit()

    def _recipe_plays_back(self, expr: Expression) -> bool:
        """True if keying ``expr``'s weights and handle offsets reproduces its displacement.

        The recipe is evaluated as the timeline plays it: its weights (0 for
        shapes it does not name), its handle offsets when the handle set is
        the one it was saved with (else none), no paint and no region weights
        (the timeline animates neither), and every other layer as it is. The
        model is restored afterwards; no events.
        """
        if any(v != 0.0 and k not in self._index for k, v in expr.weights.items()):
            return False  # a shape of the recipe is gone
        h = self.handles
        same_handles = np.array_equal(expr.handle_vertices, h.vertices)
        if not same_handles and np.any(expr.handle_offsets):
            return False  # its handle deformation cannot be keyed on this handle set
        regions = self._slots["regions"]
        saved = (dict(self._weights), h, regions, self._slots["paint_layers"], self._evaluated, self._blended)
        try:
            self._weights = {
                s.name: self._clamp(s.name, expr.weights.get(s.name, 0.0)) for s in self._shapes
            }
            offsets = expr.handle_offsets if same_handles else np.zeros_like(h.offsets)
            self._slots["handles"] = dataclasses.replace(h, offsets=offsets)
            if isinstance(regions, RegionState) and regions.weights is not None:
                self._slots["regions"] = RegionState(regions.regions, regions.level, None)
            self._slots["paint_layers"] = PaintMix()
            self._evaluated = None
            self._blended = None
            played = self.evaluate(posed=False) - self._vertices32
        finally:
            self._weights, self._slots["handles"], self._slots["regions"] = saved[0], saved[1], saved[2]
            self._slots["paint_layers"], self._evaluated, self._blended = saved[3], saved[4], saved[5]
        # float32 round-off of the same sums in another order, relative to the mesh size
        atol = _PLAYBACK_ATOL * (1.0 + float(np.abs(self._vertices32).max()))
        return bool(np.allclose(played, expr.displacement, rtol=0.0, atol=atol))

    def _baked_expression_shape(self, expr: Expression) -> str:
        """Name of a blendshape whose delta is ``expr.displacement``, added if none is (undoable).

        Tries ``<name>_baked``, ``<name>_baked_2``, ... and reuses the first that
        holds exactly this displacement unmasked, unmuted and with 1 in its
        slider range; otherwise adds the first free name at weight 0 (the live
        face does not change).
        """
        stem = f"{expr.name}_baked"
        for i in itertools.count(1):
            name = stem if i == 1 else f"{stem}_{i}"
            if name not in self._index:
                self.add_shape(name, expr.displacement)
                return name
            s = self._shapes[self._index[name]]
            if (
                s.vertex_mask is None
                and not s.mute
                and s.slider_min <= 1.0 <= s.slider_max
                and np.array_equal(s.delta, expr.displacement)
            ):
                return name
        raise AssertionError("unreachable")  # itertools.count never ends

    def key_handles(self, time: float, interpolation: Interpolation = "bezier") -> None:
        """Key the handle offsets at ``time`` (undoable)."""
        with self._lock:
            if not len(self.handles):
                raise ModelError("key_handles: the model has no handles")
            tl = self.tracks.add_key("handles", time, self.handles.offsets, interpolation=interpolation)
            self.set_timeline(self._grow_range(tl, time), f"Key handles at {time:g}s")

    def key_head_pose(
        self,
        time: float,
        rotation: ArrayLike | None = None,
        translation: ArrayLike | None = None,
        interpolation: Interpolation = "bezier",
    ) -> None:
        """Key the rigid head transform at ``time`` (one undo step).

        The head pose maps a point ``p`` of the deformed face to ``R p + t``
        (track ``"head_pose"``, see :mod:`workbench.animation.tracks`). It is applied by
        :meth:`evaluate` at the current :attr:`time`, by :meth:`evaluate_at`
        and by every export; the rotation is always slerped between keys,
        ``interpolation`` shapes the translation.

        Parameters
        ----------
        time : float
            Seconds.
        rotation : (4,) or (3, 3) float, optional
            Unit quaternion ``(x, y, z, w)`` (glTF order; normalised here) or a
            rotation matrix. Default: the rotation the timeline has at ``time``
            (identity when the head pose is not keyed).
            :func:`workbench.animation.tracks.head_rotation_from_euler` makes one from
            yaw/pitch/roll about the model's axes.
        translation : (3,) float, optional
            Model units. Default: the translation at ``time`` (0 when not keyed).
        interpolation : {"step", "linear", "bezier"}

        Raises
        ------
        ModelError
            A non-finite time, a rotation that is not a non-zero quaternion or
            a proper rotation matrix, a translation that is not 3 finite numbers.
        """
        t = float(time)
        if not math.isfinite(t):
            raise ModelError(f"key_head_pose: time must be finite, got {time!r}")
        with self._lock:
            tl = self.tracks
            hp = tl.head_pose
            current = IDENTITY_POSE if hp is None else hp.evaluate(t)
            q = current[3:] if rotation is None else _as_quaternion(rotation, "key_head_pose")
            if translation is None:
                tr = current[:3]
            else:
                tr = np.asarray(translation, np.float64).reshape(-1)
                if tr.shape != (3,) or not np.isfinite(tr).all():
                    raise ModelError(
                        "key_head_pose: translation must be 3 finite numbers (model units), "
                        f"got {np.asarray(translation).tolist()!r}"
                    )
            tl = tl.add_key(HEAD_POSE, t, np.concatenate([tr, q]), interpolation=interpolation)
            self.set_timeline(self._grow_range(tl, t), f"Key head pose at {t:g}s")

    @property
    def head_pose(self) -> NDArray[np.float64] | None:
        """(7,) float: the head pose keyed at :attr:`time` (translation + quaternion), or None.

        It is a function of the timeline and the current time only (set by
        :meth:`set_time`, and following key edits and their undo at once): the
        head pose is not keyed while a track holds no ``"head_pose"`` keys, and
        the face is then not moved.
        """
        with self._lock:
            hp = self.tracks.head_pose
            return None if hp is None else hp.sample([self._time])[0]

    def head_matrix(self) -> NDArray[np.float64]:
        """(4, 4) float: the rigid transform :meth:`evaluate` applies now (identity if none).

        Tools that pick points on the shown mesh and edit in model space map
        the picks back with its inverse.
        """
        with self._lock:
            M = self._live_head_matrix()
            return np.eye(4) if M is None else M.copy()

    def _live_head_matrix(self) -> NDArray[np.float64] | None:
        tl, t = self._slots["tracks"], self._time
        c = self._pose_cache
        if c is None or c[0] is not tl or c[1] != t:
            c = (tl, t, _head_matrix_at(tl, t))
            self._pose_cache = c
        return c[2]

    def key_marker_fit(
        self,
        fit: Any,
        start: float = 0.0,
        every: int = 1,
        *,
        interpolation: Interpolation = "linear",
    ) -> NDArray[np.float64]:
        """Key a marker fit (Joshi et al. 2003 §3) on the timeline, frame by frame; one undo step.

        Frame ``f`` of the fit is keyed at ``start + f / fps`` (``fps`` of
        :attr:`tracks`): the fitted global weights of every shape as weight
        keys (the regions' background and the global sliders) and the fitted
        weights of every region of ``fit.level`` as region keys
        (``"regions/<level>/<region>"``, see :mod:`workbench.animation.tracks`). If the
        model's region level is not ``fit.level`` it is set to it in the same
        undo step. At a keyed frame, :meth:`evaluate_at` (and :meth:`set_time`
        then :meth:`evaluate`) gives ``fit.positions(model, regions, f,
        residual=False)`` plus whatever other layers the model has (handles,
        paint...), within float32 round-off; exports bake the region weights
        per frame (their layer report says so).

        The RBF residual is not keyed: it is a per-frame displacement field, not
        a weight, and the timeline has no track for one. It is available per
        frame as ``fit.residual_displacement(model, f)`` or in
        ``fit.positions(model, regions, f)`` (residual included). Exports do
        not bake it: a registered layer cannot see which time is being
        exported (:meth:`layers_at` does not set :attr:`time`), so there is no
        clean path; write ``fit.positions`` per frame yourself (e.g. into a
        point cache) when the residual is needed.

        Parameters
        ----------
        fit : workbench.methods.regions.marker_fit.MarkerFit
            Made for this model's shapes (same names, same order) and regions
            (the names of ``fit.level`` must be the current ones).
        start : float
            Seconds of frame 0.
        every : int
            >= 1: key every ``every``-th frame (the last frame is always keyed;
            the frames in between are interpolated).
        interpolation : {"step", "linear", "bezier"}
            Of the new keys. "linear" (default) joins the fitted frames by
            straight lines; exact at the keyed frames whatever the choice.

        Returns
        -------
        (F,) float
            The key times.

        Raises
        ------
        ModelError
            ``fit`` is not a MarkerFit or was made for other shapes or regions,
            the model has no regions, ``every``/``start`` are invalid, or the
            timeline already has region keys on another level.
        """
        from workbench.methods.regions.marker_fit import MarkerFit

        if not isinstance(fit, MarkerFit):
            raise ModelError(f"key_marker_fit: fit must be a MarkerFit, got {type(fit).__name__}")
        if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
            raise ModelError(f"key_marker_fit: every must be an int >= 1, got {every!r}")
        t0 = float(start)
        if not math.isfinite(t0):
            raise ModelError(f"key_marker_fit: start must be finite seconds, got {start!r}")
        with self._lock:
            st = self._require_regions("key_marker_fit")
            if tuple(fit.shape_names) != tuple(self.shape_names):
                raise ModelError(
                    f"key_marker_fit: fit was made for {len(fit.shape_names)} shapes "
                    f"{list(fit.shape_names[:4])}..., the model has {len(self._shapes)} "
                    f"{self.shape_names[:4]}... (shape list edited since fitting: fit again)"
                )
            L = int(fit.level)
            R = st.regions
            if L >= R.n_levels or tuple(R.names[L]) != tuple(fit.region_names):
                raise ModelError(
                    f"key_marker_fit: fit was made for other regions on level {L} "
                    "(the regions were edited or re-segmented since fitting: fit again)"
                )
            tl = self.tracks
            if tl.region_level is not None and tl.region_level != L:
                raise ModelError(
                    f"key_marker_fit: the timeline has region keys on level {tl.region_level}, "
                    f"the fit is on level {L}; delete those keys or fit on level {tl.region_level}"
                )
            T = fit.n_frames
            frames = np.arange(0, T, int(every))
            if frames[-1] != T - 1:
                frames = np.append(frames, T - 1)
            times = t0 + frames / tl.fps
            G = np.asarray(fit.global_weights, np.float64)[frames]  # (F, k)
            RW = np.asarray(fit.region_weights, np.float64)[frames]  # (F, R, k)
            for k, name in enumerate(self.shape_names):
                tl = add_keys(tl, weight_track_name(name), times, G[:, k], interpolation=interpolation)
            for r, region in enumerate(fit.region_names):
                tl = add_keys(
                    tl, region_track_name(L, region), times, RW[:, r, :], interpolation=interpolation
                )
            tl = tl.replace(start=min(tl.start, float(times[0])), end=max(tl.end, float(times[-1])))
            label = f"Key marker fit ({frames.size} frames from {t0:g}s)"
            with self.history.group(label):
                if st.level != L:
                    self.set_region_level(L)
                self.set_timeline(tl, label)
            self.events.history.emit()
            return times

    def delete_key(self, track: str, index: int) -> None:
        """Delete key ``index`` of ``track`` (undoable)."""
        self.set_timeline(self.tracks.delete_key(track, index), f"Delete key {index} of {track}")

    def move_key(self, track: str, index: int, time: float, value: ArrayLike | None = None) -> None:
        """Move key ``index`` of ``track`` to ``time`` (and ``value``), undoable."""
        with self._lock:
            tl = self.tracks.move_key(track, index, time, value)
            self.set_timeline(self._grow_range(tl, time), f"Move key of {track}")

    def _apply_sample(self, time: float, timeline: Timeline | None = None) -> bool:
        """Write the timeline's values at ``time`` into the live state (no history, no events).

        Returns True when region weights were written (the timeline has region tracks).
        """
        sample = (self.tracks if timeline is None else timeline).evaluate(time)
        for n, v in sample.weights.items():
            if n in self._weights:
                s = self._shapes[self._index[n]]
                self._weights[n] = min(max(float(v), s.slider_min), s.slider_max)
        if sample.handle_offsets is not None and sample.handle_offsets.shape == self.handles.offsets.shape:
            self._slots["handles"] = dataclasses.replace(
                self.handles, offsets=np.asarray(sample.handle_offsets, np.float32)
            )
        regions = self._sampled_regions(sample)
        if regions is not None:
            self._slots["regions"] = regions
        self._evaluated = None
        self._blended = None
        return regions is not None

    def _sampled_regions(self, sample: TimelineSample) -> RegionState | None:
        """The regions slot with the region weights of ``sample`` (None: no region tracks apply).

        Keyed regions take their keyed weights; every other region of the keyed
        level follows the (already sampled) global weights, so it adds no
        correction. Tracks naming regions or levels the model no longer has, or
        holding a stale number of shapes, are skipped (``check_model`` reports them).
        """
        st = self._slots["regions"]
        L = sample.region_level
        if L is None or not isinstance(st, RegionState) or L >= st.regions.n_levels:
            return None
        names = st.regions.names[L]
        k = len(self._shapes)
        g = np.array([self._weights[s.name] for s in self._shapes], np.float32)
        values = np.tile(g, (len(names), 1))
        index = {nm: i for i, nm in enumerate(names)}
        for region, v in sample.region_weights.items():
            if region in index and v.shape == (k,):
                values[index[region]] = v
        rw = RegionWeights(L, tuple(self.shape_names), names, values)
        return RegionState(st.regions, st.level, rw)

    def set_time(self, time: float) -> None:
        """Go to ``time``: keyed weights, handle offsets, region weights and head pose animate.

        Like changing the frame in Blender this is not an undo step; unkeyed
        shapes keep their values. With region tracks the regions slot gets the
        keyed region weights (see :mod:`workbench.animation.tracks`); the head pose is the
        one keyed at ``time`` (:attr:`head_pose`). Afterwards :meth:`evaluate`
        equals ``evaluate_at(time)``. Emits ``time``, ``weights``, ``handles``,
        ``regions`` (with region tracks) and ``deformed`` (final) events.
        """
        t = float(time)
        if not math.isfinite(t):
            raise ModelError(f"time must be finite, got {time!r}")
        with self._lock:
            if self._interaction is not None:
                raise ModelError("set_time: finish the drag first")
            self._time = t
            regions = self._apply_sample(t)
            self.events.time.emit(t)
            self.events.weights.emit(dict(self._weights))
            self.events.handles.emit()
            if regions:
                self.events.regions.emit()
            self.events.deformed.emit(True)

    def evaluate_at(self, time: float, timeline: Timeline | None = None) -> NDArray[np.float32]:
        """(n, 3) float32 mesh at ``time`` (head pose applied), without changing the model.

        ``timeline`` (default: :attr:`tracks`) animates the weights, handle
        offsets, region weights and head pose; exporters pass the timeline they
        write. ``set_time(time)`` then :meth:`evaluate` gives the same array.
        """
        tl = self.tracks if timeline is None else timeline
        with self._lock:
            saved = self._save_live()
            try:
                self._apply_sample(float(time), tl)
                out = self.evaluate(posed=False).copy()
            finally:
                self._restore_live(saved)
            pose = _head_matrix_at(tl, float(time))
            return out if pose is None else _posed_points(out, pose)

    def _save_live(self) -> tuple[Any, ...]:
        """What :meth:`_apply_sample` changes, to put back after a temporary evaluation."""
        return (
            dict(self._weights), self._slots["handles"], self._slots["regions"],
            self._evaluated, self._blended,
        )

    def _restore_live(self, saved: tuple[Any, ...]) -> None:
        self._weights, self._slots["handles"], self._slots["regions"] = saved[0], saved[1], saved[2]
        self._evaluated, self._blended = saved[3], saved[4]

    def layers_at(
        self, time: float, names: Iterable[str], timeline: Timeline | None = None
    ) -> dict[str, NDArray[np.float32] | None]:
        """Displacements ``(n, 3)`` float32 (copies, or None) of the named layers at ``time``.

        The model is put in the state of ``timeline`` (default :attr:`tracks`)
        at ``time`` as in :meth:`evaluate_at`, each named provider is called,
        and the state is restored. No head pose. Exporters use it to bake
        layers that are not linear in the animated weights and offsets.
        """
        with self._lock:
            wanted = list(names)
            unknown = [n for n in wanted if n not in self._layer_providers]
            if unknown:
                raise KeyError(f"no layers named {unknown}; layers are {list(self._layer_providers)}")
            saved = self._save_live()
            try:
                self._apply_sample(float(time), timeline)
                out: dict[str, NDArray[np.float32] | None] = {}
                for n in wanted:
                    d = self._layer_providers[n](self)
                    out[n] = None if d is None else np.array(d, dtype=np.float32)
            finally:
                self._restore_live(saved)
            return out

    @property
    def layer_providers(self) -> Mapping[str, Callable[[FaceModel], NDArray[np.float32] | None]]:
        """The displacement layers of :meth:`evaluate` by name, in order (a read-only copy).

        Built in: ``"regions"``, ``"handles"``, ``"paint"`` (see
        :meth:`is_builtin_layer`); later tools add theirs with :meth:`register_layer`.
        """
        with self._lock:
            return MappingProxyType(dict(self._layer_providers))

    def is_builtin_layer(self, name: str) -> bool:
        """True if layer ``name`` is still the model's own region, handle or paint layer."""
        builtin = {"regions": region_layer, "handles": self._handle_layer, "paint": self._paint_layer}
        return name in builtin and self._layer_providers.get(name) is builtin[name]

    def register_layer(
        self, name: str, provider: Callable[[FaceModel], NDArray[np.float32] | None]
    ) -> None:
        """Add a displacement layer to :meth:`evaluate` (used by later tools).

        ``provider(model)`` returns an (n, 3) float32 displacement or None.
        """
        with self._lock:
            self._layer_providers[name] = provider
            self._evaluated = None

    # ---------------------------------------------------------------- evaluate
    def to_pyvista(self, points: ArrayLike | None = None, **kwargs: Any) -> Any:
        """This model as a ``pyvista.PolyData`` (``widgets.render.to_pyvista``).

        Parameters
        ----------
        points : (n, 3) float, optional
            Positions to use instead of the neutral (e.g. ``self.evaluate()``).
        **kwargs
            ``polygons``, ``scalars``, ``scalars_name`` (see ``widgets.render.to_pyvista``).

        Raises
        ------
        ImportError
            If ``widgets.render`` (UI extra) was not imported: the core never imports
            pyvista itself (:mod:`workbench.converters`).
        """
        return mesh_converter("pyvista").to(self, points, **kwargs)

    @classmethod
    def from_pyvista(cls, mesh: Any, **kwargs: Any) -> FaceModel:
        """A model (no blendshapes) from a pyvista mesh (``widgets.render.from_pyvista``)."""
        model = mesh_converter("pyvista").from_(mesh, **kwargs)
        if not isinstance(model, cls):
            raise TypeError(f"from_pyvista: the converter returned {type(model).__name__}")
        return model

    def evaluate(self, posed: bool = True) -> NDArray[np.float32]:
        """(n, 3) float32, read-only: the current deformed mesh.

        :meth:`blended` (``neutral + sum_k w_k * delta_k``) plus every editing
        layer (the handle layer, and layers later tools register), then moved
        by the head pose keyed at the current time (:attr:`head_pose`, as in
        :meth:`evaluate_at`). Cached until a weight, shape or layer changes; a
        handle drag reuses the cached blend.

        Parameters
        ----------
        posed : bool
            False: without the head pose (model space, where the editing
            layers, expressions and handle offsets live).
        """
        with self._lock:
            local = self._evaluate_local()
            if not posed:
                return local
            M = self._live_head_matrix()
            if M is None:
                return local
            c = self._posed
            if c is None or c[0] is not local or not np.array_equal(c[1], M):
                c = (local, M, _readonly(_posed_points(local, M)))
                self._posed = c
            return c[2]

    def _evaluate_local(self) -> NDArray[np.float32]:
        with self._lock:
            if self._evaluated is None:
                out = self.blended()
                layers = [
                    x for x in (p(self) for p in self._layer_providers.values()) if x is not None
                ]
                if layers:
                    out = out.copy()
                    for extra in layers:
                        out += extra
                self._evaluated = _readonly(out) if out.flags.writeable else out
            return self._evaluated

    def blended(self) -> NDArray[np.float32]:
        """(n, 3) float32, read-only: ``neutral + sum_k w_k * delta_k`` without editing layers.

        Masked shapes use their masked delta; muted shapes are skipped. Cached
        until a weight or shape changes.
        """
        with self._lock:
            if self._blended is None:
                self._blended = _readonly(self._blend())
            return self._blended

    def _blend(self) -> NDArray[np.float32]:
        k = len(self._shapes)
        if k == 0:  # a (0, 3n) reshape cannot infer its -1 axis: nothing to add anyway
            return self._vertices32.copy()
        w = self.weight_vector()
        nz = np.flatnonzero(w)
        if nz.size * 4 > k:
            # many active shapes: one BLAS gemv straight into the output buffer
            flat = np.empty(3 * self.n_vertices, np.float32)
            np.dot(w, self._effective.reshape(k, -1), out=flat)
            flat += self._vertices32.reshape(-1)
            return flat.reshape(-1, 3)
        out = self._vertices32.copy()
        flat = out.reshape(-1)
        D = self._effective.reshape(k, -1)
        for i in nz:  # few active shapes: in-place axpy touches only their rows
            flat += w[i] * D[i]
        return out

    # ------------------------------------------------------------ interactions
    def begin_interaction(
        self, label: str, on_close: Callable[[], None] | None = None
    ) -> InteractionToken:
        """Open an interaction that spans several messages (a drag); returns its token.

        Edits made until :meth:`end_interaction` emit ``*_changing`` events and
        become one undo step. ``on_close`` is called (without arguments) when
        somebody else closes the interaction with :meth:`close_interaction`
        (a discrete edit elsewhere), so the owner can reset its own state.

        Raises
        ------
        ModelError
            Another interaction is open (close it first with :meth:`close_interaction`).
        """
        with self._lock:
            if self._interaction is not None:
                raise ModelError(
                    f"begin_interaction({label!r}): interaction {self._interaction.label!r} is "
                    "still open; end, cancel or close it first"
                )
            token = InteractionToken(label, next(_token_serials))
            self._interaction = _Interaction(label, token=token, on_close=on_close)
            return token

    def _take_interaction(self, token: InteractionToken, what: str) -> _Interaction:
        inter = self._interaction
        if inter is None or inter.token != token:
            raise ModelError(
                f"{what}: interaction {token.label!r} is not the open one "
                f"({'none is open' if inter is None else repr(inter.label) + ' is'})"
            )
        self._interaction = None
        return inter

    def end_interaction(self, token: InteractionToken) -> None:
        """Close the interaction of ``token``: one undo step with everything it changed."""
        with self._lock:
            self._finish_interaction(self._take_interaction(token, "end_interaction"))

    def cancel_interaction(self, token: InteractionToken) -> None:
        """Close the interaction of ``token`` and put back what it changed (no undo step)."""
        with self._lock:
            inter = self._take_interaction(token, "cancel_interaction")
            self._revert_interaction(inter)

    def close_interaction(self) -> bool:
        """End whatever interaction is open (keeping its edits); True if one was open.

        Discrete edits from views (Key, Import, undo buttons) call this first so
        they never join a drag's undo step. The owner's ``on_close`` is told.
        """
        with self._lock:
            inter = self._interaction
            if inter is None:
                return False
            callback = inter.on_close
            if inter.token is not None:
                self.end_interaction(inter.token)
            else:  # a ``with interaction()`` block on another thread: let it finish
                return False
        if callback is not None:
            callback()
        return True

    @property
    def interaction_token(self) -> InteractionToken | None:
        """The token of the open interaction begun with :meth:`begin_interaction`, or None."""
        inter = self._interaction
        return None if inter is None else inter.token

    def _revert_interaction(self, inter: _Interaction) -> None:
        weights = {k: v for k, v in inter.weights_before.items() if k in self._weights}
        if weights:
            self._weights.update(weights)
            self._evaluated = None
            self._blended = None
            self.events.weights.emit(dict(weights))
        for name, value in inter.slots_before.items():
            self._slots[name] = value
            getattr(self.events, name).emit()
            if _SLOTS[name]:
                self._evaluated = None
        if weights or inter.slots_before:
            self.events.deformed.emit(True)

    @contextmanager
    def interaction(self, label: str) -> Iterator[None]:
        """Group edits (a drag, a scrub) into one undo step.

        Inside, edits emit ``*_changing`` events; on exit one ``changed`` event per
        touched field is emitted and one undo step is recorded. Nested calls join
        the outer interaction.
        """
        with self._lock:
            if self._interaction is not None:
                outer = True
            else:
                outer = False
                self._interaction = _Interaction(label)
        if outer:
            yield
            return
        try:
            yield
        finally:
            with self._lock:
                inter = self._interaction
                self._interaction = None
                assert inter is not None
                self._finish_interaction(inter)

    @property
    def interacting(self) -> bool:
        return self._interaction is not None

    def _finish_interaction(self, inter: _Interaction) -> None:
        w_before = {k: v for k, v in inter.weights_before.items() if k in self._weights}
        w_after = {k: self._weights[k] for k in w_before}
        w_before = {k: v for k, v in w_before.items() if w_after[k] != v}
        w_after = {k: w_after[k] for k in w_before}
        s_before = dict(inter.slots_before)
        s_after = {k: self._slots[k] for k in s_before}
        if not w_before and not any(s_before[k] is not s_after[k] for k in s_before):
            # nothing net changed, but views saw "changing": settle them
            if inter.weights_before or inter.slots_before:
                self.events.deformed.emit(True)
            return

        def apply(weights: dict[str, float], slots: dict[str, Any]) -> None:
            with self._lock:
                if weights:
                    self._weights.update(weights)
                    self._evaluated = None
                    self._blended = None
                    self.events.weights.emit(dict(weights))
                for name, value in slots.items():
                    self._slots[name] = value
                    getattr(self.events, name).emit()
                    if _SLOTS[name]:
                        self._evaluated = None
                self.events.deformed.emit(True)

        apply(w_after, s_after)
        self._push(
            Command(
                inter.label,
                lambda: apply(w_before, s_before),
                lambda: apply(w_after, s_after),
                payload_nbytes([w_before, w_after]) + payload_nbytes(list(s_after.values())),
            )
        )

    # ------------------------------------------------------------------- undo
    def _push(self, cmd: Command) -> None:
        self.history.push(cmd)
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

    # --------------------------------------------------------------- file I/O
    def save(self, path: str | Any) -> None:
        """Save to a workbench file (``.fwb``): atomic, checksummed; see :mod:`workbench.fileformat`."""
        from workbench.fileformat import save_model

        save_model(self, path)

    def to_trimesh(self, evaluated: bool = True) -> Any:
        """A :class:`trimesh.Trimesh` of the current (or neutral) mesh, for analysis and I/O."""
        import trimesh

        pts = self.evaluate() if evaluated else self._vertices
        return trimesh.Trimesh(np.asarray(pts, np.float64), self._faces, process=False)

    def set_metadata(self, metadata: ModelMetadata, label: str = "Set metadata") -> None:
        """Replace the metadata as one undoable step (emits ``metadata``).

        Units and axes change how every exporter reads the coordinates, so a
        wrong choice must be as easy to take back as any edit. Setting equal
        metadata records nothing.
        """
        if not isinstance(metadata, ModelMetadata):
            raise ModelError(f"set_metadata expects a ModelMetadata, got {type(metadata).__name__}")
        with self._lock:
            old = self._metadata
            if metadata == old:
                return
            self._apply_metadata(metadata)
            self._push(
                Command(
                    label,
                    lambda: self._apply_metadata(old),
                    lambda: self._apply_metadata(metadata),
                    payload_nbytes([old, metadata]),
                )
            )

    def _apply_metadata(self, metadata: ModelMetadata) -> None:
        with self._lock:
            self._metadata = metadata
            self.events.metadata.emit()
