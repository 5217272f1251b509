"""The viewport's one gesture protocol (widgets/viewport/gestures.py), without a browser.

A fake comm plays the front end's gesture client (widgets/js/src/viewport/gestures.js):
it keeps one message in flight and sends only the newest pointer position when the
ack arrives. Checked on a 3x3 grid with one handle: every message is acked with its
seq and timing, a drag is one undo step, cancel puts everything back, and messages of
a gesture another widget closed (a stale token) are refused.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("anywidget")

from widgets._threading import InteractionGrouper, close_interactions
from widgets.viewport import BUNDLE, Viewport
from widgets.viewport.gestures import Gesture, GestureDispatcher
from workbench.model import BlendShape, FaceModel, ModelError
from workbench.testing import grid_polygons

pytestmark = pytest.mark.skipif(not BUNDLE.exists(), reason="viewport bundle not built")


def _grid() -> FaceModel:
    V, quads = grid_polygons(2, 2)  # 3 x 3 vertices, 4 quads
    one = np.zeros((9, 3), np.float32)
    one[4, 2] = 1.0
    m = FaceModel(V, None, [BlendShape("jawOpen", one)], polygons=quads)
    m.handles.add(4, name="centre")
    return m


def up(p, dz):
    return np.asarray(p, float) + np.array([0.0, 0.0, dz])


class FakeFrontEnd:
    """The front end's gesture client over a fake comm: one message in flight, newest wins.

    ``vp.send`` is replaced: what the kernel sends is queued and delivered by
    :meth:`deliver` (as the browser would receive it later), so a pointer move made
    while a message is in flight waits, and only the newest one goes.
    """

    def __init__(self, vp: Viewport) -> None:
        self.vp = vp
        self.inbox: list[dict] = []
        self.sent: list[dict] = []
        self.seq = 0
        self.in_flight = 0
        self.pending: list[float] | None = None
        self.gesture = "g-1"
        vp.send = lambda content, buffers=None: self.inbox.append(content)  # type: ignore[method-assign]

    def _send(self, phase: str, **body) -> None:
        self.seq += 1
        msg = {"type": "drag", "phase": phase, "gesture": self.gesture, "seq": self.seq,
               "index": 0, "vertex": 4, **body}  # fmt: skip
        self.sent.append(msg)
        if phase in ("start", "move"):
            assert not self.in_flight, "a second message was sent while one was in flight"
            self.in_flight = self.seq
        self.vp._on_frontend_msg(self.vp, msg, [])

    def press(self, position) -> None:
        self._send("start", position=list(position))

    def move(self, position) -> None:
        self.pending = list(position)
        if not self.in_flight:
            self._send("move", position=self.pending)
            self.pending = None

    def release(self, position) -> None:
        self._send("end", position=list(position))

    def deliver(self) -> list[dict]:
        """The browser receives what the kernel sent: acks free the channel."""
        got, self.inbox = self.inbox, []
        for c in got:
            if c.get("seq") == self.in_flight and c["type"] in ("drag_ack", "patch"):
                self.in_flight = 0
                if self.pending is not None:
                    p, self.pending = self.pending, None
                    self._send("move", position=p)
        return got


def test_one_message_in_flight_every_message_acked_with_seq_and_timing_one_undo_step():
    m = _grid()
    vp = Viewport(m)
    fe = FakeFrontEnd(vp)
    p0 = m.evaluate()[4].astype(float)
    fe.press(p0)
    assert m.interacting and m.interaction_token is not None and vp.dragging
    # five pointer moves while the start is still in flight: only the newest goes
    for k in range(1, 6):
        fe.move(up(p0, 0.1 * k))
    assert [s["phase"] for s in fe.sent] == ["start"]
    got = fe.deliver()
    assert [s["phase"] for s in fe.sent] == ["start", "move"]
    assert fe.sent[-1]["position"] == pytest.approx(list(up(p0, 0.5)))
    got += fe.deliver()
    fe.release(up(p0, 0.6))
    got += fe.deliver()
    acks = [c for c in got if c["type"] == "drag_ack"]
    assert [a["seq"] for a in acks] == [s["seq"] for s in fe.sent]
    assert [a["phase"] for a in acks] == ["start", "move", "end"]
    for a in acks:
        assert isinstance(a["kernel_ms"], float) and a["kernel_ms"] >= 0
        assert a["version"] == vp._version or a["version"] <= vp._version
    assert acks[1]["kernel_ms"] > 0  # the move did work
    assert not m.interacting and not vp.dragging
    assert m.history.undo_labels[-1] == "Drag handle centre"
    np.testing.assert_allclose(m.evaluate()[4], up(p0, 0.6), atol=1e-5)
    assert vp.last_drag["moves"] == 2  # the move and the release's last position
    m.undo()
    np.testing.assert_allclose(m.evaluate()[4], p0, atol=1e-6)


def test_cancel_puts_everything_back_without_an_undo_step():
    m = _grid()
    vp = Viewport(m)
    fe = FakeFrontEnd(vp)
    p0 = m.evaluate()[4].astype(float)
    steps = list(m.history.undo_labels)
    fe.press(p0)
    fe.deliver()
    fe.move(up(p0, 0.3))
    fe.deliver()
    assert m.evaluate()[4][2] == pytest.approx(0.3, abs=1e-5)
    fe._send("cancel")
    got = fe.deliver()
    assert [c["phase"] for c in got if c["type"] == "drag_ack"] == ["cancel"]
    assert not m.interacting and not vp.dragging
    np.testing.assert_allclose(m.evaluate()[4], p0, atol=1e-6)
    assert m.history.undo_labels == steps  # no undo step
    # the Python API does the same
    vp.begin_drag(0)
    vp.drag_to(up(p0, 0.2))
    vp.cancel_gesture()
    assert not m.interacting and m.history.undo_labels == steps
    np.testing.assert_allclose(m.evaluate()[4], p0, atol=1e-6)


def test_a_gesture_closed_by_another_widget_refuses_its_late_messages():
    m = _grid()
    vp = Viewport(m)
    fe = FakeFrontEnd(vp)
    p0 = m.evaluate()[4].astype(float)
    fe.press(p0)
    fe.deliver()
    fe.move(up(p0, 0.2))
    fe.deliver()
    token = m.interaction_token
    # another widget's discrete edit (Key, Import, undo) closes the drag first
    close_interactions(m)
    assert not m.interacting and not vp.dragging
    assert m.history.undo_labels[-1] == "Drag handle centre"  # its edits kept: one step
    got = fe.deliver()
    assert {"type": "drag_cancel", "gesture": "g-1"} in got  # the front end is told to stop
    # the stale token is refused by the model ...
    with pytest.raises(ModelError):
        m.end_interaction(token)
    # ... and the gesture's late messages by the viewport: no edit, no new interaction
    n_steps = len(m.history.undo_labels)
    fe.in_flight = 0
    fe.move(up(p0, 0.9))
    fe.release(up(p0, 0.9))
    got = fe.deliver()
    acks = [c for c in got if c["type"] == "drag_ack"]
    assert [a.get("stale") for a in acks] == [True, True]
    assert vp.gestures.refused == 2
    assert not m.interacting and len(m.history.undo_labels) == n_steps
    assert m.evaluate()[4][2] == pytest.approx(0.2, abs=1e-5)


def test_messages_of_another_press_are_refused():
    m = _grid()
    vp = Viewport(m)
    fe = FakeFrontEnd(vp)
    p0 = m.evaluate()[4].astype(float)
    fe.press(p0)
    fe.deliver()
    fe.gesture = "g-old"  # e.g. a second view's stray message
    fe.move(up(p0, 0.5))
    got = fe.deliver()
    assert got[-1]["type"] == "drag_ack" and got[-1]["stale"] is True
    assert m.evaluate()[4][2] == pytest.approx(0.0, abs=1e-6) and vp.dragging
    fe.gesture = "g-1"
    fe.release(up(p0, 0.1))
    fe.deliver()
    assert not m.interacting and m.evaluate()[4][2] == pytest.approx(0.1, abs=1e-5)


def test_a_new_press_ends_the_open_gesture_and_a_slider_burst():
    m = _grid()
    vp = Viewport(m)
    fe = FakeFrontEnd(vp)
    grouper = InteractionGrouper(m, idle_s=30.0)
    grouper.touch("Drag jawOpen")
    m.set_weight("jawOpen", 0.5)
    assert grouper.active and m.interacting
    p0 = m.evaluate()[4].astype(float)
    fe.press(p0)  # closes the slider burst first: its own undo step
    assert not grouper.active and vp.dragging
    assert m.history.undo_labels[-1] == "Drag jawOpen"
    # a slider echo during the drag joins the drag; it does not end it
    grouper.touch("Drag jawOpen")
    assert vp.dragging and not grouper.active
    fe.deliver()
    fe.release(up(p0, 0.1))
    assert m.history.undo_labels[-1] == "Drag handle centre"
    grouper.flush()


def test_the_dispatcher_runs_any_gesture():
    """A Gesture subclass gets begin / update / end and the token bookkeeping for free."""

    class Nudge(Gesture):
        kind = "drag"

        def start(self, content):
            self.open_interaction("Nudge")
            return 0.0

        def has_update(self, content):
            return "dz" in content

        def apply(self, content):
            self.model.handles.move(0, [0.0, 0.0, float(content["dz"])])

    m = _grid()
    sent: list[dict] = []

    class FakeView:
        model = m
        _version = 0
        errors = None

        class sync:  # stands in for SceneSync
            @staticmethod
            def patching(seq):
                import contextlib

                return contextlib.nullcontext()

        def send(self, content, buffers=None):
            sent.append(content)

    d = GestureDispatcher(FakeView(), {"drag": lambda c: Nudge(FakeView())})
    d.on_message("drag", {"phase": "start", "seq": 1})
    d.on_message("drag", {"phase": "move", "seq": 2, "dz": 0.25})
    d.on_message("drag", {"phase": "end", "seq": 3, "dz": 0.5})
    assert [c["seq"] for c in sent] == [1, 2, 3]
    assert m.history.undo_labels[-1] == "Nudge" and not m.interacting
    assert float(m.handles.offsets[0, 2]) == pytest.approx(0.5)
