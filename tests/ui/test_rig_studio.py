"""The Rig tab (``widgets.RigStudio``) driven through its widgets in the kernel.

The front end's messages are fed to the viewports as the browser sends them
(``{"type": "pick", "vertex"}`` for a click on the surface, a ``handle``
gesture for a marker drag); the browser test (tests/browser/test_rig_in_browser.py)
clicks with the mouse.
"""

from __future__ import annotations

import numpy as np
import pytest
from rig_faces import WARP, Actor

import workbench
from workbench.rigging import RigSession

pytestmark = pytest.mark.ui


@pytest.fixture(scope="module")
def head():
    return workbench.load_sample("head")


@pytest.fixture(scope="module")
def actor(head):
    return Actor(head)


def click(view, vertex: int) -> None:
    view._on_frontend_msg(view, {"type": "pick", "vertex": int(vertex)}, [])


def nearest(actor: Actor, head, v: int) -> int:
    return int(np.argmin(np.linalg.norm(actor.model.vertices - WARP(head.vertices[v][None])[0], axis=1)))


def test_clicks_make_pairs_markers_follow_and_undo_is_per_step(head, actor) -> None:
    from widgets import RigStudio

    studio = RigStudio(head, actor.model, height=200)
    try:
        s, lp = studio.session, studio.landmarks
        tv, fv = lp.views["template"], lp.views["target"]
        assert tv.camera_group and tv.camera_group == fv.camera_group
        skin = np.flatnonzero(head.component_labels == 0)
        a = int(skin[np.argmax(head.vertices[skin, 0])])  # the far left of the head
        click(tv, a)
        assert lp.pending["template"] == a and s.landmarks == ()
        assert list(tv.markers) == [a] and tv.selected_marker == 0
        assert "your face" in lp.hint.value
        b = nearest(actor, head, a)
        click(fv, b)
        assert len(s.landmarks) == 2  # mirrored
        assert s.landmarks[0] == (a, b)
        assert list(tv.markers) == [p[0] for p in s.landmarks]
        assert list(fv.markers) == [p[1] for p in s.landmarks]
        assert len(lp.pairs.options) == 2 and lp.pairs.index == 0
        assert studio.stages.buttons["refine"].disabled
        # the template models are never edited
        assert not head.history.can_undo and not actor.model.history.can_undo
        # a click on the target first, then the template, with mirror off
        lp.mirror.value = False
        click(fv, 7)
        click(tv, 9)
        assert s.landmarks[-1] == (9, 7) and len(s.landmarks) == 3
        # Alt-click a marker: its pair goes
        fv._on_frontend_msg(fv, {"type": "unpick", "index": 2, "vertex": 7}, [])
        assert len(s.landmarks) == 2
        # drag marker 1 on the target to another vertex: one step "Move landmark 2 (target)"
        target_v = int(s.landmarks[1][1])
        drop = actor.model.vertices[target_v] + [0.3, 0.0, 0.0]
        fv.gestures.on_message("drag", {"type": "drag", "phase": "start", "index": 1, "vertex": target_v, "seq": 1})
        fv.gestures.on_message("drag", {"type": "drag", "phase": "move", "index": 1, "position": drop.tolist(),
                                          "seq": 2})
        fv.gestures.on_message("drag", {"type": "drag", "phase": "end", "index": 1, "seq": 3})
        moved = s.landmarks[1][1]
        assert moved != target_v
        assert np.linalg.norm(actor.model.vertices[moved] - drop) <= np.linalg.norm(
            actor.model.vertices[target_v] - drop)
        assert s.history.undo_labels[-1] == "Move landmark 2 (target)"
        studio.undo()
        assert s.landmarks[1][1] == target_v
        assert studio.landmarks.views["target"].markers[1] == target_v
    finally:
        studio.close()


