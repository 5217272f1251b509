"""Per-vertex colours of a face from its parts' roles (skin, eyeballs with iris and pupil, teeth, ...)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench import FaceModel
from workbench.geometry.parts import model_part_roles, part_material

__all__ = ["COMPONENT_COLORS", "vertex_colors"]

#: sRGB colours (0-255) by part material (:func:`workbench.geometry.parts.part_material`
#: of the component's role); unrecognised parts use ``skin``.
COMPONENT_COLORS: dict[str, tuple[int, int, int]] = {
    "skin": (226, 178, 152),
    "eye": (242, 240, 235),  # sclera; iris and pupil are added procedurally
    "iris": (86, 112, 78),
    "pupil": (18, 16, 16),
    # the lashes are cards meant for an alpha texture; drawn opaque, a soft
    # brown reads as a lash line instead of a heavy black band
    "eyelashes": (128, 92, 76),
    "eyebrows": (70, 50, 38),
    "teeth": (238, 232, 212),
    "tongue": (196, 96, 100),
    "gums": (190, 104, 104),
}


def vertex_colors(model: FaceModel, front: ArrayLike = (0.0, 0.0, 1.0)) -> NDArray[np.uint8]:
    """Per-vertex RGB colours from the components' part roles (``model.part_roles``).

    The roles come from the names, else from the geometry
    (:func:`workbench.geometry.parts.component_roles`), so an unnamed eyeball is
    still drawn as an eye. Eyeballs get a sclera/iris/pupil pattern: a vertex's
    direction from its eyeball's centre is compared with the face direction
    ``front``.

    Returns
    -------
    (n, 3) uint8
    """
    n = model.n_vertices
    out = np.empty((n, 3), dtype=np.uint8)
    out[:] = COMPONENT_COLORS["skin"]
    labels = np.asarray(model.component_labels)
    names = list(model.component_names)
    roles = model_part_roles(model)
    v = np.asarray(model.vertices, dtype=np.float64)
    fwd = np.asarray(front, dtype=np.float64)
    fwd = fwd / np.linalg.norm(fwd)
    for idx, cname in enumerate(names):
        sel = labels == idx
        if not np.any(sel):
            continue
        key = part_material(roles[idx], cname)
        out[sel] = COMPONENT_COLORS[key]
        if key == "eye":
            ids = np.flatnonzero(sel)
            for piece in _connected_pieces(model.faces, ids):  # both eyes may be one component
                p = v[piece]
                d = p - p.mean(axis=0)
                d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
                cos = d @ fwd
                rgb = np.empty((len(p), 3), dtype=np.uint8)
                rgb[:] = COMPONENT_COLORS["eye"]
                rgb[cos > math.cos(math.radians(36))] = COMPONENT_COLORS["iris"]
                rgb[cos > math.cos(math.radians(17))] = COMPONENT_COLORS["pupil"]
                out[piece] = rgb
    return out


def _connected_pieces(faces: ArrayLike, ids: NDArray[np.intp]) -> list[NDArray[np.intp]]:
    """The vertex ids ``ids`` split into the connected pieces of the faces among them."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    local = np.full(int(max(F.max(initial=0), ids.max(initial=0))) + 1, -1, np.int64)
    local[ids] = np.arange(ids.size)
    Fl = local[F]
    Fl = Fl[(Fl >= 0).all(axis=1)]
    m = ids.size
    adj = coo_matrix((np.ones(Fl.size), (np.repeat(Fl[:, 0], 3), Fl.ravel())), shape=(m, m))
    k, lab = connected_components(adj + adj.T, directed=False)
    return [ids[lab == i] for i in range(k)]
