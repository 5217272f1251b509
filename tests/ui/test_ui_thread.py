"""One UI thread: timers on the kernel's loop, the page ends slider drags, a guard catches the rest.

``widgets/_threading.py``. The tests that need a running loop run it as a kernel
does, on the UI thread (``tests/kernel_loop.py``).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
import time
from typing import Any

import ipywidgets as W
import pytest
from kernel_loop import in_kernel_loop, on_ui_thread

import widgets._threading as ui
from widgets import ExpressionPanel, TimelineWidget, Viewport
from widgets._threading import (
    InteractionGrouper,
    UiThreadError,
    UiTimer,
    slider_pointer,
    ui_loop,
)


@pytest.fixture(autouse=True)
def _pointer_released():
    yield
    slider_pointer.held = False


def test_timer_fires_on_the_ui_thread_and_cancel_stops_it() -> None:
    async def main():
        fired: list[Any] = []
        t = UiTimer(0.01, lambda: fired.append(threading.current_thread()))
        cancelled = UiTimer(0.01, lambda: fired.append("cancelled"))
        assert t.armed and cancelled.armed
        cancelled.cancel()
        await asyncio.sleep(0.1)
        return fired, threading.current_thread(), ui_loop() is asyncio.get_running_loop()

    fired, ui_thread, same_loop = in_kernel_loop(main)
    assert fired == [ui_thread] and same_loop


def test_without_a_loop_nothing_is_scheduled() -> None:
    # a UI thread with no event loop (a script); on_ui_thread: this process's main thread may
    # hold the Playwright fixture's loop
    def script() -> tuple[bool, list[int]]:
        fired: list[int] = []
        t = UiTimer(0.0, lambda: fired.append(1))
        time.sleep(0.05)
        return t.armed, fired

    assert on_ui_thread(script) == (False, [])


def test_guard_raises_and_records_a_widget_changed_off_the_ui_thread() -> None:
    slider = W.FloatSlider()
    n = len(ui.thread_violations)

    def off_thread() -> None:
        slider.value = 0.5

    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        with pytest.raises(UiThreadError, match=r"FloatSlider\.value set on thread"):
            pool.submit(off_thread).result()
    assert len(ui.thread_violations) == n + 1
    del ui.thread_violations[n:]  # seen and expected: the autouse check must not fail this test
    slider.value = 0.25  # the UI thread may
    assert slider.value == 0.25


def test_a_slider_drag_is_one_undo_step_ended_by_the_pages_release(tiny_model) -> None:
    m = tiny_model

    async def main():
        g = InteractionGrouper(m, idle_s=0.05)
        slider_pointer.down()
        for k in range(5):
            g.touch("Drag up")
            m.set_weight("up", 0.1 * (k + 1))
            await asyncio.sleep(0.08)  # late messages: longer than the idle time
        held = g.active and m.interacting
        slider_pointer.up()
        return held, g.active

    held, still_open = in_kernel_loop(main)
    assert held and not still_open
    assert m.history.undo_labels[-1:] == ["Drag up"] and len(m.history.undo_labels) == 1
    assert m.weights["up"] == pytest.approx(0.5)


def test_without_a_press_the_idle_timer_ends_the_burst(tiny_model) -> None:
    m = tiny_model

    async def main():
        g = InteractionGrouper(m, idle_s=0.05)
        g.touch("Drag up")  # e.g. an arrow key on the slider
        m.set_weight("up", 0.3)
        opened = m.interacting
        await asyncio.sleep(0.2)
        return opened, m.interacting

    opened, still = in_kernel_loop(main)
    assert opened and not still and m.history.undo_labels == ["Drag up"]


def test_a_page_that_vanished_mid_drag_is_covered_by_the_watchdog(tiny_model) -> None:
    m = tiny_model

    async def main():
        g = InteractionGrouper(m, idle_s=0.01, watchdog_s=0.15)
        slider_pointer.down()
        g.touch("Drag up")
        m.set_weight("up", 0.3)
        await asyncio.sleep(0.05)
        mid = m.interacting  # held: the short idle time does not end it
        await asyncio.sleep(0.3)
        return mid, m.interacting

    mid, after = in_kernel_loop(main)
    assert mid and not after and m.history.undo_labels == ["Drag up"]


def test_viewport_message_releases_the_expression_panels_drag(tiny_model) -> None:
    m = tiny_model
    vp = Viewport(m)
    panel = ExpressionPanel(m, idle_s=30.0)
    vp._on_frontend_msg(vp, {"type": "slider_pointer", "phase": "down"}, [])
    for v in (0.2, 0.4, 0.6):
        panel.sliders["up"].value = v
    assert m.interacting and m.history.undo_labels == []
    vp._on_frontend_msg(vp, {"type": "slider_pointer", "phase": "up"}, [])
    assert not m.interacting and m.history.undo_labels == ["Drag up"]
    assert m.weights["up"] == pytest.approx(0.6)
    panel.close()
    vp.close()


def test_playback_needs_the_kernels_loop(tiny_model) -> None:
    w = TimelineWidget(tiny_model)

    def script() -> None:
        w.play()

    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        with pytest.raises(RuntimeError, match="needs a running event loop"):
            pool.submit(script).result()
    assert not w.playing
    w.close()


def test_widget_comm_messages_are_routed_to_the_main_shell_whatever_the_page_asks() -> None:
    """ipykernel 7.4 asks a comm which subshell its incoming messages go to: widget comms answer the main one."""
    from ipykernel.comm.comm import BaseComm

    assert ui.route_widget_comms_to_main_thread()
    assert ui.route_widget_comms_to_main_thread()  # once is enough; again changes nothing
    widget_comm = BaseComm(target_name=ui.WIDGET_COMM_TARGET, data={})
    other = BaseComm(target_name="some.other.target", data={})
    # a message the page sent on subshell "s-1": the widget's goes to the main shell (None)
    assert widget_comm._reply_subshell_for({"method": "update"}, "s-1") is None
    # so does the control comm's request_states (it reads every widget's state)
    control = BaseComm(target_name=ui.WIDGET_CONTROL_TARGET, data={})
    assert control._reply_subshell_for({"method": "request_states"}, "s-1") is None
    # other comms keep ipykernel's own routing (here: back to where the page asked)
    assert other._reply_subshell_for({"method": "update"}, "s-1") == "s-1"
    assert BaseComm._reply_subshell_for._fwb_main_thread
