"""FBX, Alembic and USD files written by real writers from the sample head, made once and cached.

The source (:func:`face_source`) is the CC0 sample head split into two meshes,
``Head`` (skin, eyes, lashes) and ``Mouth`` (teeth, tongue), with six of its
ARKit shapes and LINEAR keys on their values (:data:`KEYS`, 30 fps). Writers:

* **Blender 5.0** (bpy in ``$WORKBENCH_BPY_PYTHON``, default
  ``.venv/blender/bin/python``; :data:`BPY_SCRIPT`) builds the two objects with
  shape keys and keyed values, then writes ``face.fbx`` (its FBX exporter, keys
  baked per frame), ``face.abc`` (its Alembic exporter: the deformed meshes at
  every frame) and ``face_blender.usda`` (its USD exporter: UsdSkel blend
  shapes + SkelAnimation weights);
* **usd-core** (Pixar's library): :func:`write_usdskel` writes the head the way
  the UsdSkel docs describe (SkelRoot, Skeleton, SkelAnimation with
  ``blendShapes``/``blendShapeWeights`` time samples, a Mesh with
  ``SkelBindingAPI``, ``skel:blendShapes``, ``skel:blendShapeTargets`` and one
  sparse ``BlendShape`` per target), centimetres, y up.

Files are cached in ``.venv/cache/import-formats/<key>/`` (else the temp
folder); ``key`` hashes this file and the sample head's manifest. A missing
Blender raises :class:`ToolMissing`.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

SHAPES = ("jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "browInnerUp", "cheekPuff", "tongueOut")
FPS = 30
#: shape -> [(frame, value)], LINEAR keys (Blender's source curves)
KEYS: dict[str, list[tuple[int, float]]] = {
    "jawOpen": [(0, 0.0), (6, 1.0), (12, 0.25), (20, 0.6)],
    "eyeBlinkLeft": [(0, 0.0), (3, 1.0), (8, 0.0)],
    "mouthSmileLeft": [(0, 0.5), (20, 0.1)],
    "browInnerUp": [(4, 0.0), (10, 0.8), (16, 0.3)],
    "cheekPuff": [(0, 0.2)],
    "tongueOut": [(0, 0.0), (10, 0.7), (20, 0.0)],
}
LAST_FRAME = 20
MOUTH_PARTS = ("tongue", "teeth_lower", "teeth_upper")


class ToolMissing(RuntimeError):
    """Blender (bpy) is not installed."""


def bpy_python() -> Path | None:
    p = os.environ.get("WORKBENCH_BPY_PYTHON") or str(ROOT / ".venv" / "blender" / "bin" / "python")
    return Path(p) if Path(p).is_file() else None


@dataclass
class Obj:
    """One mesh of the source, in the sample head's frame (decimetres, y up)."""

    name: str
    vertices: np.ndarray  # (n, 3) float64
    counts: np.ndarray
    corners: np.ndarray
    deltas: dict[str, np.ndarray]  # shape -> (n, 3), only shapes that move this mesh


@dataclass
class FaceSource:
    objects: list[Obj]  # sorted by name, as the readers order them

    def vertices(self) -> np.ndarray:
        return np.concatenate([o.vertices for o in self.objects])

    def delta(self, shape: str) -> np.ndarray:
        return np.concatenate([o.deltas.get(shape, np.zeros_like(o.vertices)) for o in self.objects])

    def weight(self, shape: str, frame: float) -> float:
        """The keyed value (LINEAR keys, constant outside) at ``frame``."""
        k = KEYS[shape]
        return float(np.interp(frame, [f for f, _ in k], [v for _, v in k]))

    def points(self, frame: float) -> np.ndarray:
        V = self.vertices().copy()
        for s in SHAPES:
            V += self.weight(s, frame) * self.delta(s)
        return V


