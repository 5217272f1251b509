"""Part roles of mesh components, from names or geometry, and the tools they drive (issue 15, item 5)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

import workbench
from workbench.geometry.parts import (
    ATTACHED_ROLES,
    RIGID_ROLES,
    ROLES,
    component_roles,
    part_material,
    role_from_name,
)
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.handles.shell import ShellDeformer
from workbench.methods.regions.segmentation import segment_blend_regions
from workbench.model import FaceModel, ModelMetadata

SAMPLE_ROLES = ("skin", "tongue", "lashes", "lashes", "eyeball_left", "eyeball_right", "teeth_lower", "teeth_upper")


@pytest.fixture(scope="module")
def head() -> FaceModel:
    return workbench.load_sample("head")


def unnamed(base: FaceModel, vertices: np.ndarray | None = None, faces: np.ndarray | None = None,
            metadata: ModelMetadata | None = None) -> FaceModel:
    """The sample as an exporter without part names ships it: components "mesh_0", "mesh_1", ..."""
    return FaceModel(base.vertices if vertices is None else vertices, base.faces if faces is None else faces,
                     base.shapes, component_labels=base.component_labels,
                     component_names=[f"mesh_{i}" for i in range(len(base.component_names))],
                     metadata=base.metadata if metadata is None else metadata)


def retriangulated(base: FaceModel) -> np.ndarray:
    """Every quad of the sample split along its other diagonal."""
    sizes = np.diff(base.polygons.offsets)
    assert (sizes == 4).all()
    q = np.asarray(base.polygons.indices).reshape(-1, 4)
    return np.concatenate([q[:, [0, 1, 3]], q[:, [1, 2, 3]]])


def warp(V: np.ndarray, asymmetric: bool = False) -> np.ndarray:
    """A smooth non-rigid warp: a wider forehead, a wavy profile, a deeper face (optionally lopsided)."""
    W = V.copy()
    W[:, 0] = V[:, 0] * (1.0 + 0.08 * (V[:, 1] - V[:, 1].mean()))
    W[:, 1] = V[:, 1] + 0.05 * np.sin(2.0 * V[:, 2])
    W[:, 2] = V[:, 2] * 1.07 + (0.03 * V[:, 0] if asymmetric else 0.0)
    return W


# ------------------------------------------------------------------ names
@pytest.mark.parametrize(
    ("name", "role"),
    [
        ("skin", "skin"), ("Head_geo", "skin"), ("eye_left", "eyeball_left"), ("EyeRight", "eyeball_right"),
        ("eye_R", "eyeball_right"), ("Eyes", "eyeball"), ("cornea_l", "eyeball_left"),
        ("eyelashes_left", "lashes"), ("Lashes.001", "lashes"), ("eyebrows", "brows"), ("beard", "hair"),
        ("teeth_upper", "teeth_upper"), ("TeethBottom", "teeth_lower"), ("lower_gums", "teeth_lower"),
        ("teeth", "teeth"), ("Tongue", "tongue"), ("mesh_3", None), ("component_0", None), ("Object.001", None),
    ],
)
def test_role_from_name(name: str, role: str | None) -> None:
    assert role_from_name(name) == role


def test_role_tables_are_consistent() -> None:
    assert RIGID_ROLES | ATTACHED_ROLES | {"skin"} == set(ROLES)
    assert not RIGID_ROLES & ATTACHED_ROLES
    assert part_material("eyeball_right") == "eye" and part_material("teeth_upper", "gums_upper") == "gums"
    assert part_material("other") == part_material("skin") == "skin"


# ------------------------------------------------------------------ the sample and its variants
def test_sample_roles_from_names(head: FaceModel) -> None:
    assert head.part_roles == SAMPLE_ROLES
    assert head.part_roles is head.part_roles  # computed once per mesh


def test_sample_roles_with_names_blanked(head: FaceModel) -> None:
    assert unnamed(head).part_roles == SAMPLE_ROLES
    # partly named, the rest by geometry; a name that says nothing never wins over the geometry
    names = ["head", "mouth", "x", "y", "Eyes", "Object", "a", "b"]
    roles = component_roles(head.vertices, head.faces, head.component_labels, names, head.metadata)
    assert tuple(roles) == SAMPLE_ROLES


@pytest.mark.parametrize("asymmetric", [False, True])
def test_sample_roles_on_a_warped_retriangulated_variant(head: FaceModel, asymmetric: bool) -> None:
    m = unnamed(head, warp(head.vertices, asymmetric), retriangulated(head))
    assert m.part_roles == SAMPLE_ROLES


@pytest.mark.parametrize("seed", [4, 5, 18])
def test_roles_of_foreign_faces_with_lopsided_busts_and_rolled_heads(head: FaceModel, seed: int) -> None:
    # foreign faces whose bust made the skin's box lopsided (both eyes "left", teeth and tongue
    # "other" when the mid-plane came from the box) or whose 10° roll moved the mouth off the eyes' middle
    from workbench.testing import foreign_face

    face = foreign_face(head, seed=seed).model
    want = {"skin": 1, "tongue": 1, "lashes": 2, "eyeball_left": 1, "eyeball_right": 1, "teeth_lower": 1,
            "teeth_upper": 1}
    roles = face.part_roles
    assert {r: roles.count(r) for r in set(roles)} == want, roles
    lab, V = face.component_labels, face.vertices
    left, right = (V[lab == roles.index(r)].mean(0) for r in ("eyeball_left", "eyeball_right"))
    assert left[0] > right[0]  # the subject's left is +x on these faces (their metadata's frame)


def test_sample_roles_in_another_frame_and_mirrored(head: FaceModel) -> None:
    V = head.vertices
    # Blender's frame: +z up, the face toward -y; the subject's left stays +x
    Vb = np.c_[V[:, 0], -V[:, 2], V[:, 1]]
    meta = dataclasses.replace(head.metadata, up_axis="+z", front_axis="-y")
    names = [f"o{i}" for i in range(8)]
    assert tuple(component_roles(Vb, head.faces, head.component_labels, names, meta)) == SAMPLE_ROLES
    # mirrored in x: the eyes swap sides
    Vm = V * np.array([-1.0, 1.0, 1.0])
    roles = component_roles(Vm, head.faces[:, ::-1], head.component_labels, names, head.metadata)
    assert roles[4:6] == ["eyeball_right", "eyeball_left"]


# ------------------------------------------------------------------ a hand-made scene
def _scene() -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """A face-like sheet with two eyeballs, a lash strip, a teeth arch, a tongue box and a stray box."""
    parts: list[tuple[np.ndarray, np.ndarray, str]] = []
    # skin: a 2 x 3 sheet bulging toward +z (a mask), open
    n = 41
    xs, ys = np.meshgrid(np.linspace(-1.0, 1.0, n), np.linspace(-1.5, 1.5, int(1.5 * n)))
    zs = 0.6 * np.cos(0.7 * xs) * np.cos(0.45 * ys)
    V = np.c_[xs.ravel(), ys.ravel(), zs.ravel()]
    rows, cols = xs.shape
    j, i = np.divmod(np.arange((rows - 1) * (cols - 1)), cols - 1)
    a = j * cols + i
    F = np.concatenate([np.c_[a, a + 1, a + cols + 1], np.c_[a, a + cols + 1, a + cols]])
    parts.append((V, F, "skin"))
    # eyeballs: spheres behind the sheet at eye height
    for x, role in ((0.35, "eyeball_left"), (-0.35, "eyeball_right")):
        s = trimesh.creation.icosphere(subdivisions=2, radius=0.15)
        parts.append((np.asarray(s.vertices) + np.array([x, 0.45, 0.45]), np.asarray(s.faces), role))
    # lashes: a thin curved strip over the left eye's front
    t = np.linspace(-0.9, 0.9, 12)
    top = np.c_[0.35 + 0.17 * np.sin(t), 0.45 + 0.1 * np.cos(t), 0.45 + 0.12 * np.cos(t)]
    bot = top + np.array([0.0, 0.03, 0.02])
    Vl = np.vstack([top, bot])
    k = np.arange(11)
    Fl = np.concatenate([np.c_[k, k + 1, k + 13], np.c_[k, k + 13, k + 12]])
    parts.append((Vl, Fl, "lashes"))
    # teeth: an open U-shaped arch behind the lips, centred on the mid-plane
    ang = np.linspace(-np.pi / 2, np.pi / 2, 15)
    ring = np.c_[0.22 * np.sin(ang), np.zeros_like(ang), 0.3 + 0.18 * np.cos(ang)]
    Vt = np.vstack([ring + np.array([0, -0.35, 0]), ring + np.array([0, -0.28, 0])])
    k = np.arange(14)
    Ft = np.concatenate([np.c_[k, k + 1, k + 16], np.c_[k, k + 16, k + 15]])
    parts.append((Vt, Ft, "teeth"))
    # tongue: a solid box below the teeth
    b = trimesh.creation.box(extents=[0.25, 0.1, 0.3])
    parts.append((np.asarray(b.vertices) + np.array([0, -0.45, 0.25]), np.asarray(b.faces), "tongue"))
    # a stray box far off the face (a hat button): other
    b2 = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    parts.append((np.asarray(b2.vertices) + np.array([0.8, 1.4, 0.2]), np.asarray(b2.faces), "other"))
    Vs, Fs, labels, roles = [], [], [], []
    off = 0
    for c, (Vp, Fp, role) in enumerate(parts):
        Vs.append(Vp)
        Fs.append(Fp + off)
        labels.append(np.full(len(Vp), c))
        roles.append(role)
        off += len(Vp)
    return np.vstack(Vs), np.vstack(Fs), np.concatenate(labels), roles


def test_hand_made_scene_roles_by_geometry() -> None:
    V, F, labels, expected = _scene()
    names = [f"part{i}" for i in range(len(expected))]
    assert component_roles(V, F, labels, names) == expected
    # names win where they say something
    named = list(names)
    named[5] = "Tongue"
    named[6] = "eyelashes_R"
    roles = component_roles(V, F, labels, named)
    assert roles[5] == "tongue" and roles[6] == "lashes" and roles[:5] == expected[:5]


def test_bad_inputs_name_the_argument() -> None:
    V, F, labels, _ = _scene()
    with pytest.raises(ValueError, match="labels"):
        component_roles(V, F, labels[:-1], ["a"] * 7)
    with pytest.raises(ValueError, match="names"):
        component_roles(V, F, labels, ["a"] * 3)
    assert component_roles(V[:3], [[0, 1, 2]], np.zeros(3, int), ["solo"]) == ["skin"]


# ------------------------------------------------------------------ the roles drive the tools
def _eyeball_drift(model: FaceModel) -> float:
    """Largest eyeball displacement (model units) for a 1 cm raise of the left brow handle."""
    model.handles.set(default_face_handles(model))
    cm = 0.01 / model.metadata.metres_per_unit
    model.move_handle(model.handles.names.index("brows_L_2"), [0.0, cm, 0.0])
    d = model.handles.displacement()
    eyes = np.isin(model.component_labels, [i for i, r in enumerate(model.part_roles) if r.startswith("eyeball")])
    return float(np.abs(d[eyes]).max())


def test_eyeball_drift_on_an_unnamed_rig_equals_the_named_rig(head: FaceModel) -> None:
    named = FaceModel(head.vertices, head.faces, head.shapes, component_labels=head.component_labels,
                      component_names=head.component_names, metadata=head.metadata)
    drift_named = _eyeball_drift(named)
    drift_unnamed = _eyeball_drift(unnamed(head))
    assert abs(drift_unnamed - drift_named) <= 1e-6
    assert drift_named == 0.0  # eyeballs are attached to the skull ("fixed")
    # what unnamed parts did before roles: "rigid", the eyeballs following the brow
    d = ShellDeformer(head.vertices, head.faces, named.handles.vertices, component_labels=head.component_labels,
                      component_roles=["skin"] + ["other"] * 7)
    u = d.displacement(named.handles.offsets)
    eyes = np.isin(head.component_labels, [4, 5])
    assert np.abs(u[eyes]).max() * head.metadata.metres_per_unit > 1e-4  # 0.19 mm


def test_shell_policies_come_from_roles(head: FaceModel) -> None:
    m = unnamed(head)
    m.handles.set(default_face_handles(m))
    policies = m.handles.deformer().policies_
    assert policies == {"mesh_1": "rigid", "mesh_2": "follow", "mesh_3": "follow", "mesh_4": "fixed",
                        "mesh_5": "fixed", "mesh_6": "rigid", "mesh_7": "fixed"}


def test_region_kinds_and_names_of_unnamed_parts_match_the_named_rig(head: FaceModel) -> None:
    a = segment_blend_regions(head, 0.25)
    b = segment_blend_regions(unnamed(head), 0.25)
    assert a.names == b.names and a.kinds == b.kinds
    for x, y in zip(a.labels, b.labels, strict=True):
        np.testing.assert_array_equal(x, y)
    rigid = {nm for nm, k in zip(a.names[0], a.kinds[0], strict=True) if k == "rigid"}
    assert rigid == {"eyeball_L", "eyeball_R", "teeth_lower", "teeth_upper", "tongue"}


def test_render_colours_of_unnamed_eyes_are_not_skin(head: FaceModel) -> None:
    render = pytest.importorskip("widgets.render")
    named = render.vertex_colors(head)
    blank = render.vertex_colors(unnamed(head))
    np.testing.assert_array_equal(named, blank)
    eyes = np.isin(head.component_labels, [4, 5])
    assert not (blank[eyes] == render.COMPONENT_COLORS["skin"]).all(axis=1).any()
    assert (blank[eyes] == render.COMPONENT_COLORS["eye"]).all(axis=1).any()


def test_viewport_colours_of_unnamed_eyes_are_not_skin(head: FaceModel) -> None:
    viewport = pytest.importorskip("widgets.viewport")
    vp = viewport.Viewport(unnamed(head))
    assert vp._component_materials == ["skin", "tongue", "eyelashes", "eyelashes", "eye", "eye", "teeth", "teeth"]
    assert viewport.Viewport(head)._component_materials == vp._component_materials
