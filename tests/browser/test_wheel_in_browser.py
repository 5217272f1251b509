"""The wheel, installed like a user installs it, works in Chromium (issue #31's install proof).

Builds the sdist and the wheel of this checkout (the ``dist`` / ``wheel`` fixtures of
``tests/test_wheel.py``: ``python -m build --no-isolation``), creates a fresh venv under
the test's tmp dir (outside the repository) and ``pip install``\\ s
``face_workbench-*.whl[ui]`` and ``notebook>=7`` into it WITH their dependencies (the
package index and pip's cache, as a user's ``pip install`` does); the wheel's size and
the install time are printed. Then, from that venv only — its python serves, the working
directory and the server root are outside the repository, no ``PYTHONPATH`` — in Chromium:

* **JupyterLab 4** and **Notebook 7** (``python -m jupyterlab`` / ``python -m notebook``
  through :class:`harness.LabServer`) open a notebook that does
  ``wb = Workbench(load_sample("head")); wb``. In the kernel, ``workbench`` and
  ``widgets`` are imported from the venv and nothing of the checkout is on ``sys.path``.
  The head draws (the viewport is ready, the canvas is covered by a shaded head); a mouse
  drag of the jawOpen slider sets the model's weight and changes the mouth's pixels;
  Export in the Export tab (path typed, button pressed) writes a .glb that the Khronos
  glTF-Validator (``tests/consumers/validate.mjs``) accepts with no error and no warning,
  and that carries the dragged jawOpen weight.
* **``workbench app``** (the venv's console script; Voila serving the notebook the wheel
  carries) draws the head, a jawOpen drag changes it, and its Export tab writes a .glb
  the validator accepts.

The servers keep the front ends' own defaults, as in a user's Jupyter: their pages ask
ipykernel to run comm messages on subshell threads (JupyterLab 4.4+: one per comm target
unless *Kernel Comms over subshells* is *Disabled*; Notebook 7.6 asks that whatever its
settings say). The widgets route their comms to the kernel's main thread themselves
(``widgets._threading.route_widget_comms_to_main_thread``), and the kernels' UI-thread
guard checks that every widget change and message happens there. Screenshots, the .glb
files, validator reports and server logs are kept in ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from harness import LabServer, NotebookPage, clip_around, pixel_change, wait_until
from test_end_to_end import _node_tools, _tab, _wait_py_true
from test_viewport import _PROBE_MOUTH, _drag_slider, _wait_settled
from test_voila_app import VoilaApp

# the same build as tests/test_wheel.py (module-scoped fixtures: built once for this module)
from test_wheel import dist, wheel  # noqa: F401

REPO = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.browser, pytest.mark.packaging, pytest.mark.slow]

CELLS = [
    "from widgets import Workbench\nfrom workbench.samples import load_sample",
    'wb = Workbench(load_sample("head"))\nmodel = wb.model\nwb',
]

#: where the kernel's packages come from, and what else it could import
_WHERE = """
import json, os, sys
import anywidget, ipywidgets, widgets, workbench
print(json.dumps({"workbench": workbench.__file__, "widgets": widgets.__file__,
                  "anywidget": anywidget.__file__, "ipywidgets": ipywidgets.__file__,
                  "version": workbench.__version__, "prefix": sys.prefix,
                  "executable": sys.executable, "sys_path": sys.path, "cwd": os.getcwd(),
                  "PYTHONPATH": os.environ.get("PYTHONPATH")}))
"""

_JS_APP = "() => ({name: window.jupyterapp.name, version: window.jupyterapp.version})"

#: How the page asks for comm messages to be run: "disabled" (the main shell) or over subshells
#: (``@jupyterlab/apputils-extension:kernels-settings``' ``commsOverSubshells``, read from the page's
#: kernel manager and its kernel connection).
_JS_COMMS_MODE = """() => {
  const app = window.jupyterapp, km = app.serviceManager.kernels;
  const kernel = app.shell.currentWidget.sessionContext.session.kernel;
  return {page: km.commsOverSubshells, kernel: kernel.commsOverSubshells};
}"""


def _inside(path: str | Path, folder: Path) -> bool:
    p = Path(path).resolve()
    return p == folder or folder in p.parents


def _checkout_dirs() -> list[Path]:
    """The checkout and this test's own site-packages (its venv may be a link into another checkout)."""
    return sorted({REPO, REPO.resolve(), Path(sysconfig.get_paths()["purelib"]).resolve()})


