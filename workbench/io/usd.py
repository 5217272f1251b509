"""USD reader (.usd/.usda/.usdc/.usdz): meshes with UsdSkel blend shapes, and their SkelAnimation weights.

The registry's module for USD (``detect``, ``read``, ``DESCRIPTION``), on
Pixar's own library (``usd-core``, already used by the USD exporter). What is read:

* **meshes**: every ``Mesh`` prim the stage draws (active, defined, not
  invisible, purpose not guide/proxy), ``points`` (the first time sample if
  animated) under the prim's local-to-world transform, ``faceVertexCounts`` /
  ``faceVertexIndices`` (n-gons kept; ``orientation = "leftHanded"`` reversed);
  several meshes become face groups named after their prims;
* **blend shapes** (``UsdSkel.BindingAPI``): ``skel:blendShapes`` names the
  shapes, ``skel:blendShapeTargets`` points at one ``UsdSkel.BlendShape`` per
  name, whose ``offsets`` apply to ``pointIndices`` (sparse) or to every point
  (no indices). In-betweens (``inbetweens:*``) are ignored with a logged note;
  a name on several meshes is one shape;
* **units and axes**: ``metersPerUnit`` (1 m, 0.1 dm, 0.01 cm, 0.001 mm,
  0.0254 in) is the face's unit; another value converts the coordinates to
  metres; unauthored, the unit is inferred from the size (USD's fallback of
  0.01 is often not what a writer meant). ``upAxis = "Z"`` is turned into y up
  (``(x, z, -y)``, as Blender and our exporter do), so the face is y up, front +z;
* **animation** (:func:`read_usd_animation`): the ``SkelAnimation`` that a
  ``skel:animationSource`` names: ``blendShapes`` + ``blendShapeWeights`` time
  samples, one key per sample at ``timeCode / timeCodesPerSecond`` seconds,
  linear (held when the stage's interpolation is held), as USD interpolates them.

Every attribute is checked (counts, ranges, finiteness, types) and a problem
raises :class:`MeshFormatError` naming the file, the prim path and the
attribute; layers that do not parse report the parser's own message.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.base import ImportedFace
from workbench.io.parts import Part, merge_parts, polygons_from_counts, reverse_winding, to_y_up

__all__ = ["DESCRIPTION", "detect", "read", "read_usd", "read_usd_animation"]

log = logging.getLogger("workbench.io")

SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
DESCRIPTION = (
    "a .usd/.usda/.usdc/.usdz stage (meshes with UsdSkel blend shapes; SkelAnimation weights "
    "via read_usd_animation)"
)
_UNIT_OF_MPU = {0.001: "mm", 0.01: "cm", 0.0254: "in", 0.1: "dm", 1.0: "m"}


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in SUFFIXES


def read(path: Path) -> ImportedFace:
    return read_usd(path)


def _open(p: Path) -> Any:
    from pxr import Sdf, Tf, Usd

    src = str(p)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    stale = Sdf.Layer.Find(str(p))  # held open elsewhere in this process: re-read from disk
    try:
        layer = Sdf.Layer.FindOrOpen(str(p))
    except Tf.ErrorException as exc:
        raise MeshFormatError(src, "layer", f"the file does not parse as USD: {_tf_message(exc)}") from None
    if layer is None:
        raise MeshFormatError(src, "layer", "the file does not parse as USD")
    try:
        if stale is not None:
            layer.Reload()
        stage = Usd.Stage.Open(layer, Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise MeshFormatError(src, "layer", f"the stage cannot be opened: {_tf_message(exc)}") from None
    if stage is None:
        raise MeshFormatError(src, "layer", "the stage cannot be opened")
    return stage


def _tf_message(exc: Exception) -> str:
    """The parser's own words: ``file:line:col: parse error ... in </Prim.attr>``, C++ names trimmed."""
    text = " ".join(str(exc).split())
    m = re.search(r" : '(.*)'\s*$", text)
    if m:
        text = m.group(1).strip()
    text = re.sub(r"pxrInternal_v\w+?__pxrReserved__::(\w+::)*", "", text)
    return text[:600]


