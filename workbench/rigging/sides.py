"""The two models of a rig transfer in its working frame, and the checks their skins must pass.

Step 1 of :mod:`workbench.rigging.transfer`: each model goes to metres with the
subject's left, up and front along x, y, z (:func:`canonical_frame`), its skin
is the surface of its skin triangles (:func:`workbench.geometry.masks.skin_surface`)
and that surface must be a usable one (:func:`check_surface`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.core.shapes import UNIT_TO_METRES
from workbench.geometry.axes import AxesError, face_axes
from workbench.geometry.masks import MissingPartError, skin_surface
from workbench.geometry.normals import triangle_areas
from workbench.geometry.similarity import Similarity
from workbench.model import FaceModel
from workbench.rigging.report import RigTransferError

__all__ = ["Side", "canonical_frame", "check_landmarks", "check_surface", "eye_centres", "part_centre", "skin_of"]


@dataclass
class Side:
    """One model in the working frame: skin, parts, roles."""

    model: FaceModel
    frame: Similarity  # model coordinates -> working frame
    skin_ids: NDArray[np.int64]  # model vertex ids of the skin
    skin_faces: NDArray[np.int64]  # local (into skin_ids)
    X: NDArray[np.float64]  # all vertices in the working frame
    roles: tuple[str, ...]

    @property
    def skin_X(self) -> NDArray[np.float64]:
        return self.X[self.skin_ids]

    def moved(self, frame: Similarity) -> Side:
        """The same model seen through another frame."""
        return Side(self.model, frame, self.skin_ids, self.skin_faces, frame(self.model.vertices), self.roles)

    def skin_local(self, vertices: NDArray[np.int64]) -> NDArray[np.int64]:
        """Positions of model vertex ids in :attr:`skin_ids` (-1 off the skin)."""
        local = np.full(self.model.n_vertices, -1, np.int64)
        local[self.skin_ids] = np.arange(self.skin_ids.size)
        return local[np.asarray(vertices, np.int64)]


def canonical_frame(model: FaceModel) -> Similarity:
    """Model coordinates -> metres, subject's left / up / front as x / y / z."""
    try:
        axes = face_axes(model)
    except AxesError as e:
        raise RigTransferError(str(e)) from None
    return Similarity(UNIT_TO_METRES[model.metadata.units], axes, np.zeros(3))


def skin_of(model: FaceModel, what: str) -> tuple[NDArray[np.int64], NDArray[np.int64], tuple[str, ...]]:
    """The skin surface (model ids, local triangles) and the part roles; raises when there is none."""
    if np.asarray(model.faces).size == 0:
        raise RigTransferError(f"{what} {model.metadata.name or 'model'}: the mesh has no triangles")
    try:
        ids, faces = skin_surface(model)
    except MissingPartError as e:
        raise RigTransferError(f"{what} {e}") from None
    return ids, faces, tuple(model.part_roles)


def check_landmarks(
    landmarks: Sequence[tuple[int, int]] | None, source: FaceModel, target: FaceModel
) -> list[tuple[int, int]]:
    """The ``(source_vertex, target_vertex)`` pairs as ints, each vertex inside its model; raises otherwise."""
    if landmarks is None:
        return []
    out = []
    for i, pair in enumerate(landmarks):
        try:
            a, b = (int(x) for x in pair)
        except (TypeError, ValueError):
            raise RigTransferError(f"landmarks[{i}]: expected a (source_vertex, target_vertex) pair, got {pair!r}") from None
        if not 0 <= a < source.n_vertices:
            raise RigTransferError(f"landmarks[{i}]: source vertex {a} is outside 0..{source.n_vertices - 1}")
        if not 0 <= b < target.n_vertices:
            raise RigTransferError(f"landmarks[{i}]: target vertex {b} is outside 0..{target.n_vertices - 1}")
        out.append((a, b))
    return out


def check_surface(X: NDArray[np.float64], F: NDArray[np.int64], what: str) -> tuple[NDArray[np.bool_], list[str]]:
    """Degenerate and non-manifold checks: (usable face mask, warnings); raises when nothing usable is left."""
    warnings: list[str] = []
    if F.shape[0] < 4:
        raise RigTransferError(f"{what}: the skin has {F.shape[0]} triangles; a face needs a surface")
    area = triangle_areas(X, F)
    scale = float(np.median(area)) if area.size else 0.0
    if not np.isfinite(scale) or scale <= 0:
        raise RigTransferError(f"{what}: the skin's triangles are degenerate (zero area)")
    good = area > 1e-8 * scale
    bad = int((~good).sum())
    if bad > 0.05 * F.shape[0]:
        raise RigTransferError(
            f"{what}: {bad} of {F.shape[0]} skin triangles are degenerate (zero area); clean the mesh first"
        )
    if bad:
        warnings.append(f"{what}: {bad} degenerate (zero-area) skin triangles left out of the solve")
    n = X.shape[0]
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    nm = int((counts > 2).sum())
    if nm > 0.01 * counts.size:
        raise RigTransferError(
            f"{what}: {nm} non-manifold edges (shared by more than two triangles) in the skin; "
            "the mesh is not a surface — split or clean it first"
        )
    if nm:
        warnings.append(f"{what}: {nm} non-manifold skin edges (shared by more than two triangles)")
    return good, warnings


def part_centre(side: Side, comp: int) -> NDArray[np.float64]:
    """(3,) centroid of component ``comp`` in the working frame."""
    ids = np.flatnonzero(side.model.component_labels == comp)
    return side.X[ids].mean(0)


def eye_centres(side: Side) -> NDArray[np.float64] | None:
    """(2, 3) left and right eyeball centres (working frame), or None."""
    roles = side.roles
    if "eyeball_left" in roles and "eyeball_right" in roles:
        return np.stack([part_centre(side, roles.index("eyeball_left")), part_centre(side, roles.index("eyeball_right"))])
    return None
