"""Numerics of editing fitted wrinkles: an example's detailed mesh, a new example, an eraser stroke's mask.

Small array-in / array-out functions behind ``model.wrinkles``
(:mod:`workbench.methods.wrinkles.facet`) and the wrinkle panel's eraser; none
of them changes a model.

* :func:`detailed_mesh`: an example's details (local frames, as the pose space
  stores them after any edit) put back on its large-scale mesh.
* :func:`example_training`: the feature vector and the local details of one
  detailed example (what a fit learns from it).
* :func:`with_example`: a pose space refitted with one more example, with the
  same edge weights, mode and cut-off (earlier examples keep their edits).
* :func:`brush_mask`: an eraser stroke's mask grown by brush dabs.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.methods.paint.painting import Brush, PaintSurface, falloff_curve
from workbench.methods.wrinkles.features import (
    FeatureGraph,
    extract_details,
    local_frames,
    to_world,
)
from workbench.methods.wrinkles.pose_space import PoseSpace, fit_pose_space

__all__ = ["brush_mask", "detailed_mesh", "example_training", "with_example"]


def detailed_mesh(
    large_scale: ArrayLike, faces: ArrayLike, neighbours: ArrayLike, local_details: ArrayLike
) -> NDArray[np.float64]:
    """``X + R_v d_v``: details stored in local frames put back on their large-scale mesh.

    Parameters
    ----------
    large_scale : (n, 3) float
        The example's large-scale mesh ``X`` (the blend of its weights).
    faces : (m, 3) int
    neighbours : (n,) int
        :func:`~workbench.methods.wrinkles.features.tangent_neighbours` of the mesh.
    local_details : (n, 3) float
        ``d_v`` in the frames of ``X`` (a row of ``PoseSpace.train_values``).

    Returns
    -------
    (n, 3) float64
        The detailed mesh (inverse of
        :func:`~workbench.methods.wrinkles.features.extract_details` up to rounding).
    """
    X = np.asarray(large_scale, np.float64)
    d = np.asarray(local_details, np.float64)
    if X.ndim != 2 or X.shape[1] != 3 or d.shape != X.shape:
        raise ValueError(f"detailed_mesh: need large_scale (n, 3) and local_details (n, 3), got {X.shape}, {d.shape}")
    return X + to_world(local_frames(X, faces, neighbours), d)


def example_training(
    graph: FeatureGraph,
    handles: ArrayLike,
    large_scale: ArrayLike,
    detailed: ArrayLike,
    faces: ArrayLike,
    neighbours: ArrayLike,
    active: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """What a fit learns from one detailed example: its strain and its local details.

    Parameters
    ----------
    graph : FeatureGraph
    handles : (h,) int
        The handle vertices the graph's edges join.
    large_scale : (n, 3) float
        The example's large-scale mesh (the blend of its weights).
    detailed : (n, 3) float
        The detailed example.
    faces : (m, 3) int
    neighbours : (n,) int
        Tangent neighbours of the mesh.
    active : (n,) bool
        Vertices that may carry details (the others get zero).

    Returns
    -------
    feature : (F,) float64
        The strain of the feature graph on ``large_scale``.
    details : (n, 3) float64
        ``R_vᵀ (detailed − large_scale)``, zero outside ``active``.
    """
    X = np.asarray(large_scale, np.float64)
    n = X.shape[0]
    D = np.asarray(detailed, np.float64)
    if D.size != 3 * n:
        raise ValueError(f"example_training: detailed must be ({n}, 3) like large_scale, got {D.shape}")
    D = D.reshape(n, 3)
    act = np.asarray(active, bool).reshape(n)
    d = extract_details(D, X, local_frames(X, faces, neighbours))
    d[~act] = 0.0
    h = np.asarray(handles, np.int64)
    return graph.strain(X[h]), d


def with_example(ps: PoseSpace, feature: ArrayLike, details: ArrayLike) -> PoseSpace:
    """``ps`` refitted with one more training pose (appended last).

    The earlier training values are kept as they are (with any
    :meth:`~PoseSpace.edited` change), and so are the edge weights, the mode and
    the cut-off. The new pose joins the basis (all poses in ``interp`` mode).

    Parameters
    ----------
    ps : PoseSpace
        A fitted pose space, ``T`` poses of ``F`` features on ``n`` vertices.
    feature : (F,) float
    details : (n, 3) float

    Returns
    -------
    PoseSpace
        ``T + 1`` training poses.
    """
    T, F = ps.train_features.shape
    n = ps.train_values.shape[1]
    f = np.asarray(feature, np.float64).reshape(-1)
    d = np.asarray(details, np.float32)
    if f.shape != (F,) or d.shape != (n, 3):
        raise ValueError(f"with_example: need a feature ({F},) and details ({n}, 3), got {f.shape}, {d.shape}")
    if not np.any(f != 0.0):
        raise ValueError("with_example: the new pose has no strain (it is the rest pose for the feature graph)")
    Ft = np.vstack([ps.train_features, f[None]])
    Dt = np.concatenate([ps.train_values, d[None]], axis=0)
    basis = [b for b in ps.basis if b >= 0] + [T]
    return fit_pose_space(Ft, Dt, alpha=ps.alpha, basis=basis, mode=ps.mode, rcond=ps.rcond)


def brush_mask(
    mask: ArrayLike, surface: PaintSurface, brush: Brush, centres: Iterable[int]
) -> NDArray[np.float32]:
    """An eraser stroke's mask after brush dabs at ``centres``: each vertex keeps its largest strength.

    As a paint stroke caps at its opacity: every dab adds the brush footprint
    (surface distance on the rest mesh, the brush's falloff, and around the
    mirror partner with ``brush.mirror``), and a vertex keeps the largest
    strength any dab of the stroke gave it.

    Parameters
    ----------
    mask : (n,) float
        The stroke's mask so far (zeros at the start); not changed.
    surface : PaintSurface
    brush : Brush
        Radius, opacity (the strength at the centre), falloff, mirror.
    centres : iterable of int
        Vertex ids of the dabs' centres.

    Returns
    -------
    (n,) float32
        A new array.
    """
    out = np.array(mask, np.float32).reshape(-1)
    n = out.shape[0]
    if n != surface.n:
        raise ValueError(f"brush_mask: the mask has {n} values for a surface of {surface.n} vertices")
    ids = np.asarray(list(centres) if not isinstance(centres, np.ndarray) else centres, np.int64).reshape(-1)
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise ValueError(f"brush_mask: vertex ids must be in 0..{n - 1}")
    for c in ids:
        dabs = [int(c)]
        if brush.mirror and surface.mirror[c] != c:
            dabs.append(int(surface.mirror[c]))
        for cc in dabs:
            near, dist = surface.within(cc, brush.radius)
            st = (brush.opacity * falloff_curve(dist / brush.radius, brush.falloff)).astype(np.float32)
            out[near] = np.maximum(out[near], st)
    return out
