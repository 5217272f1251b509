"""Kernel-side playback of a :class:`~widgets.timeline.TimelineWidget`, with frame flow control.

Playback runs in the kernel, not the browser: every frame must evaluate the
model (weights, handle layer) and the viewport ships the new vertices, which
only Python can do. An asyncio task on the kernel's event loop computes the
frame due from the wall clock, calls ``model.set_time`` for it and sleeps until
the next frame; when a frame takes longer than ``1/fps`` the frames that fell
due meanwhile are *dropped* (never queued), so playback keeps real time and the
kernel stays responsive (Pause is a comm message handled between frames).

Dropping in the kernel is not enough: a browser drawing with software WebGL can
render fewer frames per second than the kernel sends, and the geometry messages
would then pile up in the websocket (the view lags further and further behind,
and Pause takes effect seconds late). So after each frame the kernel sends a
small ``{"type": "frame", "seq"}`` message; the front end answers
``frame_ack`` from its next animation frame (after the viewport drew the
geometry that arrived before it), and playback sends a new frame only while
fewer than :data:`FRAMES_IN_FLIGHT` frames are unanswered (waiting at most
:data:`FRAME_ACK_TIMEOUT_S`). When no view answers at all (nothing displayed,
a headless run), playback stops waiting after the first timeout. The achieved
rate is shown in the status label and kept in the widget's ``playback_stats``.

When every viewport of the model evaluates the rig on the GPU
(:func:`widgets.viewport.gpu.clip_players`), playback runs in the browser
instead: the viewports get the parameters of every frame once
(``GpuSync.prepare_clip``) and play them from their own clock; the kernel only
moves the timeline's playhead (the ``time`` trait) and, at the end or on Pause,
sets the model to the frame shown (``model.set_time``, one exact update).
``playback_stats["browser"]`` tells which ran.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np

from widgets.viewport.gpu import clip_players
from workbench.model import ModelError

if TYPE_CHECKING:
    from widgets.timeline.widget import TimelineWidget

#: seconds between status-label updates during playback
STATUS_PERIOD_S = 0.5

#: playback waits at most this long for the browser to show an earlier frame
FRAME_ACK_TIMEOUT_S = 0.5

#: frames sent but not yet drawn by the browser: 2 lets the kernel prepare the next
#: frame while the browser draws the current one, and still bounds the backlog
FRAMES_IN_FLIGHT = 2


class Playback:
    """The playback task of one timeline widget and its frame acknowledgements.

    It drives the widget's traits (``playing``, ``loop``, ``status``) and
    counters (``frames_shown``, ``frames_dropped``, ``playback_stats``, the
    ``frame_ack_timeout`` setting) and calls ``model.set_time`` for each frame.
    """

    def __init__(self, widget: TimelineWidget) -> None:
        self.widget = widget
        self.frame_seq = 0  # the last "frame" message sent
        self.ack_seq = 0  # the newest frame the front end answered
        self._ack_event: asyncio.Event | None = None
        self.task: asyncio.Task[dict[str, Any]] | None = None

    def start(self) -> asyncio.Task[dict[str, Any]]:
        """Start the task on the running loop (or return the running one): see ``TimelineWidget.play``.

        Playback lives on the kernel's event loop, on the UI thread, like every
        widget change it makes; where no loop runs (a plain script) there is
        nothing to play on, and a clear error says how to run one.
        """
        w = self.widget
        if self.task is not None and not self.task.done():
            return self.task
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            raise RuntimeError(
                "TimelineWidget.play() needs a running event loop (a notebook kernel has one); "
                "in a script, run it inside one: asyncio.run(main()) with "
                "'await widget.play(loop=False)' in main()"
            ) from None
        w.playing = True
        self.task = running.create_task(self.run())
        return self.task

    def on_ack(self, seq: int) -> None:
        """The front end drew frame ``seq`` (its message arrives on the UI thread)."""
        self.ack_seq = max(self.ack_seq, seq)
        if self._ack_event is not None:
            self._ack_event.set()

    async def run(self) -> dict[str, Any]:
        w = self.widget
        model = w.model
        frames = dropped = 0
        set_ms: deque[float] = deque(maxlen=600)
        done_at: deque[float] = deque()
        started = time.perf_counter()
        last_status = started
        self._ack_event = asyncio.Event()
        # None: no front end has acknowledged a frame of this run yet
        acks_seen: bool | None = None
        seq0 = self.frame_seq  # acks above this belong to this run
        # frames of an earlier run that were never answered must not stall this one
        self.ack_seq = max(self.ack_seq, seq0)
        try:
            tl = model.timeline.value
            fps, start, end = tl.fps, tl.start, tl.end
            if not end > start:
                w.status = "nothing to play: key at two different times first"
                return self.stats(0, 0, fps, set_ms, 0.0, done_at)
            t_now = model.time
            media0 = t_now if start <= t_now < end - 0.5 / fps else start
            players = clip_players(model)
            if players and all(g.prepare_clip() for g in players):
                return await self.run_in_browser(players, fps, start, end, media0)
            clock0 = time.perf_counter()
            next_f = 0
            while w.playing:
                now = time.perf_counter()
                tl = model.timeline.value
                if tl.fps != fps or tl.start != start or tl.end != end:
                    # fps/range edited while playing: continue from the current time
                    fps, start, end = tl.fps, tl.start, tl.end
                    media0 = min(max(model.time, start), end)
                    clock0, next_f = now, 0
                f = max(next_f, math.floor((now - clock0) * fps + 1e-6))
                dropped += f - next_f  # frames that fell due while the last one ran
                t_media = media0 + f / fps
                if t_media > end + 1e-9:
                    if not w.loop or not end > start:
                        if model.time != end:
                            model.set_time(end)
                            frames += 1
                        break
                    media0, clock0, f, t_media = start, now, 0, start
                t0 = time.perf_counter()
                try:
                    model.set_time(t_media)
                except ModelError:  # a slider/handle drag is open: skip this frame
                    dropped += 1
                else:
                    frames += 1
                    self.frame_seq += 1
                    w.send({"type": "frame", "seq": self.frame_seq})
                t1 = time.perf_counter()
                set_ms.append((t1 - t0) * 1e3)
                if acks_seen is not False and w.frame_ack_timeout > 0:
                    # Flow control: the next frame goes out once the browser has drawn
                    # all but FRAMES_IN_FLIGHT - 1 of the frames sent, so geometry never
                    # queues up in the websocket; frames that fall due meanwhile are
                    # dropped by the wall-clock rule above.
                    ok = await self._wait_ack(
                        self.frame_seq - (FRAMES_IN_FLIGHT - 1), w.frame_ack_timeout
                    )
                    if ok:
                        if self.ack_seq > seq0:
                            acks_seen = True
                    elif acks_seen is None:
                        acks_seen = False  # nobody draws this widget (e.g. headless run)
                    t1 = time.perf_counter()
                done_at.append(t1)
                while done_at and t1 - done_at[0] > 1.0:
                    done_at.popleft()
                next_f = f + 1
                w.frames_shown, w.frames_dropped = frames, dropped
                if t1 - last_status >= STATUS_PERIOD_S:
                    last_status = t1
                    st = self.stats(frames, dropped, fps, set_ms, t1 - started, done_at)
                    w.playback_stats = st
                    w.status = f"playing {st['fps']:.1f}/{fps:g} fps, {dropped} dropped"
                # always yield to the loop, so Pause and other comm messages get in
                await asyncio.sleep(max(clock0 + next_f / fps - time.perf_counter(), 0.0))
            st = self.stats(frames, dropped, fps, set_ms, time.perf_counter() - started, done_at)
            w.playback_stats = st
            w.status = (
                f"played {frames} frames at {st['mean_fps']:.1f}/{fps:g} fps, {dropped} dropped"
            )
            return st
        except Exception as exc:
            w.errors.report("timeline playback", exc)
            raise
        finally:
            w.playing = False

    async def run_in_browser(
        self, players: list[Any], fps: float, start: float, end: float, media0: float
    ) -> dict[str, Any]:
        """Playback on the viewports' own clocks: the kernel moves the playhead only."""
        w = self.widget
        model = w.model
        for g in players:
            g.play(media0, end, w.loop)
        clock0 = started = time.perf_counter()
        last_status = started
        ticks = 0
        done_at: deque[float] = deque()
        t_media = media0
        try:
            while w.playing:
                now = time.perf_counter()
                t_media = browser_time(media0, now - clock0, start, end, w.loop)
                ticks += 1
                w.time = t_media
                done_at.append(now)
                while done_at and now - done_at[0] > 1.0:
                    done_at.popleft()
                if now - last_status >= STATUS_PERIOD_S:
                    last_status = now
                    st = self.stats(ticks, 0, fps, deque(), now - started, done_at)
                    w.playback_stats = {**st, "browser": True}
                    w.status = f"playing in the browser at {fps:g} fps"
                if not w.loop and t_media >= end:
                    break
                await asyncio.sleep(1.0 / fps)
        finally:
            for g in players:
                g.stop()
        # the frame shown, exactly, from the kernel (not an undo step)
        t_final = min(max(start + round((t_media - start) * fps) / fps, start), end)
        try:
            model.set_time(t_final)
        except ModelError:
            pass  # a drag is open: it keeps its state
        st = self.stats(ticks, 0, fps, deque(), time.perf_counter() - started, done_at)
        w.playback_stats = {**st, "browser": True}
        w.status = f"played in the browser at {fps:g} fps"
        return w.playback_stats

    async def _wait_ack(self, seq: int, timeout: float) -> bool:
        """Wait until the front end acknowledged frame ``seq`` (False on timeout or pause)."""
        event = self._ack_event
        assert event is not None
        deadline = time.perf_counter() + timeout
        while self.ack_seq < seq:
            remaining = deadline - time.perf_counter()
            if remaining <= 0 or not self.widget.playing:
                return False
            event.clear()
            if self.ack_seq >= seq:
                break
            try:
                await asyncio.wait_for(event.wait(), remaining)
            except TimeoutError:
                return False
        return True

    @staticmethod
    def stats(
        frames: int,
        dropped: int,
        fps: float,
        set_ms: deque[float],
        seconds: float,
        done_at: deque[float],
    ) -> dict[str, Any]:
        recent = (
            (len(done_at) - 1) / (done_at[-1] - done_at[0])
            if len(done_at) > 1 and done_at[-1] > done_at[0]
            else 0.0
        )
        return {
            "frames": frames,
            "dropped": dropped,
            "target_fps": fps,
            "fps": recent,  # over the last second
            "mean_fps": frames / seconds if seconds > 0 else 0.0,
            "seconds": seconds,
            "set_time_ms": float(np.median(set_ms)) if set_ms else 0.0,
        }


def browser_time(media0: float, elapsed: float, start: float, end: float, loop: bool) -> float:
    """Timeline time ``elapsed`` seconds after playing from ``media0`` (the browser's rule too)."""
    t = media0 + elapsed
    if t <= end:
        return t
    if not loop or not end > start:
        return end
    return start + (t - start) % (end - start)
