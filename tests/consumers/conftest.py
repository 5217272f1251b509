"""Fixtures for the consumer tests: tools nobody here wrote read our exports.

The node tools (Khronos glTF-Validator, three.js) are pinned in
``tests/consumers/package.json`` + ``package-lock.json`` and installed by the
session fixture :func:`node_tools` with ``npm ci`` when ``node_modules`` is
missing. Without node/npm the tests are skipped locally but FAIL under
``CI=true``, so CI cannot go green without running the consumers.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ci_env import in_ci

from workbench import FaceModel, load_sample

HERE = Path(__file__).resolve().parent


def _missing(what: str) -> None:
    msg = f"{what} (needed by the consumer tests in tests/consumers)"
    if in_ci():
        pytest.fail(msg + " is missing under CI=true", pytrace=False)
    pytest.skip(msg + " is not available")


@pytest.fixture(scope="session")
def node_tools() -> Callable[..., Any]:
    """A function ``run(script, *args) -> parsed JSON`` running a node script from this folder."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        _missing("node and npm")
    assert node is not None and npm is not None
    modules = HERE / "node_modules"
    if not (modules / "gltf-validator").is_dir() or not (modules / "three").is_dir():
        proc = subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund", "--prefix", str(HERE)],
            capture_output=True,
            text=True,
            timeout=600,
        )
        if proc.returncode != 0:
            pytest.fail(f"npm ci --prefix tests/consumers failed:\n{proc.stderr[-2000:]}", pytrace=False)

    def run(script: str, *args: str) -> Any:
        proc = subprocess.run(
            [node, str(HERE / script), *args], capture_output=True, text=True, timeout=120, cwd=HERE
        )
        if proc.returncode != 0:
            raise AssertionError(f"node {script} failed:\n{proc.stderr[-3000:]}")
        return json.loads(proc.stdout)

    return run


@pytest.fixture(scope="session")
def usd() -> Any:
    """The ``pxr`` package (usd-core); required under CI."""
    try:
        import pxr
        from pxr import Usd, UsdGeom, UsdSkel  # noqa: F401
    except ImportError:
        _missing("usd-core (pxr)")
    return pxr


@pytest.fixture(scope="session")
def head() -> FaceModel:
    """The base sample head (~5k vertices, 52 ARKit shapes, decimetres). Do not mutate."""
    return load_sample("head")


@pytest.fixture(scope="module")
def head_with_handles() -> FaceModel:
    """A fresh base head with three handles on the front of the skin."""
    m = load_sample("head")
    skin = m.component_vertices("skin")
    V = m.vertices
    front = skin[np.argsort(-V[skin, 2])]
    for v in (front[0], front[40], front[120]):
        m.handles.add(int(v))
    return m