class _Reader:
    def __init__(self, p: Path) -> None:
        from pxr import Usd, UsdGeom

        self.p = p
        self.src = str(p)
        self.stage = _open(p)
        self.time = Usd.TimeCode.EarliestTime()
        self.notes: list[str] = []
        st = self.stage
        up = UsdGeom.GetStageUpAxis(st)
        if up not in ("Y", "Z"):
            self.fail("upAxis", f"must be \"Y\" or \"Z\", got {up!r}")
        self.up = "+y" if up == "Y" else "+z"
        if self.up == "+z":
            self.notes.append("the stage is Z up; turned y up ((x, y, z) -> (x, z, -y))")
        self.unit: str | None
        self.scale = 1.0
        if st.HasAuthoredMetadata("metersPerUnit"):
            mpu = st.GetMetadata("metersPerUnit")
            if not isinstance(mpu, float | int) or isinstance(mpu, bool) or not math.isfinite(mpu) or mpu <= 0:
                self.fail("metersPerUnit", f"must be a positive number of metres, got {mpu!r}")
            self.unit = next((u for k, u in _UNIT_OF_MPU.items() if abs(mpu - k) <= 1e-6 * k), None)
            if self.unit is None:
                self.unit, self.scale = "m", float(mpu)
                self.notes.append(f"metersPerUnit {mpu:g} is not mm/cm/in/dm/m: coordinates converted to metres")
        else:
            self.unit = None
            self.notes.append("metersPerUnit is not authored (USD's fallback is 0.01): the unit is inferred from the size")

    def fail(self, where: str, msg: str) -> NoReturn:
        raise MeshFormatError(self.src, where, f"{where}: {msg}")

    def array(self, attr: Any, where: str, cols: int | None, *, required: bool = True, integer: bool = False) -> NDArray[Any] | None:
        if not attr or not attr.HasAuthoredValue():
            if required:
                self.fail(where, "missing (not authored)")
            return None
        v = attr.Get(self.time)
        if v is None:
            if required:
                self.fail(where, "has no value")
            return None
        try:
            a = np.asarray(v)
        except (TypeError, ValueError) as exc:
            self.fail(where, f"not an array ({exc})")
        if integer:
            if a.size and not np.issubdtype(a.dtype, np.integer):
                self.fail(where, f"expected integers ({attr.GetTypeName()}), got {a.dtype}")
            return a.reshape(-1).astype(np.int64)
        if a.size and not np.issubdtype(a.dtype, np.number):
            self.fail(where, f"expected numbers, got {attr.GetTypeName()}")
        a = a.astype(np.float64)
        if cols is not None:
            if a.size == 0:
                a = a.reshape(0, cols)
            if a.ndim != 2 or a.shape[1] != cols:
                self.fail(where, f"expected {cols}-vectors ({attr.GetTypeName()}), got shape {a.shape}")
        bad = ~np.isfinite(a)
        if bad.any():
            row = int(np.argmax(bad.reshape(a.shape[0], -1).any(axis=1))) if a.ndim > 1 else int(np.argmax(bad))
            self.fail(where, f"element {row} is not finite ({a[row].tolist()})")
        return a

    def meshes(self) -> list[Any]:
        from pxr import UsdGeom

        out = []
        for prim in self.stage.Traverse():
            if not prim.IsA(UsdGeom.Mesh):
                continue
            img = UsdGeom.Imageable(prim)
            purpose = img.ComputePurpose()
            if purpose in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy):
                self.notes.append(f"{prim.GetPath()} has purpose {purpose}: skipped")
                continue
            if img.ComputeVisibility(self.time) == UsdGeom.Tokens.invisible:
                self.notes.append(f"{prim.GetPath()} is invisible: skipped")
                continue
            out.append(prim)
        return out

    def part(self, prim: Any) -> Part:
        from pxr import UsdGeom, UsdSkel

        path = str(prim.GetPath())
        mesh = UsdGeom.Mesh(prim)
        pts_attr = mesh.GetPointsAttr()
        V = self.array(pts_attr, f"{path}.points", 3)
        assert V is not None
        n = V.shape[0]
        if n == 0:
            self.fail(f"{path}.points", "empty (the mesh has no points)")
        if pts_attr.GetNumTimeSamples() > 1:
            self.notes.append(f"{path}.points is animated ({pts_attr.GetNumTimeSamples()} samples): the first is the neutral")
        counts = self.array(mesh.GetFaceVertexCountsAttr(), f"{path}.faceVertexCounts", None, integer=True)
        idx = self.array(mesh.GetFaceVertexIndicesAttr(), f"{path}.faceVertexIndices", None, integer=True)
        assert counts is not None and idx is not None
        polys = polygons_from_counts(counts, idx, n, self.src, f"{path}.faceVertexCounts/faceVertexIndices")
        orient = mesh.GetOrientationAttr().Get()
        if orient not in (None, "rightHanded", "leftHanded"):
            self.fail(f"{path}.orientation", f"must be rightHanded or leftHanded, got {orient!r}")
        M = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(self.time), np.float64)
        if M.shape != (4, 4) or not np.isfinite(M).all():
            self.fail(f"{path} (xformOps)", "the local-to-world transform is not finite")
        L = M[:3, :3]  # USD: row vectors, p_world = p @ M
        det = float(np.linalg.det(L))
        if not abs(det) > 1e-12 * float(np.linalg.norm(L)) ** 3:
            self.fail(f"{path} (xformOps)", "the world transform is singular (a zero scale)")
        if (orient == "leftHanded") != (det < 0):
            polys = reverse_winding(polys)
        k = self.scale
        W = to_y_up(V @ L + M[3, :3], self.up) * k
        shapes: list[tuple[str, NDArray[np.float32]]] = []
        binding = UsdSkel.BindingAPI(prim)
        names_attr = binding.GetBlendShapesAttr()
        rel = binding.GetBlendShapeTargetsRel()
        has_names = bool(names_attr) and names_attr.HasAuthoredValue()
        has_targets = bool(rel) and rel.HasAuthoredTargets()
        if has_names or has_targets:
            names = list(names_attr.Get() or []) if has_names else []
            targets = rel.GetTargets() if has_targets else []
            if len(names) != len(targets):
                self.fail(
                    f"{path}.skel:blendShapes",
                    f"names {len(names)} shapes but skel:blendShapeTargets has {len(targets)} targets (one per name expected)",
                )
            seen: set[str] = set()
            for name, tpath in zip(names, targets, strict=True):
                name = str(name)
                if not name:
                    self.fail(f"{path}.skel:blendShapes", "a shape name is empty")
                if name in seen:
                    self.fail(f"{path}.skel:blendShapes", f"names shape '{name}' twice")
                seen.add(name)
                D = self.blend_shape(tpath, n, name, path)
                shapes.append((name, (to_y_up(D @ L, self.up) * k).astype(np.float32)))
        return Part(prim.GetName(), W, polys, shapes, path)

    def blend_shape(self, tpath: Any, n: int, name: str, mesh_path: str) -> NDArray[np.float64]:
        from pxr import UsdSkel

        bprim = self.stage.GetPrimAtPath(tpath)
        where = f"{mesh_path}.skel:blendShapeTargets"
        if not bprim or not bprim.IsValid():
            self.fail(where, f"target {tpath} of shape '{name}' is not a prim of the stage")
        if not bprim.IsA(UsdSkel.BlendShape):
            self.fail(where, f"target {tpath} of shape '{name}' is a {bprim.GetTypeName() or 'typeless prim'}, not a BlendShape")
        bs = UsdSkel.BlendShape(bprim)
        bp = str(tpath)
        off = self.array(bs.GetOffsetsAttr(), f"{bp}.offsets", 3)
        assert off is not None
        ix = self.array(bs.GetPointIndicesAttr(), f"{bp}.pointIndices", None, required=False, integer=True)
        D = np.zeros((n, 3), np.float64)
        if ix is None:
            if off.shape[0] != n:
                self.fail(f"{bp}.offsets", f"{off.shape[0]} offsets without pointIndices; the mesh has {n} points (one offset per point expected)")
            D[:] = off
        else:
            if ix.size != off.shape[0]:
                self.fail(f"{bp}.pointIndices", f"{ix.size} indices for {off.shape[0]} offsets (one per offset expected)")
            bad = (ix < 0) | (ix >= n)
            if bad.any():
                j = int(np.argmax(bad))
                self.fail(f"{bp}.pointIndices", f"index {j} is {int(ix[j])}, out of range (the mesh {mesh_path} has {n} points)")
            if np.unique(ix).size != ix.size:
                u, c = np.unique(ix, return_counts=True)
                self.fail(f"{bp}.pointIndices", f"point {int(u[np.argmax(c > 1)])} is listed more than once")
            D[ix] = off
        inb = bs.GetInbetweens()
        if inb:
            self.notes.append(f"{bp} has {len(inb)} in-between shape(s) ({', '.join(i.GetAttr().GetName() for i in inb)}): ignored, only the full shape is read")
        return D