@lru_cache(maxsize=1)
def face_source() -> FaceSource:
    from workbench.samples import load_sample

    m = load_sample("head")
    names = m.component_names
    mouth_ids = [i for i, n in enumerate(names) if n in MOUTH_PARTS]
    in_mouth = np.isin(m.component_labels, mouth_ids)
    P = m.polygons
    objs = []
    for name, sel in (("Head", ~in_mouth), ("Mouth", in_mouth)):
        vid = np.flatnonzero(sel)
        remap = np.full(m.n_vertices, -1, np.int64)
        remap[vid] = np.arange(vid.size)
        keep = [i for i in range(len(P)) if sel[P[i]].all()]
        counts = np.array([len(P[i]) for i in keep], np.int32)
        corners = np.concatenate([remap[P[i]] for i in keep]).astype(np.int32)
        deltas = {}
        for s in SHAPES:
            d = np.asarray(m.shape(s).delta, np.float64)[vid]
            if np.abs(d).max() > 0:
                deltas[s] = d
        objs.append(Obj(name, np.asarray(m.vertices, np.float64)[vid], counts, corners, deltas))
    return FaceSource(objs)


def _key() -> str:
    h = hashlib.sha256()
    for f in (HERE / "format_writers.py", ROOT / "sample_models" / "head" / "manifest.json"):
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    base = ROOT / ".venv" / "cache" if (ROOT / ".venv").is_dir() else Path(tempfile.gettempdir())
    d = base / "import-formats" / _key()
    d.mkdir(parents=True, exist_ok=True)
    return d


BPY_SCRIPT = r"""
import json, sys
import numpy as np
import bpy
args = json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = args["fps"]
scene.frame_start, scene.frame_end = 0, args["last"]
src = np.load(args["npz"], allow_pickle=False)
for o in args["objects"]:
    name = o["name"]
    # sample head frame (dm, y up) -> Blender (m, z up): (x, -z, y) / 10
    V = src[name + "_v"]
    Vb = np.stack([V[:, 0], -V[:, 2], V[:, 1]], axis=1) * 0.1
    counts, corners = src[name + "_counts"], src[name + "_corners"]
    starts = np.concatenate([[0], np.cumsum(counts)])
    faces = [list(corners[starts[i]:starts[i + 1]]) for i in range(len(counts))]
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in Vb], [], faces)
    me.update()
    me.shade_smooth()
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    ob.shape_key_add(name="Basis", from_mix=False)
    for s in o["shapes"]:
        D = src[name + "_" + s]
        Db = np.stack([D[:, 0], -D[:, 2], D[:, 1]], axis=1) * 0.1
        kb = ob.shape_key_add(name=s, from_mix=False)
        kb.data.foreach_set("co", (Vb + Db).astype(np.float32).ravel())
        for f, v in args["keys"][s]:
            kb.value = v
            kb.keyframe_insert("value", frame=f)
    ad = me.shape_keys.animation_data
    from bpy_extras import anim_utils
    bag = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot)
    for fc in bag.fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"
out = args["out"]
bpy.ops.export_scene.fbx(
    filepath=out + "/face.fbx", object_types={"MESH"}, use_mesh_modifiers=False,
    bake_anim=True, bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
    bake_anim_force_startend_keying=True, bake_anim_step=1.0, bake_anim_simplify_factor=0.0,
    add_leaf_bones=False, apply_unit_scale=True,
)
bpy.ops.wm.alembic_export(
    filepath=out + "/face.abc", start=0, end=args["last"], selected=False, flatten=False,
    uvs=False, normals=False, face_sets=False, export_hair=False, export_particles=False,
)
bpy.ops.wm.usd_export(
    filepath=out + "/face_blender.usda", export_animation=True, export_shapekeys=True,
    export_materials=False, export_uvmaps=False, export_normals=False,
)
print("WRITTEN")
"""


