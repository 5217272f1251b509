"""The shared panel plumbing (widgets/panels/): base, undo/redo buttons, progress row, names.

On the tiny 3x3 grid model (``tiny_model``), without a browser. Connections are
counted on the real ``model.events`` signals: a panel adds its slots while open,
and closing it (once or twice) takes every one of them away exactly once.
"""

from __future__ import annotations

import pytest

pytest.importorskip("anywidget")

import ipywidgets as W

from widgets.panels import (
    ExportPanel,
    ExpressionPanel,
    ModelPanel,
    PaintPanel,
    ProgressRow,
    SculptPanel,
    UndoRedoButtons,
    next_free_name,
)
from widgets.panels.base import button

pytestmark = pytest.mark.ui


def _errors(out: W.Output) -> str:
    return "".join(o.get("text", "") for o in out.outputs)


def _counts(model) -> dict[str, int]:
    return {name: len(sig) for name, sig in model.events.signals.items()}


# ------------------------------------------------------------------ names
@pytest.mark.parametrize(
    ("name", "taken", "expected"),
    [
        ("sculpt_1", [], "sculpt_1"),  # free: kept
        ("sculpt_1", ["sculpt_1"], "sculpt_2"),
        ("sculpt_1", ["sculpt_1", "sculpt_2", "sculpt_3"], "sculpt_4"),
        ("sculpt_3", ["sculpt_3"], "sculpt_4"),  # counts on from its own number
        ("bump", ["bump"], "bump_1"),  # no number: _1
        ("bump", ["bump", "bump_1"], "bump_2"),
        ("x_0", ["x_0"], "x_1"),  # _0 counts from 1
        ("_7", ["_7"], "_7_1"),  # no stem: the whole name is the stem
        ("a_b", ["a_b"], "a_b_1"),  # not a number after the last _
        ("paint_1", iter(["paint_1"]), "paint_2"),  # any iterable
    ],
)
def test_next_free_name(name, taken, expected) -> None:
    assert next_free_name(name, taken) == expected


# ------------------------------------------------------------------ progress
def test_progress_row_is_the_callback_and_hides_when_done() -> None:
    row = ProgressRow("fwb-test-progress", "fwb-test-label", template="<i>basis: {message}</i>")
    assert "fwb-test-progress" in row.bar._dom_classes
    assert "fwb-test-label" in row.label._dom_classes
    assert row.children == (row.bar, row.label)
    assert not row.visible and row.label.value == ""  # hidden until work starts
    row(0.4, "solving")
    assert row.visible and row.bar.value == pytest.approx(0.4)
    assert row.label.value == "<i>basis: solving</i>"
    row(-1.0, "clamped")
    assert row.bar.value == 0.0 and row.visible
    row(1.0, "done")
    assert not row.visible and row.label.value == "" and row.bar.value == 1.0
    row(0.5, "again")
    row(2.0, "")  # past the end counts as done
    assert not row.visible and row.bar.value == 1.0
    # start / fail / finish: what the Regions and wrinkle panels show around their work
    row.start("<i>segmenting …</i>")
    assert row.visible and row.bar.value == 0.0 and row.label.value == "<i>segmenting …</i>"
    row.fail("fit failed <see below>")
    assert row.bar.bar_style == "danger" and "fit failed &lt;see below&gt;" in row.label.value
    row(0.3, "retry")
    assert row.bar.bar_style == "info"  # a new run is not red
    row.finish("12 regions in 80 ms")
    assert not row.visible and row.label.value == "12 regions in 80 ms"


# ------------------------------------------------------------------ undo / redo
def test_undo_redo_buttons_follow_the_history_with_tooltips(tiny_model) -> None:
    m = tiny_model
    calls: list[str] = []
    b = UndoRedoButtons(
        m,
        on_undo=lambda: calls.append(f"undo {m.undo()}"),
        on_redo=lambda: calls.append(f"redo {m.redo()}"),
        classes=("fwb-x-undo", "fwb-x-redo"),
        width="77px",
    )
    undo, redo = b.buttons
    assert (undo, redo) == (b.undo_button, b.redo_button)
    assert "fwb-x-undo" in undo._dom_classes and "fwb-x-redo" in redo._dom_classes
    assert undo.layout.width == "77px" and (undo.icon, redo.icon) == ("undo", "repeat")
    assert undo.disabled and redo.disabled
    assert (undo.tooltip, redo.tooltip) == ("Nothing to undo", "Nothing to redo")

    m.set_weight("up", 0.5)
    m.set_weight("left", 0.25)
    assert not undo.disabled and redo.disabled
    assert undo.tooltip == "Undo Set left" and redo.tooltip == "Nothing to redo"
    undo.click()
    assert calls == ["undo Set left"]
    assert undo.tooltip == "Undo Set up" and redo.tooltip == "Redo Set left"
    assert not undo.disabled and not redo.disabled
    undo.click()
    assert undo.disabled and undo.tooltip == "Nothing to undo"
    redo.click()
    assert calls[-1] == "redo Set up" and redo.tooltip == "Redo Set left"

    n = len(m.events.history)
    b.close()
    b.close()  # idempotent
    assert len(m.events.history) == n - 1
    m.set_weight("up", 0.9)  # no longer followed
    assert undo.tooltip == "Undo Set up"


