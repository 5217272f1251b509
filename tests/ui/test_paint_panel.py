"""PaintPanel (widgets/panels/paint.py) regional blend on the automatic regions, without a browser.

The "automatic regions" preset is offered once ``model.regions`` exists; its
memberships are the soft region weights of the level the Regions tab shows.
Runs on the 5k sample head (segmentation ~0.2 s, no thumbnails needed: the
palette is a small gallery).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("anywidget")

import ipywidgets as W

from widgets import PaintPanel
from widgets.gallery import ExpressionGallery
from workbench import load_sample

pytestmark = pytest.mark.ui


def _errors(out: W.Output) -> str:
    return "".join(o.get("text", "") for o in out.outputs)


@pytest.fixture
def segmented():
    model = load_sample("head")
    model.segment_regions(0.25)
    errors = W.Output()
    gallery = ExpressionGallery(model, size=(16, 16), names=["jawOpen", "browInnerUp"])
    panel = PaintPanel(model, gallery, errors=errors)
    yield model, panel, errors
    panel.close()
    gallery.close()


def test_automatic_regions_preset_blends_per_region(segmented) -> None:
    model, panel, errors = segmented
    state = model.regions.state
    names = list(state.regions.names[state.level])
    assert "auto" in [k for _, k in panel.preset.options]
    panel.preset.value = "auto"
    assert _errors(errors) == ""
    assert list(panel.region_sliders) == names  # one slider per region of the level shown
    assert panel.feather.layout.display == "none"

    panel.pick("jawOpen")
    # the region jawOpen moves most
    Wm = state.regions.weight_matrix(state.level)
    jaw = np.linalg.norm(model.shape("jawOpen").effective_delta(), axis=1)
    r = int(np.argmax(Wm.T @ jaw))
    region = names[r]
    undo_depth = len(model.history.undo_labels)
    panel.region_sliders[region].value = 0.6
    panel.grouper.flush()  # the slider drag's undo step is closed when it idles
    assert _errors(errors) == ""
    assert model.history.undo_labels[-1] == "Blend jawOpen (auto)"
    assert len(model.history.undo_labels) == undo_depth + 1

    # jawOpen painted at 0.6 x the region's soft membership, nothing else painted
    W_region = np.asarray(Wm[:, r].toarray()).ravel()
    assert list(model.paint) == ["jawOpen"]
    np.testing.assert_allclose(model.paint["jawOpen"], 0.6 * W_region, atol=1e-6)
    assert np.count_nonzero(model.paint["jawOpen"]) == np.count_nonzero(W_region)
    # the blend reaches the face only where the region is
    d = np.linalg.norm(model.evaluate() - np.asarray(model.vertices), axis=1)
    assert d[W_region == 0].max() < 1e-5 < 1e-3 < d.max()

    # the slider shows the picked expression's weight; another expression has its own
    assert panel.region_sliders[region].value == pytest.approx(0.6)
    panel.pick("browInnerUp")
    assert panel.region_sliders[region].value == 0.0

    model.undo()
    assert len(model.paint) == 0


def test_automatic_regions_follow_the_level_and_resegmentation(segmented) -> None:
    model, panel, errors = segmented
    panel.preset.value = "auto"
    panel.pick("jawOpen")
    names0 = list(panel.region_sliders)
    panel.set_region_weight(names0[0], 0.5)
    coarse = model.regions.regions.n_levels - 1
    if coarse > 0:
        model.regions.set_level(coarse)
        lv = model.regions.level
        assert list(panel.region_sliders) == list(model.regions.regions.names[lv])
        assert panel.preset.value == "auto"
        # the mixes of the finer level's regions do not carry over to other regions
        assert all(s.value == 0.0 for s in panel.region_sliders.values())
    assert _errors(errors) == ""
