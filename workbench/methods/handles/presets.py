"""Default handle sets: mocap-marker-like points where the face moves.

A face rig's handles belong where the expressions move the skin (brows, lids,
cheeks, nose, lips, jaw), spread out, and in left/right pairs. We find them
from the model's own blendshapes:

1. the *expressiveness* of a skin vertex is its largest displacement over all shapes;
2. seeds are the most-moved vertex of every shape (mapped to the +x side);
3. farthest-point sampling over the expressive vertices of the +x half adds
   points until the set is spread evenly;
4. each point off the mid-plane gets its mirror vertex (nearest vertex to its
   x-reflection), so symmetric dragging works.

Handles are named by the shape group that moves them most (``mouth_L_3``).
Written here because it is specific to blendshape faces; the nearest-neighbour
queries are scipy's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.arkit import canonical_arkit_name, shape_group
from workbench.methods.shapes.symmetry import nearest_reflected

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel
    from workbench.methods.handles.handle_set import HandleSet


def mirror_vertices(V: NDArray[np.float64], ids: NDArray[np.int64], candidates: NDArray[np.int64]) -> NDArray[np.int64]:
    """For each vertex in ``ids``, the candidate vertex nearest to its reflection x -> -x."""
    return nearest_reflected(V, ids, candidates, axis=0, mid=0.0)[0]


def default_face_handles(model: FaceModel, per_side: int = 40, min_fraction: float = 0.15) -> HandleSet:
    """A symmetric, spread-out handle set on the moving part of the face.

    Parameters
    ----------
    model : FaceModel
        Needs blendshapes (they define where the face moves) and a face symmetric
        about x = 0 (as the sample head is).
    per_side : int
        Handles on the +x half including the mid-plane; the total is about
        ``2 * per_side - (points on the mid-plane)``.
    min_fraction : float
        Vertices moving less than this fraction of the largest displacement are
        not candidates.

    Returns
    -------
    HandleSet with zero offsets and mirror links.
    """
    from workbench.core.shapes import ModelError
    from workbench.methods.handles.handle_set import HandleSet

    if not model.shapes:
        raise ModelError("default_face_handles: the model has no blendshapes to find moving regions")
    names = model.component_names
    skin_label = names.index("skin") if "skin" in names else int(np.bincount(model.component_labels).argmax())
    skin = np.flatnonzero(model.component_labels == skin_label)
    V = model.vertices
    mags = np.linalg.norm(model.deltas[:, skin], axis=2)  # (k, n_skin)
    expressive = mags.max(axis=0)
    size = float(np.linalg.norm(V[skin].max(0) - V[skin].min(0)))
    tol = 1e-3 * size
    cand_mask = (expressive >= min_fraction * expressive.max()) & (V[skin, 0] >= -tol)
    cand = skin[cand_mask]
    if cand.size == 0:
        raise ModelError("default_face_handles: no expressive skin vertices found")
    # seeds: the most-moved vertex of each shape, reflected onto the +x side
    seeds = skin[mags.argmax(axis=1)]
    neg = V[seeds, 0] < -tol
    seeds[neg] = mirror_vertices(V, seeds[neg], cand)
    chosen: list[int] = []
    min_sep = 0.03 * size
    for s in seeds:
        if all(np.linalg.norm(V[s] - V[c]) > min_sep for c in chosen):
            chosen.append(int(s))
    # farthest-point sampling over the candidates
    d = np.full(cand.size, np.inf)
    for c in chosen:
        d = np.minimum(d, np.linalg.norm(V[cand] - V[c], axis=1))
    while len(chosen) < per_side:
        i = int(np.argmax(d))
        chosen.append(int(cand[i]))
        d = np.minimum(d, np.linalg.norm(V[cand] - V[cand[i]], axis=1))
    chosen = chosen[: max(per_side, 1)]
    # snap near-mid-plane points onto it; mirror the rest
    verts: list[int] = []
    mirror: list[int] = []
    labels: list[str] = []
    groups = [shape_group(canonical_arkit_name(s.name) or s.name) for s in model.shapes]
    skin_pos = {int(v): i for i, v in enumerate(skin)}
    counters: dict[str, int] = {}

    def label(v: int, side: str) -> str:
        g = groups[int(mags[:, skin_pos[v]].argmax())]
        key = f"{g}_{side}"
        counters[key] = counters.get(key, 0) + 1
        return f"{key}_{counters[key]}"

    mid_tol = 0.01 * size
    for v in chosen:
        if abs(V[v, 0]) <= mid_tol:
            verts.append(v)
            mirror.append(-1)
            labels.append(label(v, "C"))
            continue
        m = int(mirror_vertices(V, np.array([v]), skin)[0])
        i = len(verts)
        verts += [v, m]
        mirror += [i + 1, i]
        labels += [label(v, "L"), label(m, "R")]
    return HandleSet(
        np.array(verts, np.int32), np.zeros((len(verts), 3), np.float32), tuple(labels), np.array(mirror, np.int32)
    )