def test_undo_redo_click_errors_go_to_the_sink(tiny_model) -> None:
    from widgets._threading import ErrorSink

    out = W.Output()

    def broken() -> None:
        raise RuntimeError("undo exploded")

    b = UndoRedoButtons(tiny_model, on_undo=broken, on_redo=broken, errors=ErrorSink(out))
    b.undo_button.click()  # must not raise
    assert "[undo]" in _errors(out) and "undo exploded" in _errors(out)
    b.close()


# ------------------------------------------------------------------ the base
class _Panel(ModelPanel):
    def __init__(self, model, **kw) -> None:
        super().__init__(model, layout=W.Layout(width="300px"), **kw)
        self.seen: list[dict] = []
        self.children = [W.HTML("x")]
        self.listen(model.events.weights, self.seen.append, "test weights")


def test_listen_guards_and_close_disconnects_exactly_once(tiny_model) -> None:
    m = tiny_model
    out = W.Output()
    before = _counts(m)
    p = _Panel(m, errors=out)
    assert p.model is m and p.connected and p.layout.width == "300px"
    assert _counts(m)["weights"] == before["weights"] + 1
    m.set_weight("up", 0.5)
    assert p.seen == [{"up": 0.5}]

    # a raising slot is reported under its label, never raised into the model's emit
    p.listen(m.events.shapes, lambda: 1 / 0, "test shapes")
    m.set_shape_mute("up", True)
    assert "[test shapes]" in _errors(out) and "ZeroDivisionError" in _errors(out)
    assert m.shape("up").mute

    seen = len(p.seen)
    closed: list[str] = []
    p.on_close(closed.append, "first registered")
    p.on_close(closed.append, "last registered")
    p.close()
    assert _counts(m) == before
    assert closed == ["last registered", "first registered"]  # last in, first out
    assert not p.connected
    p.close()  # a second close (and the widget's __del__) change nothing
    p.disconnect()
    assert _counts(m) == before and len(closed) == 2
    m.set_weight("up", 0.9)
    assert len(p.seen) == seen


def test_link_and_observe_trait_hold_until_close(tiny_model) -> None:
    out = W.Output()
    p = _Panel(tiny_model, errors=out)
    a, b, other = W.FloatSlider(value=0.1), W.FloatSlider(value=0.7), W.Checkbox(value=False)
    p.link((a, "value"), (b, "value"))
    assert b.value == 0.1  # the source's value wins, as traitlets.link does
    b.value = 0.4
    assert a.value == 0.4
    seen: list[bool] = []

    def slot(change) -> None:
        seen.append(change["new"])
        if change["new"] is False:
            raise ValueError("bad tick")

    p.observe_trait(other, slot, "value", "test tick")
    other.value = True
    other.value = False  # raises inside the slot: reported, not raised into the trait's notify
    assert seen == [True, False]
    assert "[test tick]" in _errors(out) and "ValueError" in _errors(out)
    p.close()
    a.value = 0.9
    other.value = True
    assert b.value == 0.4 and seen == [True, False]  # both let go on close


def test_close_runs_every_teardown_even_if_one_raises(tiny_model) -> None:
    m = tiny_model
    before = _counts(m)
    p = _Panel(m)

    def boom() -> None:
        raise RuntimeError("teardown failed")

    p.on_close(boom)
    with pytest.raises(RuntimeError, match="teardown failed"):
        p.close()
    assert _counts(m) == before and not p.connected  # the listen was still undone
    p.close()  # and nothing runs twice


def test_flush_undo_redo_end_interactions_and_call_before_edit(tiny_model) -> None:
    m = tiny_model
    order: list[str] = []
    p = _Panel(m, before_edit=[lambda: order.append("before_edit")])
    m.set_weight("up", 0.5)
    m.begin_interaction("Drag up")  # a drag another widget left open
    m.set_weight("up", 0.7)
    assert m.interacting
    assert p.undo() == "Drag up"  # the open drag became its step, then was undone
    assert not m.interacting and order == ["before_edit"]
    assert m.weights["up"] == pytest.approx(0.5)
    assert p.redo() == "Drag up" and m.weights["up"] == pytest.approx(0.7)
    assert order == ["before_edit", "before_edit"]
    p.close()


