"""Offscreen rendering and the pyvista bridge (widgets/render.py).

Image-regression tests compare small renders of a hand-built mesh with PNG
baselines in tests/ui/baselines/. Regenerate them after an intended visual
change with ``FW_UPDATE_BASELINES=1 pytest tests/ui/test_render.py`` and look
at the new pictures before committing them. A missing baseline fails under
CI=true (it is never written silently there); elsewhere it is written and the
test is skipped so a developer sees it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from ci_env import in_ci

pv = pytest.importorskip("pyvista")
PIL_Image = pytest.importorskip("PIL.Image")

from widgets.render import (  # noqa: E402
    COMPONENT_COLORS,
    expression_thumbnails,
    from_pyvista,
    png_to_array,
    render_png,
    screen_positions,
    to_pyvista,
)
from widgets.rendering.convert import polygon_cell_array as _polygon_cell_array  # noqa: E402
from workbench import BlendShape, FaceModel, ModelMetadata, load_sample  # noqa: E402
from workbench.core.polygons import Polygons  # noqa: E402
from workbench.geometry.normals import vertex_normals  # noqa: E402

pytestmark = pytest.mark.ui

BASELINES = Path(__file__).parent / "baselines"
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "ui"
# mean |difference| over all pixels and channels, 0-255 scale: absorbs
# rasteriser/driver rounding, catches any change in framing, colour or shading
TOLERANCE = 1.5


def tetra_and_quad(up_axis: str = "+y", front_axis: str = "+z", rotate=None) -> FaceModel:
    """A tetrahedron ("skin") beside a unit quad ("teeth_upper") facing +z."""
    v = np.array(
        [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.5, 0.0, 0.0],
            [2.5, 0.0, 0.0],
            [2.5, 1.0, 0.0],
            [1.5, 1.0, 0.0],
        ]
    )
    if rotate is not None:
        v = v @ np.asarray(rotate).T
    polys = Polygons.from_lists([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [4, 5, 6, 7]])
    lift = np.zeros((8, 3))
    lift[3] = [0.0, 0.5, 0.0]  # the tetra apex moves up
    return FaceModel(
        v,
        None,
        [BlendShape("lift", lift)],
        polygons=polys,
        component_labels=[0, 0, 0, 0, 1, 1, 1, 1],
        component_names=["skin", "teeth_upper"],
        metadata=ModelMetadata(name="tiny", up_axis=up_axis, front_axis=front_axis),
    )


def mean_abs_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.int16) - b.astype(np.int16)).mean())


def check_baseline(name: str, png: bytes) -> None:
    path = BASELINES / f"{name}.png"
    if os.environ.get("FW_UPDATE_BASELINES") == "1":
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(png)
        return
    if not path.exists():
        if in_ci():
            pytest.fail(f"baseline {path} is missing; create it with FW_UPDATE_BASELINES=1")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(png)
        pytest.skip(f"baseline {path} was missing and has been written; look at it")
    got, want = png_to_array(png), png_to_array(path.read_bytes())
    assert got.shape == want.shape, f"{name}: size {got.shape} != baseline {want.shape}"
    diff = mean_abs_diff(got, want)
    if diff > TOLERANCE:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        (ARTIFACTS / f"{name}.actual.png").write_bytes(png)
        delta = np.abs(got.astype(np.int16) - want.astype(np.int16)).max(axis=2)
        PIL_Image.fromarray(np.clip(delta * 4, 0, 255).astype(np.uint8)).save(
            ARTIFACTS / f"{name}.diff.png"
        )
    assert diff <= TOLERANCE, (
        f"{name}: mean abs pixel difference {diff:.2f} > {TOLERANCE}; actual and diff "
        f"images written to {ARTIFACTS}"
    )


# --------------------------------------------------------------------- hand-worked


def test_polygon_cell_array_hand_case():
    out = _polygon_cell_array(np.array([0, 1, 2, 0, 2, 3, 4]), np.array([0, 3, 7]))
    assert out.tolist() == [3, 0, 1, 2, 4, 0, 2, 3, 4]


def test_vertex_normals_of_flat_square_point_up_and_isolated_vertex_is_zero():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 5, 5]], float)
    n = vertex_normals(v, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(n[:4], [[0, 0, 1]] * 4)
    np.testing.assert_array_equal(n[4], [0, 0, 0])


def test_to_pyvista_keeps_quads_or_triangles_and_component_labels():
    m = tetra_and_quad()
    tri = to_pyvista(m)
    assert tri.n_cells == 6  # 4 tetra faces + the quad as 2 triangles
    quads = to_pyvista(m, polygons=True)
    assert quads.n_cells == 5
    assert sorted(len(f) for f in quads.irregular_faces) == [3, 3, 3, 3, 4]
    np.testing.assert_array_equal(quads.point_data["component"], m.component_labels)
    assert list(quads.field_data["component_names"]) == ["skin", "teeth_upper"]


def test_to_pyvista_rejects_wrong_point_count():
    with pytest.raises(ValueError, match=r"\(8, 3\)"):
        to_pyvista(tetra_and_quad(), points=np.zeros((7, 3)))


def test_from_pyvista_triangulates_and_records_provenance():
    m = from_pyvista(pv.Plane(i_resolution=2, j_resolution=1), name="plane")
    assert len(m.polygons) == 2 and m.faces.shape == (4, 3)
    assert m.shape_names == []
    assert m.metadata.name == "plane"
    assert m.metadata.provenance[-1]["source"] == "pyvista"


# -------------------------------------------------------------------- tiny renders


@pytest.mark.parametrize("camera", ["front", "three_quarter"])
def test_tiny_mesh_matches_baseline(camera):
    check_baseline(f"tiny_{camera}", render_png(tetra_and_quad(), size=(96, 96), camera=camera))


def test_tiny_mesh_scalars_match_baseline():
    m = tetra_and_quad()
    png = render_png(m, size=(96, 96), scalars=m.vertices[:, 0], cmap="viridis")
    check_baseline("tiny_scalars_x", png)


def test_tiny_render_background_component_colour_and_scalar_gradient():
    m = tetra_and_quad()
    size = (96, 96)
    img = png_to_array(render_png(m, size=size))
    assert img.shape == (96, 96, 3)
    np.testing.assert_array_equal(img[0, 0], [255, 255, 255])  # background corner
    col, row = screen_positions(m, [[2.0, 0.5, 0.0]], size=size)[0].astype(int)
    quad = img[row, col].astype(int)
    teeth = np.array(COMPONENT_COLORS["teeth"])
    # lit teeth colour: same hue (channel order R >= G >= B) and not background
    assert quad[0] >= quad[1] >= quad[2] and quad.tolist() != [255, 255, 255]
    assert np.all(quad <= teeth + 40)
    # viridis over x: left end of the quad purple/blue-ish, right end yellow
    sc = png_to_array(render_png(m, size=size, scalars=m.vertices[:, 0], cmap="viridis"))
    (cl, rl), (cr, rr) = screen_positions(m, [[1.55, 0.5, 0], [2.45, 0.5, 0]], size=size)
    left, right = sc[int(rl), int(cl)].astype(int), sc[int(rr), int(cr)].astype(int)
    assert right[0] > left[0] and right[1] > left[1]  # toward yellow
    assert right[2] < right[1]  # yellow has little blue


def test_up_and_front_axes_come_from_metadata():
    # Rotating the mesh by +90 degrees about x turns +y into +z and +z into -y;
    # with matching metadata the picture must not change.
    rot = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    a = png_to_array(render_png(tetra_and_quad(), size=(96, 96), camera="three_quarter"))
    b = png_to_array(
        render_png(tetra_and_quad("+z", "-y", rotate=rot), size=(96, 96), camera="three_quarter")
    )
    assert mean_abs_diff(a, b) < 0.5


def test_weights_render_without_changing_the_model():
    m = tetra_and_quad()
    lifted = png_to_array(render_png(m, {"lift": 1.0}, size=(64, 64)))
    assert m.weights["lift"] == 0.0
    assert mean_abs_diff(lifted, png_to_array(render_png(m, size=(64, 64)))) > 0.5
    m.set_weight("lift", 1.0)  # weights=None shows the model's own state
    np.testing.assert_array_equal(png_to_array(render_png(m, size=(64, 64))), lifted)


def test_bad_arguments_are_named():
    m = tetra_and_quad()
    with pytest.raises(KeyError, match="nope"):
        render_png(m, {"nope": 1.0})
    with pytest.raises(ValueError, match="camera"):
        render_png(m, camera="top")
    with pytest.raises(ValueError, match="rows"):
        render_png(m, scalars=np.zeros(3))


def test_thumbnail_from_shared_plotter_equals_fresh_render():
    m = tetra_and_quad()
    thumbs = expression_thumbnails(m, size=(48, 48), progress=False)
    assert list(thumbs) == ["lift"]
    fresh = render_png(m, {"lift": 1.0}, size=(48, 48), camera="face")
    np.testing.assert_array_equal(png_to_array(thumbs["lift"]), png_to_array(fresh))


# ------------------------------------------------------------------- sample head


@pytest.fixture(scope="module")
def head():
    return load_sample("head")


def test_head_round_trip_through_pyvista_keeps_vertices_and_faces(head):
    back = from_pyvista(to_pyvista(head, polygons=True), name="rt")
    np.testing.assert_array_equal(back.vertices, head.vertices)
    assert back.polygons.equals(head.polygons)
    np.testing.assert_array_equal(back.faces, head.polygons.triangulate()[0])
    np.testing.assert_array_equal(back.component_labels, head.component_labels)
    assert list(back.component_names) == list(head.component_names)
    tri = from_pyvista(to_pyvista(head))
    np.testing.assert_array_equal(tri.vertices, head.vertices)
    np.testing.assert_array_equal(tri.faces, head.faces)


def test_head_renders_are_deterministic(head):
    assert render_png(head, size=(96, 96)) == render_png(head, size=(96, 96))


def test_head_jaw_open_changes_mouth_pixels_not_forehead(head):
    size = (160, 160)
    neutral = png_to_array(render_png(head, size=size))
    jaw = png_to_array(render_png(head, {"jawOpen": 1.0}, size=size))
    v = head.vertices
    delta = np.linalg.norm(head.shape("jawOpen").delta, axis=1)
    skin = head.component_labels == head.component_names.index("skin")

    # mouth: where the most-moved skin vertices (lower lip, chin) were drawn
    moved = skin & (delta > 0.5 * delta[skin].max())
    cols_rows = screen_positions(head, v[moved], size=size).astype(int)
    mouth = [
        mean_abs_diff(neutral[r - 2 : r + 3, c - 2 : c + 3], jaw[r - 2 : r + 3, c - 2 : c + 3])
        for c, r in cols_rows
    ]
    assert np.median(mouth) > 20, mouth

    # forehead: the frontmost still skin vertex on the midline, in a band above the eyes
    eye_ids = [head.component_names.index(n) for n in ("eye_left", "eye_right")]
    eye_top = v[np.isin(head.component_labels, eye_ids), 1].max()
    height = np.ptp(v[skin, 1])
    band = (v[:, 1] > eye_top + 0.15 * height) & (v[:, 1] < eye_top + 0.3 * height)
    midline = np.abs(v[:, 0]) < 0.05 * np.ptp(v[skin, 0])
    candidates = np.flatnonzero(skin & (delta == 0) & band & midline)
    forehead = v[candidates[np.argmax(v[candidates, 2])]]
    c, r = screen_positions(head, [forehead], size=size)[0].astype(int)
    patch_n, patch_j = neutral[r - 4 : r + 5, c - 4 : c + 5], jaw[r - 4 : r + 5, c - 4 : c + 5]
    assert not np.all(patch_n == 255), "forehead probe landed on the background"
    assert mean_abs_diff(patch_n, patch_j) < 1.0


def test_model_methods_convert_through_pyvista(head):
    """``FaceModel.to_pyvista`` / ``from_pyvista`` are the widgets.render converters."""
    X = head.evaluate()
    mesh = head.to_pyvista(X, polygons=True)
    np.testing.assert_array_equal(np.asarray(mesh.points), np.asarray(X, np.float64))
    np.testing.assert_array_equal(np.asarray(mesh.point_data["component"]), head.component_labels)
    back = FaceModel.from_pyvista(mesh, name="rt")
    assert isinstance(back, FaceModel)
    assert back.polygons.equals(head.polygons)
    np.testing.assert_array_equal(back.vertices, np.asarray(X, np.float32))
