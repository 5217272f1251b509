"""The one evaluation pipeline: blend, then each method's layer on the mesh below.

``mesh = neutral + sum_k w_k delta_k`` (the blend), then for every layer in
order ``mesh += layer.displacement(view, mesh)``, then the rigid head pose.
:meth:`FaceState.evaluate`, :meth:`FaceState.evaluate_at`, every exporter
and the viewport get their vertices from :meth:`Pipeline.run`, so they agree
bit for bit (float32 throughout, the same operations in the same order).

A layer sees the state through a :class:`StateView`: the live state, or the
state sampled from a timeline at some time (``evaluate_at``), never the model
object itself, so a layer cannot pull anything it did not declare. Each stage's
output is cached under a key built from the versions of what it reads (the
blend: shapes and weights; a layer: its ``reads`` slots, plus the key of the
stage below), so an edit recomputes only the stages at and after it.

Derived weights (combination / corrective shapes, whose weight is the product
of other shapes' weights: :class:`workbench.core.families.WeightProducts`) are
applied once, when a view is made, so the blend, every layer and everything
that samples views (``evaluate_at``, the exporters) see the same weights.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from workbench.core import families as _families
from workbench.core.shapes import BlendShape, ModelMetadata, readonly

if TYPE_CHECKING:
    from workbench.core.polygons import Polygons
    from workbench.core.state import FaceState


class StateView:
    """What a layer may read: the mesh, the shapes, weights and slot values at one time.

    Parameters
    ----------
    state : FaceState
        Gives the mesh and shapes (they do not change over time).
    weights : mapping of str to float
        Clamped weight of every shape; derived weights (products of other
        weights, :func:`workbench.core.families.derive_weights`) are computed here.
    slots : mapping of str to object
        Every slot's value.
    versions : mapping of str to int
        Version of ``"shapes"``, ``"weights"`` and every slot; equal versions
        mean equal values (the evaluation cache relies on it).
    time : float
    interacting : bool
        True during a drag: layers may trade exactness for speed (rank-1 updates);
        the release bumps the versions, so the settled result is exact.
    """

    __slots__ = ("_state", "_versions", "_weights", "interacting", "slots", "time")

    def __init__(
        self,
        state: FaceState,
        weights: Mapping[str, float],
        slots: Mapping[str, Any],
        versions: Mapping[str, int],
        time: float,
        interacting: bool = False,
    ) -> None:
        self._state = state
        self.slots = MappingProxyType(dict(slots))
        self._weights = _families.derive_weights(state.shapes, weights, self.slots)
        self._versions = dict(versions)
        self.time = float(time)
        self.interacting = bool(interacting)

    # -- what never changes over time: straight from the state
    @property
    def vertices(self) -> NDArray[np.float64]:
        return self._state.vertices

    @property
    def vertices32(self) -> NDArray[np.float32]:
        return self._state.vertices32

    @property
    def faces(self) -> NDArray[np.int32]:
        return self._state.faces

    @property
    def polygons(self) -> Polygons:
        return self._state.polygons

    @property
    def n_vertices(self) -> int:
        return self._state.n_vertices

    @property
    def component_labels(self) -> NDArray[np.int32]:
        return self._state.component_labels

    @property
    def component_names(self) -> list[str]:
        return self._state.component_names

    @property
    def metadata(self) -> ModelMetadata:
        return self._state.metadata

    @property
    def shapes(self) -> tuple[BlendShape, ...]:
        return self._state.shapes

    @property
    def shape_names(self) -> list[str]:
        return self._state.shape_names

    @property
    def deltas(self) -> NDArray[np.float32]:
        return self._state.deltas

    @property
    def effective_deltas(self) -> NDArray[np.float32]:
        """(k, n, 3) float32: deltas with their vertex masks applied."""
        return self._state.effective_deltas

    # -- what a timeline can animate
    @property
    def weights(self) -> Mapping[str, float]:
        return MappingProxyType(self._weights)

    def weight_vector(self) -> NDArray[np.float32]:
        """(k,) float32 weights in shape order, muted shapes as 0."""
        w = self._weights
        return np.array([0.0 if s.mute else w[s.name] for s in self.shapes], np.float32)

    def slot(self, name: str) -> Any:
        try:
            return self.slots[name]
        except KeyError:
            raise KeyError(f"no slot {name!r}; slots are {sorted(self.slots)}") from None

    def version(self, name: str) -> int:
        return self._versions[name]


@runtime_checkable
class Layer(Protocol):
    """One method's stage of the pipeline.

    Attributes
    ----------
    name : str
    reads : tuple of str or None
        Slots the displacement depends on besides the mesh below (which already
        carries the shapes and weights). None: unknown inputs, never cached.
    linear : bool
        Linear in the timeline's keys (weights, handle offsets): exporters may
        write it as morph targets instead of baking it per frame.

    A layer may also define ``active(view) -> bool`` (False: it adds nothing for
    this state whatever the time; exporters then need not bake it), and set ``uses_below = False`` when its displacement does not
    depend on the mesh below (the handle shell): the cache then keeps it while
    the blend changes.
    """

    name: str
    reads: tuple[str, ...] | None
    linear: bool

    def displacement(self, view: StateView, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        """(n, 3) float32 added to ``below`` (the mesh after the earlier stages), or None for zero."""
        ...


class FunctionLayer:
    """A layer from a function ``fn(view) -> (n, 3) | None`` (user extensions, tests).

    Its inputs are unknown to the pipeline, so it is never cached, and it is not
    linear in the keys: exporters bake it per frame.
    """

    reads: tuple[str, ...] | None = None
    linear = False

    def __init__(self, name: str, fn: Any) -> None:
        self.name = name
        self.fn = fn

    def displacement(self, view: StateView, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        return self.fn(view)


@dataclass(frozen=True)
class Evaluation:
    """One run of the pipeline: the model-space mesh and what each layer added."""

    mesh: NDArray[np.float32]
    blend: NDArray[np.float32]
    displacements: Mapping[str, NDArray[np.float32] | None]
    #: the mesh each layer was handed (the stages before it)
    below: Mapping[str, NDArray[np.float32]]


def blend(view: StateView) -> NDArray[np.float32]:
    """(n, 3) float32 ``neutral + sum_k w_k delta_k`` (masks applied, muted shapes skipped).

    Many active shapes: one BLAS gemv into the output; few: in-place axpy on
    their rows only. Which one runs depends only on the weights, so the same
    weights always give the same bits.
    """
    V32 = view.vertices32
    D = view.effective_deltas
    k = D.shape[0]
    if k == 0:
        return V32.copy()
    w = view.weight_vector()
    nz = np.flatnonzero(w)
    if nz.size * 4 > k:
        flat = np.empty(V32.size, np.float32)
        np.dot(w, D.reshape(k, -1), out=flat)
        flat += V32.reshape(-1)
        return flat.reshape(-1, 3)
    out = V32.copy()
    flat = out.reshape(-1)
    Df = D.reshape(k, -1)
    for i in nz:
        flat += w[i] * Df[i]
    return out


class Pipeline:
    """The ordered layers of one model and the cache of the live state's stages."""

    def __init__(self, layers: list[Layer]) -> None:
        names = [layer.name for layer in layers]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate layer names in {names}")
        self._layers = list(layers)
        # stage index (-1: blend) -> (key, mesh, displacement)
        self._cache: dict[int, tuple[Any, NDArray[np.float32], NDArray[np.float32] | None]] = {}
        # stage index -> (the layer's own key, displacement): for layers with ``uses_below = False``
        self._alone: dict[int, tuple[Any, NDArray[np.float32] | None]] = {}

    @property
    def names(self) -> list[str]:
        return [layer.name for layer in self._layers]

    @property
    def layers(self) -> tuple[Layer, ...]:
        return tuple(self._layers)

    def layer(self, name: str) -> Layer:
        for layer in self._layers:
            if layer.name == name:
                return layer
        raise KeyError(f"no layer named {name!r}; layers are {self.names}")

    def add(self, layer: Layer, before: str | None = None) -> None:
        """Insert ``layer`` (at the end, or before the layer named ``before``); replaces a same-named one."""
        self._layers = [x for x in self._layers if x.name != layer.name]
        at = len(self._layers) if before is None else self.names.index(before)
        self._layers.insert(at, layer)
        self.invalidate()

    def remove(self, name: str) -> None:
        self._layers = [x for x in self._layers if x.name != name]
        self.invalidate()

    def invalidate(self) -> None:
        self._cache.clear()
        self._alone.clear()

    def run(self, view: StateView, cache: bool = True, below: str | None = None) -> Evaluation:
        """Evaluate ``view``: blend, then every layer on the mesh below it.

        ``cache`` (the live state only) reuses stages whose inputs' versions
        are unchanged. ``below``: stop before the layer of that name (its
        input is then the returned mesh; it and the later layers do not run).
        Returned arrays are read-only.
        """
        if below is not None and below not in self.names:
            raise KeyError(f"no layer named {below!r}; layers are {self.names}")
        key: Any = ("blend", view.version("shapes"), view.version("weights"),
                    *(view.version(r) for r in _families.weight_product_reads()))
        hit = self._cache.get(-1) if cache else None
        if hit is not None and hit[0] == key:
            mesh = hit[1]
        else:
            mesh = readonly(blend(view))
            if cache:
                self._cache[-1] = (key, mesh, None)
        base = mesh
        shown: dict[str, NDArray[np.float32] | None] = {}
        inputs: dict[str, NDArray[np.float32]] = {}
        for i, layer in enumerate(self._layers):
            if layer.name == below:
                break
            inputs[layer.name] = mesh
            reads = layer.reads
            own = None if reads is None else (layer.name, *(view.version(r) for r in reads))
            key = None if own is None or key is None else (key, own)
            hit = self._cache.get(i) if cache and key is not None else None
            if hit is not None and hit[0] == key:
                mesh, d = hit[1], hit[2]
                shown[layer.name] = d
                continue
            # a layer that ignores the mesh below keeps its displacement across blend changes
            alone = self._alone.get(i) if cache and own is not None else None
            if alone is not None and alone[0] == own and not getattr(layer, "uses_below", True):
                d = alone[1]
            else:
                d = layer.displacement(view, mesh)
                if d is not None:
                    d = readonly(np.asarray(d, np.float32))
                if cache and own is not None:
                    self._alone[i] = (own, d)
            if d is not None:
                mesh = readonly(mesh + d)
            if cache:
                self._cache[i] = (key, mesh, d)
            shown[layer.name] = d
        return Evaluation(mesh, base, MappingProxyType(shown), MappingProxyType(inputs))


def posed_points(points: NDArray[np.float32], matrix: NDArray[np.float64]) -> NDArray[np.float32]:
    """(n, 3) float32 ``R p + t`` for a (4, 4) rigid ``matrix``: the one rounding rule of the head pose."""
    out: NDArray[np.float32] = (points @ matrix[:3, :3].T.astype(np.float32)) + matrix[:3, 3].astype(
        np.float32
    )
    return out