def test_stages_report_gallery_examples_and_open_in_workbench(head, actor) -> None:
    from widgets import RigStudio

    session = RigSession(head, actor.model)
    studio = RigStudio(session, height=200)
    try:
        st = studio.stages
        assert studio.open_button.disabled
        st.buttons["transfer"].click()
        assert session.stages_done == ("transfer",)
        assert "52 shapes" in st.rows["transfer"].label.value
        assert not st.rows["transfer"].visible
        assert "52 shapes" in studio.report.summary.value
        assert studio.report.table.value.count("<tr") == 53
        # gallery: template + transferred columns, pictures differ (the faces differ)
        imgs = [c for c in studio.gallery.grid.children if c.__class__.__name__ == "Image"]
        assert len(imgs) == 2 * len(studio.gallery.shapes)
        assert imgs[0].value != imgs[1].value
        # picking a shape in the report puts it first in the gallery
        studio.report.show.value = "cheekPuff"
        assert studio.gallery.shapes[0] == "cheekPuff"
        assert studio.tabs.selected_index == 2
        # examples: add from a file, sliders edit the rough weights
        assert st.buttons["refine"].disabled
        for w in ({"jawOpen": 0.8}, {"mouthSmileLeft": 0.9}):
            session.add_example(actor.pose(w), {k: v - 0.2 for k, v in w.items()})
        sl = studio.examples.sliders[("example 1", "jawOpen")]
        assert sl.value == pytest.approx(0.6)
        sl.value = 0.7
        assert session.example("example 1").weights["jawOpen"] == pytest.approx(0.7)
        assert not st.buttons["refine"].disabled
        st.iterations.value = 2
        st.buttons["refine"].click()
        assert session.stages_done == ("transfer", "refine")
        assert "2 examples, 2 iterations" in st.rows["refine"].label.value
        heads = [c.value for c in studio.gallery.grid.children if c.__class__.__name__ == "HTML"]
        assert "<b>refined</b>" in heads
        # undo the refinement: one step, the gallery drops the column
        assert studio.undo() == "Refine from 2 examples"
        heads = [c.value for c in studio.gallery.grid.children if c.__class__.__name__ == "HTML"]
        assert "<b>refined</b>" not in heads
        studio.redo()
        wb = studio.open_in_workbench(height=240)
        assert wb.model is not session.rig
        assert wb.model.shape_names == session.rig.shape_names
        assert studio.opened.children[-1] is wb
        wb.model.set_weight("jawOpen", 1.0)
        assert session.rig.weights.get("jawOpen", 0.0) == 0.0
    finally:
        studio.close()


def test_a_failing_stage_says_why_and_changes_nothing(head) -> None:
    from widgets import RigStudio
    from workbench.model import FaceModel

    sphere = __import__("trimesh").creation.icosphere(subdivisions=3)
    target = FaceModel(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    studio = RigStudio(head, target, height=200)
    try:
        studio.stages.buttons["transfer"].click()
        assert studio.session.stages_done == ()
        assert not studio.session.can_undo
        assert "transfer failed" in studio.stages.rows["transfer"].label.value
        assert studio.errors.count == 1
    finally:
        studio.close()


def test_suggest_adds_named_pairs_in_one_step_with_progress(head, actor) -> None:
    from widgets import RigStudio

    studio = RigStudio(head, actor.model, height=200)
    try:
        lp = studio.landmarks
        seen: list[float] = []
        lp.progress.bar.observe(lambda ch: seen.append(ch["new"]), "value")
        lp.suggest_button.click()
        s = studio.session
        assert len(s.landmarks) >= 10
        assert s.history.undo_labels == [f"Suggest {len(s.landmarks)} landmarks"]
        assert len(seen) >= 3 and "pairs suggested" in lp.progress.label.value
        assert len(lp.views["target"].markers) == len(s.landmarks)
        # each suggested target vertex is near the warped template vertex (ground truth)
        size = np.ptp(actor.model.vertices, axis=0).max()
        for a, b in s.landmarks:
            true = WARP(head.vertices[a][None])[0]
            assert np.linalg.norm(actor.model.vertices[b] - true) < 0.02 * size
        studio.undo()
        assert s.landmarks == () and len(lp.views["target"].markers) == 0
    finally:
        studio.close()
