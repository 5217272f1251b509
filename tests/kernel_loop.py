"""Run widget code as a notebook kernel runs it: on the UI thread, inside its asyncio loop.

A kernel runs its event loop on its main thread, and the widgets' timers and
playback live on that loop (``widgets/_threading.py``). Tests run it on a fresh
thread declared the UI thread meanwhile (``ui_thread_is``): the session's
Playwright fixture keeps an asyncio loop registered on this process's main
thread, so ``asyncio.run`` there would refuse to start.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
from collections.abc import Callable
from typing import Any


def on_ui_thread(fn: Callable[..., Any], *args: Any, timeout: float = 60.0) -> Any:
    """``fn(*args)`` on a fresh thread that is the UI thread meanwhile."""
    from widgets._threading import ui_thread_is

    def run() -> Any:
        with ui_thread_is(threading.current_thread()):
            return fn(*args)

    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(run).result(timeout=timeout)


def in_kernel_loop(main: Callable[[], Any], timeout: float = 60.0) -> Any:
    """``asyncio.run(main())`` on the UI thread, as a notebook cell or comm handler runs."""
    return on_ui_thread(lambda: asyncio.run(main()), timeout=timeout)