def _say(request: pytest.FixtureRequest, line: str) -> None:
    """Show ``line`` in the test output whatever the capture mode (as ``capsys.disabled()`` does)."""
    tr = request.config.pluginmanager.get_plugin("terminalreporter")
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    if tr is not None and capture is not None:
        with capture.global_and_fixture_disabled():
            tr.write_line(line)
    else:
        print(line)


# --------------------------------------------------------------------------- the wheel's venv
@pytest.fixture(scope="module")
def wheel_venv(browser: Any, wheel: Path, tmp_path_factory: pytest.TempPathFactory,  # noqa: F811
               request: pytest.FixtureRequest) -> Path:
    """A fresh venv outside the repository with ``wheel[ui]`` and Notebook 7 installed with deps.

    ``browser`` first: without Chromium the module skips (fails under CI) before building.
    """
    root = tmp_path_factory.mktemp("wheel-browser")
    assert not any(_inside(root, d) for d in _checkout_dirs()), root
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, cwd=root)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    cmd = [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--disable-pip-version-check",
           f"{wheel}[ui]", "notebook>=7"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, timeout=1200)
    seconds = time.perf_counter() - t0
    assert proc.returncode == 0, f"{' '.join(cmd)} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    versions = subprocess.run(
        [str(venv / "bin" / "python"), "-I", "-c",
         "import json, importlib.metadata as m; print(json.dumps({d: m.version(d) for d in "
         "('face-workbench', 'jupyterlab', 'notebook', 'voila', 'ipywidgets', 'anywidget', 'ipykernel')}))"],
        cwd=root, env=env, check=True, capture_output=True, text=True,
    ).stdout
    report = {
        "wheel": wheel.name, "wheel_MB": round(wheel.stat().st_size / 1e6, 2),
        "install_seconds": round(seconds, 1), "installed": json.loads(versions),
        "venv": str(venv),
    }  # fmt: skip
    line = (f"wheel in the browser: {wheel.name} {report['wheel_MB']:.2f} MB; "
            f"pip install [ui] + notebook>=7 with dependencies into a fresh venv: {seconds:.1f} s; "
            + ", ".join(f"{k} {v}" for k, v in report["installed"].items()))
    _say(request, line)
    from harness import ARTIFACTS

    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    (ARTIFACTS / "wheel-in-browser-install.json").write_text(json.dumps(report, indent=1))
    return venv


def _defaults_only(base: Path) -> Path:
    """An empty overrides.json: the front end's own defaults (a user's Jupyter as installed)."""
    path = base / "no-overrides.json"
    path.write_text("{}")
    return path


@pytest.fixture(scope="module", params=["jupyterlab", "notebook"])
def lab(request: pytest.FixtureRequest, wheel_venv: Path,
        tmp_path_factory: pytest.TempPathFactory) -> Iterator[LabServer]:
    """JupyterLab 4 / Notebook 7 served by the wheel venv's python (overrides conftest's ``lab``,
    so ``open_notebook`` opens its notebooks there)."""
    base = tmp_path_factory.mktemp(f"wheel-{request.param}")
    assert not any(_inside(base, d) for d in _checkout_dirs()), base
    server = LabServer(
        base,
        python=wheel_venv / "bin" / "python",
        app=request.param,
        repo_on_path=False,
        settings=_defaults_only(base),
        env={"WORKBENCH_CACHE_DIR": str(base / "sample-cache"), "VIRTUAL_ENV": str(wheel_venv),
             "PATH": f"{wheel_venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}"},
    )
    try:
        server.start(timeout=240)
        yield server
    finally:
        server.stop()


