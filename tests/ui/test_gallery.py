"""Expression gallery widget (widgets/gallery.py): selection and thumbnail cache."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pyvista")
pytest.importorskip("ipywidgets")

import widgets.gallery as gallery_mod
from widgets.gallery import ExpressionGallery, cached_thumbnails, clear_thumbnail_cache
from widgets.render import png_to_array
from workbench import BlendShape, FaceModel
from workbench.core.polygons import Polygons

pytestmark = pytest.mark.ui

SIZE = (32, 32)


def tetra_model() -> FaceModel:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    polys = Polygons.from_lists([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])

    def moving(i, d):
        delta = np.zeros((4, 3))
        delta[i] = d
        return delta

    shapes = [
        BlendShape("up", moving(3, [0, 0.5, 0])),
        BlendShape("out", moving(3, [0, 0, 0.5])),
        BlendShape("side", moving(1, [0.5, 0, 0])),
    ]
    return FaceModel(v, None, shapes, polygons=polys)


@pytest.fixture
def counting(monkeypatch):
    """Count the shapes the gallery actually renders."""
    clear_thumbnail_cache()
    rendered: list[str] = []
    real = gallery_mod.expression_thumbnails

    def spy(model, names, **kw):
        rendered.extend(names)
        return real(model, names, **kw)

    monkeypatch.setattr(gallery_mod, "expression_thumbnails", spy)
    yield rendered
    clear_thumbnail_cache()


def test_gallery_shows_every_shape_in_model_order(counting):
    g = ExpressionGallery(tetra_model(), size=SIZE, columns=2)
    assert g.names == ["up", "out", "side"]
    assert len(g._grid.children) == 3
    assert png_to_array(g.thumbnails["up"]).shape == (32, 32, 3)
    # different expressions give different pictures
    assert g.thumbnails["up"] != g.thumbnails["side"]


def test_click_selects_and_callbacks_fire(counting):
    g = ExpressionGallery(tetra_model(), size=SIZE)
    seen = []
    g.on_select(seen.append)
    g._cells["out"][1].click()
    assert g.selected == "out"
    assert g._cells["out"][1].button_style == "info"
    assert g._cells["up"][1].button_style == ""
    g.select(None)
    assert seen == ["out", None]
    g.on_select(seen.append, remove=True)
    g.select("up")
    assert seen == ["out", None]
    with pytest.raises(KeyError, match="nope"):
        g.select("nope")


def test_thumbnails_are_cached_per_shape_and_delta(counting):
    m = tetra_model()
    ExpressionGallery(m, size=SIZE)
    assert sorted(counting) == ["out", "side", "up"]
    counting.clear()
    ExpressionGallery(m, size=SIZE)  # same shapes: nothing rendered
    assert counting == []
    cached_thumbnails(m, ["up"], size=(40, 40))  # other size: rendered again
    assert counting == ["up"]


def test_shape_edits_rerender_only_changed_shapes_and_drop_stale_selection(counting):
    m = tetra_model()
    g = ExpressionGallery(m, size=SIZE)
    g.select("side")
    counting.clear()
    m.remove_shape("side")
    assert g.names == ["up", "out"]
    assert g.selected is None
    assert counting == []  # the remaining thumbnails came from the cache
    new = np.zeros((4, 3))
    new[2] = [0.0, 0.3, 0.0]
    m.add_shape("new", new)
    assert g.names == ["up", "out", "new"]
    assert counting == ["new"]
    g.close()
    m.remove_shape("new")  # a closed gallery no longer follows the model
    assert g.names == ["up", "out", "new"]


def test_fixed_names_subset(counting):
    g = ExpressionGallery(tetra_model(), size=SIZE, names=["side", "up"])
    assert g.names == ["side", "up"]
