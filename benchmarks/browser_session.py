"""Shared set-up of the real-browser benchmarks: one JupyterLab, one Chromium, a notebook per size.

The browser benchmarks (``bench_viewport_latency``, ``bench_drag_latency``,
``bench_paint``, ``bench_playback``) all measure the same way: start a
JupyterLab of their own on 127.0.0.1 (the test harness's
:class:`harness.LabServer`), open a fresh notebook per sample resolution in
Debian's Chromium (software WebGL), run its set-up cell, wait for the viewport
and hand the page to a measuring function. A failure at one size is reported
with a screenshot and the next size still runs.
"""

from __future__ import annotations

import contextlib
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests" / "browser"))

from harness import CHROMIUM, CHROMIUM_ARGS, LabServer, NotebookPage, write_notebook  # noqa: E402

__all__ = ["CHROMIUM", "REPO", "NotebookPage", "chromium_missing", "each_resolution", "lab_and_browser"]


def chromium_missing() -> bool:
    """Print how to install Chromium and return True when it is missing."""
    if CHROMIUM.exists():
        return False
    print(f"{CHROMIUM} is missing: apt-get install chromium", file=sys.stderr)
    return True


def each_resolution(
    tag: str,
    resolutions: Sequence[str],
    setup_cell: Callable[[str], str],
    measure: Callable[[str, NotebookPage], list[tuple[Any, ...]]],
    *,
    viewport: dict[str, int] | None = None,
    browser_args: Sequence[str] = (),
) -> list[tuple[Any, ...]]:
    """Run ``measure(res, nb)`` in a fresh notebook for every sample resolution.

    Parameters
    ----------
    tag : str
        Names the notebooks, the JupyterLab workspace and ``test-artifacts/<tag>/``.
    resolutions : sequence of str
        Sample head resolutions (``"base"``, ``"25k"``, ``"100k"``, ...).
    setup_cell : callable
        ``setup_cell(res) -> str``: the notebook's only cell; it must display one viewport.
    measure : callable
        ``measure(res, nb) -> rows``; its rows are concatenated in order.
    viewport : dict, optional
        Browser window size, default 1400 x 1000.
    browser_args : sequence of str
        More Chromium switches (e.g. a fake camera).

    Returns
    -------
    rows : list of tuple
    """
    rows: list[tuple[Any, ...]] = []
    with lab_and_browser("fwb-bench-", browser_args) as (lab, browser):
        for res in resolutions:
            name = f"bench_{tag}_{res}.ipynb"
            write_notebook(lab.root / name, [setup_cell(res)])
            ctx = browser.new_context(viewport=viewport or {"width": 1400, "height": 1000})
            page = ctx.new_page()
            nb = NotebookPage(page, lab, REPO / "test-artifacts" / f"bench-{tag}", name)
            page.goto(f"{lab.url}/lab/workspaces/bench-{tag}-{res}/tree/{name}?reset")
            try:
                nb.wait_kernel_idle()
                nb.run_all(timeout=900)
                nb.wait_viewports(1, timeout=120)
                rows.extend(measure(res, nb))
            except Exception as exc:  # report and go on with the next size
                print(f"[{res}] failed: {type(exc).__name__}: {exc}", file=sys.stderr)
                nb.screenshot(f"failed-{res}")
            finally:
                ctx.close()
                lab.shutdown_kernels()
    return rows


@contextlib.contextmanager
def lab_and_browser(prefix: str, browser_args: Sequence[str] = ()) -> Iterator[tuple[LabServer, Any]]:
    """A JupyterLab of our own (temporary dirs, 127.0.0.1) and Debian's headless Chromium.

    Both are stopped on exit, whatever happened inside.
    """
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        lab = LabServer(Path(tmp))
        lab.start()
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(
                    executable_path=str(CHROMIUM), headless=True, args=[*CHROMIUM_ARGS, *browser_args]
                )
                try:
                    yield lab, browser
                finally:
                    browser.close()
        finally:
            lab.stop()
