"""``model.wrinkles``: fit pose-space wrinkles and edit them, each edit one undo step.

The fitted state is the ``wrinkles`` slot (:class:`WrinkleState`); this facet
reads it (``fitted``, ``fresh``, ``strength``, ``example_names``, ``strain()``,
``example_detailed()``…) and replaces it for every edit: fitting, strength,
on/off, scaling or painting out one example's wrinkles and adding an example
(both refit, so the change reaches every pose near that example). Undo puts the
previous state back as it was (the same pose space object: no refit).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.shapes import ModelError
from workbench.geometry.masks import skin_or_all_mask
from workbench.methods.wrinkles.editing import detailed_mesh, example_training, with_example
from workbench.methods.wrinkles.features import tangent_neighbours
from workbench.methods.wrinkles.layer import (
    WrinkleLayer,
    WrinkleState,
    blend_weights,
    fit_wrinkles,
)

if TYPE_CHECKING:
    from workbench.core.state import FaceState
    from workbench.methods.wrinkles.features import FeatureGraph
    from workbench.methods.wrinkles.pose_space import PoseSpace


def check_state(model: FaceState, value: Any) -> WrinkleState:
    if not isinstance(value, WrinkleState):
        raise ModelError(f"wrinkles: expected a WrinkleState, got {type(value).__name__}")
    return value


class WrinklesFacet:
    """The pose-space wrinkle tool of one model (see the module docstring)."""

    def __init__(self, model: FaceState) -> None:
        self._model = model

    # ------------------------------------------------------------------ reading
    @property
    def state(self) -> WrinkleState:
        return self._model.slot("wrinkles")

    @property
    def layer(self) -> WrinkleLayer:
        return self._model.pipeline.layer("wrinkles")  # type: ignore[return-value]

    @property
    def fitted(self) -> bool:
        return self.state.fitted

    @property
    def strength(self) -> float:
        return self.state.strength

    @property
    def enabled(self) -> bool:
        return self.state.enabled

    @property
    def graph(self) -> FeatureGraph | None:
        return self.state.graph

    @property
    def pose_space(self) -> PoseSpace | None:
        return self.state.pose_space

    @property
    def example_names(self) -> list[str]:
        return list(self.state.example_names)

    @property
    def example_weights(self) -> list[Mapping[str, float]]:
        return list(self.state.example_weights)

    @property
    def last_strain(self) -> NDArray[np.float64] | None:
        """Strain of the feature graph at the last evaluation (for colouring it)."""
        return self.layer.last_strain

    @property
    def fresh(self) -> bool:
        """Fitted, and for the model's current handle vertices (a fit for other handles adds nothing)."""
        return self.state.made_for(self._model.slot("handles").vertices)

    @property
    def feature_edges(self) -> NDArray[np.int32] | None:
        """(F, 2) int32: the feature graph's edges as pairs of vertex ids (None when not fitted)."""
        st = self.state
        if st.graph is None or st.handles is None:
            return None
        return st.handles[np.asarray(st.graph.edges, np.int64)]

    def strain(self) -> NDArray[np.float64] | None:
        """(F,) float64: the feature graph's strain on the live large-scale mesh.

        What the layer measures (whether or not the wrinkles are shown); None
        when not :attr:`fresh`.
        """
        st = self.state
        if not self.fresh:
            return None
        assert st.graph is not None and st.handles is not None
        X = self.large_scale()
        return st.graph.strain(X[st.handles].astype(np.float64))

    def large_scale(self) -> NDArray[np.float32]:
        """(n, 3) float32: the live mesh the wrinkles sit on (every layer below them)."""
        m = self._model
        with m.lock:
            return m.pipeline.run(m.view()).below["wrinkles"]

    def details(self, X: ArrayLike | None = None) -> NDArray[np.float32] | None:
        """(n, 3) float32 world detail displacement: what the layer adds to the live mesh, or on ``X``.

        Without ``X`` this is the live evaluation's (cached, read-only); None
        when the layer adds nothing (not fitted or not fresh, off, strength 0,
        or the rest pose).
        """
        m = self._model
        with m.lock:
            if X is None:
                return m.pipeline.run(m.view()).displacements.get("wrinkles")
            return self.layer.details(m, X)

    def example_mesh(self, example: str | int) -> NDArray[np.float64]:
        """(n, 3) float64 blend of an example's weights (its large-scale mesh)."""
        j = self._index(example)
        return blend_weights(self._model, self.state.example_weights[j])

    def example_detailed(self, example: str | int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The large-scale and the detailed mesh of one example, as the fit holds it now.

        The fit keeps each example's details in local frames of its blend
        (after any :meth:`edit_example`); this puts them back on the blend.

        Returns
        -------
        blend, detailed : (n, 3) float64
        """
        ps = self._require_fit("example_detailed")
        j = self._index(example)
        m = self._model
        X = blend_weights(m, self.state.example_weights[j])
        return X, detailed_mesh(X, m.faces, tangent_neighbours(m.faces, m.n_vertices), ps.train_values[j])

    def __repr__(self) -> str:
        st = self.state
        if not st.fitted:
            return "<wrinkles: not fitted>"
        return f"<wrinkles: {len(st.example_names)} examples, strength {st.strength:g}, {'on' if st.enabled else 'off'}>"

    def _require_fit(self, what: str) -> PoseSpace:
        ps = self.state.pose_space
        if ps is None:
            raise ModelError(f"wrinkles.{what}: nothing is fitted (model.wrinkles.fit first)")
        return ps

    def _index(self, example: str | int) -> int:
        names = self.state.example_names
        if isinstance(example, str):
            if example not in names:
                raise KeyError(f"no wrinkle example {example!r}; examples are {list(names)}")
            return names.index(example)
        j = int(example)
        if not 0 <= j < len(names):
            raise IndexError(f"wrinkle example index must be in 0..{len(names) - 1}, got {example}")
        return j

    # -------------------------------------------------------------------- edits
    def fit(self, examples: Mapping[str, tuple[Mapping[str, float], ArrayLike]], **options: Any) -> PoseSpace:
        """Learn details from ``{name: (weights, detailed (n, 3))}`` (undoable); see :func:`fit_wrinkles`."""
        st = fit_wrinkles(self._model, examples, **options)
        self._model.set_slot("wrinkles", st, f"Fit wrinkles ({len(st.example_names)} examples)")
        assert st.pose_space is not None
        return st.pose_space

    def set_strength(self, strength: float) -> None:
        """Scale the details (0 = off, 1 = as learned); undoable, equal values record nothing."""
        try:
            s = float(strength)
        except (TypeError, ValueError):
            raise ModelError(f"wrinkle strength must be a number, got {strength!r}") from None
        if not (np.isfinite(s) and s >= 0.0):
            raise ModelError(f"wrinkle strength must be a finite number >= 0, got {strength!r}")
        if s != self.state.strength:
            self._model.set_slot("wrinkles", self.state.replace(strength=s), f"Wrinkle strength {s:g}")

    def set_enabled(self, enabled: bool) -> None:
        """Show or hide the wrinkles (undoable; equal values record nothing)."""
        e = bool(enabled)
        if e != self.state.enabled:
            self._model.set_slot("wrinkles", self.state.replace(enabled=e), "Wrinkles on" if e else "Wrinkles off")

    def edit_example(self, example: str | int, *, scale: float | ArrayLike = 1.0,
                     mask: ArrayLike | None = None) -> PoseSpace:
        """Scale / paint out one example's details and refit (one undo step).

        Parameters
        ----------
        example : name or index
        scale : float or (n,) float
            Multiplies the example's details (per vertex for an array); finite.
        mask : (n,) float, optional
            Paint-out mask in [0, 1] (clipped): 1 removes the details, 0 keeps them.

        Returns
        -------
        PoseSpace
            The new pose space; the current one, and no undo step, when the edit
            changes nothing (``scale`` 1 and no mask, or a mask of zeros).
        """
        st = self.state
        ps = self._require_fit("edit_example")
        j = self._index(example)
        n = self._model.n_vertices
        s = self._per_vertex(scale, n, "scale")
        m = None if mask is None else np.clip(self._per_vertex(mask, n, "mask"), 0.0, 1.0)
        if m is not None and not np.any(m > 0):
            m = None
        if m is None and s.ndim == 0 and float(s) == 1.0:
            return ps
        new = ps.edited(j, scale=s, mask=m)
        name = st.example_names[j]
        label = f"Erase wrinkles of {name}" if m is not None else (
            f"Scale wrinkles of {name} ×{float(s):g}" if s.ndim == 0 else f"Scale wrinkles of {name}")
        self._model.set_slot("wrinkles", st.replace(pose_space=new), label)
        return new

    def add_example(self, name: str, weights: Mapping[str, float], detailed: ArrayLike) -> PoseSpace:
        """One more detailed example ``(weights, detailed (n, 3))`` and refit (one undo step).

        Keeps the feature graph, the fitted handles, the edge weights and every
        earlier example's (possibly edited) details; the new example's details
        are taken on the skin like :meth:`fit`'s.

        Raises
        ------
        ModelError
            Not fitted; an empty or taken name; weights of the rest pose or of
            an existing example; ``detailed`` not (n, 3) finite.
        KeyError
            A weight names no blendshape.
        """
        st = self.state
        ps = self._require_fit("add_example")
        assert st.graph is not None and st.handles is not None
        m = self._model
        if not isinstance(name, str) or not name.strip():
            raise ModelError(f"wrinkles.add_example: the example needs a name, got {name!r}")
        if name in st.example_names:
            raise ModelError(f"wrinkles.add_example: an example named {name!r} exists already")
        w = {str(k): float(v) for k, v in weights.items() if float(v) != 0.0}
        if not w:
            raise ModelError("wrinkles.add_example: every weight is 0 (the rest pose has no wrinkles to learn)")
        for other, ow in zip(st.example_names, st.example_weights, strict=True):
            keys = set(ow) | set(w)
            if all(abs(ow.get(k, 0.0) - w.get(k, 0.0)) < 1e-6 for k in keys):
                raise ModelError(f"wrinkles.add_example: these are the weights of example {other!r} already")
        D = np.asarray(detailed, np.float64)
        if D.shape != (m.n_vertices, 3) or not np.all(np.isfinite(D)):
            raise ModelError(f"wrinkles.add_example: detailed must be ({m.n_vertices}, 3) finite, got {D.shape}")
        X = blend_weights(m, w)
        f, d = example_training(st.graph, st.handles, X, D, m.faces,
                                tangent_neighbours(m.faces, m.n_vertices), skin_or_all_mask(m))
        try:
            new = with_example(ps, f, d)
        except ValueError as exc:
            raise ModelError(f"wrinkles.add_example: {exc}") from None
        self._model.set_slot("wrinkles", st.replace(
            pose_space=new, example_names=(*st.example_names, name), example_weights=(*st.example_weights, w),
        ), f"Add wrinkle example {name}")
        return new

    def prepare(self) -> None:
        """Build the handle shell and load the detail kernels now, not on the first drag.

        The first detail evaluation in a fresh process loads numba's cached
        machine code (or compiles it: seconds), and the first drag of a new
        handle set factorises the shell; both would otherwise stall the first
        drag. Changes nothing (no undo step, no event).
        """
        m = self._model
        m.handles.prepare()  # type: ignore[attr-defined]
        st = self.state
        if not (st.enabled and st.strength and self.fresh):
            return
        layer = self.layer
        seen = layer.last_strain
        # a 1 % stretch of every feature edge: a non-zero strain, so the kernels run
        layer.details(m, self.large_scale() * np.float32(1.01))
        layer.last_strain = seen

    def clear(self) -> None:
        """Forget the fit (undoable)."""
        if self.state.fitted:
            self._model.set_slot("wrinkles", WrinkleState(), "Clear wrinkles")

    @staticmethod
    def _per_vertex(value: float | ArrayLike, n: int, what: str) -> NDArray[np.float64]:
        """A finite scalar, or (n,) finite values (a 0-d array or an (n,) array)."""
        try:
            a = np.asarray(value, np.float64)
        except (TypeError, ValueError):
            raise ModelError(f"wrinkles.edit_example: {what} must be a number or ({n},) numbers") from None
        if a.ndim != 0:
            if a.size != n:
                raise ModelError(f"wrinkles.edit_example: {what} must be a number or ({n},) values, got {a.shape}")
            a = a.reshape(n)
        if not np.all(np.isfinite(a)):
            raise ModelError(f"wrinkles.edit_example: {what} must be finite")
        return a