@contextlib.contextmanager
def _evidence(page: Any, out: Path, log: Any) -> Iterator[None]:
    """On failure: keep the page as drawn, its text and the server's log in ``out``."""
    try:
        yield
    except BaseException:
        with contextlib.suppress(Exception):
            out.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(out / "failed.png"))
            (out / "failed-page.txt").write_text(page.inner_text("body")[-6000:])
            (out / "server.log").write_text(log())
        raise


def _settle_layout(page: Any) -> None:
    """Two animation frames: the layout after a scroll or a resize has been drawn."""
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


def _covered(img: np.ndarray) -> float:
    """Share of the canvas that differs from its corner (the background)."""
    return float((np.abs(img.astype(int) - img[2, 2].astype(int)).max(axis=2) > 30).mean())


def _validate(glb: Path, out: Path) -> dict[str, Any]:
    """The Khronos glTF-Validator's report of ``glb`` (kept as ``<name>-validator.json``)."""
    _node, run = _node_tools()
    report: dict[str, Any] = run("validate.mjs", str(glb))[str(glb)]
    (out / f"{glb.stem}-validator.json").write_text(json.dumps(report, indent=1))
    assert report["numErrors"] == 0, report["messages"]
    assert report["numWarnings"] == 0, report["messages"]
    return report


def _glb_weights(glb: Path) -> dict[str, float]:
    """The default morph weights of the .glb's mesh, by target name."""
    import pygltflib

    mesh = pygltflib.GLTF2().load(str(glb)).meshes[0]
    return dict(zip((mesh.extras or {})["targetNames"], mesh.weights or [], strict=True))


