"""Loop subdivision as a linear operator, for meshes that carry blendshapes.

A blendshape model is only consistent after subdivision if the neutral and every
delta go through the *same* linear map ``S``: then ``S (V + sum_k w_k D_k) =
S V + sum_k w_k S D_k`` and evaluating the subdivided model equals subdividing the
evaluated model. So instead of subdividing positions (``igl.loop``) we build the
sparse matrix once with ``igl.loop_matrix`` and apply it to all of them.

libigl does the stencil work (Loop's vertex rule with Warren's weights inside,
the 1/8-3/4-1/8 crease rule on open boundaries such as the neck cut, edge points
3/8-3/8-1/8-1/8 inside and 1/2-1/2 on boundaries). What is hand-written here is
only what libigl does not cover:

* vertices referenced by no triangle (``igl.loop_matrix`` crashes on them): they
  are taken out before the call and kept fixed (identity rows);
* input validation (libigl assumes an edge-manifold triangle mesh and does not
  check), several levels composed into one matrix, and carrying a whole
  :class:`~workbench.model.FaceModel` (deltas, masks, component labels, metadata)
  through the operator.

Row ``i < n`` of ``S`` is the new position of old vertex ``i``; the edge points
follow. Loop weights are non-negative and each row sums to 1, so ``S`` reproduces
translations (affine invariance), maps data in [0, 1] to [0, 1], and a row only
touches vertices of one connected component.
"""

from __future__ import annotations

from importlib import metadata as _importlib_metadata
from typing import TYPE_CHECKING

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.core.polygons import Polygons
from workbench.core.shapes import BlendShape

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["loop_subdivision", "subdivide_model", "subdivided_vertex_count"]

# Shapes are pushed through S in groups so the float64 work array stays small
# (3 levels on the sample head: 325k rows x 3 * _SHAPE_CHUNK columns).
_SHAPE_CHUNK = 16


def _check_faces(faces: ArrayLike, n_vertices: int) -> NDArray[np.int64]:
    """Validate an (m, 3) triangle array for libigl's Loop code; return it as int64."""
    F = np.asarray(faces)
    if F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"faces: expected an (m, 3) triangle array, got shape {F.shape}")
    if F.size and not np.issubdtype(F.dtype, np.integer):
        raise ValueError(f"faces: expected integer vertex ids, got dtype {F.dtype}")
    F = F.astype(np.int64, copy=False)
    n = int(n_vertices)
    if n < 0:
        raise ValueError(f"n_vertices: expected >= 0, got {n_vertices}")
    if F.size and (F.min() < 0 or F.max() >= n):
        bad = int(np.flatnonzero((F < 0).any(1) | (F >= n).any(1))[0])
        raise ValueError(
            f"faces: triangle {bad} = {F[bad].tolist()} has a vertex id outside 0..{n - 1}"
        )
    degenerate = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if degenerate.any():
        bad = int(np.flatnonzero(degenerate)[0])
        raise ValueError(f"faces: triangle {bad} = {F[bad].tolist()} repeats a vertex")
    # Loop's edge rule needs each edge shared by at most two triangles.
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    ue, counts = np.unique(e, axis=0, return_counts=True)
    if np.any(counts > 2):
        bad_e = ue[np.argmax(counts > 2)]
        raise ValueError(
            f"faces: edge {bad_e.tolist()} is shared by {int(counts.max())} triangles; "
            "Loop subdivision needs an edge-manifold mesh (at most 2 triangles per edge)"
        )
    return F


