"""Shared fixtures for the core tests: tiny hand-checkable models.

Every test run has the UI-thread guard on (``WORKBENCH_UI_THREAD_GUARD``, see
``widgets/_threading.py``): a widget changed off the UI thread raises, and a
test after which the guard recorded any violation fails.
"""

from __future__ import annotations

import asyncio
import os
import sys

os.environ.setdefault("WORKBENCH_UI_THREAD_GUARD", "1")

import numpy as np
import pytest
from grid_meshes import grid_polygons

from workbench.model import BlendShape, FaceModel


@pytest.fixture(autouse=True)
def _widgets_stay_on_the_ui_thread():
    """Fail a test after which a widget was changed, or a comm message sent, off the UI thread."""
    guard = sys.modules.get("widgets._threading")
    before = len(guard.thread_violations) if guard is not None else 0
    yield
    guard = sys.modules.get("widgets._threading")
    if guard is not None and len(guard.thread_violations) > before:
        found = guard.thread_violations[before:]
        del guard.thread_violations[before:]
        pytest.fail(f"widgets changed off the UI thread: {found}")


@pytest.fixture(autouse=True)
def _no_foreign_event_loop(request: pytest.FixtureRequest):
    """Run each test that drives no browser with no asyncio loop marked running on this thread.

    Playwright's sync API marks the main thread as running its loop between
    calls (``asyncio._set_running_loop``), for the rest of the session once a
    browser test started it. Widget code would take that loop for a kernel's
    and schedule on it (``widgets._threading.ui_loop``), where nothing runs
    until the next Playwright call; a unit test runs as a script does, with no
    loop.
    """
    if "browser" in request.fixturenames:
        yield
        return
    foreign = asyncio._get_running_loop()
    threading_mod = sys.modules.get("widgets._threading")
    if foreign is not None:
        asyncio._set_running_loop(None)
        if threading_mod is not None and threading_mod._ui_loop is foreign:
            threading_mod._ui_loop = None
    try:
        yield
    finally:
        if foreign is not None:
            asyncio._set_running_loop(foreign)


@pytest.fixture
def tiny_model() -> FaceModel:
    """9 vertices, 4 quads; 'up' lifts the centre vertex by 1, 'left' moves column 0 by -x."""
    V, polys = grid_polygons(2, 2)
    up = np.zeros((9, 3), np.float32)
    up[4, 2] = 1.0
    left = np.zeros((9, 3), np.float32)
    left[[0, 3, 6], 0] = -0.5
    return FaceModel(
        V,
        None,
        [BlendShape("up", up), BlendShape("left", left, slider_min=-1.0, slider_max=2.0)],
        polygons=polys,
    )


# --- The browser harness's health counts (tests/browser/harness.py HEALTH), printed once at the
# end (the line CI logs show). Under pytest-xdist (the test command runs ``-n 2``) they live in
# the worker that ran the browser tests: each worker hands its counts to the controller, which
# prints their sum.
_WORKER_HEALTH: dict[str, int] = {}


def pytest_sessionfinish(session: pytest.Session) -> None:
    out = getattr(session.config, "workeroutput", None)  # set on an xdist worker only
    harness = sys.modules.get("harness")
    if out is not None and harness is not None:
        out["browser_health"] = dict(harness.HEALTH)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error) -> None:  # type: ignore[no-untyped-def]
    for k, v in (getattr(node, "workeroutput", None) or {}).get("browser_health", {}).items():
        _WORKER_HEALTH[k] = _WORKER_HEALTH.get(k, 0) + int(v)


def pytest_terminal_summary(terminalreporter) -> None:  # type: ignore[no-untyped-def]
    harness = sys.modules.get("harness")  # loaded here when the browser tests ran in this process
    health = _WORKER_HEALTH or (dict(harness.HEALTH) if harness is not None else {})
    if any(health.values()):
        terminalreporter.write_line(
            "browser health: " + ", ".join(f"{k} {v}" for k, v in health.items())
            + " (all but 'checked' must be 0)"
        )
