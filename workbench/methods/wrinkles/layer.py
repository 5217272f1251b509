"""Pose-space wrinkles as a FaceModel layer: large-scale (blend + handles) + WPSD details.

Register with ``layer.attach(model)`` (after the built-in handle layer). On
every :meth:`FaceModel.evaluate` the provider

1. takes the large-scale mesh ``X = model.blended() + model.handle_displacement()``,
2. measures the strain of the feature graph at the model's handle vertices,
3. returns ``strength · R_v d_v(f)``: WPSD details in the local frames of ``X``
   (numba kernels when available) — so a handle drag gives large-scale and
   fine-scale deformation in one evaluate.

Training (:meth:`WrinkleLayer.fit`) uses the *model's* large-scale map: the
detail of a detailed example is ``detailed − blended(example weights)``, so
dialling an example expression in with the sliders reproduces it exactly,
and dragging handles adds wrinkles according to the strain they cause.

Cheap when idle: returns None (no work, no allocation) when nothing is
fitted, the layer is disabled, the strength is 0, the model's handles differ
from the fitted ones, or the strain is zero (the rest pose has zero detail).
Hand-written glue; the numerics are in :mod:`workbench.methods.wrinkles.pose_space`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.methods.wrinkles.pose_space import (
    DetailEvaluator,
    FeatureGraph,
    FitMode,
    PoseSpace,
    edge_weights,
    extract_details,
    fit_pose_space,
    greedy_fit,
    local_frames,
    tangent_neighbours,
)

if TYPE_CHECKING:
    from workbench.model import FaceModel

#: below this relative stretch the pose counts as the rest pose (float32 blend noise is ~5e-6)
_ZERO_STRAIN = 2e-5


def _blend(model: FaceModel, weights: Mapping[str, float]) -> NDArray[np.float64]:
    X = np.array(model.vertices, dtype=np.float64)
    shapes = {s.name: s for s in model.shapes}
    for name, w in weights.items():
        if name not in shapes:
            raise KeyError(f"WrinkleLayer: unknown blendshape {name!r}")
        if w and not shapes[name].mute:
            X += float(w) * shapes[name].effective_delta()
    return X


class WrinkleLayer:
    """Callable layer ``layer(model) -> (n, 3) float32 | None`` adding pose-space wrinkles.

    Parameters
    ----------
    strength : float
        Multiplies the details (0 = off, 1 = as learned).
    weighted : bool
        WPSD (default) or global PSD.
    backend : {"auto", "numba", "numpy"}
    large_scale : callable, optional
        ``large_scale(model) -> (n, 3)`` mesh on which details sit. Default
        ``model.blended() + model.handle_displacement()``.

    Attributes
    ----------
    graph : FeatureGraph or None
    pose_space : PoseSpace or None
    example_names : list of str
    last_strain : (F,) float or None
        Strain of the last evaluation (for colouring the feature graph).
    """

    def __init__(
        self,
        strength: float = 1.0,
        *,
        weighted: bool = True,
        backend: str = "auto",
        large_scale: Callable[[FaceModel], NDArray] | None = None,
    ) -> None:
        self.strength = float(strength)
        self.enabled = True
        self.weighted = weighted
        self.backend = backend
        self.large_scale = large_scale or (lambda m: np.asarray(m.blended()) + m.handle_displacement())
        self.graph: FeatureGraph | None = None
        self.pose_space: PoseSpace | None = None
        self.example_names: list[str] = []
        self.example_weights: list[dict[str, float]] = []
        self.last_strain: NDArray[np.float64] | None = None
        self._handles: NDArray[np.int32] | None = None
        self._evaluator: DetailEvaluator | None = None
        self._model: FaceModel | None = None
        self._name = "wrinkles"
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ model glue
    def attach(self, model: FaceModel, name: str = "wrinkles") -> WrinkleLayer:
        """Register as a displacement layer of ``model`` (after the handle layer)."""
        self._model, self._name = model, name
        model.register_layer(name, self)
        return self

    def _changed(self) -> None:
        """Our state changed: drop the model's cached evaluate and tell observers."""
        m = self._model
        if m is not None:
            m.register_layer(self._name, self)  # public way to invalidate the cache
            m.events.deformed.emit(True)

    def set_strength(self, strength: float) -> None:
        self.strength = float(strength)
        self._changed()

    def set_enabled(self, enabled: bool) -> None:
        self.enabled = bool(enabled)
        self._changed()

    @property
    def fitted(self) -> bool:
        return self.pose_space is not None

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        model: FaceModel,
        examples: Mapping[str, tuple[Mapping[str, float], ArrayLike]],
        *,
        graph: FeatureGraph | None = None,
        neighbours: int = 4,
        beta: float | None = None,
        mode: FitMode = "interp",
        max_basis: int | None = None,
        tolerance: float = 0.0,
        active: ArrayLike | None = None,
    ) -> PoseSpace:
        """Learn details from detailed examples ``{name: (weights, detailed (n, 3))}``.

        The model must have handles (e.g. ``default_face_handles``). The
        feature graph defaults to each handle's ``neighbours`` nearest handles.
        ``active`` (n,) bool limits details to those vertices (default: skin).
        """
        h = np.asarray(model.handles.vertices, np.int64)
        if h.size < 2:
            raise ValueError("WrinkleLayer.fit: the model needs at least 2 handles (model.set_handles)")
        V = np.asarray(model.vertices, np.float64)
        n = V.shape[0]
        g = graph or FeatureGraph.from_handles(V[h], neighbours)
        if active is None:
            names = model.component_names
            act = (
                np.asarray(model.component_labels) == names.index("skin")
                if "skin" in names
                else np.ones(n, bool)
            )
        else:
            act = np.asarray(active, bool).reshape(n)
        nb = tangent_neighbours(model.faces, n)
        feats, dets = [], []
        for _, (w, detailed) in examples.items():
            X = _blend(model, w)
            D = np.asarray(detailed, np.float64).reshape(n, 3)
            d = extract_details(D, X, local_frames(X, model.faces, nb))
            d[~act] = 0.0
            feats.append(g.strain(X[h]))
            dets.append(d)
        Ft, Dt = np.array(feats), np.array(dets, np.float32)
        alpha = edge_weights(V, V[h], g, beta=beta) if self.weighted else None
        if mode == "interp" and max_basis is None and tolerance == 0.0:
            ps = fit_pose_space(Ft, Dt, alpha=alpha, mode="interp")
        else:
            ps, _ = greedy_fit(Ft, Dt, alpha=alpha, mode=mode, max_basis=max_basis, tolerance=tolerance)
        with self._lock:
            self.graph = g
            self._handles = h.astype(np.int32)
            self.example_names = list(examples)
            self.example_weights = [dict(w) for w, _ in examples.values()]
            self._set_pose_space(ps, model)
        self._changed()
        return ps

    def _set_pose_space(self, ps: PoseSpace, model: FaceModel) -> None:
        self.pose_space = ps
        self._evaluator = DetailEvaluator(ps, model.faces, tangent_neighbours(model.faces, model.n_vertices), self.backend)

    def edit_example(
        self,
        example: str | int,
        *,
        scale: float | ArrayLike = 1.0,
        mask: ArrayLike | None = None,
    ) -> PoseSpace:
        """Scale / paint out the details of one example and refit (propagates to every pose near it).

        Parameters
        ----------
        example : name or index
        scale : float or (n,) float
        mask : (n,) float, optional
            1 removes the details there (paint out), 0 keeps them.
        """
        if self.pose_space is None or (self._model is None and self._evaluator is None):
            raise RuntimeError("WrinkleLayer.edit_example: fit first")
        assert self.pose_space is not None
        j = self.example_names.index(example) if isinstance(example, str) else int(example)
        ps = self.pose_space.edited(j, scale=scale, mask=mask)
        with self._lock:
            self.pose_space = ps
            assert self._evaluator is not None
            self._evaluator = DetailEvaluator(ps, self._evaluator.faces, self._evaluator.neighbours, self.backend)
        self._changed()
        return ps

    # ------------------------------------------------------------------ evaluate
    def details(self, model: FaceModel, X: ArrayLike | None = None) -> NDArray[np.float32] | None:
        """World detail displacement for the model's current state (or a given large-scale mesh)."""
        if not self.enabled or self.strength == 0.0 or self._evaluator is None or self.graph is None:
            return None
        h = model.handles.vertices
        if self._handles is None or h.shape != self._handles.shape or np.any(h != self._handles):
            return None  # handles changed since the fit: stale until refitted
        X32 = np.ascontiguousarray(self.large_scale(model) if X is None else X, np.float32)
        f = self.graph.strain(X32[self._handles].astype(np.float64))
        self.last_strain = f
        if not np.any(np.abs(f) > _ZERO_STRAIN):
            return None
        with self._lock:
            return self._evaluator.apply(X32, f, self.strength, add_base=False)

    def __call__(self, model: FaceModel) -> NDArray[np.float32] | None:
        return self.details(model)


def fit_sample_wrinkles(
    model: FaceModel,
    layer: WrinkleLayer | None = None,
    poses: Mapping[str, Mapping[str, float]] | None = None,
    sculptor: object | None = None,
) -> WrinkleLayer:
    """Convenience: procedural example poses (:mod:`workbench.methods.wrinkles.examples`) -> fitted, attached layer.

    Sets the default handles first if the model has none.
    """
    from workbench.methods.handles.presets import default_face_handles
    from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor

    if len(model.handles) == 0:
        model.set_handles(default_face_handles(model), label="Default handles")
    s = sculptor if isinstance(sculptor, WrinkleSculptor) else WrinkleSculptor(model)
    poses = poses or EXAMPLE_POSES
    examples = {k: (w, s.detailed(w)) for k, w in poses.items()}
    layer = layer or WrinkleLayer()
    layer.fit(model, examples)
    if layer._model is not model:
        layer.attach(model)
    return layer


__all__: Sequence[str] = ["WrinkleLayer", "fit_sample_wrinkles"]
