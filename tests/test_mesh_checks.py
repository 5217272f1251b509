"""Mesh validation and component labelling on tiny hand-made meshes."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import (
    MeshFormatError,
    check_faces,
    check_vertices,
    label_components,
)

# unit square split in two quads: 0-1-2 / 3-4-5 grid
GRID_V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], dtype=float)
GRID_QUADS = [[0, 1, 4, 3], [1, 2, 5, 4]]


def test_check_vertices_accepts_and_converts() -> None:
    out = check_vertices([[0, 1, 2]], "a.obj", "v")
    assert out.dtype == np.float64 and out.shape == (1, 3)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_check_vertices_names_file_field_and_row(bad: float) -> None:
    V = GRID_V.copy()
    V[4, 1] = bad
    with pytest.raises(MeshFormatError) as exc:
        check_vertices(V, "/tmp/x/head.obj", "POSITION")
    assert exc.value.source == "/tmp/x/head.obj"
    assert exc.value.field == "POSITION"
    msg = str(exc.value)
    assert msg.startswith("head.obj: POSITION: row 4 is not finite")


def test_check_vertices_reports_line_number_when_given() -> None:
    V = GRID_V.copy()
    V[2, 0] = np.nan
    with pytest.raises(MeshFormatError, match=r"head.obj: line 13: row 2 is not finite"):
        check_vertices(V, "head.obj", "v", line_numbers=np.arange(6) + 11)


def test_check_vertices_wrong_shape() -> None:
    with pytest.raises(MeshFormatError, match=r"expected an \(n, 3\) array, got shape \(4, 2\)"):
        check_vertices(np.zeros((4, 2)), "a.glb", "POSITION")


def test_check_faces_accepts_quads_and_triangles() -> None:
    P = check_faces(Polygons.from_lists(GRID_QUADS), 6, "a.obj", vertices=GRID_V)
    assert len(P) == 2
    P = check_faces(np.array([[0, 1, 4], [0, 4, 3]]), 6, "a.obj", vertices=GRID_V)
    assert P.sizes.tolist() == [3, 3]


def test_out_of_range_index_message() -> None:
    with pytest.raises(MeshFormatError) as exc:
        check_faces(Polygons.from_lists([[0, 1, 4, 3], [1, 2, 9001, 4]]), 6, "head.obj")
    assert str(exc.value) == "head.obj: f: face 1 index 9001 out of range (file has 6 vertices)"
    assert exc.value.field == "f"


def test_out_of_range_index_with_lines() -> None:
    with pytest.raises(MeshFormatError, match=r"^head.obj: line 123: face 1 index -1 out of range"):
        check_faces(
            Polygons.from_lists([[0, 1, 4], [1, -1, 4]]), 6, "head.obj", line_numbers=[7, 123]
        )


def test_repeated_corner() -> None:
    with pytest.raises(
        MeshFormatError, match=r"face 1 uses vertex 4 more than once \(\[1, 4, 2, 4\]\)"
    ):
        check_faces(Polygons.from_lists([[0, 1, 4, 3], [1, 4, 2, 4]]), 6, "a.obj")


def test_duplicate_face_same_vertex_set_any_order() -> None:
    with pytest.raises(MeshFormatError, match=r"face 2 \[4, 3, 0, 1\] duplicates face 0"):
        check_faces(Polygons.from_lists([*GRID_QUADS, [4, 3, 0, 1]]), 6, "a.obj")


def test_triangles_sharing_vertices_are_not_duplicates_of_quads() -> None:
    # a triangle whose corners are a subset of a quad's is a different face
    check_faces(Polygons.from_lists([[0, 1, 4, 3], [0, 1, 4]]), 6, "a.obj")


def test_zero_area_triangle_and_quad() -> None:
    V = GRID_V.copy()
    with pytest.raises(MeshFormatError, match=r"face 1 \[0, 1, 2\] has zero area"):
        check_faces(Polygons.from_lists([[0, 1, 4], [0, 1, 2]]), 6, "a.obj", vertices=V)
    V[4] = V[1]  # two coincident corners: triangle 0-1-4 has no area
    with pytest.raises(MeshFormatError, match=r"face 0 \[0, 1, 4\] has zero area"):
        check_faces(Polygons.from_lists([[0, 1, 4], [3, 5, 2]]), 6, "a.obj", vertices=V)


def test_zero_area_is_scale_invariant() -> None:
    tiny = GRID_V * 1e-9
    check_faces(Polygons.from_lists(GRID_QUADS), 6, "a.obj", vertices=tiny)


def test_giant_ngon_uses_slow_path_with_same_result() -> None:
    n = 8000
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = np.stack([np.cos(t), np.sin(t), np.zeros(n)], axis=1)
    polys = [list(range(n))] + [[i, i + 1, (i + 2)] for i in range(0, 6400, 1)]
    P = check_faces(Polygons.from_lists(polys), n, "disc.obj", vertices=V)
    assert len(P) == 6401
    polys.append([2, 1, 0])
    with pytest.raises(MeshFormatError, match="face 6401 duplicates face 1"):
        check_faces(Polygons.from_lists(polys), n, "disc.obj")


def test_label_components_names_groups_and_skin() -> None:
    # skin: two quads (6 vertices); eye: one triangle; loose piece: one triangle; vertex 12 unused
    V = np.zeros((13, 3))
    polys = Polygons.from_lists([[0, 1, 4, 3], [1, 2, 5, 4], [6, 7, 8], [9, 10, 11]])
    groups = np.array([-1, -1, 0, -1])
    labels, names = label_components(polys, len(V), groups, ["eye_left"])
    assert names == ["skin", "eye_left", "component_1", "component_2"]
    assert labels.dtype == np.int32
    assert labels.tolist() == [0] * 6 + [1] * 3 + [2] * 3 + [3]


def test_label_components_merges_pieces_of_one_group() -> None:
    # two separate lash strands in group "lashes" become one part
    polys = Polygons.from_lists([[0, 1, 2], [3, 4, 5], [6, 7, 8, 9]])
    labels, names = label_components(polys, 10, [0, 0, 1], ["lashes", "skin"])
    assert names == ["lashes", "skin"]
    assert labels.tolist() == [0] * 6 + [1] * 4


def test_label_components_component_spanning_groups_is_not_named_after_one() -> None:
    polys = Polygons.from_lists([[0, 1, 2], [1, 2, 3]])
    labels, names = label_components(polys, 4, [0, 1], ["a", "b"])
    assert names == ["skin"] and labels.tolist() == [0, 0, 0, 0]


def test_label_components_without_groups_and_with_triangles() -> None:
    labels, names = label_components(np.array([[0, 1, 2], [3, 4, 5], [5, 4, 6]]), 7)
    assert names == ["skin", "component_1"]
    assert labels.tolist() == [1, 1, 1, 0, 0, 0, 0]


def test_label_components_skin_name_taken_by_group() -> None:
    polys = Polygons.from_lists([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    _, names = label_components(polys, 9, [0, -1, -1], ["skin"])
    assert names == ["skin", "component_1", "component_2"]