def read_usd(path: str | Path) -> ImportedFace:
    """Read a USD stage's meshes and UsdSkel blend shapes (see the module docstring).

    Raises
    ------
    FileNotFoundError
        No such file.
    MeshFormatError
        The layer does not parse, or a mesh/blend-shape attribute is malformed
        (the message names the prim path and attribute).
    """
    r = _Reader(Path(path))
    prims = r.meshes()
    if not prims:
        r.fail("meshes", "the stage has no Mesh prim to draw")
    parts = [r.part(prim) for prim in prims]
    face = merge_parts(parts, r.src, units=r.unit, up_axis="+y")
    for n in r.notes:
        log.info("%s: %s", r.p.name, n)
    return face


def _animations(r: _Reader) -> list[Any]:
    from pxr import UsdSkel

    anims: list[Any] = []
    seen: set[str] = set()
    for prim in r.stage.Traverse():
        rel = UsdSkel.BindingAPI(prim).GetAnimationSourceRel()
        if not rel or not rel.HasAuthoredTargets():
            continue
        for t in rel.GetTargets():
            a = r.stage.GetPrimAtPath(t)
            where = f"{prim.GetPath()}.skel:animationSource"
            if not a or not a.IsA(UsdSkel.Animation):
                r.fail(where, f"target {t} is not a SkelAnimation prim")
            if str(t) not in seen:
                seen.add(str(t))
                anims.append(a)
    if not anims:
        loose = [p for p in r.stage.Traverse() if p.IsA(UsdSkel.Animation)]
        if loose:
            r.notes.append(f"no skel:animationSource names a SkelAnimation; read {loose[0].GetPath()}")
            anims = loose[:1]
    return anims


