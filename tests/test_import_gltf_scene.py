"""The glTF scene graph: node transforms, several meshes as parts, shape merging, extension notes.

Small hand-built files (JSON + a binary chunk) whose expected result is
computed independently here: world = parent x local with the spec's
T x R x S order; deltas take only the linear part.
"""

from __future__ import annotations

import json
import logging
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import workbench
from workbench.animation.curves import HEAD_POSE
from workbench.animation.tracks import Timeline
from workbench.export import export
from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.gltf import read_gltf

# a 2x1 quad strip as 4 triangles, and two morph deltas
V0 = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], np.float32) * 0.1
F0 = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]], np.uint16)
D_UP = np.zeros((6, 3), np.float32)
D_UP[4] = [0.0, 0.0, 0.25]
D_SIDE = np.zeros((6, 3), np.float32)
D_SIDE[[0, 3]] = [-0.125, 0.0, 0.0]


def shift(x: float, y: float, z: float) -> np.ndarray:
    return V0 + np.array([x, y, z], np.float32)


class Doc:
    """A glTF document being built: JSON plus one binary buffer."""

    def __init__(self) -> None:
        self.j: dict[str, Any] = {
            "asset": {"version": "2.0"},
            "buffers": [],
            "bufferViews": [],
            "accessors": [],
            "meshes": [],
            "nodes": [],
            "scenes": [{"nodes": []}],
            "scene": 0,
        }
        self.bin = bytearray()

    def accessor(self, arr: np.ndarray, type_: str) -> int:
        while len(self.bin) % 4:
            self.bin.append(0)
        if arr.dtype == np.float64:
            arr = arr.astype(np.float32)
        raw = np.ascontiguousarray(arr).tobytes()
        self.j["bufferViews"].append({"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(raw)})
        self.bin += raw
        ctype = {np.dtype(np.float32): 5126, np.dtype(np.uint16): 5123}[arr.dtype]
        acc = {"bufferView": len(self.j["bufferViews"]) - 1, "componentType": ctype, "count": len(arr), "type": type_}
        if type_ == "VEC3":
            acc["min"], acc["max"] = arr.min(0).tolist(), arr.max(0).tolist()
        self.j["accessors"].append(acc)
        return len(self.j["accessors"]) - 1

    def mesh(self, name: str | None, targets: dict[str, np.ndarray] | None = None, names: bool = True, V: np.ndarray = V0) -> int:
        targets = targets or {}
        prim: dict[str, Any] = {
            "attributes": {"POSITION": self.accessor(V, "VEC3")},
            "indices": self.accessor(F0.reshape(-1), "SCALAR"),
        }
        if targets:
            prim["targets"] = [{"POSITION": self.accessor(d, "VEC3")} for d in targets.values()]
        m: dict[str, Any] = {"primitives": [prim]}
        if name:
            m["name"] = name
        if targets and names:
            m["extras"] = {"targetNames": list(targets)}
        self.j["meshes"].append(m)
        return len(self.j["meshes"]) - 1

    def node(self, root: bool = True, **fields: Any) -> int:
        self.j["nodes"].append(fields)
        i = len(self.j["nodes"]) - 1
        if root:
            self.j["scenes"][0]["nodes"].append(i)
        return i

    def write(self, path: Path) -> Path:
        self.j["buffers"] = [{"byteLength": len(self.bin)}]
        j = json.dumps(self.j).encode()
        j += b" " * (-len(j) % 4)
        b = bytes(self.bin) + b"\0" * (-len(self.bin) % 4)
        body = struct.pack("<II", len(j), 0x4E4F534A) + j + struct.pack("<II", len(b), 0x004E4942) + b
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
        return path


def quat(axis: tuple[float, float, float], degrees: float) -> list[float]:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = math.radians(degrees) / 2
    return [*(a * math.sin(h)).tolist(), math.cos(h)]


def rot(q: list[float]) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w), via Rodrigues (independent of the reader's formula)."""
    x, y, z, w = q
    angle = 2 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle == 0:
        return np.eye(3)
    k = np.array([x, y, z]) / math.sqrt(x * x + y * y + z * z)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def trs(t: list[float], q: list[float], s: list[float]) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3] = rot(q) @ np.diag(s)
    M[:3, 3] = t
    return M


def apply(M: np.ndarray, V: np.ndarray) -> np.ndarray:
    return V.astype(np.float64) @ M[:3, :3].T + M[:3, 3]


def normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


# ---- node transforms -----------------------------------------------------------------------


def test_rotated_and_scaled_node_under_a_parent(tmp_path: Path) -> None:
    d = Doc()
    m = d.mesh("face", {"up": D_UP, "side": D_SIDE})
    parent_t, parent_q = [0.0, 1.5, -0.2], quat((0, 1, 0), 90)
    child = dict(translation=[0.1, 0.2, 0.3], rotation=quat((1, 1, 0), 35), scale=[2.0, 3.0, 0.5])
    c = d.node(root=False, name="head", mesh=m, **child)
    d.node(name="root", translation=parent_t, rotation=parent_q, children=[c])
    face = read_gltf(d.write(tmp_path / "a.glb"))

    M = trs(parent_t, parent_q, [1, 1, 1]) @ trs(child["translation"], child["rotation"], child["scale"])
    np.testing.assert_allclose(face.vertices, apply(M, V0), atol=1e-6)
    L = M[:3, :3]
    shapes = dict(face.shapes)
    np.testing.assert_allclose(shapes["up"], D_UP @ L.T, atol=1e-6)  # no translation on deltas
    np.testing.assert_allclose(shapes["side"], D_SIDE @ L.T, atol=1e-6)
    # rotation + positive scales keep the winding: normals are the transformed ones
    n_local = normals(V0.astype(np.float64), F0.astype(np.int64))
    n_world = n_local @ np.linalg.inv(L)  # normals transform by the inverse transpose
    n_world /= np.linalg.norm(n_world, axis=1, keepdims=True)
    tris, _ = face.polygons.triangulate()
    np.testing.assert_allclose(normals(face.vertices, tris), n_world, atol=1e-6)


def test_matrix_node_equals_trs_node(tmp_path: Path) -> None:
    t, q, s = [0.3, -0.1, 0.05], quat((0.2, 1, 0.4), -70), [1.5, 1.5, 0.75]
    d1, d2 = Doc(), Doc()
    d1.node(mesh=d1.mesh("m", {"up": D_UP}), translation=t, rotation=q, scale=s)
    d2.node(mesh=d2.mesh("m", {"up": D_UP}), matrix=trs(t, q, s).T.reshape(-1).tolist())  # column-major
    a = read_gltf(d1.write(tmp_path / "trs.glb"))
    b = read_gltf(d2.write(tmp_path / "matrix.glb"))
    np.testing.assert_allclose(a.vertices, b.vertices, atol=1e-9)
    np.testing.assert_allclose(a.shapes[0][1], b.shapes[0][1], atol=1e-6)


def test_mirroring_node_flips_the_winding(tmp_path: Path) -> None:
    d = Doc()
    d.node(mesh=d.mesh("m"), scale=[-1.0, 1.0, 1.0])
    face = read_gltf(d.write(tmp_path / "mirror.glb"))
    np.testing.assert_allclose(face.vertices, V0 * np.array([-1, 1, 1], np.float32), atol=1e-7)
    tris, _ = face.polygons.triangulate()
    np.testing.assert_array_equal(tris, F0[:, [0, 2, 1]])
    # the mirrored surface still faces +z, as the original did
    assert np.allclose(normals(face.vertices, tris), [0, 0, 1])


def test_skinned_node_transform_is_ignored(tmp_path: Path) -> None:
    d = Doc()
    d.node(mesh=d.mesh("m"), translation=[5.0, 0.0, 0.0], skin=0)
    face = read_gltf(d.write(tmp_path / "skin.glb"))
    np.testing.assert_allclose(face.vertices, V0, atol=1e-7)


def test_animated_node_transform_is_rigid_motion_not_shape(tmp_path: Path) -> None:
    """The workbench's own export puts the head pose on the mesh node; reading it back gives the neutral."""
    model = workbench.load_sample("head")
    pose = np.r_[0.02, -0.01, 0.03, quat((0, 1, 0), 25)]
    tl = Timeline(fps=24.0).add_key(HEAD_POSE, 0.0, pose).add_key(HEAD_POSE, 1.0, np.r_[0, 0, 0, 0, 0, 0, 1.0])
    tl = tl.add_key("weights/jawOpen", 0.0, 0.0).add_key("weights/jawOpen", 1.0, 1.0)
    export(model, tl, tmp_path / "posed.glb")
    data = (tmp_path / "posed.glb").read_bytes()
    doc = json.loads(data[20 : 20 + struct.unpack_from("<I", data, 12)[0]])
    assert doc["nodes"][0]["rotation"] != [0, 0, 0, 1]  # the file does carry the t=0 pose
    face = read_gltf(tmp_path / "posed.glb")
    np.testing.assert_allclose(face.vertices, model.vertices * 0.1, atol=1e-6)  # decimetres -> metres


# ---- several meshes ----------------------------------------------------------------------


def test_meshes_become_named_parts_and_shapes_merge_by_name(tmp_path: Path) -> None:
    d = Doc()
    head = d.mesh("head_mesh", {"jawOpen": D_UP, "eyeBlink_L": D_SIDE})
    teeth = d.mesh("teeth_mesh", {"jawOpen": D_SIDE}, V=shift(0, 0, -0.05))
    eyes = d.mesh(None, {"eyeBlinkLeft": D_UP, "eyeLookUpLeft": D_SIDE}, V=shift(0, 0.2, 0))
    plain = d.mesh(None, V=shift(0, -0.3, 0))  # no morph targets at all
    d.node(name="Head", mesh=head)
    d.node(name="Teeth", mesh=teeth, translation=[0, 0, 0.01])
    d.node(mesh=eyes)  # unnamed node and mesh
    d.node(mesh=plain)
    face = read_gltf(d.write(tmp_path / "parts.glb"))

    assert face.group_names == ["Head", "Teeth", "mesh_2", "mesh_3"]
    _, names = face.components()
    assert sorted(names) == ["Head", "Teeth", "mesh_2", "mesh_3"]
    # same name merges; ARKit spellings of one shape merge (first spelling kept); new ones append
    assert face.shape_names == ["jawOpen", "eyeBlink_L", "eyeLookUpLeft"]
    s = dict(face.shapes)
    z = np.zeros((6, 3), np.float32)
    np.testing.assert_array_equal(s["jawOpen"], np.concatenate([D_UP, D_SIDE, z, z]))
    np.testing.assert_array_equal(s["eyeBlink_L"], np.concatenate([D_SIDE, z, D_UP, z]))
    np.testing.assert_array_equal(s["eyeLookUpLeft"], np.concatenate([z, z, D_SIDE, z]))
    assert face.n_vertices == 24


def test_unnamed_targets_of_several_meshes_stay_apart(tmp_path: Path) -> None:
    d = Doc()
    d.node(mesh=d.mesh("head", {"a": D_UP}, names=False))
    d.node(mesh=d.mesh("teeth", {"b": D_SIDE}, names=False), translation=[0, 0, -1])
    assert read_gltf(d.write(tmp_path / "u.glb")).shape_names == ["head_target_0", "teeth_target_0"]


def test_one_mesh_drawn_twice(tmp_path: Path) -> None:
    d = Doc()
    eye = d.mesh("eye", {"eyeLookUpLeft": D_UP})
    d.node(name="eye_L", mesh=eye, translation=[0.3, 0, 0])
    d.node(name="eye_R", mesh=eye, translation=[-0.3, 0, 0])
    face = read_gltf(d.write(tmp_path / "twice.glb"))
    assert face.group_names == ["eye_L", "eye_R"]
    np.testing.assert_allclose(face.vertices, np.concatenate([shift(0.3, 0, 0), shift(-0.3, 0, 0)]), atol=1e-7)
    np.testing.assert_array_equal(face.shapes[0][1], np.concatenate([D_UP, D_UP]))


def test_mesh_argument_reads_one_mesh_under_its_node(tmp_path: Path) -> None:
    d = Doc()
    d.node(name="Head", mesh=d.mesh("head", {"jawOpen": D_UP}))
    d.node(name="Teeth", mesh=d.mesh("teeth", {"jawOpen": D_SIDE}), translation=[0, 0, -0.5])
    p = d.write(tmp_path / "two.glb")
    teeth = read_gltf(p, mesh="teeth")
    np.testing.assert_allclose(teeth.vertices, shift(0, 0, -0.5), atol=1e-7)
    assert teeth.face_groups is None
    np.testing.assert_array_equal(read_gltf(p, mesh=0).vertices, V0)
    with pytest.raises(MeshFormatError, match=r"no mesh named 'tongue'"):
        read_gltf(p, mesh="tongue")


def test_only_the_default_scene_is_read(tmp_path: Path) -> None:
    d = Doc()
    d.node(mesh=d.mesh("a"))
    hidden = d.node(root=False, mesh=d.mesh("b", V=V0 + 1))
    d.j["scenes"].append({"nodes": [hidden]})
    p = d.write(tmp_path / "scenes.glb")
    np.testing.assert_array_equal(read_gltf(p).vertices, V0)
    d.j["scene"] = 1
    np.testing.assert_allclose(read_gltf(d.write(tmp_path / "scene1.glb")).vertices, V0 + 1)


def test_meshes_without_nodes_are_read_untransformed(tmp_path: Path) -> None:
    d = Doc()
    d.mesh("a")
    d.mesh("b", V=shift(0, 0, 1))
    d.j["nodes"], d.j["scenes"] = [], []
    del d.j["scene"]
    face = read_gltf(d.write(tmp_path / "nonodes.glb"))
    assert face.group_names == ["a", "b"] and face.n_vertices == 12


# ---- extensions ---------------------------------------------------------------------------


def test_texture_and_material_extensions_are_skipped_with_a_note(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    d = Doc()
    d.node(mesh=d.mesh("m"))
    d.j["extensionsRequired"] = ["KHR_texture_basisu", "KHR_materials_emissive_strength", "EXT_texture_webp"]
    with caplog.at_level(logging.WARNING, logger="workbench.io.gltf"):
        face = read_gltf(d.write(tmp_path / "tex.glb"))
    assert face.n_vertices == 6
    assert "tex.glb: skipped KHR_texture_basisu, KHR_materials_emissive_strength, EXT_texture_webp" in caplog.text


@pytest.mark.parametrize("ext", ["EXT_mesh_gpu_instancing", "KHR_gaussian_splatting", "FB_geometry_metadata"])
def test_geometry_extensions_we_do_not_read_are_refused(tmp_path: Path, ext: str) -> None:
    d = Doc()
    d.node(mesh=d.mesh("m"))
    d.j["extensionsRequired"] = [ext]
    with pytest.raises(MeshFormatError, match=rf"unsupported extensions \['{ext}'\]") as e:
        read_gltf(d.write(tmp_path / "x.glb"))
    assert e.value.field == "extensionsRequired"
