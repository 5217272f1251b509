"""What Blender's importer will read, checked before it runs: global settings and ``Objects``.

The mesh, shape, curve and unit fields Blender will read are checked for
counts, ranges and finite numbers, so a malformed file fails with a
:class:`MeshFormatError` naming the file, the node path and the field, never
half-loaded or as a traceback from inside Blender.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.fbx.binary import _ARRAY, FbxFile, FbxNode, parse_fbx


@dataclass
class _Settings:
    unit_scale: float = 1.0
    up_axis: int = 1
    up_sign: int = 1
    fps: float | None = None
    notes: list[str] = field(default_factory=list)


def _p70(node: FbxNode | None) -> dict[str, list[Any]]:
    """Properties70 ``P`` records of a node: name -> values."""
    out: dict[str, list[Any]] = {}
    if node is None:
        return out
    p70 = node.child("Properties70")
    for p in p70.children if p70 is not None else ():
        if p.name == "P" and p.props and isinstance(p.props[0], bytes):
            out[p.props[0].decode("utf-8", "replace")] = p.props[4:]
    return out


def _number(v: list[Any], src: str, where: str, *, integer: bool = False) -> float:
    if not v or isinstance(v[0], bytes | np.ndarray) or isinstance(v[0], bool):
        raise MeshFormatError(src, where, f"{where}: expected a number, got {v[:1]!r}")
    x = float(v[0])
    if not math.isfinite(x) or (integer and x != int(x)):
        raise MeshFormatError(src, where, f"{where}: expected a finite {'integer' if integer else 'number'}, got {v[0]!r}")
    return x


#: FBX TimeMode enum -> frames per second (14 = custom: CustomFrameRate)
_TIME_MODES = {1: 120.0, 2: 100.0, 3: 60.0, 4: 50.0, 5: 48.0, 6: 30.0, 7: 30.0, 8: 30.0,
               9: 29.97, 10: 25.0, 11: 24.0, 12: 1000.0, 13: 23.976, 15: 96.0, 16: 72.0,
               17: 59.94, 18: 119.88}


def _settings(f: FbxFile, src: str) -> _Settings:
    s = _Settings()
    gs = f.top("GlobalSettings")
    if gs is None:
        s.notes.append("no GlobalSettings: centimetres and y up assumed (the FBX defaults)")
        return s
    p = _p70(gs)
    if "UnitScaleFactor" in p:
        s.unit_scale = _number(p["UnitScaleFactor"], src, "GlobalSettings.UnitScaleFactor")
        if not s.unit_scale > 0:
            raise MeshFormatError(
                src, "GlobalSettings.UnitScaleFactor",
                f"GlobalSettings.UnitScaleFactor: must be > 0 (centimetres per unit), got {s.unit_scale:g}",
            )
    for key, lo, hi in (("UpAxis", 0, 2), ("FrontAxis", 0, 2), ("CoordAxis", 0, 2)):
        if key in p:
            v = _number(p[key], src, f"GlobalSettings.{key}", integer=True)
            if not lo <= v <= hi:
                raise MeshFormatError(src, f"GlobalSettings.{key}", f"GlobalSettings.{key}: must be 0, 1 or 2 (x, y, z), got {v:g}")
            if key == "UpAxis":
                s.up_axis = int(v)
    for key in ("UpAxisSign", "FrontAxisSign", "CoordAxisSign"):
        if key in p:
            v = _number(p[key], src, f"GlobalSettings.{key}", integer=True)
            if v not in (1, -1):
                raise MeshFormatError(src, f"GlobalSettings.{key}", f"GlobalSettings.{key}: must be 1 or -1, got {v:g}")
            if key == "UpAxisSign":
                s.up_sign = int(v)
    mode = int(_number(p["TimeMode"], src, "GlobalSettings.TimeMode", integer=True)) if "TimeMode" in p else 0
    if mode in _TIME_MODES:
        s.fps = _TIME_MODES[mode]
    if "CustomFrameRate" in p:
        rate = _number(p["CustomFrameRate"], src, "GlobalSettings.CustomFrameRate")
        if mode == 14 or mode not in _TIME_MODES:
            if not rate > 0 and mode == 14:
                raise MeshFormatError(src, "GlobalSettings.CustomFrameRate", f"GlobalSettings.CustomFrameRate: must be > 0 with TimeMode 14 (custom), got {rate:g}")
            if rate > 0:
                s.fps = rate
    return s


def _array(node: FbxNode, name: str, src: str, kinds: str, *, required: bool = True) -> NDArray[Any] | None:
    c = node.child(name)
    where = f"{node.label()}.{name}"
    if c is None or not c.props:
        if required:
            raise MeshFormatError(src, where, f"{where}: missing (an array is required here)")
        return None
    a = c.props[0]
    if not isinstance(a, np.ndarray) or a.dtype not in [_ARRAY[k] for k in kinds]:
        raise MeshFormatError(src, where, f"{where}: expected an array of {'/'.join(kinds)} values, got {type(a).__name__}")
    return a


def _check_objects(f: FbxFile, src: str) -> list[str]:
    """Check what Blender's importer reads from ``Objects``; return notes."""
    notes: list[str] = []
    objs = f.top("Objects")
    if objs is None:
        raise MeshFormatError(src, "Objects", "Objects: missing (the file has no objects)")
    by_id: dict[int, FbxNode] = {}
    for o in objs.children:
        if o.props and isinstance(o.props[0], int):
            by_id[o.props[0]] = o
    mesh_vertices: dict[int, int] = {}
    n_meshes = 0
    for o in objs.children:
        if o.name != "Geometry" or len(o.props) < 3 or o.props[2] != b"Mesh":
            continue
        n_meshes += 1
        V = _array(o, "Vertices", src, "df")
        assert V is not None
        where = f"{o.label()}.Vertices"
        if V.size % 3:
            raise MeshFormatError(src, where, f"{where}: {V.size} values, not a multiple of 3 (x, y, z)")
        bad = ~np.isfinite(V)
        if bad.any():
            i = int(np.argmax(bad))
            raise MeshFormatError(src, where, f"{where}: vertex {i // 3} is not finite ({V[i - i % 3 : i - i % 3 + 3].tolist()})")
        n = V.size // 3
        mesh_vertices[o.props[0]] = n
        P = _array(o, "PolygonVertexIndex", src, "i")
        assert P is not None
        where = f"{o.label()}.PolygonVertexIndex"
        if P.size == 0:
            raise MeshFormatError(src, where, f"{where}: empty (the mesh has no faces)")
        if P[-1] >= 0:
            raise MeshFormatError(src, where, f"{where}: the last index {int(P[-1])} does not close a polygon (the last corner of each polygon is stored as -(index+1))")
        idx = np.where(P < 0, -P.astype(np.int64) - 1, P)
        out = idx >= n
        if out.any():
            k = int(np.argmax(out))
            raise MeshFormatError(src, where, f"{where}: corner {k} refers to vertex {int(idx[k])}, out of range (the mesh has {n} vertices)")
    if n_meshes == 0:
        raise MeshFormatError(src, "Objects/Geometry", "Objects: the file has no mesh geometry (Geometry of class Mesh)")
    # connections: child id -> parent ids
    parents: dict[int, list[int]] = {}
    conns = f.top("Connections")
    for c in conns.children if conns is not None else ():
        if c.name == "C" and len(c.props) >= 3 and isinstance(c.props[1], int) and isinstance(c.props[2], int):
            parents.setdefault(c.props[1], []).append(c.props[2])

    def mesh_of_shape(shape_id: int) -> int | None:
        for ch in parents.get(shape_id, []):  # BlendShapeChannel
            for bs in parents.get(ch, []):  # BlendShape deformer
                for g in parents.get(bs, []):
                    if g in mesh_vertices:
                        return g
        return None

    for o in objs.children:
        if o.name == "Geometry" and len(o.props) >= 3 and o.props[2] == b"Shape":
            ix = _array(o, "Indexes", src, "i")
            V = _array(o, "Vertices", src, "df")
            assert ix is not None and V is not None
            where = f"{o.label()}.Vertices"
            if V.size != 3 * ix.size:
                raise MeshFormatError(src, where, f"{where}: {V.size} values for {ix.size} Indexes (3 per index expected)")
            bad = ~np.isfinite(V)
            if bad.any():
                i = int(np.argmax(bad))
                raise MeshFormatError(src, where, f"{where}: offset {i // 3} (vertex {int(ix[i // 3])}) is not finite")
            where = f"{o.label()}.Indexes"
            if (ix < 0).any():
                k = int(np.argmax(ix < 0))
                raise MeshFormatError(src, where, f"{where}: index {k} is negative ({int(ix[k])})")
            g = mesh_of_shape(o.props[0]) if isinstance(o.props[0], int) else None
            if g is not None and ix.size and int(ix.max()) >= mesh_vertices[g]:
                k = int(np.argmax(ix >= mesh_vertices[g]))
                raise MeshFormatError(
                    src, where,
                    f"{where}: index {k} refers to vertex {int(ix[k])}, out of range "
                    f"(its mesh {by_id[g].label()} has {mesh_vertices[g]} vertices)",
                )
        elif o.name == "Deformer" and len(o.props) >= 3 and o.props[2] == b"BlendShapeChannel":
            fw = _array(o, "FullWeights", src, "d", required=False)
            shapes = [
                c for c, ps in parents.items()
                if o.props[0] in ps and c in by_id and by_id[c].name == "Geometry"
            ]
            if fw is not None and len(shapes) > 1:
                notes.append(f"{o.label()} has {len(shapes)} in-between shapes; Blender's importer reads them as separate shape keys")
        elif o.name == "AnimationCurve":
            T = _array(o, "KeyTime", src, "l")
            Vv = _array(o, "KeyValueFloat", src, "fd")
            assert T is not None and Vv is not None
            where = f"{o.label()}.KeyValueFloat"
            if T.size != Vv.size:
                raise MeshFormatError(src, where, f"{where}: {Vv.size} values for {T.size} KeyTime entries (one per key expected)")
            if not np.isfinite(Vv).all():
                k = int(np.argmax(~np.isfinite(Vv)))
                raise MeshFormatError(src, where, f"{where}: key {k} value is not finite")
            if T.size > 1 and (np.diff(T) <= 0).any():
                k = int(np.argmax(np.diff(T) <= 0))
                raise MeshFormatError(
                    src, f"{o.label()}.KeyTime",
                    f"{o.label()}.KeyTime: key {k + 1} time {int(T[k + 1])} does not come after key {k} ({int(T[k])}); times must increase",
                )
    return notes


def _prepare(path: str | Path) -> tuple[Path, _Settings, list[str]]:
    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    f = parse_fbx(p)
    s = _settings(f, src)
    notes = s.notes + _check_objects(f, src)
    return p, s, notes
