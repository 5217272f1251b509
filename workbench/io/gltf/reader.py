"""Read the meshes of a glTF scene and their morph targets into one :class:`ImportedFace`.

Every mesh the default scene draws is read (see :mod:`.scene`) under its
node's world transform: positions get the full affine transform, morph
deltas only its linear part (a delta is a difference of two positions), and
a mirroring transform flips the triangles' winding. Several meshes (head,
teeth, eyes) become separate parts (face groups named by node, else mesh);
a single mesh with several primitives keeps one group per primitive, named
by its material.

Morph targets are named per mesh from ``extras.targetNames`` (the convention
of Blender and three.js), else ``target_<i>`` (``<mesh>_target_<i>`` when
several meshes have unnamed targets). The same name on several meshes is one
shape (also when the names differ only in case or ARKit spelling); a shape
that a mesh does not have is zero on that mesh.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.arkit import canonical_arkit_name
from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import check_faces, check_vertices
from workbench.io.base import ImportedFace, check_shape_names
from workbench.io.gltf.compression import (
    DRACO,
    GEOMETRY_EXTENSIONS,
    MAX_DRACO_ELEMENTS,
    MESHOPT_EXTENSIONS,
    decode_draco,
    is_skippable,
)
from workbench.io.gltf.container import read_container
from workbench.io.gltf.document import FLOAT, NORMALIZE, Gltf
from workbench.io.gltf.scene import Instance, instances, mesh_name

__all__ = ["read_gltf"]

logger = logging.getLogger("workbench.io.gltf")

_TRIANGLES = 4
_MODES = {
    0: "POINTS",
    1: "LINES",
    2: "LINE_LOOP",
    3: "LINE_STRIP",
    4: "TRIANGLES",
    5: "TRIANGLE_STRIP",
    6: "TRIANGLE_FAN",
}


@dataclass
class _Part:
    """One mesh instance, decoded and in world coordinates."""

    name: str
    vertices: NDArray[np.float64]
    triangles: NDArray[np.int64]  # local indices
    prim_of_tri: NDArray[np.int64]
    group_names: list[str]
    targets: list[tuple[str, NDArray[np.float64]]] = field(default_factory=list)
    named: bool = True  # target names from extras.targetNames (else target_<i>)
    mesh_label: str = ""


def _check_extensions(g: Gltf) -> None:
    required = g.doc.get("extensionsRequired", [])
    if not isinstance(required, list) or not all(isinstance(e, str) for e in required):
        g.fail("extensionsRequired", "expected an array of strings")
    skipped = [e for e in required if e not in GEOMETRY_EXTENSIONS and is_skippable(e)]
    unsupported = [e for e in required if e not in GEOMETRY_EXTENSIONS and not is_skippable(e)]
    if unsupported:
        g.fail(
            "extensionsRequired",
            f"unsupported extensions {unsupported}: they may change the geometry "
            f"(supported: {sorted(GEOMETRY_EXTENSIONS)}; texture, material and light "
            f"extensions are skipped)",
        )
    if skipped:
        logger.warning(
            "%s: skipped %s (textures/materials only; the geometry does not need them)",
            Path(g.src).name,
            ", ".join(skipped),
        )


def _draco(
    g: Gltf, prim: dict[str, Any], pfield: str, attrs: dict[str, Any]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Positions and triangle indices of a Draco-compressed primitive."""
    efield = f"{pfield}.extensions.{DRACO}"
    ext = g.obj(g.obj(prim, "extensions", pfield), DRACO, f"{pfield}.extensions")
    ids = g.obj(ext, "attributes", efield)
    if "POSITION" not in ids:
        g.fail(f"{efield}.attributes", "POSITION is missing")
    uid = g.get_int(ids, "POSITION", f"{efield}.attributes")
    pos_field = f"{pfield}.attributes.POSITION"
    _, afield, ctype, _, n, normalized = g.accessor_header(
        attrs["POSITION"], pos_field, types=("VEC3",)
    )
    n_idx = None
    if "indices" in prim:
        _, ifield, _, _, n_idx, _ = g.accessor_header(
            prim["indices"], f"{pfield}.indices", types=("SCALAR",), as_index=True
        )
        if n_idx % 3:
            g.fail(f"{ifield}.count", f"{n_idx} indices is not a multiple of 3")
    if n > MAX_DRACO_ELEMENTS or (n_idx or 0) > MAX_DRACO_ELEMENTS:
        g.fail(afield, f"more than {MAX_DRACO_ELEMENTS} elements in a Draco primitive")
    v = g.view(ext.get("bufferView"), f"{efield}.bufferView")
    data, start = g.view_bytes(v)
    try:
        dec = decode_draco(data[start : start + v.length])
    except ValueError as exc:
        g.fail(efield, f"Draco data cannot be decoded ({exc})")
    if uid not in dec.attributes:
        g.fail(
            f"{efield}.attributes.POSITION",
            f"the Draco data has no attribute with unique id {uid} "
            f"(it has {sorted(dec.attributes)})",
        )
    P = dec.attributes[uid]
    if P.shape[1] != 3:
        g.fail(
            f"{efield}.attributes.POSITION", f"Draco attribute has {P.shape[1]} components, not 3"
        )
    if P.shape[0] != n:
        g.fail(
            f"{afield}.count",
            f"is {n} but the Draco data decodes to {P.shape[0]} vertices",
        )
    V = P.astype(np.float64)
    if normalized and np.issubdtype(P.dtype, np.integer):
        div, lo = NORMALIZE[ctype]
        V = np.maximum(V / div, lo)
    tris = dec.triangles.reshape(-1)
    if n_idx is not None and tris.size != n_idx:
        g.fail(
            f"accessors[{prim['indices']}] ({pfield}.indices).count",
            f"is {n_idx} but the Draco data decodes to {tris.size} indices",
        )
    return V, tris


