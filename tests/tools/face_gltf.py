"""The uncompressed source .glb that the real writers (gltfpack, glTF-Transform, Blender) compress.

Built from the bundled CC0 sample head as a three.js-style scene:

* three meshes on three nodes under a translated root: ``head`` (skin, tongue,
  lashes), ``teeth`` and ``eyes``, each with only the morph targets that move
  it (names in each mesh's ``extras.targetNames``; ``jawOpen`` is on head and
  teeth, ``eyeLook*`` on eyes only, ...);
* the teeth node is rotated 30 degrees about x, scaled by 2 and translated,
  the eyes node rotated -40 degrees about y and scaled by 0.5; vertices and
  deltas are stored in node-local coordinates (deltas through the linear part
  only) so that the world positions equal the sample head (metres);
* a textured material on the head (TEXCOORD_0 + an embedded 8x8 PNG) so that
  texture compression has something to compress;
* one animation with a LINEAR ``weights`` channel per mesh node, the same
  curve for a shape on every mesh that has it.

:class:`FaceSource` keeps the world-space truth the tests compare against.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pygltflib

SHAPES = [
    "jawOpen",
    "eyeBlinkLeft",
    "eyeBlinkRight",
    "mouthSmileLeft",
    "mouthSmileRight",
    "browInnerUp",
    "eyeLookUpLeft",
    "eyeLookUpRight",
    "tongueOut",
]
PARTS = {
    "head": ["skin", "tongue", "eyelashes_left", "eyelashes_right"],
    "teeth": ["teeth_lower", "teeth_upper"],
    "eyes": ["eye_left", "eye_right"],
}
ROOT_TRANSLATION = np.array([0.0, -1.5, 0.25])  # metres, undone by the stored coordinates
KEY_TIMES = np.linspace(0.0, 1.0, 11)


def quat_axis_angle(axis: tuple[float, float, float], degrees: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = math.radians(degrees) / 2
    return np.array([*(a * math.sin(h)), math.cos(h)])  # x, y, z, w


def trs_matrix(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    M = np.eye(4)
    M[:3, :3] = R * np.asarray(s, float)[None, :]
    M[:3, 3] = t
    return M


#: node-local TRS of each mesh node (under the root)
NODE_TRS = {
    "head": (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.ones(3)),
    "teeth": (np.array([0.01, 0.02, -0.03]), quat_axis_angle((1, 0, 0), 30.0), np.full(3, 2.0)),
    "eyes": (np.array([0.0, 0.05, 0.0]), quat_axis_angle((0, 1, 0), -40.0), np.full(3, 0.5)),
}


def weight_curve(shape: str, t: np.ndarray) -> np.ndarray:
    """The value of ``shape``'s key at key times ``t`` (same on every mesh)."""
    phase = 0.7 * (sum(map(ord, shape)) % 9)
    return 0.5 - 0.5 * np.cos(2 * np.pi * np.asarray(t, float) + phase)


def keyed_weight(shape: str, t: np.ndarray) -> np.ndarray:
    """The animated weight at any time: LINEAR interpolation of the keys."""
    return np.interp(t, KEY_TIMES, weight_curve(shape, KEY_TIMES))


def tiny_png(size: int = 8) -> bytes:
    """A size x size RGB checkerboard PNG, written by hand (no imaging library needed)."""
    rows = b"".join(
        b"\0" + bytes(c for x in range(size) for c in ((200, 150, 120) if (x + y) % 2 else (90, 60, 50)))
        for y in range(size)
    )

    def chunk(tag: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body))

    head = struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", head) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")


@dataclass
class MeshPart:
    name: str
    vertices: np.ndarray  # (n, 3) world, metres
    triangles: np.ndarray  # (m, 3) local indices
    shapes: dict[str, np.ndarray] = field(default_factory=dict)  # world deltas of this part


@dataclass
class FaceSource:
    parts: list[MeshPart]
    shapes: list[str] = field(default_factory=lambda: list(SHAPES))

    @property
    def shape_names(self) -> list[str]:
        return [s for s in self.shapes if any(s in p.shapes for p in self.parts)]

    def vertices(self) -> np.ndarray:
        return np.concatenate([p.vertices for p in self.parts])

    def delta(self, shape: str) -> np.ndarray:
        return np.concatenate(
            [p.shapes.get(shape, np.zeros_like(p.vertices)) for p in self.parts]
        )

    def part_of_vertex(self) -> np.ndarray:
        return np.concatenate([np.full(len(p.vertices), k) for k, p in enumerate(self.parts)])


def face_source(resolution: str = "base", shapes: list[str] | None = None) -> FaceSource:
    """The sample head (``load_sample("head", resolution)``) cut into head, teeth and eyes."""
    from workbench import load_sample

    shapes = list(SHAPES if shapes is None else shapes)
    m = load_sample("head", resolution)
    V = np.asarray(m.vertices, np.float64) * 0.1  # dm -> m
    tris = np.asarray(m.faces)
    deltas = {s.name: np.asarray(s.delta, np.float64) * 0.1 for s in m.shapes if s.name in shapes}
    parts = []
    for name, comps in PARTS.items():
        vids = np.unique(np.concatenate([m.component_vertices(c) for c in comps]))
        remap = np.full(len(V), -1)
        remap[vids] = np.arange(vids.size)
        keep = np.all(remap[tris] >= 0, axis=1)
        part = MeshPart(name, V[vids], remap[tris[keep]])
        for s in shapes:
            d = deltas[s][vids]
            if np.any(np.abs(d) > 1e-9):
                part.shapes[s] = d
        parts.append(part)
    return FaceSource(parts, shapes)


