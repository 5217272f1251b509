"""ShapeToolsPanel (widgets/panels/shape_tools.py) and the correctives' sliders, without a browser.

Buttons are clicked from Python (``Button.click()`` runs the handlers as a
click in the browser does); the checks are on the model (split halves sum to
the original exactly, one undo step per action and undo gives the state back,
corrective sliders disabled and following their drivers), on the viewport's
colour overlay (the split preview and its end) and on the error text of
refused actions. On the sample head (5k vertices, 52 ARKit shapes).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import ipywidgets as W
import numpy as np
import pytest

pytest.importorskip("anywidget")

import workbench
from widgets import TAB_TITLES, Workbench
from widgets.panels.expressions import ExpressionPanel
from widgets.panels.shape_tools import (
    LEFT_COLOR,
    RIGHT_COLOR,
    ShapeToolsPanel,
    split_preview_colors,
)
from widgets.viewport import Viewport
from workbench.model import FaceModel

pytestmark = pytest.mark.ui


@dataclass
class Tab:
    model: FaceModel
    sliders: ExpressionPanel
    tools: ShapeToolsPanel
    viewport: Viewport
    errors: W.Output

    def error_text(self) -> str:
        return "".join(o.get("text", "") for o in self.errors.outputs)


@pytest.fixture
def tab() -> Iterator[Tab]:
    """The Shapes tab's two panels over the sample head, sharing one error Output, with a viewport."""
    m = workbench.load_sample("head")
    errors = W.Output()
    vp = Viewport(m, errors=errors)
    sliders = ExpressionPanel(
        m, errors=errors, idle_s=30.0
    )  # a slider burst ends only when flushed
    tools = ShapeToolsPanel(
        m, vp, sliders=sliders, errors=errors, before_edit=[sliders.grouper.flush]
    )
    yield Tab(m, sliders, tools, vp, errors)
    tools.close()
    sliders.close()
    vp.close()