def blender_files() -> dict[str, Path]:
    """``{"fbx", "abc", "usd"}`` -> the files Blender wrote (cached)."""
    d = cache_dir()
    want = {"fbx": d / "face.fbx", "abc": d / "face.abc", "usd": d / "face_blender.usda"}
    if all(p.is_file() for p in want.values()):
        return want
    py = bpy_python()
    if py is None:
        raise ToolMissing("Blender as a Python module (WORKBENCH_BPY_PYTHON)")
    src = face_source()
    with tempfile.TemporaryDirectory(prefix="fwb-formats-") as tmp:
        arrays = {}
        objects = []
        for o in src.objects:
            arrays[o.name + "_v"] = o.vertices
            arrays[o.name + "_counts"] = o.counts
            arrays[o.name + "_corners"] = o.corners
            for s, D in o.deltas.items():
                arrays[o.name + "_" + s] = D
            objects.append({"name": o.name, "shapes": [s for s in SHAPES if s in o.deltas]})
        np.savez(Path(tmp) / "src.npz", **arrays)
        script = Path(tmp) / "write.py"
        script.write_text(BPY_SCRIPT)
        out = Path(tmp) / "out"
        out.mkdir()
        args = {
            "npz": str(Path(tmp) / "src.npz"), "objects": objects, "keys": KEYS, "fps": FPS,
            "last": LAST_FRAME, "out": str(out),
        }
        proc = subprocess.run([str(py), str(script), json.dumps(args)], capture_output=True, text=True, timeout=600)
        if proc.returncode != 0 or "WRITTEN" not in proc.stdout:
            raise RuntimeError(f"Blender could not write the test files:\n{proc.stderr[-3000:]}")
        for p in want.values():
            (out / p.name).replace(p)
    return want


def write_usdskel(path: Path, *, meters_per_unit: float = 0.01, sparse: bool = True) -> Path:
    """The source head as UsdSkel, written with usd-core as the UsdSkel docs describe.

    Coordinates in centimetres (``metersPerUnit`` 0.01, the sample's decimetres x 10),
    y up; one mesh per source object under one SkelRoot, bound to one Skeleton
    (no joints) whose ``skel:animationSource`` is a SkelAnimation with one
    ``blendShapeWeights`` sample per frame 0..:data:`LAST_FRAME`.
    """
    from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt

    src = face_source()
    scale = 0.1 / meters_per_unit
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(FPS)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(LAST_FRAME)
    root = UsdSkel.Root.Define(stage, "/Face")
    stage.SetDefaultPrim(root.GetPrim())
    skel = UsdSkel.Skeleton.Define(stage, "/Face/Skel")
    skel.CreateJointsAttr(Vt.TokenArray([]))
    anim = UsdSkel.Animation.Define(stage, "/Face/Skel/Anim")
    anim.CreateBlendShapesAttr(Vt.TokenArray(list(SHAPES)))
    w_attr = anim.CreateBlendShapeWeightsAttr()
    for f in range(LAST_FRAME + 1):
        w_attr.Set(Vt.FloatArray([src.weight(s, f) for s in SHAPES]), Usd.TimeCode(f))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    for o in src.objects:
        mesh = UsdGeom.Mesh.Define(stage, f"/Face/{o.name}")
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy((o.vertices * scale).astype(np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(o.counts))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(o.corners))
        binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        names = [s for s in SHAPES if s in o.deltas]
        binding.CreateBlendShapesAttr(Vt.TokenArray(names))
        targets = []
        for s in names:
            bs = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(s))
            D = (o.deltas[s] * scale).astype(np.float32)
            if sparse:
                ix = np.flatnonzero(np.abs(D).max(axis=1) > 0).astype(np.int32)
                bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(D[ix]))
                bs.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(ix))
            else:
                bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(D))
            targets.append(bs.GetPath())
        binding.CreateBlendShapeTargetsRel().SetTargets([Sdf.Path(t) for t in targets])
    stage.GetRootLayer().Save()
    return path
