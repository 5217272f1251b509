"""A face the tests rig: the sample head re-triangulated and warped by a known smooth warp, in cm.

``Actor(head)`` is a :class:`workbench.testing.GeneratedFace`: it knows its true
shapes (``truth(name)``: ``warp(p + delta) - warp(p)``) and makes example poses
at known weights (``pose``), so refinement and the Rig tab are tested against
ground truth. ``WARP`` is the warp's data (two bumps, a scale, dm -> cm, no turn).
"""

from __future__ import annotations

import numpy as np

from workbench.model import FaceModel
from workbench.testing import GeneratedFace, SmoothWarp, remeshed

WARP = SmoothWarp(
    centres=np.array([[0.4, 7.3, 1.2], [-0.3, 6.4, 1.3]]),
    radii=np.array([0.35, 0.4]),
    amplitudes=np.array([[0.05, 0.04, 0.08], [-0.04, 0.0, 0.06]]),
    scale=np.array([1.06, 0.96, 1.03]),
    unit=10.0,
    translation=np.array([0.0, -60.0, 0.0]),
)


class Actor(GeneratedFace):
    """The sample head remeshed (seed 3) and warped by ``WARP``, in cm, without shapes."""

    def __init__(self, head: FaceModel) -> None:
        face = remeshed(head, seed=3, warp=WARP, units="cm", name="actor")
        super().__init__(face.model, face.source, face.W, face.points, face.warp)