def test_undo_redo_buttons_of_a_panel_close_with_it(tiny_model) -> None:
    m = tiny_model
    before = _counts(m)
    p = _Panel(m)
    hb = p.undo_redo_buttons("fwb-p-undo", "fwb-p-redo")
    assert _counts(m)["history"] == before["history"] + 1
    m.set_weight("left", 0.3)
    assert hb.undo_button.tooltip == "Undo Set left"
    hb.undo_button.click()
    assert m.weights["left"] == 0.0 and hb.redo_button.tooltip == "Redo Set left"
    p.close()
    assert _counts(m) == before


def test_button_helper() -> None:
    b = button("Bake", "fwb-x-bake", "bake it", icon="cube", width="90px")
    assert (b.description, b.tooltip, b.icon, b.layout.width) == ("Bake", "bake it", "cube", "90px")
    assert "fwb-x-bake" in b._dom_classes


# ------------------------------------------------------------------ the real panels
@pytest.mark.parametrize("make", ["sculpt", "paint", "expressions", "export", "wrinkles"])
def test_every_panel_leaves_no_connection_behind(tiny_model, make) -> None:
    from widgets.gallery import ExpressionGallery
    from widgets.wrinkles import WrinklePanel

    m = tiny_model
    gallery = ExpressionGallery(m, size=(8, 8), names=["up"])  # the palette is the caller's
    before = _counts(m)
    out = W.Output()
    if make == "sculpt":
        p = SculptPanel(m, errors=out)
    elif make == "paint":
        p = PaintPanel(m, gallery, errors=out)
    elif make == "expressions":
        p = ExpressionPanel(m, errors=out)
    elif make == "export":
        p = ExportPanel(m, errors=out)
    else:
        p = WrinklePanel(m, errors=out, thumbnails=False)
    assert _counts(m) != before
    m.set_weight("up", 0.4)
    p.close()
    assert _counts(m) == before
    p.close()
    assert _counts(m) == before
    if make == "sculpt":
        assert m.handles.layer.progress is None  # the progress callback went too
    gallery.close()
    assert _errors(out) == ""


def test_wrinkle_panel_lets_go_of_the_viewport_exactly_once(tiny_model) -> None:
    from widgets import Viewport
    from widgets.wrinkles import WrinklePanel

    m = tiny_model
    out = W.Output()
    vp = Viewport(m, errors=out)
    try:
        before = _counts(m)
        listeners = list(vp.drag_listeners)
        tool_observers = len(vp._trait_notifiers.get("tool", {}).get("change", []))
        p = WrinklePanel(m, vp, errors=out, thumbnails=False)
        assert _counts(m) != before and len(vp.drag_listeners) == len(listeners) + 1
        p.show_graph.value = not vp.feature_graph  # linked while open
        assert p.show_graph.value == vp.feature_graph
        p.close()
        assert _counts(m) == before and vp.drag_listeners == listeners
        assert len(vp._trait_notifiers["tool"]["change"]) == tool_observers
        p.close()
        assert _counts(m) == before and vp.drag_listeners == listeners
        shown = vp.feature_graph
        p.show_graph.value = not shown  # unlinked
        assert vp.feature_graph == shown
        vp.tool = "paint"  # the panel no longer follows the tool
        assert _errors(out) == ""
    finally:
        vp.close()


def test_panels_keep_their_undo_classes(tiny_model) -> None:
    m = tiny_model
    panels = [SculptPanel(m), ExpressionPanel(m)]
    expected = [("fwb-sculpt-undo", "fwb-sculpt-redo"), ("fwb-undo", "fwb-redo")]
    for p, (u, r) in zip(panels, expected, strict=True):
        assert u in p.undo_button._dom_classes and r in p.redo_button._dom_classes
        assert p.undo_button.tooltip == "Nothing to undo" and p.undo_button.disabled
    m.set_weight("up", 0.2)
    for p in panels:
        assert p.undo_button.tooltip == "Undo Set up" and not p.undo_button.disabled
        p.close()


def _tree(widget: W.Widget) -> list[W.Widget]:
    out = [widget]
    for child in getattr(widget, "children", ()):
        out += _tree(child)
    return out


def test_rebuilt_sliders_close_the_old_rows_and_show_no_closed_widget(tiny_model) -> None:
    m = tiny_model
    p = ExpressionPanel(m)
    old = [w for w in _tree(p.body) if w is not p.body]
    assert old and all(w.comm is not None for w in old)
    m.shape_tools.split("up")  # the shapes change: the rows are rebuilt
    new = [w for w in _tree(p.body) if w is not p.body]
    assert {"up_L", "up_R"} <= set(p.sliders) and "up" not in p.sliders
    # every widget of the old rows is closed (none leaks), none of them is still shown,
    # and nothing the body shows is closed: the page never meets a child the kernel closed
    assert all(w.comm is None for w in old)
    assert not {id(w) for w in old} & {id(w) for w in new}
    assert all(w.comm is not None for w in new)
    p.close()
    assert all(w.comm is None for w in new)
