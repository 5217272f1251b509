"""Transfer of fine-scale details as printed: the fitted pose space itself (Bickel et al. 2008 §5.4).

"Due to the fact that the fine-scale deformation is already defined in pose-space,
controlled by local skin strain and measured in per-vertex local coordinate
frames, its transfer reduces to establishing dense correspondence": with a
:class:`~workbench.rigging.RigTransfer`'s correspondence (each target skin vertex
on a template triangle, barycentric),

1. the **feature graph** is mapped: each node (a template handle) goes to the
   target vertex nearest to where the fitted template put it, the edges keep
   their pose-space coordinate (relative stretch is unit-free) and take the
   target's rest lengths. "The nodes of the feature graph and the handle vertices
   on the target model do not have to match": the state is marked
   ``free_nodes`` and the strain is measured at those vertices of whatever the
   target plays (a point cache, an imported timeline, a marker replay);
2. the **per-vertex RBF weights** ``w_{v,j}`` are carried by linear interpolation
   with the barycentric coordinates — through world space at the rest poses,
   since neighbouring vertices' local frames differ: the normal component along
   the target normal (scaled by the units and the fit's area stretch), the
   tangential part through the fit's local Jacobian (:class:`DetailMap`);
3. the WPSD edge weights ``α_{v,i}`` are eq. 4 on the target's rest pose with
   the mapped graph (they are geometry, not learned).

Then evaluating (5) on the target animation gives its details. Nothing is
refitted, so no rig able to make the template's examples is needed (the
example-based path, :func:`~workbench.rigging.transfer_details`, needs one).

The ``.fwb`` file stores a fit's inputs: a transferred state is saved with its
training details (the carried fit evaluated at the training poses) and reloads
as the fit of those on the target. Hand-written glue over
:mod:`workbench.methods.wrinkles` (no library carries an RBF pose space).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.methods.wrinkles.features import (
    FeatureGraph,
    edge_weights,
    local_frames,
    tangent_neighbours,
    to_local,
    to_world,
)
from workbench.methods.wrinkles.layer import WrinkleState
from workbench.methods.wrinkles.pose_space import PoseSpace
from workbench.model import FaceModel
from workbench.rigging.details import DetailMap, wrinkled_template

if TYPE_CHECKING:
    from workbench.rigging.transfer import RigTransfer

__all__ = ["transfer_pose_space"]


def _mapped_graph(st: WrinkleState, dm: DetailMap, V_t: NDArray[np.float64]
                  ) -> tuple[FeatureGraph, NDArray[np.int32], NDArray[np.intp]]:
    """The graph on the target: node vertices, edges re-indexed, the feature columns kept."""
    assert st.graph is not None and st.handles is not None
    hv = dm.nearest_target(np.asarray(st.handles, np.int64))
    index = np.full(hv.size, -1, np.int64)
    nodes: list[int] = []
    seen: dict[int, int] = {}
    for i, v in enumerate(hv):
        if v >= 0 and int(v) not in seen:
            seen[int(v)] = len(nodes)
            index[i] = len(nodes)
            nodes.append(int(v))
    e = np.asarray(st.graph.edges, np.int64)
    a, b = index[e[:, 0]], index[e[:, 1]]
    node_v = np.asarray(nodes, np.int64)
    ok = (a >= 0) & (b >= 0)
    lengths = np.zeros(len(e))
    lengths[ok] = np.linalg.norm(V_t[node_v[a[ok]]] - V_t[node_v[b[ok]]], axis=1)
    ok &= lengths > 0
    cols = np.flatnonzero(ok)
    if cols.size == 0:
        raise ValueError("transfer_pose_space: no feature edge of the template maps onto the target")
    edges = np.sort(np.stack([a[cols], b[cols]], 1), axis=1).astype(np.int32)
    return FeatureGraph(edges, lengths[cols]), node_v.astype(np.int32), cols


def transfer_pose_space(
    source: FaceModel,
    target: FaceModel,
    correspondence: RigTransfer | DetailMap,
    *,
    apply: bool = True,
) -> WrinkleState:
    """Carry ``source``'s fitted pose-space details onto ``target`` as Bickel et al. §5.4 prints it.

    Parameters
    ----------
    source : FaceModel
        The template with fitted wrinkles (when it has none, the procedural sample
        examples are fitted on a copy of it).
    target : FaceModel
        A face with the transfer's target vertices (the rigged target, or any face
        playing an animation of that mesh: baked frames, a point cache, a replay).
    correspondence : RigTransfer or DetailMap
        From the template to the target's mesh.
    apply : bool
        Install the result as ``target``'s wrinkles (one undo step).

    Returns
    -------
    WrinkleState
        With ``free_nodes``: the strain is measured at the mapped nodes of any mesh the
        target plays, whatever its handles.

    Raises
    ------
    ValueError
        The correspondence is not between these meshes, or no feature edge maps.
    """
    dm = DetailMap.between(correspondence, source, target, "transfer_pose_space")
    st: WrinkleState = wrinkled_template(source).slot("wrinkles")
    ps = st.pose_space
    assert ps is not None
    V_s = np.asarray(source.vertices, np.float64)
    V_t = np.asarray(dm.target_rest, np.float64)
    graph, nodes, cols = _mapped_graph(st, dm, V_t)

    # the RBF weights: local (source rest frames) -> world -> carried -> local (target rest frames)
    R_s = local_frames(V_s, source.faces, tangent_neighbours(source.faces, source.n_vertices))
    R_t = local_frames(V_t, target.faces, tangent_neighbours(target.faces, target.n_vertices))
    W_s = ps.weights if ps.weighted else np.swapaxes(ps.weights, 0, 1)  # (n_s, P, 3)
    P = W_s.shape[1]
    W_t = np.zeros((target.n_vertices, P, 3), np.float32)
    for j in range(P):
        world = to_world(R_s, W_s[:, j].astype(np.float64))
        carried = dm.carry(world, V_s, source.faces, V_t, target.faces)
        W_t[:, j] = to_local(R_t, carried)
    alpha = edge_weights(V_t, V_t[nodes], graph) if ps.weighted else None
    ps_t = PoseSpace(
        basis_features=np.asarray(ps.basis_features, np.float64)[:, cols],
        weights=W_t if ps.weighted else np.ascontiguousarray(np.swapaxes(W_t, 0, 1)),
        alpha=alpha,
        basis=ps.basis,
        mode=ps.mode,
        train_features=np.asarray(ps.train_features, np.float64)[:, cols],
        train_values=np.zeros((ps.train_features.shape[0], target.n_vertices, 3), np.float32),
        rcond=ps.rcond,
    )
    ps_t = dataclasses.replace(ps_t, train_values=ps_t.evaluate_many(ps_t.train_features))
    out = WrinkleState(graph, nodes, ps_t, st.example_names, st.example_weights, st.strength, st.enabled,
                       ps.weighted, free_nodes=True)
    if apply:
        target.set_slot("wrinkles", out, f"Details from {source.metadata.name or 'the template'} (§5.4)")
    return out
