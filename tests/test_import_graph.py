"""No import cycles among ``workbench`` modules (imports under TYPE_CHECKING aside).

The same check runs in CI as the ``acyclic_modules`` import-linter contract
(``lint-imports``, configured in pyproject.toml); here it also runs on small
synthetic packages to show it does catch a cycle, and how it reports one.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

grimp = pytest.importorskip("grimp", reason="grimp comes with import-linter (the test extra)")
pytest.importorskip("importlinter", reason="import-linter is in the test extra")

from contracts.acyclic import Cycle, find_cycles, format_cycles  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _graph(*packages: str) -> grimp.ImportGraph:
    return grimp.build_graph(*packages, exclude_type_checking_imports=True, cache_dir=None)


def test_workbench_has_no_import_cycles() -> None:
    knots = find_cycles(_graph("workbench"), ["workbench"])
    assert not knots, "\n" + format_cycles(knots)


@pytest.mark.parametrize("package", ["workbench.io", "workbench.export"])
def test_io_and_export_have_no_import_cycles(package: str) -> None:
    """Readers/writers import only their package's ``base``; the registries load them by name."""
    knots = find_cycles(_graph("workbench"), [package])
    assert not knots, "\n" + format_cycles(knots)


def _write_package(root: Path, name: str, files: dict[str, str]) -> None:
    pkg = root / name
    pkg.mkdir()
    for mod, text in files.items():
        (pkg / f"{mod}.py").write_text(textwrap.dedent(text))


CYCLIC = {
    "__init__": "",
    # a -> b -> c -> a; c's import is function-local and still counts
    "a": "from {pkg} import b\n",
    "b": "import {pkg}.c\n",
    "c": "def f():\n    from {pkg}.a import f\n",
    # d <-> a would be a cycle, but d's import of a is for type checking only
    "d": (
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from {pkg} import a\n"
    ),
    "e": "import {pkg}.d\nimport {pkg}.a\n",
}


def _cyclic(root: Path, name: str) -> None:
    files = {k: v.format(pkg=name) for k, v in CYCLIC.items()}
    files["a"] += f"from {name} import d\n"
    _write_package(root, name, files)


def test_checker_reports_a_synthetic_cycle(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _cyclic(tmp_path, "cyc_demo")
    monkeypatch.syspath_prepend(str(tmp_path))
    knots = find_cycles(_graph("cyc_demo"), ["cyc_demo"])
    assert knots == [
        [
            Cycle(("cyc_demo.a", "cyc_demo.b", "cyc_demo.c"), ((1,), (1,), (2,))),
        ]
    ]
    text = format_cycles(knots)
    assert "Import cycle among 3 modules: cyc_demo.a, cyc_demo.b, cyc_demo.c" in text
    assert "cyc_demo.a -> cyc_demo.b (l.1) -> cyc_demo.c (l.1) -> cyc_demo.a (l.2)" in text


def test_checker_covers_every_import_of_a_knot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two cycles sharing a module: both are shown, not only the first found."""
    _write_package(
        tmp_path,
        "knot_demo",
        {
            "__init__": "",
            "hub": "import knot_demo.x\nimport knot_demo.y\n",
            "x": "import knot_demo.hub\n",
            "y": "import knot_demo.hub\n",
            "z": "import knot_demo.hub\n",
        },
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    (cycles,) = find_cycles(_graph("knot_demo"), ["knot_demo"])
    assert [str(c) for c in cycles] == [
        "knot_demo.hub -> knot_demo.x (l.1) -> knot_demo.hub (l.1)",
        "knot_demo.hub -> knot_demo.y (l.2) -> knot_demo.hub (l.1)",
    ]


def _lint_imports(root: Path, package: str) -> subprocess.CompletedProcess[str]:
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.fail("lint-imports is not installed next to this Python (test extra)")
    (root / ".importlinter").write_text(
        textwrap.dedent(
            f"""\
            [importlinter]
            root_package = {package}
            exclude_type_checking_imports = True
            contract_types =
                acyclic_modules: tests.contracts.acyclic.AcyclicModulesContract

            [importlinter:contract:no-cycles]
            name = No cycles in {package}
            type = acyclic_modules
            packages = {package}
            """
        )
    )
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), str(ROOT)]),
        "COLUMNS": "250",
        "NO_COLOR": "1",
    }
    return subprocess.run(
        [exe, "--config", str(root / ".importlinter"), "--no-cache"],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_contract_fails_lint_imports_on_a_cycle(tmp_path: Path) -> None:
    _cyclic(tmp_path, "cyc_cli")
    run = _lint_imports(tmp_path, "cyc_cli")
    assert run.returncode == 1, run.stdout + run.stderr
    assert "No cycles in cyc_cli BROKEN" in run.stdout
    assert "cyc_cli.a -> cyc_cli.b (l.1) -> cyc_cli.c (l.1) -> cyc_cli.a (l.2)" in run.stdout


def test_contract_keeps_an_acyclic_package(tmp_path: Path) -> None:
    _write_package(
        tmp_path,
        "dag_cli",
        {
            "__init__": "from dag_cli import top\n",
            "base": "",
            "top": "from dag_cli import base\n",
            # type-checking-only back edge: not a cycle
            "low": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import dag_cli.top\n",
        },
    )
    (tmp_path / "dag_cli" / "base.py").write_text("import dag_cli.low\n")
    run = _lint_imports(tmp_path, "dag_cli")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "No cycles in dag_cli KEPT" in run.stdout
