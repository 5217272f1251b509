"""``workbench app``: the workbench served by Voila, driven in Chromium.

Starts the real command (``python -m workbench.cli app``) on a free port of
127.0.0.1 with temporary Jupyter and recovery dirs, reads the tokened URL it
prints, opens it in Chromium and checks what an app user sees: no code
cells, the viewport drawing the head, and a slider moving the face (state in
the pixels: the jaw region changes). Only the process started here is stopped.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from harness import ARTIFACTS, _free_port, pixel_change

REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.browser


class VoilaApp:
    """``workbench app`` on a free port, started here (and the only process stopped here).

    By default the checkout's (``python -m workbench.cli`` with the repository on
    ``PYTHONPATH``); ``command``: another way to start it (e.g. an installed
    ``venv/bin/workbench``, to which ``app --port=N`` is appended), run with no
    ``PYTHONPATH`` and the working directory ``base``; ``env``: more variables.
    """

    def __init__(self, base: Path, *, command: list[str] | None = None,
                 env: dict[str, str] | None = None) -> None:
        self.base = base
        self.port = _free_port()
        self.log_path = base / "voila.log"
        environ = dict(os.environ)
        environ.update(
            JUPYTER_CONFIG_DIR=str(base / "config"),
            JUPYTER_RUNTIME_DIR=str(base / "runtime"),
            JUPYTER_DATA_DIR=str(base / "data"),
            JUPYTER_PLATFORM_DIRS="1",
            WORKBENCH_RECOVERY_DIR=str(base / "recovery"),
        )
        checkout = command is None
        if command is None:
            command = [sys.executable, "-m", "workbench.cli"]
            environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), environ.get("PYTHONPATH", "")) if p)
        else:
            environ.pop("PYTHONPATH", None)
        environ.update(env or {})
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            [*command, "app", f"--port={self.port}"],
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=environ,
            cwd=None if checkout else base,
        )
        self.url = self._wait_url()

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def _wait_url(self, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        pat = re.compile(rf"http://127\.0\.0\.1:{self.port}/\?token=[0-9a-f]+")
        while time.monotonic() < deadline:
            m = pat.search(self.log())
            if m:
                return m.group(0)
            if self.proc.poll() is not None:
                raise RuntimeError(f"workbench app exited with {self.proc.returncode}:\n{self.log()}")
            time.sleep(0.25)
        raise RuntimeError(f"workbench app printed no URL within {timeout} s:\n{self.log()}")

    def children(self) -> list[int]:
        """PIDs of the server's child processes (its kernels)."""
        try:
            text = Path(f"/proc/{self.proc.pid}/task/{self.proc.pid}/children").read_text()
        except OSError:
            return []
        return [int(p) for p in text.split()]

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        self._log.close()


@pytest.fixture
def app(tmp_path: Path) -> Iterator[VoilaApp]:
    a = VoilaApp(tmp_path)
    try:
        yield a
    finally:
        a.stop()


def test_app_serves_the_workbench_without_code(app: VoilaApp, browser) -> None:
    out = ARTIFACTS / "test_app_serves_the_workbench_without_code"
    out.mkdir(parents=True, exist_ok=True)
    # without the token the server sends a visitor to its login page, not to the app
    import urllib.request

    class NoRedirect(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *args, **kwargs):  # type: ignore[no-untyped-def]
            return None

    import urllib.error

    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.build_opener(NoRedirect).open(app.url.split("?")[0], timeout=10)
    assert refused.value.code == 302 and "/login" in refused.value.headers["Location"]

    page = browser.new_page(viewport={"width": 1500, "height": 1100})
    try:
        page.goto(app.url, timeout=120_000)
        try:
            page.wait_for_function(
                "() => { const e = document.querySelector('.fwb-viewport');"
                " return e && e.getAttribute('data-ready') === '1'; }",
                timeout=180_000,
            )
        except Exception:
            # say where the app stood: the page as drawn, its text and the server's log
            page.screenshot(path=str(out / "not-ready.png"))
            (out / "not-ready-page.txt").write_text(page.inner_text("body")[-4000:])
            (out / "server.log").write_text(app.log())
            raise AssertionError(f"the workbench app drew no ready viewport within 180 s; the page says "
                                 f"{page.inner_text('body')[-300:]!r}; server log tail: {app.log()[-1500:]}") from None
        assert page.locator(".fwb-workbench").count() == 1
        # app mode: the notebook's code is not on the page
        assert "open_workbench" not in page.content()
        assert page.locator(".jp-InputArea-editor, .CodeMirror, .cm-editor").count() == 0
        vp = page.locator(".fwb-viewport")
        vp.scroll_into_view_if_needed()
        box = vp.locator("canvas").bounding_box()
        assert box is not None and box["width"] > 200
        import io

        from PIL import Image

        def shot(name: str) -> np.ndarray:
            png = page.screenshot(path=str(out / f"{name}.png"), clip=box)
            return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

        before = shot("1-neutral")
        assert before.std() > 10, "the viewport is blank"
        frame = int(vp.get_attribute("data-frame") or 0)
        # drag the jawOpen slider to its right end, as a user would
        root = page.locator(".fwb-slider-jawOpen")
        root.evaluate("e => e.scrollIntoView({block: 'center'})")
        hb = root.locator(".noUi-handle").bounding_box()
        track = root.locator(".noUi-base").bounding_box()
        assert hb is not None and track is not None, "the jawOpen slider is not visible"
        page.mouse.move(hb["x"] + hb["width"] / 2, hb["y"] + hb["height"] / 2)
        page.mouse.down()
        page.mouse.move(track["x"] + 0.9 * track["width"], hb["y"] + hb["height"] / 2, steps=12)
        page.mouse.up()
        page.wait_for_function(
            "(f) => Number(document.querySelector('.fwb-viewport').getAttribute('data-frame')) > f",
            arg=frame,
            timeout=30_000,
        )
        page.wait_for_timeout(500)
        vp.scroll_into_view_if_needed()
        box = vp.locator("canvas").bounding_box()
        after = shot("2-jaw-open")
        assert pixel_change(before, after) > 0.01, "the face did not change after the slider drag"
        # one slider drag = one undo step, shown in the status line
        page.wait_for_function(
            "() => (document.querySelector('.fwb-wb-status') || {}).innerText.includes('undo depth 1')",
            timeout=15_000,
        )
    finally:
        page.close()
    # stopping `workbench app` by its PID stops the server and its kernel (no orphans)
    kernels = app.children()
    assert kernels, "the app's kernel is not a child of the process `workbench app` started"
    app.stop()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and any(Path(f"/proc/{k}").exists() for k in kernels):
        time.sleep(0.2)
    alive = [k for k in kernels if Path(f"/proc/{k}").exists() and "zombie" not in _state(k)]
    assert not alive, f"kernels {alive} outlived `workbench app`"


def _state(pid: int) -> str:
    try:
        return "zombie" if Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z" else "running"
    except OSError:
        return "gone"
