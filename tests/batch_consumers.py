"""The consumer checks of tests/consumers (glTF-Validator, three.js, UsdSkel) for the batch tests.

tests/consumers is not on ``sys.path`` for tests in tests/, so this module adds it and reuses
its pieces as they are: the node scripts ``validate.mjs`` and ``three_sample.mjs`` (installed
by ``npm ci --prefix tests/consumers``, as its ``node_tools`` fixture does), UsdSkel's own
evaluation (``usdskel_points`` of ``test_usd_consumer.py``) and ``played_weights`` /
``expected_points`` of ``consumer_timelines.py``. A missing node tool skips locally and fails
under ``CI=true`` (:func:`ci_env.in_ci`), like the consumer tests.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ci_env import in_ci

CONSUMERS = Path(__file__).resolve().parent / "consumers"
if str(CONSUMERS) not in sys.path:
    sys.path.insert(0, str(CONSUMERS))

from consumer_timelines import expected_points, played_weights  # noqa: E402
from test_usd_consumer import usdskel_points  # noqa: E402

__all__ = ["expected_points", "node", "played_weights", "three_js", "usd", "usdskel_points", "validate_gltf"]


def _missing(what: str) -> None:
    msg = f"{what} (needed by the batch consumer checks)"
    if in_ci():
        pytest.fail(msg + " is missing under CI=true", pytrace=False)
    pytest.skip(msg + " is not available")


def node(script: str, *args: str) -> Any:
    """Run ``tests/consumers/<script>`` with node; its JSON output."""
    node_bin, npm = shutil.which("node"), shutil.which("npm")
    if node_bin is None or npm is None:
        _missing("node and npm")
    assert node_bin is not None and npm is not None
    modules = CONSUMERS / "node_modules"
    if not (modules / "gltf-validator").is_dir() or not (modules / "three").is_dir():
        proc = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--prefix", str(CONSUMERS)],
                              capture_output=True, text=True, timeout=600)
        if proc.returncode != 0:
            pytest.fail(f"npm ci --prefix tests/consumers failed:\n{proc.stderr[-2000:]}", pytrace=False)
    proc = subprocess.run([node_bin, str(CONSUMERS / script), *args], capture_output=True, text=True,
                          timeout=300, cwd=CONSUMERS)
    if proc.returncode != 0:
        raise AssertionError(f"node {script} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout)


def usd() -> Any:
    """The ``pxr`` package with ``Usd``, ``UsdGeom`` and ``UsdSkel`` loaded (usd-core; required under CI)."""
    try:
        import pxr
        from pxr import Usd, UsdGeom, UsdSkel  # noqa: F401
    except ImportError:
        _missing("usd-core (pxr)")
    return pxr


def validate_gltf(paths: list[Path]) -> None:
    """Khronos glTF-Validator: no errors and no warnings in any of ``paths``."""
    report = node("validate.mjs", *map(str, paths))
    assert sorted(report) == sorted(map(str, paths))
    for path, r in report.items():
        assert (r["numErrors"], r["numWarnings"]) == (0, 0), (path, r["messages"])


def three_js(path: Path, times: list[float]) -> dict[str, Any]:
    """three.js GLTFLoader + AnimationMixer: target names and morph weights at ``times``."""
    result: dict[str, Any] = node("three_sample.mjs", str(path), json.dumps(times))
    result["weights"] = np.array(result["weights"])
    return result