def _read_instance(g: Gltf, inst: Instance) -> _Part:
    src = g.src
    m = g.item("meshes", inst.mesh, inst.field)
    mfield = f"meshes[{inst.mesh}]"
    prims = m.get("primitives")
    if not isinstance(prims, list) or not prims:
        g.fail(f"{mfield}.primitives", "expected a non-empty array")
    L = inst.matrix[:3, :3]
    t = inst.matrix[:3, 3]
    det = float(np.linalg.det(L))
    if not abs(det) > 1e-12 * float(np.linalg.norm(L)) ** 3:  # scale-invariant
        g.fail(
            inst.field,
            "the node's world transform is singular (a zero scale): its mesh would collapse",
        )
    verts: list[NDArray[np.float64]] = []
    tris: list[NDArray[np.int64]] = []
    lossy: list[bool] = []
    deltas: list[list[NDArray[np.float64]]] = []
    n_targets: int | None = None
    group_names: list[str] = []
    offset = 0
    for k, prim in enumerate(prims):
        pfield = f"{mfield}.primitives[{k}]"
        if not isinstance(prim, dict):
            g.fail(pfield, "expected a JSON object")
        mode = g.get_int(prim, "mode", pfield, default=_TRIANGLES)
        if mode != _TRIANGLES:
            g.fail(
                f"{pfield}.mode",
                f"{mode} ({_MODES.get(mode, '?')}) is not supported; only TRIANGLES (4)",
            )
        attrs = prim.get("attributes")
        if not isinstance(attrs, dict) or "POSITION" not in attrs:
            g.fail(f"{pfield}.attributes", "POSITION is missing")
        pos_field = f"{pfield}.attributes.POSITION"
        draco = DRACO in g.obj(prim, "extensions", pfield)
        if draco:
            V, idx = _draco(g, prim, pfield, attrs)
            ifield = f"{pfield}.extensions.{DRACO}"
        else:
            V = g.accessor(attrs["POSITION"], pos_field, types=("VEC3",))
            if "indices" in prim:
                idx = g.accessor(
                    prim["indices"], f"{pfield}.indices", types=("SCALAR",), as_index=True
                )
                ifield = f"{pfield}.indices"
            else:
                idx = np.arange(V.shape[0], dtype=np.int64)
                ifield = f"{pfield} (non-indexed)"
        V = check_vertices(V, src, pos_field)
        lossy.append(draco or _quantized(g, attrs["POSITION"]))
        n = V.shape[0]
        if idx.size % 3:
            g.fail(ifield, f"{idx.size} indices is not a multiple of 3")
        if idx.size and (idx.max() >= n or idx.min() < 0):
            bad = int(idx.max()) if idx.max() >= n else int(idx.min())
            g.fail(ifield, f"index {bad} out of range (POSITION has {n} vertices)")

        targets = prim.get("targets", [])
        if not isinstance(targets, list):
            g.fail(f"{pfield}.targets", "expected an array")
        if n_targets is None:
            n_targets = len(targets)
            deltas = [[] for _ in range(n_targets)]
        elif len(targets) != n_targets:
            g.fail(f"{pfield}.targets", f"has {len(targets)} targets, primitive 0 has {n_targets}")
        for ti, target in enumerate(targets):
            tfield = f"{pfield}.targets[{ti}]"
            if not isinstance(target, dict):
                g.fail(tfield, "expected a JSON object")
            if "POSITION" in target:
                D = g.accessor(
                    target["POSITION"], f"{tfield}.POSITION", types=("VEC3",), expect_count=n
                )
                D = check_vertices(D, src, f"{tfield}.POSITION")
            else:  # a target may move only normals
                D = np.zeros((n, 3))
            deltas[ti].append(_linear(D, L))

        verts.append(_linear(V, L) + t)
        tris.append(idx.reshape(-1, 3) + offset)
        offset += n
        mat = prim.get("material")
        name = None
        if mat is not None:
            material = g.item("materials", mat, f"{pfield}.material")
            name = material.get("name") if isinstance(material.get("name"), str) else None
        group_names.append(name or f"primitive_{k}")

    V_all = np.concatenate(verts)
    F = np.concatenate(tris)
    if det < 0:  # a mirroring transform: keep the triangles facing outward
        F = F[:, [0, 2, 1]]
    if not np.isfinite(V_all).all():
        g.fail(inst.field, "the node transform makes positions overflow to infinity")
    prim_of_tri = np.repeat(np.arange(len(prims)), [len(x) for x in tris])
    if any(lossy):
        # quantization (gltfpack, Draco, glTF-Transform) can snap a tiny triangle flat: it
        # covers no area, so it is dropped; in float data a flat triangle stays an error
        drop = _zero_area(V_all, F) & np.asarray(lossy)[prim_of_tri]
        if drop.any():
            logger.warning(
                "%s: %s: dropped %d of %d triangles that quantization made zero-area",
                Path(src).name,
                mfield,
                int(drop.sum()),
                len(F),
            )
            F, prim_of_tri = F[~drop], prim_of_tri[~drop]
    if F.shape[0] == 0:
        g.fail(mfield, "has no triangles")
    check_faces(
        Polygons.from_triangles(F), V_all.shape[0], src, vertices=V_all, field=f"{mfield} triangles"
    )
    part = _Part(inst.name, V_all, F, prim_of_tri, group_names)
    names = _target_names(g, m, mfield, n_targets or 0)
    part.named = names is not None
    part.mesh_label = mesh_name(g, inst.mesh) or f"mesh_{inst.mesh}"
    if names is None:
        names = [f"target_{ti}" for ti in range(n_targets or 0)]
    check_shape_names(names, [src] * len(names), src)
    for ti, name in enumerate(names):
        part.targets.append((name, np.concatenate(deltas[ti])))
    return part


