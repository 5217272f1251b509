"""The wheel works outside the repository (issue #31, step 6: ship it).

Builds the sdist and, from it, the wheel (``python -m build --no-isolation``, as
``python -m build`` does: the wheel is made from the unpacked sdist, so this also
proves the sdist carries the front-end bundle and the sample head), installs the
wheel with ``--no-deps`` into a fresh venv under the test's tmp dir, and runs
Python there with the source tree off ``sys.path`` (``-I``, the working directory
outside the repository). The venv borrows this venv's third-party packages
through a ``.pth`` line: a path line in a ``.pth`` is appended to ``sys.path``
after the venv's own site-packages, and ``.pth`` files inside it are not run, so
this venv's editable install of the repository is not seen (checked below).
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = [pytest.mark.packaging, pytest.mark.slow]


def _project_version() -> str:
    with (ROOT / "pyproject.toml").open("rb") as f:
        return str(tomllib.load(f)["project"]["version"])


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sdist and wheel ``python -m build`` makes of this checkout."""
    out = tmp_path_factory.mktemp("dist")
    subprocess.run(
        [sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(ROOT)],
        check=True, capture_output=True, text=True,
    )
    return out


@pytest.fixture(scope="module")
def wheel(dist: Path) -> Path:
    (whl,) = dist.glob("face_workbench-*-py3-none-any.whl")
    return whl


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv outside the repository with only the wheel installed in it."""
    root = tmp_path_factory.mktemp("wheel-venv")
    env_dir = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True)
    python = env_dir / "bin" / "python"
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps",
         "--no-index", str(wheel)],
        check=True, capture_output=True, text=True,
    )
    site = Path(subprocess.run(
        [str(python), "-I", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True).stdout.strip())
    # this venv's third-party packages, appended after the venv's own site-packages
    (site / "zz_borrowed_packages.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return env_dir


def _run(venv: Path, code: str, **env: str) -> dict:
    """Run ``code`` in the wheel's venv from a directory outside the repository; its JSON."""
    cwd = venv.parent
    assert ROOT not in cwd.parents
    clean = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    clean.update(env)
    proc = subprocess.run(
        [str(venv / "bin" / "python"), "-I", "-c", code],
        cwd=cwd, env=clean, capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-4000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_wheel_carries_bundle_and_sample_head(wheel: Path, dist: Path) -> None:
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        bundle = zf.read("widgets/static/viewport.js")
    assert {"widgets/static/viewport.js", "widgets/static/timeline.js", "widgets/static/camera.js"} <= names
    assert len(bundle) > 100_000 and b"three" in bundle.lower()
    head = "workbench/_sample_models/head/"
    assert {head + "head.obj", head + "manifest.json", head + "LICENSE.txt"} <= names
    assert "workbench/_app/workbench.ipynb" in names  # what `workbench app` serves
    assert sum(n.startswith(head + "targets/") for n in names) == 52
    assert sum(n.startswith(head + "identity/") for n in names) > 100
    # sources of the bundle, node_modules and the build cache stay out of the wheel
    assert not any(n.startswith("widgets/js/") or "node_modules" in n or "_cache" in n
                   for n in names)
    (sdist,) = dist.glob("face_workbench-*.tar.gz")
    assert wheel.name.startswith(f"face_workbench-{_project_version()}-")
    assert sdist.stat().st_size > wheel.stat().st_size


def test_installed_wheel_runs_outside_the_repository(venv: Path, tmp_path: Path) -> None:
    got = _run(venv, """
import json, sys
import workbench, widgets
from workbench.samples import load_sample, sample_models_dir, cache_dir
from widgets.viewport.common import load_bundle
from widgets.timeline.bundle import load_timeline_bundle
m = load_sample("head")
m25 = load_sample("head", resolution="25k")
from workbench.capture.identity import identity_targets
targets = identity_targets()
print(json.dumps({
    "workbench": workbench.__file__, "widgets": widgets.__file__,
    "version": workbench.__version__, "sys_path": sys.path,
    "samples": str(sample_models_dir()), "cache": str(cache_dir()),
    "n": len(m.vertices), "shapes": len(m.shape_names), "n25": len(m25.vertices),
    "identity": len(targets), "identity_n": len(next(iter(targets.values()))),
    "bundle": len(load_bundle()), "timeline": len(load_timeline_bundle()),
}))
""", WORKBENCH_CACHE_DIR=str(tmp_path / "cache"), HOME=str(tmp_path / "home"))
    site = str(venv)
    assert got["workbench"].startswith(site) and got["widgets"].startswith(site)
    assert got["samples"].startswith(site)
    # nothing of the checkout is importable: only the borrowed third-party site-packages (which
    # may lie inside the checkout's .venv) is allowed under it
    borrowed = Path(sysconfig.get_paths()["purelib"]).resolve()
    inside = [p for p in got["sys_path"] if p and Path(p).resolve() != borrowed
              and (Path(p).resolve() == ROOT or ROOT in Path(p).resolve().parents)]
    assert not inside, got["sys_path"]
    assert got["version"] == _project_version()
    assert (got["n"], got["shapes"], got["n25"]) == (5084, 52, 20051)
    assert got["identity"] > 100 and got["identity_n"] == 5084
    assert got["bundle"] > 100_000 and got["timeline"] > 1_000
    # the 25k head was built from the wheel's base head into the given cache
    assert list((tmp_path / "cache").glob("head_25k_*.fwb"))


def test_installed_wheel_caches_outside_site_packages(venv: Path, tmp_path: Path) -> None:
    home = tmp_path / "home"
    got = _run(venv, """
import json
from workbench.samples import cache_dir
print(json.dumps({"cache": str(cache_dir())}))
""", HOME=str(home))
    assert got["cache"] == str(home / ".cache" / "face-workbench")


def test_workbench_app_serves_the_notebook_the_wheel_carries(venv: Path) -> None:
    got = _run(venv, """
import json
from workbench.cli import app_command
print(json.dumps({"cmd": app_command(9001)}))
""")
    notebook = Path(got["cmd"][3])
    assert notebook.is_file() and str(notebook).startswith(str(venv)), got["cmd"]
    assert notebook.read_bytes() == (ROOT / "notebooks" / "workbench.ipynb").read_bytes()
    assert got["cmd"][1:3] == ["-m", "voila"] and "--Voila.ip=127.0.0.1" in got["cmd"]


def test_console_script_from_the_wheel(venv: Path) -> None:
    proc = subprocess.run(
        [str(venv / "bin" / "workbench"), "info", str(next(venv.rglob("_sample_models")) / "head")],
        cwd=venv.parent, capture_output=True, text=True, timeout=300,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "vertices    5084" in proc.stdout and "shapes      52" in proc.stdout


def _hatch_build() -> Any:
    spec = importlib.util.spec_from_file_location("face_workbench_hatch_build", ROOT / "hatch_build.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_build_hook_rebuilds_a_stale_bundle_and_refuses_without_npm(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    hook = _hatch_build()
    js = tmp_path / "widgets" / "js"
    shutil.copytree(ROOT / "widgets" / "js", js, ignore=shutil.ignore_patterns("node_modules"))
    static = tmp_path / "widgets" / "static"
    static.mkdir()
    # no bundle: both entries are stale
    assert sorted(hook.stale_bundles(tmp_path)) == ["widgets/static/camera.js", "widgets/static/timeline.js",
                                                    "widgets/static/viewport.js"]
    for name in ("viewport.js", "timeline.js", "camera.js"):
        (static / name).write_text("// bundle")
    assert hook.stale_bundles(tmp_path) == []
    # a source edited after the bundle was built makes it stale again
    src = js / "src" / "viewport" / "scene.js"
    later = (static / "viewport.js").stat().st_mtime + 10
    os.utime(src, (later, later))
    assert set(hook.stale_bundles(tmp_path)) == {"widgets/static/camera.js", "widgets/static/timeline.js",
                                                 "widgets/static/viewport.js"}
    # without npm the build stops with a message instead of shipping an old or missing bundle
    monkeypatch.setenv("PATH", str(tmp_path / "no-npm-here"))
    with pytest.raises(RuntimeError, match="npm is not on PATH"):
        hook.build_frontend(tmp_path)


def test_version_of_a_checkout_that_was_never_installed() -> None:
    from workbench._version import DISTRIBUTION, _source_version

    assert DISTRIBUTION == "face-workbench"
    # what __version__ falls back to without package metadata: pyproject.toml's version
    assert _source_version() == _project_version()
