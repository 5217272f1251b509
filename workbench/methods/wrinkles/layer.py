"""Pose-space wrinkles as a pipeline layer: large-scale mesh below + WPSD details (Bickel et al. 2008, §5).

The fitted wrinkles are the model's ``wrinkles`` slot (:class:`WrinkleState`,
immutable: fitting, strength, on/off and example edits replace it, so each is
one undo step through ``model.wrinkles``). On every evaluation the layer

1. takes the mesh below it as the large-scale mesh ``X`` (blend, regions,
   handle shell, paint),
2. measures the strain of the feature graph at the fitted handle vertices,
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

import dataclasses
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.masks import skin_or_all_mask
from workbench.methods.wrinkles.editing import example_training
from workbench.methods.wrinkles.features import FeatureGraph, edge_weights, tangent_neighbours
from workbench.methods.wrinkles.hybrid_deformer import DetailEvaluator
from workbench.methods.wrinkles.pose_space import FitMode, PoseSpace, fit_pose_space, greedy_fit

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState

#: below this relative stretch the pose counts as the rest pose (float32 blend noise is ~5e-6)
_ZERO_STRAIN = 2e-5


@dataclass(frozen=True, eq=False)
class WrinkleState:
    """What the ``wrinkles`` slot holds: a fitted pose space and how strongly it is shown.

    Attributes
    ----------
    graph : FeatureGraph or None
    handles : (h,) int32 or None
        Handle vertices the fit was made for (the layer is silent for other handles).
    pose_space : PoseSpace or None
    example_names : tuple of str
    example_weights : tuple of dict
        The blendshape weights of each example pose.
    strength : float
        Multiplies the details (0 = off, 1 = as learned).
    enabled : bool
    weighted : bool
        WPSD (True) or global PSD.
    free_nodes : bool
        The feature graph's nodes (``handles``) need not be the model's handles: the
        strain is measured at those vertices of whatever mesh is below (a §5.4
        transfer onto a face animated some other way: "the nodes of the feature graph
        and the handle vertices on the target model do not have to match").
    """

    graph: FeatureGraph | None = None
    handles: NDArray[np.int32] | None = None
    pose_space: PoseSpace | None = None
    example_names: tuple[str, ...] = ()
    example_weights: tuple[Mapping[str, float], ...] = ()
    strength: float = 1.0
    enabled: bool = True
    weighted: bool = True
    free_nodes: bool = False

    @property
    def fitted(self) -> bool:
        return self.pose_space is not None

    def replace(self, **changes: Any) -> WrinkleState:
        return dataclasses.replace(self, **changes)

    def made_for(self, handles: NDArray[np.int32]) -> bool:
        """Fitted for exactly these handle vertices (a fit for other handles adds nothing)."""
        h = self.handles
        return (
            self.pose_space is not None and self.graph is not None and h is not None
            and h.shape == handles.shape and bool(np.all(h == handles))
        )

    def active_for(self, handles: NDArray[np.int32]) -> bool:
        """Fitted, shown, and made for exactly these handle vertices (any, with :attr:`free_nodes`)."""
        if not (self.enabled and self.strength != 0.0):
            return False
        if self.free_nodes:
            return self.pose_space is not None and self.graph is not None and self.handles is not None
        return self.made_for(handles)


def blend_weights(model: FaceState | StateView, weights: Mapping[str, float]) -> NDArray[np.float64]:
    """(n, 3) float64 ``neutral + sum_k w_k delta_k`` for given weights (an example's large-scale mesh)."""
    X = np.array(model.vertices, dtype=np.float64)
    names = model.shape_names
    for name, w in weights.items():
        if name not in names:
            raise KeyError(f"wrinkles: unknown blendshape {name!r}")
        s = model.shapes[names.index(name)]
        if w and not s.mute:
            X += float(w) * model.effective_deltas[names.index(name)]
    return X


class WrinkleLayer:
    """Pipeline layer ``"wrinkles"``: reads the ``wrinkles`` and ``handles`` slots.

    Parameters
    ----------
    backend : {"auto", "numba", "numpy"}
        Kernels of the per-frame detail evaluation.
    """

    name = "wrinkles"
    reads = ("wrinkles", "handles")
    linear = False

    def __init__(self, backend: str = "auto") -> None:
        self.backend = backend
        self.last_strain: NDArray[np.float64] | None = None
        self._lock = threading.Lock()
        self._evaluator: tuple[PoseSpace, DetailEvaluator] | None = None

    def evaluator(self, view: FaceState | StateView, ps: PoseSpace) -> DetailEvaluator:
        with self._lock:
            if self._evaluator is None or self._evaluator[0] is not ps:
                nb = tangent_neighbours(view.faces, view.n_vertices)
                self._evaluator = (ps, DetailEvaluator(ps, view.faces, nb, self.backend))
            return self._evaluator[1]

    def details(self, view: FaceState | StateView, X: ArrayLike) -> NDArray[np.float32] | None:
        """World detail displacement on the large-scale mesh ``X`` (None when silent or at rest)."""
        st: WrinkleState = view.slot("wrinkles")
        if not st.active_for(view.slot("handles").vertices):
            return None
        assert st.graph is not None and st.pose_space is not None and st.handles is not None
        X32 = np.ascontiguousarray(X, np.float32)
        f = st.graph.strain(X32[st.handles].astype(np.float64))
        self.last_strain = f
        if not np.any(np.abs(f) > _ZERO_STRAIN):
            return None
        ev = self.evaluator(view, st.pose_space)
        with self._lock:
            return ev.apply(X32, f, st.strength, add_base=False)

    def active(self, view: FaceState | StateView) -> bool:
        """Whether the layer can add anything for this state (fitted, shown, for these handles)."""
        return bool(view.slot("wrinkles").active_for(view.slot("handles").vertices))

    def displacement(self, view: StateView, below: NDArray[np.float32]) -> NDArray[np.float32] | None:
        return self.details(view, below)


def fit_wrinkles(
    model: FaceState,
    examples: Mapping[str, tuple[Mapping[str, float], ArrayLike]],
    *,
    graph: FeatureGraph | None = None,
    neighbours: int = 4,
    beta: float | None = None,
    mode: FitMode = "interp",
    max_basis: int | None = None,
    tolerance: float = 0.0,
    active: ArrayLike | None = None,
    weighted: bool = True,
) -> WrinkleState:
    """Learn details from detailed examples ``{name: (weights, detailed (n, 3))}``; the model is unchanged.

    The model must have handles (e.g. ``default_face_handles``). The feature graph
    defaults to each handle's ``neighbours`` nearest handles. ``active`` (n,) bool
    limits details to those vertices (default: skin). An example's detail is its
    difference from the blend of its weights, so dialling an example in with the
    sliders reproduces it exactly, and dragging handles adds wrinkles by strain.
    """
    h = np.asarray(model.slot("handles").vertices, np.int64)
    if h.size < 2:
        raise ValueError("fit wrinkles: the model needs at least 2 handles (model.handles.set)")
    V = np.asarray(model.vertices, np.float64)
    n = V.shape[0]
    g = graph or FeatureGraph.from_handles(V[h], neighbours)
    act = skin_or_all_mask(model) if active is None else np.asarray(active, bool).reshape(n)
    nb = tangent_neighbours(model.faces, n)
    feats, dets = [], []
    for _, (w, detailed) in examples.items():
        f, d = example_training(g, h, blend_weights(model, w), detailed, model.faces, nb, act)
        feats.append(f)
        dets.append(d)
    Ft, Dt = np.array(feats), np.array(dets, np.float32)
    alpha = edge_weights(V, V[h], g, beta=beta) if weighted else None
    if mode == "interp" and max_basis is None and tolerance == 0.0:
        ps = fit_pose_space(Ft, Dt, alpha=alpha, mode="interp")
    else:
        ps, _ = greedy_fit(Ft, Dt, alpha=alpha, mode=mode, max_basis=max_basis, tolerance=tolerance)
    old = model.slot("wrinkles")
    return WrinkleState(
        g, h.astype(np.int32), ps, tuple(examples), tuple(dict(w) for w, _ in examples.values()),
        old.strength, old.enabled, weighted,
    )