def _loop_once(F: NDArray[np.int64], n: int) -> tuple[sp.csr_matrix, NDArray[np.int64]]:
    """One Loop level on validated triangles ``F`` over ``n`` vertices.

    Returns
    -------
    S : (n + e, n) float64 CSR
        Rows ``0..n-1``: old vertices (identity for unreferenced ones); then one row
        per edge point.
    new_faces : (4 m, 3) int64
    """
    used = np.zeros(n, dtype=bool)
    used[F.reshape(-1)] = True
    if used.all():
        S_c, NF = igl.loop_matrix(F, n)
        return sp.csr_matrix(S_c, dtype=np.float64), np.asarray(NF, dtype=np.int64)
    # Compact the referenced vertices (igl.loop_matrix segfaults on isolated ones),
    # then put the result back: old vertices keep their ids, edge points go after.
    kept = np.flatnonzero(used)
    n_ref = kept.size
    remap = np.full(n, -1, dtype=np.int64)
    remap[kept] = np.arange(n_ref)
    if n_ref == 0:
        return sp.identity(n, dtype=np.float64, format="csr"), np.zeros((0, 3), np.int64)
    S_c, NF = igl.loop_matrix(remap[F], n_ref)
    S_c = sp.coo_matrix(S_c)
    NF = np.asarray(NF, dtype=np.int64)
    n_edge = S_c.shape[0] - n_ref
    # row map: compact old vertex j -> kept[j]; edge point r -> n + (r - n_ref)
    row_map = np.concatenate([kept, n + np.arange(n_edge)])
    iso = np.flatnonzero(~used)
    rows = np.concatenate([row_map[S_c.row], iso])
    cols = np.concatenate([kept[S_c.col], iso])
    vals = np.concatenate([S_c.data, np.ones(iso.size)])
    S = sp.csr_matrix((vals, (rows, cols)), shape=(n + n_edge, n), dtype=np.float64)
    return S, row_map[NF]


def _loop_levels(
    faces: ArrayLike, n_vertices: int, levels: int
) -> tuple[list[sp.csr_matrix], NDArray[np.int64]]:
    """Per-level operators ``[S_1, ..., S_L]`` and the final triangles."""
    if int(levels) != levels or levels < 0:
        raise ValueError(f"levels: expected a non-negative integer, got {levels!r}")
    F = _check_faces(faces, n_vertices)
    n = int(n_vertices)
    ops = []
    for _ in range(int(levels)):
        S, F = _loop_once(F, n)
        ops.append(S)
        n = S.shape[0]
    return ops, F


def loop_subdivision(
    faces: ArrayLike, n_vertices: int, levels: int = 1
) -> tuple[sp.csr_matrix, NDArray[np.int64]]:
    """Loop subdivision operator of a triangle mesh.

    Parameters
    ----------
    faces : (m, 3) int
        Triangles; several connected components and open boundaries are fine; every
        edge must be shared by at most two triangles.
    n_vertices : int
        Number of vertices ``n`` (vertices used by no triangle stay where they are).
    levels : int, default 1
        Number of subdivision steps; 0 gives the identity.

    Returns
    -------
    S : (n_new, n) float64 scipy.sparse CSR matrix
        Subdivided positions are ``S @ V`` for any per-vertex data ``V : (n, d)``.
        Rows ``0..n-1`` are the old vertices (repositioned); each row sums to 1.
    new_faces : (4**levels * m, 3) int64
        Triangles on the ``n_new`` vertices, same orientation as ``faces``.

    Raises
    ------
    ValueError
        If ``faces`` is not an (m, 3) integer array over ``0..n-1``, has a
        degenerate triangle, or an edge shared by more than two triangles.

    Examples
    --------
    >>> S, F1 = loop_subdivision([[0, 1, 2]], 3)
    >>> S.shape, F1.shape
    ((6, 3), (4, 3))
    """
    ops, F = _loop_levels(faces, n_vertices, levels)
    S: sp.csr_matrix = sp.identity(int(n_vertices), dtype=np.float64, format="csr")
    for op in ops:
        S = (op @ S).tocsr()
    S.sum_duplicates()
    S.eliminate_zeros()
    return S, F


def subdivided_vertex_count(faces: ArrayLike, n_vertices: int, levels: int = 1) -> int:
    """Vertex count after ``levels`` Loop steps, without building the operator.

    Each step adds one vertex per edge; edges ``e``, faces ``m`` become ``2 e + 3 m``
    and ``4 m``.

    Parameters
    ----------
    faces : (m, 3) int
    n_vertices : int
    levels : int

    Returns
    -------
    int
    """
    F = _check_faces(faces, n_vertices)
    e = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)
    n, n_e, m = int(n_vertices), len(e), len(F)
    for _ in range(int(levels)):
        n, n_e, m = n + n_e, 2 * n_e + 3 * m, 4 * m
    return n


