"""``model.wrinkles``: fit pose-space wrinkles and edit them, each edit one undo step.

The fitted state is the ``wrinkles`` slot (:class:`WrinkleState`); this facet
reads it (``fitted``, ``strength``, ``example_names``…) and replaces it for
every edit: fitting, strength, on/off, scaling or painting out one example's
wrinkles (which refits, so the change reaches every pose near that example).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.shapes import ModelError
from workbench.methods.wrinkles.layer import WrinkleLayer, WrinkleState, blend_weights, fit_wrinkles

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

    def large_scale(self) -> NDArray[np.float32]:
        """(n, 3) float32: the live mesh the wrinkles sit on (every layer below them)."""
        m = self._model
        with m.lock:
            return m.pipeline.run(m.view()).below["wrinkles"]

    def details(self, X: ArrayLike | None = None) -> NDArray[np.float32] | None:
        """World detail displacement for the live state, or on a given large-scale mesh ``X``."""
        m = self._model
        with m.lock:
            return self.layer.details(m, self.large_scale() if X is None else X)

    def example_mesh(self, example: str | int) -> NDArray[np.float64]:
        """(n, 3) float64 blend of an example's weights (its large-scale mesh)."""
        j = self._index(example)
        return blend_weights(self._model, self.state.example_weights[j])

    def __repr__(self) -> str:
        st = self.state
        if not st.fitted:
            return "<wrinkles: not fitted>"
        return f"<wrinkles: {len(st.example_names)} examples, strength {st.strength:g}, {'on' if st.enabled else 'off'}>"

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
        s = float(strength)
        if not np.isfinite(s):
            raise ModelError(f"wrinkle strength must be finite, got {strength!r}")
        if s != self.state.strength:
            self._model.set_slot("wrinkles", self.state.replace(strength=s), "Wrinkle strength")

    def set_enabled(self, enabled: bool) -> None:
        """Show or hide the wrinkles (undoable)."""
        e = bool(enabled)
        if e != self.state.enabled:
            self._model.set_slot("wrinkles", self.state.replace(enabled=e), "Wrinkles on" if e else "Wrinkles off")

    def edit_example(self, example: str | int, *, scale: float | ArrayLike = 1.0,
                     mask: ArrayLike | None = None) -> PoseSpace:
        """Scale / paint out one example's details and refit (one undo step).

        ``scale`` a float or (n,) per vertex; ``mask`` (n,) where 1 removes the details.
        """
        st = self.state
        if st.pose_space is None:
            raise ModelError("wrinkles.edit_example: fit first")
        j = self._index(example)
        ps = st.pose_space.edited(j, scale=scale, mask=mask)
        verb = "Erase wrinkles of" if mask is not None else "Scale wrinkles of"
        self._model.set_slot("wrinkles", st.replace(pose_space=ps), f"{verb} {st.example_names[j]}")
        return ps

    def clear(self) -> None:
        """Forget the fit (undoable)."""
        if self.state.fitted:
            self._model.set_slot("wrinkles", WrinkleState(), "Clear wrinkles")
