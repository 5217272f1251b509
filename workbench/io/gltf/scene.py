"""The scene graph: which meshes are drawn, where, and under which name.

The default scene (``scene``, else ``scenes[0]``; with no scenes, every root
node) is walked from its root nodes. Each node with a ``mesh`` is one
*instance*: the mesh under the node's world transform, the product of the
local transforms (``matrix``, or ``translation`` x ``rotation`` x ``scale``)
from the root down. Exceptions, as in the spec and for a face:

* a skinned node's own transform is ignored (the spec says so; the bind pose
  is the mesh's own coordinates);
* a node whose translation/rotation/scale is animated moves rigidly over
  time (a head pose): that motion is not part of the face's shape, so its
  transform is left out (its children's static transforms still apply). The
  workbench's own exports put the head pose there.

A file with meshes but no nodes draws each mesh once, untransformed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.io.gltf.document import Gltf, is_int

__all__ = ["Instance", "instances", "mesh_name"]


@dataclass(frozen=True)
class Instance:
    """One drawn mesh: index, world matrix (4x4), the node that draws it, a display name."""

    mesh: int
    matrix: NDArray[np.float64]
    node: int | None
    name: str
    field: str


def mesh_name(g: Gltf, mi: int) -> str | None:
    m = g.array("meshes")[mi]
    name = m.get("name") if isinstance(m, dict) else None
    return name if isinstance(name, str) and name else None


def _quat_matrix(q: NDArray[np.float64]) -> NDArray[np.float64]:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def local_matrix(g: Gltf, node: dict[str, Any], field: str) -> NDArray[np.float64]:
    """4x4 local transform of a node (column vectors)."""
    if "matrix" in node:
        if any(k in node for k in ("translation", "rotation", "scale")):
            g.fail(f"{field}.matrix", "a node has either a matrix or translation/rotation/scale")
        m = g.get_numbers(node, "matrix", field, 16, [])
        M = m.reshape(4, 4).T  # glTF stores column-major
        if not np.allclose(M[3], [0, 0, 0, 1], atol=1e-6):
            g.fail(f"{field}.matrix", f"last row {M[3].tolist()} is not [0, 0, 0, 1] (not affine)")
        return M
    t = g.get_numbers(node, "translation", field, 3, [0.0, 0.0, 0.0])
    q = g.get_numbers(node, "rotation", field, 4, [0.0, 0.0, 0.0, 1.0])
    s = g.get_numbers(node, "scale", field, 3, [1.0, 1.0, 1.0])
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > 1e-3:
        g.fail(f"{field}.rotation", f"{q.tolist()} is not a unit quaternion (length {norm:.4g})")
    M = np.eye(4)
    M[:3, :3] = _quat_matrix(q / norm) * s[None, :]
    M[:3, 3] = t
    return M


def _animated_nodes(g: Gltf) -> set[int]:
    """Nodes whose translation, rotation or scale is the target of an animation channel."""
    out: set[int] = set()
    for a in g.array("animations"):
        chans = a.get("channels") if isinstance(a, dict) else None
        for c in chans if isinstance(chans, list) else []:
            t = c.get("target") if isinstance(c, dict) else None
            if (
                isinstance(t, dict)
                and t.get("path") in ("translation", "rotation", "scale")
                and is_int(t.get("node"))
            ):
                out.add(int(t["node"]))
    return out


def _roots(g: Gltf) -> tuple[list[int], str]:
    scenes = g.array("scenes")
    nodes = g.array("nodes")
    if scenes:
        si = g.doc.get("scene", 0)
        scene = g.item("scenes", si, "scene")
        roots = scene.get("nodes", [])
        field = f"scenes[{si}].nodes"
        if not isinstance(roots, list):
            g.fail(field, "expected an array of node indices")
        return roots, field
    children: set[int] = set()
    for n in nodes:
        ch = n.get("children", []) if isinstance(n, dict) else []
        if isinstance(ch, list):
            children.update(c for c in ch if is_int(c))
    return [i for i in range(len(nodes)) if i not in children], "nodes"


def instances(g: Gltf, only_mesh: int | None = None) -> list[Instance]:
    """Every mesh drawn by the default scene, depth first, with its world transform."""
    meshes = g.array("meshes")
    if not g.array("nodes"):
        return [
            Instance(mi, np.eye(4), None, mesh_name(g, mi) or f"mesh_{mi}", f"meshes[{mi}]")
            for mi in range(len(meshes))
            if only_mesh is None or mi == only_mesh
        ]
    animated = _animated_nodes(g)
    roots, rfield = _roots(g)
    out: list[Instance] = []
    seen: set[int] = set()
    # (node index, field that refers to it, parent world matrix, nearest named ancestor)
    stack: list[tuple[Any, str, NDArray[np.float64], str | None]] = [
        (r, f"{rfield}[{k}]", np.eye(4), None) for k, r in reversed(list(enumerate(roots)))
    ]
    while stack:
        ni, ref, parent, ancestor = stack.pop()
        node = g.item("nodes", ni, ref)
        field = f"nodes[{ni}]"
        if ni in seen:
            g.fail(ref, f"node {ni} is reached twice (a node has one parent, no cycles)")
        seen.add(ni)
        local = local_matrix(g, node, field)
        world = parent if ni in animated else parent @ local
        name = node.get("name") if isinstance(node.get("name"), str) and node["name"] else None
        if "mesh" in node:
            mi = node["mesh"]
            g.item("meshes", mi, f"{field}.mesh")
            if only_mesh is None or mi == only_mesh:
                M = np.eye(4) if "skin" in node else world
                label = name or mesh_name(g, mi) or ancestor or f"mesh_{mi}"
                out.append(Instance(int(mi), M, int(ni), label, f"{field} (meshes[{mi}])"))
        children = node.get("children", [])
        if not isinstance(children, list):
            g.fail(f"{field}.children", "expected an array of node indices")
        for k in range(len(children) - 1, -1, -1):
            stack.append((children[k], f"{field}.children[{k}]", world, name or ancestor))
    if only_mesh is not None and not out:  # a mesh no node draws: read it in its own frame
        out.append(
            Instance(
                only_mesh,
                np.eye(4),
                None,
                mesh_name(g, only_mesh) or f"mesh_{only_mesh}",
                f"meshes[{only_mesh}]",
            )
        )
    return out
