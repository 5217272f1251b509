"""Voluntary regions with soft weights (Bermano et al. 2014, §4.3 and §5.3).

Each region is a set of *core* vertices (the paper: left/right mouth halves and
the left/right eyebrows of Tena et al.'s segmentation; here any vertex sets,
e.g. regions of :mod:`workbench.methods.regions`). A triangle's weight is 1 in
the core and decays as a Gaussian of the geodesic distance from it,
``ω = exp(−d² / (2σ²))``. The geodesic distance is the shortest path along mesh
edges (multi-source Dijkstra, ``scipy.sparse.csgraph``), an upper bound of the
true geodesic, ~15 % longer on an icosphere (pinned by a test) — ample for a soft
falloff. A triangle's distance is the mean of its corners'.

Hand-written because it is a few lines around scipy's Dijkstra.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import dijkstra

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["face_voluntary_cores", "voluntary_region_weights"]


def checked_mesh(neutral: ArrayLike, faces: ArrayLike, who: str) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``(V, F)`` as float64 / int64 after checking shapes and indices (errors name ``who``)."""
    V = np.asarray(neutral, np.float64)
    F = np.asarray(faces, np.int64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"{who}neutral must be (n, 3), got {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or (F.size and (F.min() < 0 or F.max() >= len(V))):
        raise ValueError(f"{who}faces must be (m, 3) indices into the {len(V)} vertices of neutral")
    return V, F


def mesh_edges(F: NDArray[np.int64]) -> NDArray[np.int64]:
    """Unique undirected edges ``(e, 2)`` of triangles ``F``, each as (low, high)."""
    return np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)


def voluntary_region_weights(
    neutral: ArrayLike, faces: ArrayLike, cores: Mapping[str, ArrayLike], sigma: float
) -> dict[str, NDArray[np.float32]]:
    """Per-triangle weights of each region: 1 on its core, Gaussian in geodesic distance outside.

    Parameters
    ----------
    neutral : (n, 3) float
    faces : (m, 3) int
    cores : mapping name -> vertex indices (k,) int
        The core vertices of each region (at least one each).
    sigma : float
        Standard deviation of the falloff, in model units (> 0).

    Returns
    -------
    dict name -> (m,) float32 in [0, 1]
        Ready for ``PerformanceDatabase.from_frames(..., regions=...)``.
    """
    V, F = checked_mesh(neutral, faces, "")
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be > 0, got {sigma!r}")
    if not cores:
        raise ValueError("cores is empty: give at least one region")
    e = mesh_edges(F)
    w = np.maximum(np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1), 1e-12)
    n = len(V)
    graph = sp.csr_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n))
    out: dict[str, NDArray[np.float32]] = {}
    for name, ids in cores.items():
        idx = np.unique(np.asarray(ids, np.int64).ravel())
        if idx.size == 0 or idx.min() < 0 or idx.max() >= n:
            raise ValueError(f"cores[{name!r}] must be a non-empty set of vertex indices in [0, {n})")
        d = dijkstra(graph, directed=False, indices=idx, min_only=True)
        d = np.where(np.isfinite(d), d, np.inf)[F].mean(axis=1)
        out[str(name)] = np.exp(-0.5 * (d / sigma) ** 2).astype(np.float32)
    return out


#: shape-name fragments (lower case) of the two voluntary groups, after Tena et al.'s segmentation
_GROUPS = {"brow": ("brow",), "mouth": ("mouth", "jaw", "lip", "cheek")}


def face_voluntary_cores(model: FaceState, share: float = 0.04) -> dict[str, NDArray[np.int64]]:
    """The paper's four voluntary regions on a rigged face: mouth and brow, left and right.

    A group's core is the ``share`` of the vertices its shapes (names containing
    ``brow``; ``mouth``/``jaw``/``lip``/``cheek`` — ARKit's and most rigs' spelling)
    move most, split by the side of the face (the model's left axis from its
    metadata, about the median of the core).

    Parameters
    ----------
    model : FaceModel
    share : float
        Fraction of the vertices in each group's core (before the left/right split).

    Returns
    -------
    dict name -> (k,) int64
        ``mouth_left``, ``mouth_right``, ``brow_left``, ``brow_right`` (groups the rig has no shape for are left out).

    Raises
    ------
    ValueError
        The rig has no brow or mouth shapes at all.
    """
    from workbench.geometry.axes import face_axes

    V = np.asarray(model.vertices, np.float64)
    left = V @ face_axes(model)[0]
    k = max(2, round(share * len(V)))
    out: dict[str, NDArray[np.int64]] = {}
    for group, parts in _GROUPS.items():
        mags = [np.linalg.norm(np.asarray(s.delta, np.float64), axis=1)
                for s in model.shapes if any(p in s.name.lower() for p in parts)]
        if not mags:
            continue
        motion = np.sum(mags, axis=0)
        core = np.argsort(motion)[-k:]
        mid = float(np.median(left[core]))
        out[f"{group}_left"] = np.sort(core[left[core] >= mid])
        out[f"{group}_right"] = np.sort(core[left[core] < mid])
    if not out:
        raise ValueError("face_voluntary_cores: the rig has no brow or mouth shapes (names with brow/mouth/jaw/lip/cheek)")
    return out
