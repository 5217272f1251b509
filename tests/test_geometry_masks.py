"""Part masks with named meanings and the face axes (``workbench.geometry.masks``, ``workbench.geometry.axes``)."""

from __future__ import annotations

import numpy as np
import pytest
from grid_meshes import grid_triangles

import workbench
from workbench.geometry.axes import AxesError, axis_vector, face_axes, head_axes
from workbench.geometry.masks import (
    MissingPartError,
    eyeball_mask,
    role_mask,
    skin_mask,
    skin_or_all_mask,
    skin_surface,
)
from workbench.model import FaceModel, ModelMetadata


def _two_parts(names: list[str]) -> FaceModel:
    """A 4 x 4 grid (vertices 0-15, component 0) and a separate triangle (16-18, component 1)."""
    xs, ys = np.meshgrid(np.arange(4.0), np.arange(4.0))
    grid = np.stack([xs.ravel(), ys.ravel(), np.zeros(16)], 1)
    tri = np.array([[10.0, 0.0, 0.0], [10.5, 0.0, 0.0], [10.0, 0.5, 0.0]])
    F = np.concatenate([grid_triangles(4), [[16, 17, 18]]])
    labels = np.r_[np.zeros(16, np.int32), np.ones(3, np.int32)]
    return FaceModel(np.concatenate([grid, tri]), F, component_labels=labels, component_names=names,
                     metadata=ModelMetadata(name="parts"))


def test_skin_by_role_and_the_two_meanings_without_skin() -> None:
    m = _two_parts(["face", "eyelashes"])  # "face" names a skin, "eyelashes" lashes
    skin = np.r_[np.ones(16, bool), np.zeros(3, bool)]
    np.testing.assert_array_equal(skin_mask(m), skin)
    np.testing.assert_array_equal(skin_or_all_mask(m), skin)
    np.testing.assert_array_equal(role_mask(m, {"lashes"}), ~skin)
    np.testing.assert_array_equal(role_mask(m, {"teeth", "tongue"}), np.zeros(19, bool))
    # no skin among the parts: skin_mask says so, skin_or_all_mask takes the whole mesh
    bare = _two_parts(["eye_left", "tongue"])
    with pytest.raises(MissingPartError, match=r"parts: no skin found among its parts \['eye_left', 'tongue'\]"):
        skin_mask(bare)
    with pytest.raises(MissingPartError, match="no skin"):
        skin_surface(bare)
    np.testing.assert_array_equal(skin_or_all_mask(bare), np.ones(19, bool))
    np.testing.assert_array_equal(eyeball_mask(bare), skin)  # the grid is named an eye here


def test_skin_surface_keeps_only_triangles_with_three_skin_corners() -> None:
    m = _two_parts(["skin", "lashes"])
    ids, faces = skin_surface(m)
    np.testing.assert_array_equal(ids, np.arange(16))
    np.testing.assert_array_equal(ids[faces], grid_triangles(4))
    # a triangle joining the skin to the lashes belongs to neither surface; a skin vertex on no
    # skin triangle (the grid's corner 15, once its triangles are gone) is left out
    F = np.concatenate([grid_triangles(4)[:-2], [[14, 16, 15]]])
    cut = FaceModel(m.vertices, F, component_labels=m.component_labels, component_names=m.component_names)
    ids, faces = skin_surface(cut)
    assert 15 not in ids and 14 in ids
    np.testing.assert_array_equal(ids[faces], grid_triangles(4)[:-2])


def test_skin_without_triangles_is_an_error() -> None:
    m = _two_parts(["skin", "lashes"])
    # every triangle of the grid replaced by one across the parts
    F = np.array([[0, 16, 17], [16, 17, 18]])
    cut = FaceModel(m.vertices, F, component_labels=m.component_labels, component_names=m.component_names,
                    metadata=ModelMetadata(name="cut"))
    with pytest.raises(MissingPartError, match="cut: the skin has no triangles"):
        skin_surface(cut)


def test_sample_head_masks() -> None:
    head = workbench.load_sample("head")
    by_name = head.component_labels == head.component_names.index("skin")
    np.testing.assert_array_equal(skin_mask(head), by_name)
    eyes = np.isin(head.component_labels, [head.component_names.index(n) for n in ("eye_left", "eye_right")])
    np.testing.assert_array_equal(eyeball_mask(head), eyes)


def test_axis_vector_by_hand() -> None:
    np.testing.assert_array_equal(axis_vector("+y"), [0, 1, 0])
    np.testing.assert_array_equal(axis_vector("-Z"), [0, 0, -1])
    np.testing.assert_array_equal(axis_vector("x"), [1, 0, 0])
    for bad in ("+w", "", "--x", "y+"):
        with pytest.raises(AxesError, match="expected an axis"):
            axis_vector(bad)


@pytest.mark.parametrize("up, front", [("+y", "+z"), ("+z", "-y"), ("-x", "+y"), ("+y", "-z")])
def test_face_axes_rows_are_left_up_front(up: str, front: str) -> None:
    R = face_axes(FaceModel(np.zeros((3, 3)), [[0, 1, 2]], metadata=ModelMetadata(up_axis=up, front_axis=front)))
    np.testing.assert_array_equal(R[1], axis_vector(up))
    np.testing.assert_array_equal(R[2], axis_vector(front))
    np.testing.assert_allclose(R @ R.T, np.eye(3))
    assert np.linalg.det(R) == pytest.approx(1.0)  # a rotation: left = up x front
    # +y up, +z front: the subject's left is +x
    np.testing.assert_array_equal(head_axes("+y", "+z"), np.eye(3))


def test_face_axes_refuse_parallel_axes() -> None:
    m = FaceModel(np.zeros((3, 3)), [[0, 1, 2]], metadata=ModelMetadata(name="odd", up_axis="+y", front_axis="-y"))
    with pytest.raises(AxesError, match="odd: metadata up_axis '\\+y' and front_axis '-y' are not perpendicular"):
        face_axes(m)