# ------------------------------------------------------------------ split
def test_split_button_halves_sum_to_the_original_and_undo_restores(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    m.set_weight("browInnerUp", 0.7)
    whole = m.shape("browInnerUp").delta.copy()
    looks = m.evaluate().copy()
    names = list(m.shape_names)
    undo = list(m.history.undo_labels)
    st.select("browInnerUp")
    assert (
        st.left_name.placeholder == "browInnerUp_L" and st.right_name.placeholder == "browInnerUp_R"
    )
    st.falloff.value = 0.12
    st.split_button.click()

    left, right = m.shape("browInnerUp_L").delta, m.shape("browInnerUp_R").delta
    np.testing.assert_array_equal(left + right, whole)  # exactly, in float32
    assert np.any(left) and np.any(right) and not np.array_equal(left, right)
    x = m.vertices[:, 0]  # the sample's subject's left is +x
    assert not np.any(left[x < -0.07]) and not np.any(right[x > 0.07])  # zero beyond the 0.12 band
    assert "browInnerUp" not in m.shape_names
    assert m.weights["browInnerUp_L"] == m.weights["browInnerUp_R"] == pytest.approx(0.7)
    np.testing.assert_allclose(m.evaluate(), looks, atol=1e-5)  # the face looks the same
    assert m.history.undo_labels == [*undo, "Split browInnerUp"]  # one undo step
    assert (
        st.status.value.count("split browInnerUp into browInnerUp_L + browInnerUp_R (band 0.12 dm)")
        == 1
    )
    assert st.selected == "browInnerUp_L"  # the new left half is selected
    assert set(tab.sliders.sliders) == set(m.shape_names)  # the sliders were rebuilt

    assert st.undo() == "Split browInnerUp"
    assert list(m.shape_names) == names
    np.testing.assert_array_equal(m.shape("browInnerUp").delta, whole)
    assert m.weights["browInnerUp"] == pytest.approx(0.7)
    assert tab.error_text() == ""


def test_split_with_typed_names_keep_and_a_refusal(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    st.select("jawOpen")
    st.left_name.value = "jawOpenL"  # the right name left empty: its default
    st.keep.value = True
    st.split_button.click()
    assert {"jawOpen", "jawOpenL", "jawOpen_R"} <= set(m.shape_names)
    np.testing.assert_array_equal(
        m.shape("jawOpenL").delta + m.shape("jawOpen_R").delta, m.shape("jawOpen").delta
    )
    assert "original kept" in st.status.value and st.last_error == ""
    assert st.left_name.value == ""  # the fields empty again after a split

    # Refused: a name that is taken. Nothing changes; the error names the argument.
    undo = list(m.history.undo_labels)
    st.select("jawOpen")
    st.left_name.value = "jawOpenL"
    st.split_button.click()
    assert m.history.undo_labels == undo
    msg = "split('jawOpen'): names[0]: a blendshape named 'jawOpenL' already exists"
    assert st.last_error == msg
    assert "Split refused" in st.status.value and "#b00" in st.status.value
    assert tab.error_text() == f"[Shape tools: Split] {msg}\n"  # one clear line, no traceback
    assert st.errors.count == 1


def test_split_preview_colours_the_viewport_and_gives_the_colours_back(tab: Tab) -> None:
    m, st, vp = tab.model, tab.tools, tab.viewport
    own = np.full((m.n_vertices, 3), 0.5, np.float32)
    vp.vertex_colors = own  # e.g. someone's colours before the preview
    st.select("browInnerUp")
    assert not st.previewing
    st.falloff.value = 0.3  # adjusting the band turns the preview on
    assert st.previewing and st.preview.value
    shown = vp.vertex_colors
    assert shown is not None
    expected = split_preview_colors(m.shape_tools.split_weights(0.3), m.shape("browInnerUp").delta)
    np.testing.assert_allclose(shown, expected, atol=1e-6)
    x = m.vertices[:, 0]
    far_left, far_right = np.argmax(x), np.argmin(x)
    # the far sides in their colours (faded toward grey where the shape does not move)
    assert shown[far_left, 0] > shown[far_left, 2] and shown[far_right, 2] > shown[far_right, 0]
    moving = np.linalg.norm(m.shape("browInnerUp").delta, axis=1)
    top_left = np.argmax(moving * (x > 0.2))
    np.testing.assert_allclose(shown[top_left], LEFT_COLOR, atol=1e-6)  # full colour where it moves
    top_right = np.argmax(moving * (x < -0.2))
    np.testing.assert_allclose(shown[top_right], RIGHT_COLOR, atol=1e-6)
    st.falloff.value = 0.05  # live: the band narrows
    assert not np.array_equal(vp.vertex_colors, shown)

    st.preview.value = False  # the toggle ends it
    np.testing.assert_array_equal(vp.vertex_colors, own)
    st.preview.value = True
    assert st.previewing
    st.split_button.click()  # a split ends it too
    assert not st.previewing and not st.preview.value
    np.testing.assert_array_equal(vp.vertex_colors, own)
    assert m.history.undo_labels[-1] == "Split browInnerUp"


def test_the_selection_follows_the_last_slider_touched(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    tab.sliders.sliders["mouthSmileLeft"].value = 0.4  # as a drag in the browser
    assert tab.sliders.selected == "mouthSmileLeft" and st.selected == "mouthSmileLeft"
    assert st.mirror_target.value == "mouthSmileRight"
    m.set_weight("jawOpen", 0.3)  # an edit from code is not a touch
    assert st.selected == "mouthSmileLeft"
    # the open slider burst becomes its own undo step before the action
    st.mirror_button.click()
    assert m.history.undo_labels[-2:] == [
        "Drag mouthSmileLeft",
        "Mirror mouthSmileLeft to mouthSmileRight",
    ]


# ------------------------------------------------------------------ mirror
def test_mirror_button_replaces_the_target_and_adds_a_new_one(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    ref = workbench.load_sample("head")
    ref.shape_tools.mirror("mouthSmileLeft")
    before = m.shape("mouthSmileRight").delta.copy()
    st.select("mouthSmileLeft")
    st.mirror_button.click()
    np.testing.assert_array_equal(
        m.shape("mouthSmileRight").delta, ref.shape("mouthSmileRight").delta
    )
    assert "mirrored mouthSmileLeft onto mouthSmileRight (replaced)" in st.status.value
    assert "0.0 % of the vertices without a mirror partner" in st.status.value
    assert "mirror plane x = 0" in st.symmetry_label.value
    st.undo()
    np.testing.assert_array_equal(m.shape("mouthSmileRight").delta, before)

    st.mirror_target.value = "smileCopy"
    st.mirror_button.click()
    names = list(m.shape_names)
    assert names[names.index("mouthSmileLeft") + 1] == "smileCopy"
    np.testing.assert_array_equal(m.shape("smileCopy").delta, ref.shape("mouthSmileRight").delta)
    assert m.history.undo_labels[-1] == "Mirror mouthSmileLeft to smileCopy"
    assert "smileCopy" in tab.sliders.sliders

    st.select("jawOpen")  # unsided: flipped in place
    assert st.mirror_target.value == "jawOpen"
    st.mirror_button.click()
    assert "flipped jawOpen in place" in st.status.value
    assert tab.error_text() == ""


def test_mirror_expression_and_mirror_paint(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    assert st.mirror_expression_button.disabled and st.mirror_paint_button.disabled
    m.set_weights({"mouthSmileLeft": 1.0, "eyeBlinkLeft": 0.5})
    m.expressions.save("smirkLeft")
    assert st.expression.value == "smirkLeft" and st.expression_target.value == "smirkRight"
    assert not st.mirror_expression_button.disabled
    st.mirror_expression_button.click()
    assert m.expressions["smirkRight"].weights["mouthSmileRight"] == pytest.approx(1.0)
    assert m.expressions["smirkRight"].weights["eyeBlinkRight"] == pytest.approx(0.5)
    assert m.history.undo_labels[-1] == "Mirror expression smirkLeft to smirkRight"
    assert "mirrored expression smirkLeft into smirkRight" in st.status.value

    ref = workbench.load_sample("head")
    left = np.flatnonzero(m.vertices[:, 0] > 0.3)
    for model in (m, ref):
        model.paint.flood("mouthSmileLeft", 0.8, vertices=left)
    ref.shape_tools.mirror_paint("mouthSmileLeft")
    assert st.painted.value == "mouthSmileLeft" and st.paint_target.value == "mouthSmileRight"
    st.mirror_paint_button.click()
    np.testing.assert_array_equal(m.paint["mouthSmileRight"], ref.paint["mouthSmileRight"])
    assert m.history.undo_labels[-1] == "Mirror paint of mouthSmileLeft"
    assert "mirrored the paint of mouthSmileLeft onto mouthSmileRight" in st.status.value
    st.undo()
    assert "mouthSmileRight" not in m.paint

    st.expression_target.value = "   "  # empty: the facet's default target
    st.paint_target.value = "noSuchTarget"
    st.mirror_paint_button.click()
    assert "target 'noSuchTarget' is neither a saved expression nor a shape" in st.last_error
    assert "[Shape tools: Mirror paint]" in tab.error_text()


# ------------------------------------------------------------------ correctives
def test_add_corrective_slider_is_disabled_badged_and_follows_its_drivers(tab: Tab) -> None:
    m, st, sl = tab.model, tab.tools, tab.sliders
    st.driver_a.value, st.driver_b.value = "jawOpen", "mouthSmileLeft"
    assert st.corrective_name.placeholder == "jawOpen_mouthSmileLeft"
    before = m.evaluate().copy()
    st.add_corrective_button.click()
    name = "jawOpen_mouthSmileLeft"
    assert m.shape_tools.drivers(name) == ("jawOpen", "mouthSmileLeft")
    assert not np.any(m.shape(name).delta)
    np.testing.assert_array_equal(m.evaluate(), before)
    assert m.history.undo_labels[-1] == f"Add corrective {name}"
    assert "added corrective jawOpen_mouthSmileLeft = jawOpen × mouthSmileLeft" in st.status.value
    assert st.selected == name and "corrective = jawOpen × mouthSmileLeft" in st.badge.value
    assert not st.remove_corrective_button.disabled
    assert name not in st.driver_a.options  # a corrective cannot drive

    slider = sl.sliders[name]
    assert slider.disabled and not sl.sliders["jawOpen"].disabled
    assert "= jawOpen × mouthSmileLeft" in sl.badges[name].value
    mute, column = sl._cells[name].children  # the badge under the slider
    assert mute is sl.mutes[name] and column.children == (slider, sl.badges[name])
    sl.sliders["jawOpen"].value = 0.5  # the driver's slider, as a drag
    m.set_weight("mouthSmileLeft", 0.8)  # the other from code
    assert slider.value == pytest.approx(0.4) == pytest.approx(m.weights[name])
    sl.grouper.flush()
    m.undo()  # the code edit
    assert slider.value == 0.0
    m.redo()
    assert slider.value == pytest.approx(0.4)
    slider.value = (
        0.9  # a write to a corrective's slider (it is disabled in the browser) changes nothing
    )
    assert m.weights[name] == pytest.approx(0.4)

    st.remove_corrective_button.click()
    assert name not in m.shape_names and name not in sl.sliders and name not in sl.badges
    assert m.history.undo_labels[-1] == f"Remove corrective {name}"
    m.undo()
    assert sl.sliders[name].disabled and name in sl.badges
    assert sl.sliders[name].value == pytest.approx(0.4)
    assert tab.error_text() == ""


def test_set_drivers_and_remove_keeping_the_shape(tab: Tab) -> None:
    m, st, sl = tab.model, tab.tools, tab.sliders
    m.set_weights({"cheekPuff": 0.3, "jawOpen": 0.5, "mouthFunnel": 0.6})
    st.select("cheekPuff")
    assert st.remove_corrective_button.disabled
    st.driver_a.value, st.driver_b.value = "jawOpen", "mouthFunnel"
    st.set_drivers_button.click()  # only the correctives event and a derived weight: no shapes event
    assert m.shape_tools.drivers("cheekPuff") == ("jawOpen", "mouthFunnel")
    assert sl.sliders["cheekPuff"].disabled and sl.sliders["cheekPuff"].value == pytest.approx(0.3)
    assert "cheekPuff is now driven by jawOpen × mouthFunnel" in st.status.value
    assert "cheekPuff" in sl.badges
    st.keep_shape.value = True
    st.remove_corrective_button.click()
    assert "cheekPuff" in m.shape_names and not m.shape_tools.correctives
    assert not sl.sliders["cheekPuff"].disabled and "cheekPuff" not in sl.badges
    assert sl._cells["cheekPuff"].children == (sl.mutes["cheekPuff"], sl.sliders["cheekPuff"])
    assert "(kept as an ordinary shape)" in st.status.value
    m.undo()
    assert sl.sliders["cheekPuff"].disabled


def test_corrective_from_the_handle_sculpt(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    m.handles.add(100)
    m.handles.add(2000)
    m.set_weights({"jawOpen": 1.0, "mouthSmileLeft": 0.5})
    m.handles.set_offsets([[0.0, 0.02, 0.0], [0.01, 0.0, 0.0]])
    sculpted = m.evaluate().copy()
    st.driver_a.value, st.driver_b.value = "jawOpen", "mouthSmileLeft"
    st.corrective_name.value = "fix"
    st.corrective_source.value = "handles"
    st.add_corrective_button.click()
    assert m.shape_tools.drivers("fix") == ("jawOpen", "mouthSmileLeft")
    assert not np.any(m.handles.offsets)
    np.testing.assert_allclose(m.evaluate(), sculpted, atol=2e-6)
    assert "from the handle sculpt (handles reset)" in st.status.value
    assert st.corrective_name.value == ""
    m.undo()
    np.testing.assert_array_equal(m.evaluate(), sculpted)


def test_corrective_refusals_show_the_facets_message(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    undo = list(m.history.undo_labels)
    st.driver_a.value = st.driver_b.value = "jawOpen"
    st.add_corrective_button.click()
    assert "must name different shapes" in st.last_error
    st.driver_b.value = "mouthClose"
    st.corrective_source.value = "handles"  # drivers at rest: nothing to divide by
    st.add_corrective_button.click()
    assert "delta='handles' needs the drivers posed" in st.last_error
    st.corrective_source.value = "empty"
    st.corrective_name.value = "jawOpen"
    st.add_corrective_button.click()
    assert "name: a blendshape named 'jawOpen' already exists" in st.last_error
    assert m.history.undo_labels == undo and not m.shape_tools.correctives
    lines = tab.error_text().splitlines()
    assert len(lines) == 3 and all(
        ln.startswith("[Shape tools: Add corrective] add_corrective") for ln in lines
    )
    assert "Traceback" not in tab.error_text()
    st.corrective_name.value = ""
    st.add_corrective_button.click()  # a good one clears the error
    assert st.last_error == "" and "jawOpen_mouthClose" in m.shape_names


# ------------------------------------------------------------------ in the Workbench
def test_workbench_shapes_tab_holds_the_tools_and_leaving_it_ends_the_preview() -> None:
    wb = Workbench(workbench.load_sample("head"))
    try:
        assert wb.tabs.children[TAB_TITLES.index("Shapes")].children == (wb.panel, wb.shape_tools)
        st = wb.shape_tools
        wb.panel.sliders["eyeBlinkLeft"].value = 0.2
        assert st.selected == "eyeBlinkLeft"
        st.preview.value = True
        assert wb.viewport.vertex_colors is not None
        wb.tabs.selected_index = TAB_TITLES.index("Regions")  # the regions overlay takes over ...
        assert not st.previewing
        wb.tabs.selected_index = TAB_TITLES.index("Shapes")
        assert wb.viewport.vertex_colors is None  # ... and gives back the plain colours
        st.split_button.click()
        assert wb.model.history.undo_labels[-1] == "Split eyeBlinkLeft"
        assert {"eyeBlinkLeft_L", "eyeBlinkLeft_R"} <= set(wb.model.shape_names)
        assert wb.errors.outputs == ()
    finally:
        wb.close()
    assert not wb.shape_tools.connected


def test_keys_go_on_the_drivers_never_on_the_corrective(tab: Tab) -> None:
    m, st = tab.model, tab.tools
    st.driver_a.value, st.driver_b.value = "jawOpen", "mouthSmileLeft"
    st.add_corrective_button.click()
    m.set_weights({"jawOpen": 1.0, "mouthSmileLeft": 0.5})
    assert m.weights["jawOpen_mouthSmileLeft"] == 0.5
    m.timeline.key_weights(0.0)  # the timeline's "Key"
    assert sorted(m.tracks.weight_tracks) == ["jawOpen", "mouthSmileLeft"]
    m.set_weight("mouthSmileLeft", 1.0)
    m.expressions.save("wide")
    m.expressions.key(1.0, "wide")  # an expression chip dropped on the timeline
    assert sorted(m.tracks.weight_tracks) == ["jawOpen", "mouthSmileLeft"]
    assert m.tracks.evaluate(1.0).weights["mouthSmileLeft"] == pytest.approx(1.0)
    m.set_time(1.0)
    assert m.weights["jawOpen_mouthSmileLeft"] == pytest.approx(
        1.0
    )  # derived from the keyed drivers