# --------------------------------------------------------------------------- JupyterLab 4, Notebook 7
def test_notebook_from_the_wheel_draws_drags_and_exports(
        lab: LabServer, wheel_venv: Path, open_notebook: Any, artifacts_dir: Path,
        request: pytest.FixtureRequest) -> None:
    nb: NotebookPage = open_notebook(CELLS, run=False, viewport_size=(1500, 1100))
    page = nb.page
    artifacts_dir.mkdir(parents=True, exist_ok=True)
    with _evidence(page, artifacts_dir, lambda: lab.log_tail(400)):
        # ---- the front end is the one asked for, with the README's setting in force
        app = page.evaluate(_JS_APP)
        want = {"jupyterlab": ("JupyterLab", "4."), "notebook": ("Jupyter Notebook", "7.")}[lab.app]
        assert app["name"] == want[0] and app["version"].startswith(want[1]), app
        if lab.app == "notebook":
            assert "/notebooks/" in page.url and "/lab" not in page.url, page.url
        comms = page.evaluate(_JS_COMMS_MODE)
        (artifacts_dir / "comms-over-subshells.json").write_text(json.dumps(comms, indent=1))
        # the page asks for subshells: the widgets' own routing keeps their messages on the main thread
        assert comms["kernel"] not in (None, "disabled"), comms
        _say(request, f"wheel in the browser: {app['name']} {app['version']} runs kernel comms over subshells "
                      f"({comms['kernel']!r}); the UI-thread guard checks the widgets stay on the main thread")
        # ---- run the cells (as open_notebook does)
        nb.wait_widgets_restored()
        nb.install_comm_log()
        nb.run_all(timeout=300)
        # ---- everything comes from the wheel's venv
        where = nb.kernel_eval(_WHERE)
        (artifacts_dir / "kernel-where.json").write_text(json.dumps({"app": app, **where}, indent=1))
        venv = wheel_venv.resolve()
        for name in ("workbench", "widgets", "anywidget", "ipywidgets"):
            assert _inside(where[name], venv), f"{name} imported from {where[name]}, not {venv}"
        assert Path(where["prefix"]).resolve() == venv, where["prefix"]
        assert where["PYTHONPATH"] is None, where["PYTHONPATH"]
        for d in _checkout_dirs():
            assert not _inside(where["cwd"], d), where["cwd"]
            inside = [p for p in where["sys_path"] if p and _inside(p, d)]
            assert not inside, f"the kernel can import from {d}: {inside}"

        # ---- the head draws
        nb.wait_viewports(1, timeout=180)
        ids = nb.kernel_eval("VIEWPORTS = [wb.viewport]\n" + _PROBE_MOUTH)
        page.locator(".fwb-slider-jawOpen").evaluate("e => e.scrollIntoView({block: 'center'})")
        page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")
        _settle_layout(page)
        vp = nb.viewport(0)
        assert vp.get_attribute("data-error") == ""
        assert vp.get_attribute("data-vertex-count") == "5084"
        assert nb.frame(0) >= 1
        canvas = nb.canvas_shot("1-canvas")
        nb.screenshot("1-page")
        covered = _covered(canvas)
        assert 0.08 < covered < 0.95, f"the head covers {covered:.0%} of the canvas"
        assert canvas.reshape(-1, 3).std(axis=0).max() > 20, "the head is one flat colour"

        # ---- a mouse drag of the jawOpen slider moves it
        clip = clip_around(nb.project(ids), pad=40)
        mouth0 = nb.screenshot("2-mouth-before", clip=clip)
        frame0 = nb.frame(0)
        _drag_slider(nb, "jawOpen", 0.85)
        nb.wait_frame_after(0, frame0, timeout=60)
        _wait_settled(nb, timeout=60)
        weight = nb.kernel_eval("import json; print(json.dumps(model.weights['jawOpen']))")
        assert weight > 0.4, f"jawOpen is {weight} after the drag"
        mouth1 = nb.screenshot("2-mouth-after", clip=clip)
        nb.screenshot("2-page-after")
        changed = pixel_change(mouth0, mouth1)
        assert changed > 0.03, f"only {changed:.1%} of the mouth region changed"
        undo = nb.kernel_eval("import json; print(json.dumps(model.history.undo_labels))")
        assert undo == ["Drag jawOpen"], undo

        # ---- Export (the Export tab, with the mouse): a .glb the validator accepts
        _tab(nb, "Export", "orbit")
        glb = lab.root / f"head-{lab.app}.glb"
        page.locator(".fwb-export-path input").fill(str(glb))
        _wait_py_true(nb, f"wb.export.path.value == {str(glb)!r}")
        page.locator(".fwb-export-button").click()
        page.locator(".fwb-export-files").wait_for(timeout=180_000)
        page.locator(".fwb-export-panel").screenshot(path=str(artifacts_dir / "3-exported.png"))
        written = nb.kernel_eval("import json; print(json.dumps([str(p) for p in wb.export.last_written]))")
        assert written == [str(glb.resolve())], written
        shutil.copyfile(glb, artifacts_dir / glb.name)
        _validate(glb, artifacts_dir)
        assert _glb_weights(glb)["jawOpen"] == pytest.approx(weight, abs=1e-6)
        errors = nb.kernel_eval("import json; print(json.dumps([o.get('text', '') for o in wb.errors.outputs]))")
        assert errors == [], errors


# --------------------------------------------------------------------------- workbench app (Voila)
@pytest.fixture
def app_from_wheel(wheel_venv: Path, tmp_path: Path) -> Iterator[VoilaApp]:
    assert not any(_inside(tmp_path, d) for d in _checkout_dirs()), tmp_path
    a = VoilaApp(
        tmp_path,
        command=[str(wheel_venv / "bin" / "workbench")],
        env={"WORKBENCH_CACHE_DIR": str(tmp_path / "sample-cache"), "VIRTUAL_ENV": str(wheel_venv),
             "PATH": f"{wheel_venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}"},
    )
    try:
        yield a
    finally:
        a.stop()


