"""A face the tests rig: the sample head re-triangulated and warped by a known smooth warp, in cm.

:class:`Actor` knows its true shapes (``warp(p + delta) - warp(p)``) and makes
example poses at known weights, so refinement and the Rig tab are tested
against ground truth.
"""

from __future__ import annotations

import numpy as np

from workbench.model import FaceModel, ModelMetadata
from workbench.rigging import synthetic as syn

WARP = syn.SmoothWarp(
    centres=np.array([[0.4, 7.3, 1.2], [-0.3, 6.4, 1.3]]),
    radii=np.array([0.35, 0.4]),
    amplitudes=np.array([[0.05, 0.04, 0.08], [-0.04, 0.0, 0.06]]),
    scale=np.array([1.06, 0.96, 1.03]),
    rotation=syn.SmoothWarp.rotation_xyz([0, 0, 0]),
    unit=10.0,
    translation=np.array([0.0, -60.0, 0.0]),
)


class Actor:
    def __init__(self, head: FaceModel) -> None:
        V2, F2, W = syn.split_remesh(head.vertices, head.faces, seed=3)
        lab = head.component_labels[np.asarray(W.argmax(axis=1)).ravel()]
        self.head, self.W, self.points = head, W, V2
        self.model = FaceModel(WARP(V2), F2, component_labels=lab, component_names=head.component_names,
                               metadata=ModelMetadata(name="actor", units="cm"))

    def truth(self, name: str) -> np.ndarray:
        d = self.W @ self.head.shapes[self.head.shape_names.index(name)].delta.astype(np.float64)
        return WARP(self.points + d) - WARP(self.points)

    def pose(self, weights: dict[str, float]) -> np.ndarray:
        d = sum(self.W @ (w * self.head.shapes[self.head.shape_names.index(k)].delta.astype(np.float64))
                for k, w in weights.items())
        return WARP(self.points + d)
