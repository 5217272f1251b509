"""Which vertices the point-cloud tracker fits (step 1 of :mod:`workbench.capture.clouds`).

The front-facing skin around the moving part of the face
(:func:`~workbench.capture.synthetic.face_vertices`), without the mesh border
and its first ring, spread by farthest-point sampling into vertices the shapes
move (the weights' constraints) and vertices they barely move (the rigid pose).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.capture.result import CloudTrackError
from workbench.capture.rig import ExpressionSpace
from workbench.capture.synthetic import face_vertices
from workbench.geometry.surface import boundary_vertices

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["STABLE_MOTION", "sample_vertices"]

#: vertices moving less than this share of the head size under any one shape are the stable region
STABLE_MOTION = 0.005


def _farthest(V: NDArray[np.float64], cand: NDArray[np.intp], m: int, seed: int) -> NDArray[np.intp]:
    """``m`` spread-out vertices of ``cand`` by farthest-point sampling (deterministic from ``seed``)."""
    m = min(int(m), cand.size)
    if m <= 0:
        return np.zeros(0, np.intp)
    P = V[cand]
    first = int(np.random.default_rng(seed).integers(cand.size))
    chosen = np.empty(m, np.intp)
    chosen[0] = first
    d = ((P - P[first]) ** 2).sum(1)
    for j in range(1, m):
        i = int(np.argmax(d))
        chosen[j] = i
        np.minimum(d, ((P - P[i]) ** 2).sum(1), out=d)
    return np.sort(cand[chosen])


def _border_ring(F: NDArray[np.int64], n: int) -> NDArray[np.bool_]:
    """(n,) bool: vertices on the mesh border (an edge of one face) and their neighbours."""
    on = boundary_vertices(F, n)
    ring = on.copy()
    touch = on[F].any(1)
    ring[F[touch].ravel()] = True
    return ring


def sample_vertices(model: FaceState, samples: int = 1200, rigid_samples: int = 400, *, seed: int = 0
                    ) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """The vertices the cloud tracker fits: moving face vertices and stable ones (module docstring, step 1).

    Parameters
    ----------
    model : FaceModel
    samples : int
        Vertices the shapes move (the weights' constraints), ≥ 1.
    rigid_samples : int
        Stable vertices (the rigid pose), ≥ 6.
    seed : int
        Start of the farthest-point sampling.

    Returns
    -------
    ids : (s,) int
        Sorted vertex ids (give them to :class:`AdaptiveModel` as ``vertex_ids`` to reuse it).
    stable : (s,) bool
        Which of them are stable.
    """
    if int(samples) < 1:
        raise CloudTrackError(f"samples must be ≥ 1, got {samples!r}")
    if int(rigid_samples) < 6:
        raise CloudTrackError(f"rigid_samples must be ≥ 6, got {rigid_samples!r}")
    V = np.asarray(model.vertices, np.float64)
    F = np.asarray(model.faces, np.int64)
    space = ExpressionSpace.from_model(model)
    cand = face_vertices(model)
    if F.size:
        cand = cand[~_border_ring(F, model.n_vertices)[cand]]
    if cand.size < 6:
        raise CloudTrackError(f"model: only {cand.size} front-facing skin vertices away from the border to fit")
    mot = space.motion(cand) / space.size
    still = cand[mot <= STABLE_MOTION]
    if still.size < 6:  # a face whose shapes move everything: the least moving vertices
        still = cand[np.argsort(mot)[: max(6, min(int(rigid_samples), cand.size // 4))]]
    moving = np.setdiff1d(cand, still)
    if moving.size == 0:
        moving = cand
    r = _farthest(V, still, int(rigid_samples), seed)
    w = _farthest(V, moving, int(samples), seed + 1)
    ids = np.union1d(r, w)
    return ids.astype(np.intp), np.isin(ids, r)