def test_workbench_app_from_the_wheel_draws_drags_and_exports(
        app_from_wheel: VoilaApp, wheel_venv: Path, browser: Any, artifacts_dir: Path) -> None:
    app = app_from_wheel
    # the server is the venv's Voila serving the notebook the wheel carries
    cmdline = Path(f"/proc/{app.proc.pid}/cmdline").read_bytes().split(b"\0")
    served = [a.decode() for a in cmdline if a.endswith(b".ipynb")]
    assert len(served) == 1 and _inside(served[0], wheel_venv.resolve()), cmdline
    assert cmdline[0].decode().startswith(f"{wheel_venv}/"), cmdline  # the venv's python runs Voila
    artifacts_dir.mkdir(parents=True, exist_ok=True)
    page = browser.new_page(viewport={"width": 1500, "height": 1100})
    shell = SimpleNamespace(page=page)  # the helpers borrowed below only use ``.page``
    try:
        with _evidence(page, artifacts_dir, app.log):
            page.goto(app.url, timeout=180_000)
            page.wait_for_function(
                "() => { const e = document.querySelector('.fwb-viewport');"
                " return e && e.getAttribute('data-ready') === '1'; }",
                timeout=300_000,
            )
            assert page.locator(".fwb-workbench").count() == 1
            assert page.locator(".jp-InputArea-editor, .CodeMirror, .cm-editor").count() == 0
            vp = page.locator(".fwb-viewport")
            assert vp.get_attribute("data-error") == ""
            page.locator(".fwb-slider-jawOpen").evaluate("e => e.scrollIntoView({block: 'center'})")
            vp.scroll_into_view_if_needed()
            _settle_layout(page)

            def shot(name: str) -> np.ndarray:
                from PIL import Image

                page.wait_for_function(
                    "() => document.querySelector('.fwb-viewport').getAttribute('data-detail') !== 'draft'",
                    timeout=60_000)
                box = vp.locator("canvas").bounding_box()
                assert box is not None and box["width"] > 200, box
                png = page.screenshot(path=str(artifacts_dir / f"{name}.png"), clip=box)
                return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

            before = shot("1-canvas")
            page.screenshot(path=str(artifacts_dir / "1-page.png"))
            covered = _covered(before)
            assert 0.08 < covered < 0.95, f"the head covers {covered:.0%} of the canvas"

            frame = int(vp.get_attribute("data-frame") or 0)
            _drag_slider(shell, "jawOpen", 0.85)  # type: ignore[arg-type]
            page.wait_for_function(
                "(f) => Number(document.querySelector('.fwb-viewport').getAttribute('data-frame')) > f",
                arg=frame, timeout=60_000)
            # one drag = one undo step, once the kernel closed the interaction
            page.wait_for_function(
                "() => (document.querySelector('.fwb-wb-status') || {}).innerText.includes('undo depth 1')",
                timeout=60_000)
            vp.scroll_into_view_if_needed()
            _settle_layout(page)
            after = shot("2-canvas-jaw-open")
            page.screenshot(path=str(artifacts_dir / "2-page.png"))
            changed = pixel_change(before, after)
            assert changed > 0.01, f"only {changed:.1%} of the canvas changed after the slider drag"

            _tab(shell, "Export", "orbit")  # type: ignore[arg-type]
            glb = app.base / "head-app.glb"
            page.locator(".fwb-export-path input").fill(str(glb))
            # the typed path reaches the kernel before the click (one comm channel, in order);
            # the result line names the file written
            page.locator(".fwb-export-path input").press("Tab")
            page.locator(".fwb-export-button").click()
            page.locator(".fwb-export-files").wait_for(timeout=180_000)
            page.locator(".fwb-export-panel").screenshot(path=str(artifacts_dir / "3-exported.png"))
            result = page.locator(".fwb-export-result").inner_text()
            assert str(glb) in result, result
            wait_until("the exported .glb", glb.exists, bool, timeout=30)
            shutil.copyfile(glb, artifacts_dir / glb.name)
            _validate(glb, artifacts_dir)
            assert _glb_weights(glb)["jawOpen"] > 0.4
            errors = page.locator(".fwb-errors").inner_text().strip()
            assert errors == "", f"the app's error area says: {errors}"
    finally:
        page.close()
    (artifacts_dir / "server.log").write_text(app.log())
