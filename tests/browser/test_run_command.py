"""The README's run command, ``bash .ci/workbench run``, as a new user runs it.

It must print a URL that opens the workbench notebook in JupyterLab (not the
launcher), bind 127.0.0.1 only, refuse visitors without the token, work when
the user is root (containers), and stop — kernel included — when the process
it started is stopped by its PID. Jupyter's config/data/runtime dirs and the
recovery dir are temporary, so the test leaves nothing in the user's home.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import socket
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from harness import ARTIFACTS, NotebookPage, _free_port, wait_until

REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.browser


@pytest.fixture
def run_command(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[bytes], str, Path]]:
    port = _free_port()
    log = tmp_path / "run.log"
    env = dict(os.environ)
    env.update(
        WORKBENCH_PORT=str(port),
        JUPYTER_CONFIG_DIR=str(tmp_path / "config"),
        JUPYTER_DATA_DIR=str(tmp_path / "data"),
        JUPYTER_RUNTIME_DIR=str(tmp_path / "runtime"),
        JUPYTER_PLATFORM_DIRS="1",
        WORKBENCH_RECOVERY_DIR=str(tmp_path / "recovery"),
    )
    env.pop("WORKBENCH_RESOLUTION", None)  # the notebook's own default, as a new user gets it
    with open(log, "wb") as fh:
        proc = subprocess.Popen(
            ["bash", str(REPO / ".ci" / "workbench"), "run"], stdout=fh, stderr=subprocess.STDOUT, env=env
        )
    try:
        url = ""
        deadline = time.monotonic() + 600  # the first run may install packages
        pat = re.compile(r"http://127\.0\.0\.1:(\d+)/lab/tree/notebooks/workbench\.ipynb\?token=[0-9a-f]+")
        while time.monotonic() < deadline and not url:
            m = pat.search(log.read_text(errors="replace"))
            if m:
                url = m.group(0)
                assert int(m.group(1)) == port
            elif proc.poll() is not None:
                pytest.fail(f"bash .ci/workbench run exited with {proc.returncode}:\n{log.read_text()[-3000:]}")
            else:
                time.sleep(0.5)
        assert url, f"no URL printed:\n{log.read_text()[-3000:]}"
        while time.monotonic() < deadline:  # the URL is printed just before the server starts
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=5)
            except urllib.error.HTTPError:
                break  # 403 without the token: it answers
            except OSError:
                if proc.poll() is not None:
                    pytest.fail(f"JupyterLab exited with {proc.returncode}:\n{log.read_text()[-3000:]}")
                time.sleep(0.5)
            else:
                break
        yield proc, url, log
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)


def _outside_address() -> str | None:
    """An address of this machine that is not loopback (None when there is none)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("10.255.255.255", 1))  # no packet is sent for UDP connect
            addr = s.getsockname()[0]
        except OSError:
            return None
    return None if addr.startswith("127.") else addr


@pytest.fixture
def keep_notebook() -> Iterator[None]:
    """The server's root is the checkout: put back the notebook JupyterLab saves after running."""
    nb = REPO / "notebooks" / "workbench.ipynb"
    original = nb.read_bytes()
    try:
        yield
    finally:
        nb.write_bytes(original)


def test_run_command_opens_the_workbench_notebook(keep_notebook, run_command, browser) -> None:
    proc, url, log = run_command
    port = int(url.split(":")[2].split("/")[0])
    # the token is required ...
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(f"http://127.0.0.1:{port}/api/contents/notebooks", timeout=10)
    assert refused.value.code in (401, 403)
    token = url.split("token=")[1]
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/contents/notebooks?token={token}", timeout=10) as r:
        assert r.status == 200
    # ... and only loopback listens
    outside = _outside_address()
    if outside is not None:
        with pytest.raises(OSError), socket.create_connection((outside, port), timeout=3):
            pass
    # the printed URL opens the workbench notebook itself, with a kernel
    out = ARTIFACTS / "test_run_command_opens_the_workbench_notebook"
    out.mkdir(parents=True, exist_ok=True)
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    nb = NotebookPage(page, None, out, "run_command")  # type: ignore[arg-type]  # console from the start
    try:
        page.goto(url, timeout=120_000)
        tab = page.locator(".lm-DockPanel .lm-TabBar-tab.lm-mod-current .lm-TabBar-tabLabel")
        tab.wait_for(timeout=120_000)
        assert tab.inner_text() == "workbench.ipynb"
        page.wait_for_function(
            "() => (document.querySelector('.jp-Notebook') || {innerText: ''})"
            ".innerText.includes('Facial Editing Workbench')",
            timeout=60_000,
        )
        page.screenshot(path=str(out / "opened.png"))
        # as the README says, once the status bar shows the kernel Idle: JupyterLab silently skips
        # cells run before its kernel connects (jupyterlab#8490; test_jupyterlab_upstream.py shows it)
        page.locator("#jp-main-statusbar", has_text="Idle").wait_for(timeout=120_000)
        # Run > Run All Cells from the menu bar, as the README says: the head is drawn
        page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
        page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()
        nb.wait_viewports(1, timeout=300)
        # the notebook's default: the 25k sample head (20,051 vertices), rig on the GPU
        assert nb.viewport().get_attribute("data-vertex-count") == "20051"
        wait_until("GPU evaluation", lambda: nb.viewport().get_attribute("data-gpu"), lambda v: v == "1")
        assert nb.viewport().get_attribute("data-error") in (None, "")
        page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
        page.wait_for_timeout(300)
        head = nb.canvas_shot("workbench_drawn")
        # a drawn, shaded head, not an empty canvas: many distinct grey levels
        assert len(np.unique(head[..., :3].reshape(-1, 3) // 8, axis=0)) > 50
        # JupyterLab asks for news consent in a toast over the tabs a few seconds after it opens
        # (shown by now without the run command's overrides.json); the workbench's lab asks nothing
        assert page.get_by_text("Jupyter news").count() == 0
    except Exception:
        # what the user would have seen, the cells' state and the page's console, for the diagnosis
        with contextlib.suppress(Exception):
            page.screenshot(path=str(out / "failed.png"), full_page=True)
        with contextlib.suppress(Exception):
            (out / "notebook-state.json").write_text(json.dumps(nb.state(), indent=1, default=str))
        (out / "console.log").write_text("\n".join(nb.console))
        (out / "server.log").write_text(log.read_text()[-20000:])
        raise
    finally:
        page.close()
    # stopping the process the command started stops JupyterLab (it execs the server)
    proc.terminate()
    proc.wait(timeout=30)
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=3)
    assert "Running as root is not recommended" not in log.read_text()