def read_usd_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    fps: float | None = None,
    on_unknown: str = "error",
) -> Any:
    """The blend-shape weights of a USD stage's SkelAnimation as a Timeline.

    Mirrors :func:`workbench.animation.importers.read_gltf_animation`: the
    ``blendShapes`` tokens are matched to ``shape_names`` exactly, else by ARKit
    meaning; one key per time sample (linear; step when the stage's
    interpolation is held).

    Raises
    ------
    AnimationImportError
        Malformed file, no SkelAnimation with weights, a weights sample whose
        length is not the number of ``blendShapes``, NaN, unknown names.
    """
    from pxr import Usd

    from workbench.animation.curves import Interpolation, Key, Track, weight_track_name
    from workbench.animation.importers import AnimationImportError, map_shape_names
    from workbench.animation.tracks import Timeline

    p = Path(path)
    src = str(p)
    try:
        r = _Reader(p)
        st = r.stage
        tcps = float(st.GetTimeCodesPerSecond())
        if not (math.isfinite(tcps) and tcps > 0):
            r.fail("timeCodesPerSecond", f"must be > 0, got {tcps!r}")
        anims = _animations(r)
        if not anims:
            r.fail("SkelAnimation", "the stage has no SkelAnimation (no blend-shape animation)")
        held = st.GetInterpolationType() == Usd.InterpolationTypeHeld
        curves: dict[str, tuple[str, NDArray[np.float64], NDArray[np.float64]]] = {}
        for a in anims:
            from pxr import UsdSkel

            anim = UsdSkel.Animation(a)
            ap = str(a.GetPath())
            tok_attr = anim.GetBlendShapesAttr()
            w_attr = anim.GetBlendShapeWeightsAttr()
            if not w_attr or not (w_attr.HasAuthoredValue() or w_attr.GetNumTimeSamples()):
                continue
            tokens = [str(t) for t in (tok_attr.Get() or [])] if tok_attr else []
            if not tokens:
                r.fail(f"{ap}.blendShapes", "missing or empty, but blendShapeWeights are authored")
            if len(set(tokens)) != len(tokens):
                r.fail(f"{ap}.blendShapes", "names a shape twice")
            times = list(w_attr.GetTimeSamples()) or [0.0]
            W = np.zeros((len(times), len(tokens)))
            for k, tc in enumerate(times):
                v = w_attr.Get(tc) if w_attr.GetNumTimeSamples() else w_attr.Get()
                row = np.asarray(v if v is not None else [], np.float64).reshape(-1)
                if row.size != len(tokens):
                    r.fail(f"{ap}.blendShapeWeights", f"the sample at time {tc:g} has {row.size} weights, blendShapes names {len(tokens)}")
                if not np.isfinite(row).all():
                    j = int(np.argmax(~np.isfinite(row)))
                    r.fail(f"{ap}.blendShapeWeights", f"the sample at time {tc:g}: weight {j} ('{tokens[j]}') is not finite")
                W[k] = row
            T = np.asarray(times, np.float64) / tcps
            for j, tok in enumerate(tokens):
                if tok in curves and not (np.array_equal(curves[tok][1], T) and np.array_equal(curves[tok][2], W[:, j])):
                    r.fail(f"{ap}.blendShapes", f"shape '{tok}' is also animated, differently, by {curves[tok][0]}")
                curves[tok] = (ap, T, W[:, j].copy())
        if not curves:
            r.fail("SkelAnimation", "no SkelAnimation has blendShapeWeights")
    except MeshFormatError as exc:
        raise AnimationImportError(src, exc.detail) from None
    names = list(curves)
    mapping = map_shape_names(names, shape_names, src)
    unknown = [n for n in names if mapping[n] is None]
    if unknown and on_unknown != "ignore":
        raise AnimationImportError(
            src,
            f"unknown shape names {unknown[:10]}{'...' if len(unknown) > 10 else ''} (the model has no "
            "shape of that name or ARKit meaning; pass on_unknown='ignore' to skip them)",
        )
    mode: Interpolation = "step" if held else "linear"
    tracks = {}
    for name in names:
        shape = mapping[name]
        if shape is None:
            continue
        _, T, w = curves[name]
        tn = weight_track_name(shape)
        tracks[tn] = Track(tn, tuple(Key(float(t), float(v), mode) for t, v in zip(T, w, strict=True)))
    if not tracks:
        raise AnimationImportError(src, "no animated blend shape matches a shape of the model")
    rate = fps
    if rate is None:
        rate = float(st.GetFramesPerSecond()) if st.HasAuthoredMetadata("framesPerSecond") else tcps
    for n in r.notes:
        log.info("%s: %s", p.name, n)
    return Timeline(fps=rate, tracks=tracks).fit_range()