def _propagate_labels(S: sp.csr_matrix, labels: NDArray[np.int32]) -> NDArray[np.int32]:
    """Label of each new vertex = label of its parents (checked to be unique per row)."""
    S = S.tocsr()
    starts = S.indptr[:-1]
    if np.any(np.diff(S.indptr) == 0):
        raise ValueError("subdivision operator has an empty row")
    parent = labels[S.indices]
    lo = np.minimum.reduceat(parent, starts)
    hi = np.maximum.reduceat(parent, starts)
    if np.any(lo != hi):
        row = int(np.flatnonzero(lo != hi)[0])
        raise ValueError(
            f"new vertex {row} mixes component labels {int(lo[row])} and {int(hi[row])}; "
            "component_labels must be constant on each connected piece of the mesh"
        )
    return lo.astype(np.int32)


def subdivide_model(model: FaceModel, levels: int = 1) -> FaceModel:
    """Loop-subdivide a face model: neutral, every delta and every mask by the same operator.

    Parameters
    ----------
    model : FaceModel
        Source model with ``n`` vertices and ``m`` triangles (its triangles are
        subdivided; the original quads are not kept).
    levels : int, default 1
        Loop steps; vertices grow about 4x per step.

    Returns
    -------
    FaceModel
        ``n_new`` vertices: ``vertices = S @ model.vertices`` (float64); each shape
        keeps name, slider range and mute, its delta is ``S @ delta`` stored float32
        and its vertex mask (if any) ``S @ mask``, still in [0, 1]; current weights
        are kept; component labels follow the parent vertices; ``polygons`` are the
        new triangles; metadata gains a provenance entry. Editing layers (handles,
        regions, paint, tracks) and history are not carried over.

    Notes
    -----
    For unmasked shapes evaluation commutes with subdivision: ``evaluate()`` of the
    result equals ``S @ model.evaluate()``. A vertex mask multiplies its delta, which
    is not linear: ``(S m) * (S D)`` differs from ``S (m * D)`` where the mask varies
    across a triangle. The subdivided mask is kept (so it stays editable) instead of
    being baked into the delta; bake masks into the deltas before subdividing if
    the exact identity matters.
    """
    n = model.n_vertices
    ops, F = _loop_levels(model.faces, n, levels)
    n_new = ops[-1].shape[0] if ops else n

    def apply(X: NDArray[np.floating]) -> NDArray[np.float64]:
        Y = np.asarray(X, dtype=np.float64)
        for op in ops:
            Y = op @ Y
        return np.asarray(Y)

    V = apply(model.vertices)

    shapes = model.shapes
    k = len(shapes)
    D = np.empty((k, n_new, 3), dtype=np.float32)
    # (chunk, n, 3) -> (n, 3 * chunk) so one sparse product handles a group of shapes
    for s0 in range(0, k, _SHAPE_CHUNK):
        s1 = min(k, s0 + _SHAPE_CHUNK)
        block = model.deltas[s0:s1].transpose(1, 0, 2).reshape(n, -1)
        D[s0:s1] = apply(block).reshape(n_new, s1 - s0, 3).transpose(1, 0, 2)

    new_shapes = []
    for i, s in enumerate(shapes):
        mask = None
        if s.vertex_mask is not None:
            # rows are convex combinations: stays in [0, 1] up to rounding
            mask = np.clip(apply(s.vertex_mask[:, None])[:, 0], 0.0, 1.0).astype(np.float32)
        new_shapes.append(
            BlendShape(s.name, D[i], s.slider_min, s.slider_max, s.mute, vertex_mask=mask)
        )

    labels = model.component_labels
    for op in ops:
        labels = _propagate_labels(op, labels)

    F32 = F.astype(np.int32)
    entry = {
        "operation": "loop_subdivision",
        "levels": int(levels),
        "library": f"libigl {_libigl_version()} (igl.loop_matrix)",
        "from_vertices": n,
        "from_triangles": len(model.faces),
        "vertices": int(n_new),
        "triangles": len(F32),
    }
    meta = model.metadata.with_provenance(entry)
    # the input's own class (FaceModel): importing it here would close a cycle
    return type(model)(
        V,
        F32,
        new_shapes,
        polygons=Polygons.from_triangles(F32),
        component_labels=labels,
        component_names=model.component_names,
        metadata=meta,
        weights=dict(model.weights),
    )


def _libigl_version() -> str:
    try:
        return _importlib_metadata.version("libigl")
    except _importlib_metadata.PackageNotFoundError:  # pragma: no cover - source builds
        return "unknown"