def _linear(X: NDArray[np.float64], L: NDArray[np.float64]) -> NDArray[np.float64]:
    """``X @ L.T`` for (n, 3) rows; three broadcasts (a BLAS call per target is slower here)."""
    if np.array_equal(L, np.eye(3)):
        return X
    if np.count_nonzero(L - np.diag(np.diag(L))) == 0:  # a scale (gltfpack's dequantization)
        return X * np.diag(L)
    return X[:, 0:1] * L[:, 0] + X[:, 1:2] * L[:, 1] + X[:, 2:3] * L[:, 2]


def _quantized(g: Gltf, ai: Any) -> bool:
    """True if POSITION accessor ``ai`` (already checked) holds integers or meshopt data."""
    acc = g.item("accessors", ai, "POSITION")
    if acc.get("componentType") != FLOAT:
        return True
    if "bufferView" not in acc:
        return False
    exts = g.item("bufferViews", acc["bufferView"], "bufferView").get("extensions")
    return isinstance(exts, dict) and any(e in exts for e in MESHOPT_EXTENSIONS)


def _zero_area(V: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Triangles with no area, by the criterion of :func:`check_faces` (scale-invariant)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max([((b - a) ** 2).sum(1), ((c - b) ** 2).sum(1), ((a - c) ** 2).sum(1)], axis=0)
    return np.asarray(area2 <= 1e-12 * longest)


def _target_names(g: Gltf, m: dict[str, Any], mfield: str, n_t: int) -> list[str] | None:
    extras = m.get("extras")
    names = extras.get("targetNames") if isinstance(extras, dict) else None
    if names is None:
        return None
    if not isinstance(names, list) or not all(isinstance(s, str) for s in names):
        g.fail(f"{mfield}.extras.targetNames", "expected an array of strings")
    if len(names) != n_t:
        g.fail(f"{mfield}.extras.targetNames", f"has {len(names)} names for {n_t} targets")
    if any(not s.strip() for s in names):
        g.fail(f"{mfield}.extras.targetNames", "has an empty name")
    return list(names)


def _shape_key(name: str) -> str:
    canon = canonical_arkit_name(name)
    return "arkit:" + canon if canon is not None else name.lower()


def _merge(parts: list[_Part]) -> tuple[list[str], list[NDArray[np.float32]]]:
    """Shape names (first spelling wins) and full-length deltas, zero where a part lacks a shape."""
    sizes = [p.vertices.shape[0] for p in parts]
    starts = np.concatenate([[0], np.cumsum(sizes)])
    several = len({p.mesh_label for p in parts if p.targets}) > 1
    order: list[str] = []
    by_key: dict[str, NDArray[np.float32]] = {}
    for k, p in enumerate(parts):
        for name, D in p.targets:
            if several and not p.named:
                name = f"{p.mesh_label}_{name}"
            key = _shape_key(name)
            if key not in by_key:
                by_key[key] = np.zeros((int(starts[-1]), 3), np.float32)
                order.append(name)
            by_key[key][starts[k] : starts[k + 1]] = D
    return order, [by_key[_shape_key(n)] for n in order]


def read_gltf(path: str | Path, mesh: int | str | None = None) -> ImportedFace:
    """Read the meshes of a .glb or .gltf scene and their morph targets.

    Parameters
    ----------
    path : str or Path
        .glb (binary) or .gltf (JSON with external or data-URI buffers); plain,
        quantized (``KHR_mesh_quantization``), meshopt- or Draco-compressed.
    mesh : int or str, optional
        Read only this mesh (index or name), under each node that draws it.
        Default: every mesh of the default scene.

    Returns
    -------
    ImportedFace
        World-space positions (n, 3) float64, triangles as polygons, face
        groups per part (several meshes) or per primitive (one mesh), shapes
        from the targets' POSITION (float32 world-space deltas), units "m",
        up axis "+y".

    Raises
    ------
    MeshFormatError
        Truncated or garbled container/JSON/compressed data, counts larger than
        the data, index out of range, non-TRIANGLES primitives, NaN/inf, bad
        node transforms, mismatched targets, degenerate or duplicate
        triangles, duplicate target names within a mesh, unsupported required
        extensions. The message names the file and the JSON field.
    """
    p = Path(path)
    src = str(p)
    doc, bin_chunk = read_container(p)
    g = Gltf(doc, src, bin_chunk, p.parent)
    asset = g.doc.get("asset")
    if not isinstance(asset, dict) or not str(asset.get("version", "")).startswith("2"):
        g.fail("asset.version", "missing or not glTF 2.x")
    _check_extensions(g)
    meshes = g.array("meshes")
    if not meshes:
        g.fail("meshes", "the file has no meshes")
    only = None if mesh is None else _mesh_index(g, mesh)
    insts = instances(g, only)
    if not insts:
        g.fail("scene", "the scene draws no mesh")
    parts = [_read_instance(g, inst) for inst in insts]

    V = np.concatenate([q.vertices for q in parts])
    offsets = np.cumsum([0] + [q.vertices.shape[0] for q in parts])
    F = np.concatenate([q.triangles + offsets[k] for k, q in enumerate(parts)])
    names, deltas = _merge(parts)
    check_shape_names(names, [src] * len(names), src)

    face_groups: NDArray[np.int32] | None = None
    group_names: list[str] = []
    if len(parts) > 1:
        group_names = [q.name for q in parts]
        face_groups = np.repeat(
            np.arange(len(parts), dtype=np.int32), [len(q.triangles) for q in parts]
        )
    elif len(parts[0].group_names) > 1:
        group_names = parts[0].group_names
        face_groups = parts[0].prim_of_tri.astype(np.int32)
    return ImportedFace(
        vertices=V,
        polygons=Polygons.from_triangles(F),
        face_groups=face_groups,
        group_names=group_names,
        shapes=list(zip(names, deltas, strict=True)),
        source_files=[src],
        units="m",
        up_axis="+y",
    )


def _mesh_index(g: Gltf, mesh: int | str) -> int:
    meshes = g.array("meshes")
    if isinstance(mesh, str):
        names = [m.get("name") if isinstance(m, dict) else None for m in meshes]
        if mesh not in names:
            g.fail("meshes", f"no mesh named {mesh!r}; names: {names}")
        return names.index(mesh)
    if not 0 <= mesh < len(meshes):
        g.fail("meshes", f"mesh index {mesh} out of range ({len(meshes)} meshes)")
    return mesh
