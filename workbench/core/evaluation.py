"""Evaluation of the state: live, at a time of the timeline, layer by layer.

A mixin of :class:`workbench.core.state.FaceState`. The live state and the
state sampled at a time are both :class:`~workbench.core.pipeline.StateView`
objects run through the model's one :class:`~workbench.core.pipeline.Pipeline`;
what a timeline animates comes from the families' hooks (``"sampler"``,
``animate``, ``"head_pose"``), so this module knows no method.
"""

from __future__ import annotations

import itertools
import math
import threading
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import NDArray

from workbench.core import families as _families
from workbench.core.pipeline import Evaluation, Layer, Pipeline, StateView, posed_points
from workbench.core.shapes import BlendShape, ModelError, readonly

if TYPE_CHECKING:
    from workbench.core.state import FaceState

#: versions of values that exist only in a sampled view (never equal to a live one)
_versions = itertools.count(-1, -1)


class Evaluator:
    """Evaluation methods of the state (see the module docstring)."""

    _lock: threading.RLock
    _interaction: Any
    _weights: dict[str, float]
    _slots: dict[str, Any]
    _version: dict[str, int]
    _time: float
    _shapes: tuple[BlendShape, ...]
    _index: dict[str, int]
    _animators: list[Callable[[StateView, Any], Mapping[str, Any]]]
    _posed: tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float32]] | None
    pipeline: Pipeline
    events: Any

    @property
    def _me(self) -> FaceState:
        return cast("FaceState", self)

    def _bump(self, name: str) -> None:  # provided by FaceState
        raise NotImplementedError

    @property
    def n_vertices(self) -> int:  # provided by FaceState
        raise NotImplementedError

    @property
    def time(self) -> float:
        """Current time in seconds (set by :meth:`set_time`)."""
        return self._time

    def view(self) -> StateView:
        """The live state as layers see it."""
        return StateView(self._me, self._weights, self._slots, self._version, self._time,
                         self._interaction is not None)

    def view_at(self, time: float, timeline: Any = None) -> StateView:
        """The state sampled at ``time`` from ``timeline`` (default: the model's own), unchanged live."""
        t = float(time)
        if not math.isfinite(t):
            raise ModelError(f"time must be finite, got {time!r}")
        with self._lock:
            weights, slots = self._sampled(t, timeline)
            versions = dict(self._version)
            for name in (*slots, "weights"):
                versions[name] = next(_versions)
            return StateView(self._me, weights, {**self._slots, **slots}, versions, t, False)

    def _sampled(self, t: float, timeline: Any) -> tuple[dict[str, float], dict[str, Any]]:
        """Weights (clamped) and slot values the timeline gives at ``t``; the live state is untouched.

        The timeline's family (registered as the ``"sampler"`` hook) samples it; each
        family's ``animate`` turns the sample into values of its own slots.
        """
        sampler = _families._HOOKS.get("sampler")
        weights = dict(self._weights)
        if sampler is None:
            return weights, {}
        tl = {} if timeline is None else {"tracks": timeline}
        sample = sampler(StateView(self._me, weights, {**self._slots, **tl}, self._version, t))
        for name, w in sample.weights.items():
            if name in weights:
                s = self._shapes[self._index[name]]
                weights[name] = min(max(float(w), s.slider_min), s.slider_max)
        view = StateView(self._me, weights, {**self._slots, **tl}, self._version, t)
        slots: dict[str, Any] = dict(tl)
        for animate in self._animators:
            slots.update(animate(view, sample))
        return weights, slots

    def set_time(self, time: float) -> None:
        """Go to ``time``: whatever the timeline keys animates; not an undo step (as in Blender).

        Afterwards :meth:`evaluate` equals ``evaluate_at(time)`` bit for bit.
        """
        t = float(time)
        if not math.isfinite(t):
            raise ModelError(f"time must be finite, got {time!r}")
        with self._lock:
            if self._interaction is not None:
                raise ModelError("set_time: finish the drag first")
            weights, slots = self._sampled(t, None)
            self._time = t
            changed_w = {k: v for k, v in weights.items() if self._weights[k] != v}
            self._weights.update(changed_w)
            if changed_w:
                self._bump("weights")
            for name, value in slots.items():
                if self._slots[name] is not value:
                    self._slots[name] = value
                    self._bump(name)
            self.events.time.emit(t)
            self.events.weights.emit(dict(self._weights))
            for name in slots:
                getattr(self.events, name).emit()
            self.events.deformed.emit(True)

    def evaluate(self, posed: bool = True) -> NDArray[np.float32]:
        """(n, 3) float32, read-only: the current mesh (blend + every layer, then the head pose).

        ``posed=False``: without the head pose (model space, where layers,
        expressions and handle offsets live).
        """
        with self._lock:
            local = self.pipeline.run(self.view()).mesh
            if not posed:
                return local
            M = self.head_matrix(identity=False)
            if M is None:
                return local
            c = self._posed
            if c is None or c[0] is not local or not np.array_equal(c[1], M):
                c = (local, M, readonly(posed_points(local, M)))
                self._posed = c
            return c[2]

    def evaluate_at(self, time: float, timeline: Any = None) -> NDArray[np.float32]:
        """(n, 3) float32 mesh at ``time`` (head pose applied), without changing the model.

        ``timeline`` (default: the model's) animates what it keys; exporters pass
        the one they write. ``set_time(time)`` then :meth:`evaluate` gives the same bits.
        """
        with self._lock:
            view = self.view_at(time, timeline)
            out = self.pipeline.run(view, cache=False).mesh
            M = self._head(view)
            return np.array(out) if M is None else posed_points(out, M)

    def evaluation_at(self, time: float, timeline: Any = None, *, below: str | None = None) -> Evaluation:
        """The whole :class:`Evaluation` (mesh without head pose, each layer's displacement) at ``time``.

        ``below``: stop before the layer of that name (the mesh it would get; later layers do not run).
        """
        with self._lock:
            return self.pipeline.run(self.view_at(time, timeline), cache=False, below=below)

    def layers_at(
        self, time: float, names: Iterable[str], timeline: Any = None
    ) -> dict[str, NDArray[np.float32] | None]:
        """Displacements (n, 3) float32 (or None) of the named layers at ``time``; no head pose."""
        wanted = list(names)
        unknown = [n for n in wanted if n not in self.pipeline.names]
        if unknown:
            raise KeyError(f"no layers named {unknown}; layers are {self.pipeline.names}")
        shown = self.evaluation_at(time, timeline).displacements
        return {n: shown[n] for n in wanted}

    def blended(self) -> NDArray[np.float32]:
        """(n, 3) float32, read-only: ``neutral + sum_k w_k delta_k`` without the layers."""
        with self._lock:
            return self.pipeline.run(self.view()).blend

    def layer_displacement(self, name: str) -> NDArray[np.float32]:
        """(n, 3) float32 copy of what layer ``name`` adds to the live mesh (zeros when nothing)."""
        with self._lock:
            d = self.pipeline.run(self.view()).displacements.get(name)
            if name not in self.pipeline.names:
                raise KeyError(f"no layer named {name!r}; layers are {self.pipeline.names}")
            return np.zeros((self.n_vertices, 3), np.float32) if d is None else np.array(d)

    def register_layer(self, layer: Layer, before: str | None = None) -> None:
        """Add a layer to this model's pipeline (tests, user extensions); emits ``deformed``."""
        with self._lock:
            if not isinstance(layer, Layer):
                raise ModelError(f"register_layer expects a Layer (name, reads, linear, displacement), got {layer!r}")
            self.pipeline.add(layer, before)
            self.events.deformed.emit(True)

    def _head(self, view: StateView) -> NDArray[np.float64] | None:
        pose = _families._HOOKS.get("head_pose")
        return None if pose is None else pose(view)

    def head_matrix(self, identity: bool = True) -> NDArray[np.float64] | None:
        """(4, 4) rigid transform :meth:`evaluate` applies now (identity when no head pose is keyed).

        Tools that pick points on the shown mesh map them back to model space with its inverse.
        """
        with self._lock:
            M = self._head(self.view())
            if M is None:
                return np.eye(4) if identity else None
            return M.copy()

