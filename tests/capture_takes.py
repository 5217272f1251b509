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


def warped_actor(head):
    """The capture tests' actor: ``head`` smoothly warped (a longer nose and chin, other proportions;
    markers up to 9 mm off the rig's neutral), as a :class:`SmoothWarp` in the head's own units."""
    from workbench.rigging.synthetic import SmoothWarp

    V = head.vertices
    lo, hi = V.min(0), V.max(0)
    size = float(np.linalg.norm(hi - lo))
    centre = 0.5 * (lo + hi)
    return SmoothWarp(
        centres=centre + np.array([[0.0, -0.3, 0.6], [0.0, 0.2, 0.9]]),
        radii=np.array([0.25, 0.15]) * size,
        amplitudes=np.array([[0.0, -0.01, 0.015], [0.0, 0.0, 0.02]]) * size,
        scale=np.array([1.03, 0.98, 1.01]),
    )
