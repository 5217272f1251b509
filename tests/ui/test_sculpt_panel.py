"""SculptPanel (widgets/panels/sculpt.py) stiffness sliders follow the model, without a browser."""

from __future__ import annotations

import pytest

pytest.importorskip("anywidget")

import ipywidgets as W

from widgets.panels.sculpt import SculptPanel

pytestmark = pytest.mark.ui


def _errors(out: W.Output) -> str:
    return "".join(o.get("text", "") for o in out.outputs)


def test_stiffness_sliders_follow_undo_and_redo_without_new_steps(tiny_model):
    m = tiny_model
    errors = W.Output()
    panel = SculptPanel(m, errors=errors)
    k_s0, k_b0 = m.handles.stiffness
    assert (panel.k_s.value, panel.k_b.value) == pytest.approx((k_s0, k_b0))
    panel.k_s.value = 10.0  # a slider release: one undo step
    panel.k_b.value = 0.1
    assert m.handles.stiffness == pytest.approx((10.0, 0.1))
    assert m.history.undo_labels == ["Shell stiffness", "Shell stiffness"]
    m.undo()
    assert (panel.k_s.value, panel.k_b.value) == pytest.approx((10.0, k_b0))
    m.undo()
    assert (panel.k_s.value, panel.k_b.value) == pytest.approx((k_s0, k_b0))
    # syncing the sliders recorded nothing and left the redo steps alone
    assert m.history.undo_labels == [] and len(m.history.redo_labels) == 2
    assert m.handles.stiffness == pytest.approx((k_s0, k_b0))
    m.redo()
    m.redo()
    assert (panel.k_s.value, panel.k_b.value) == pytest.approx((10.0, 0.1))
    m.handles.set_stiffness(2.0, 3.0)  # from code
    assert (panel.k_s.value, panel.k_b.value) == pytest.approx((2.0, 3.0))
    assert m.history.undo_labels[-1] == "Shell stiffness" and len(m.history.undo_labels) == 3
    assert _errors(errors) == ""
    panel.close()
    m.handles.set_stiffness(5.0, 5.0)  # a closed panel no longer follows
    assert (panel.k_s.value, panel.k_b.value) == pytest.approx((2.0, 3.0))
