"""Shared pieces of the capture tests' generated takes."""

from __future__ import annotations

import numpy as np

from workbench.capture import synthetic_performance
from workbench.capture.rig import ExpressionSpace


def marker_visible_shapes(model, seed: int = 1) -> np.ndarray:
    """Indices of the shapes that move one of the default 100 face markers by > 0.5 % of the head.

    (The eyeball and tongue shapes move no skin marker: a marker take cannot see them.)
    """
    space = ExpressionSpace.from_model(model)
    probe = synthetic_performance(model, 1, seed=seed)
    _, D = space.marker_basis(probe.marker_ids)
    return np.flatnonzero(np.linalg.norm(D, axis=1).max(0) > 0.005 * space.size)
