"""The paint palette: ExpressionGallery(expressions=True) with saved expressions (widgets/gallery.py)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pyvista")
pytest.importorskip("ipywidgets")

from widgets.gallery import ExpressionGallery, clear_thumbnail_cache
from workbench import BlendShape, FaceModel
from workbench.core.polygons import Polygons

pytestmark = pytest.mark.ui

SIZE = (32, 32)


def tetra_model() -> FaceModel:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    polys = Polygons.from_lists([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    up = np.zeros((4, 3))
    up[3] = [0, 0.5, 0]
    side = np.zeros((4, 3))
    side[1] = [0.5, 0, 0]
    return FaceModel(v, None, [BlendShape("up", up), BlendShape("side", side)], polygons=polys)


@pytest.fixture(autouse=True)
def _fresh_cache():
    clear_thumbnail_cache()
    yield
    clear_thumbnail_cache()


def test_saved_expressions_come_first_and_follow_the_model():
    m = tetra_model()
    g = ExpressionGallery(m, size=SIZE, expressions=True)
    assert g.names == ["up", "side"]
    tiles = dict(g._tiles)
    m.set_weight("up", 1.0)
    m.expressions.save("lifted")  # displacement == the "up" delta
    assert g.names == ["lifted", "up", "side"]
    _img, btn = g._cells["lifted"]
    assert btn.description == "★ lifted"
    # the same face gives the same picture as the blendshape's thumbnail
    assert g.thumbnails["lifted"] == g.thumbnails["up"]
    # tiles of names still shown are reused (no picture is sent again)
    assert g._tiles["up"] is tiles["up"] and g._tiles["side"] is tiles["side"]
    g.select("lifted")
    m.undo()  # the save is undone: the tile goes, the stale selection too
    assert g.names == ["up", "side"] and g.selected is None
    g.close()
    m.redo()
    assert g.names == ["up", "side"]  # a closed gallery no longer follows the model


def test_without_expressions_flag_saved_expressions_are_not_shown():
    m = tetra_model()
    m.expressions.save("rest")
    g = ExpressionGallery(m, size=SIZE)
    assert g.names == ["up", "side"]
    g2 = ExpressionGallery(m, size=SIZE, expressions=True, names=["side", "rest"])
    assert g2.names == ["side", "rest"]
    assert g2._cells["rest"][1].description == "★ rest"


def test_label_size_styles_the_name_buttons():
    g = ExpressionGallery(tetra_model(), size=SIZE, label_size="10px")
    assert g._cells["up"][1].style.font_size == "10px"