def world_matrix(name: str) -> np.ndarray:
    """4x4 world transform of the node that draws mesh ``name``."""
    root = trs_matrix(ROOT_TRANSLATION, np.array([0, 0, 0, 1.0]), np.ones(3))
    return root @ trs_matrix(*NODE_TRS[name])


def local_vertices(part: MeshPart) -> np.ndarray:
    """The part's positions as stored in the file (node-local, float32 like the file)."""
    Minv = np.linalg.inv(world_matrix(part.name))
    return (part.vertices @ Minv[:3, :3].T + Minv[:3, 3]).astype(np.float32).astype(np.float64)


def local_delta(part: MeshPart, shape: str) -> np.ndarray:
    Minv = np.linalg.inv(world_matrix(part.name))
    return (part.shapes[shape] @ Minv[:3, :3].T).astype(np.float32).astype(np.float64)


def build_source_glb(src: FaceSource, path: Path) -> Path:
    """Write the uncompressed source file (pygltflib) and return its path."""
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0", generator="workbench tests"))
    blob = bytearray()

    def view(arr: np.ndarray, target: int | None = None) -> int:
        while len(blob) % 4:
            blob.append(0)
        raw = np.ascontiguousarray(arr).tobytes()
        g.bufferViews.append(
            pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(raw), target=target)
        )
        blob.extend(raw)
        return len(g.bufferViews) - 1

    def accessor(arr: np.ndarray, type_: str, ctype: int, minmax: bool = False, target: int | None = None) -> int:
        a = np.ascontiguousarray(arr)
        acc = pygltflib.Accessor(
            bufferView=view(a, target), componentType=ctype, count=len(a), type=type_
        )
        if minmax:
            acc.min = np.asarray(a.min(0)).reshape(-1).tolist()
            acc.max = np.asarray(a.max(0)).reshape(-1).tolist()
        g.accessors.append(acc)
        return len(g.accessors) - 1

    img_view = view(np.frombuffer(tiny_png(), np.uint8))
    g.images.append(pygltflib.Image(bufferView=img_view, mimeType="image/png"))
    g.samplers.append(pygltflib.Sampler())
    g.textures.append(pygltflib.Texture(source=0, sampler=0))
    g.materials.append(
        pygltflib.Material(
            name="skin",
            pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                baseColorTexture=pygltflib.TextureInfo(index=0)
            ),
        )
    )
    g.materials.append(pygltflib.Material(name="enamel"))
    g.materials.append(pygltflib.Material(name="sclera"))

    g.nodes.append(pygltflib.Node(name="face_root", translation=ROOT_TRANSLATION.tolist(), children=[]))
    anim = pygltflib.Animation(name="expressions", samplers=[], channels=[])
    t_acc = accessor(KEY_TIMES.astype(np.float32), pygltflib.SCALAR, pygltflib.FLOAT, minmax=True)
    for k, part in enumerate(src.parts):
        local = local_vertices(part)
        pos = accessor(local.astype(np.float32), pygltflib.VEC3, pygltflib.FLOAT, True, pygltflib.ARRAY_BUFFER)
        idx = accessor(
            part.triangles.astype(np.uint32).reshape(-1),
            pygltflib.SCALAR,
            pygltflib.UNSIGNED_INT,
            target=pygltflib.ELEMENT_ARRAY_BUFFER,
        )
        attrs = pygltflib.Attributes(POSITION=pos)
        if part.name == "head":
            V = part.vertices
            uv = (V[:, :2] - V[:, :2].min(0)) / (V[:, :2].max(0) - V[:, :2].min(0))
            attrs.TEXCOORD_0 = accessor(uv.astype(np.float32), pygltflib.VEC2, pygltflib.FLOAT, target=pygltflib.ARRAY_BUFFER)
        names = list(part.shapes)
        targets = []
        for s in names:
            d_local = local_delta(part, s)
            targets.append(
                {"POSITION": accessor(d_local.astype(np.float32), pygltflib.VEC3, pygltflib.FLOAT, True, pygltflib.ARRAY_BUFFER)}
            )
        prim = pygltflib.Primitive(
            attributes=attrs, indices=idx, material=k, mode=pygltflib.TRIANGLES, targets=targets or None
        )
        g.meshes.append(
            pygltflib.Mesh(
                name=part.name,
                primitives=[prim],
                weights=[0.0] * len(names) or None,
                extras={"targetNames": names} if names else {},
            )
        )
        t, q, s = NODE_TRS[part.name]
        g.nodes.append(
            pygltflib.Node(
                name=part.name, mesh=k, translation=t.tolist(), rotation=q.tolist(), scale=s.tolist()
            )
        )
        g.nodes[0].children.append(len(g.nodes) - 1)
        if names:
            W = np.stack([weight_curve(s, KEY_TIMES) for s in names], axis=1)
            out = accessor(W.astype(np.float32).reshape(-1), pygltflib.SCALAR, pygltflib.FLOAT)
            anim.samplers.append(pygltflib.AnimationSampler(input=t_acc, output=out, interpolation="LINEAR"))
            anim.channels.append(
                pygltflib.AnimationChannel(
                    sampler=len(anim.samplers) - 1,
                    target=pygltflib.AnimationChannelTarget(node=len(g.nodes) - 1, path="weights"),
                )
            )
    g.animations.append(anim)
    g.scenes.append(pygltflib.Scene(nodes=[0]))
    g.scene = 0
    g.buffers.append(pygltflib.Buffer(byteLength=len(blob)))
    g.set_binary_blob(bytes(blob))
    path.write_bytes(b"".join(g.save_to_bytes()))
    return path
