"""The documentation site builds with zero warnings, has every public name, and its code runs.

* ``mkdocs build --strict`` into a tmp dir (warnings are errors: broken links and anchors,
  docstrings griffe cannot parse, a missing API object, a notebook that does not render);
* every name in the ``__all__`` of every package under ``workbench/`` and ``widgets/`` has
  an anchor on its package's API page, and every tutorial notebook and its pictures are
  there (rendered from the stored notebook, not executed);
* every ```` ```python ```` block of every page under ``docs/`` runs: a page's blocks in
  order, in one fresh interpreter, in an empty tmp dir (``console``, ``toml`` and ``text``
  blocks are shown, not run). A block that only includes a repository file
  (``--8<-- "path"``: the add-a-family page's listing of ``tests/example_family/``) is that
  file, run by its own test (``tests/consumers/test_add_a_family.py``);
* every docstring example (``>>>``) in ``workbench/`` and ``widgets/`` — the API pages show
  them — passes as a doctest.
"""

from __future__ import annotations

import doctest
import importlib
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"

pytestmark = [pytest.mark.packaging, pytest.mark.slow]



@pytest.fixture(scope="module")
def hooks() -> Any:
    """``docs/hooks.py``: the same lists the site is built from (imported here, not at
    collection: it needs the docs extra, which the core-only CI venv does not have)."""
    spec = importlib.util.spec_from_file_location("workbench_docs_hooks", DOCS / "hooks.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module

FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("WARNING")]
    assert not warnings, warnings
    return out


def test_every_public_name_has_a_page(site: Path, hooks: Any) -> None:
    modules = hooks.public_modules()
    assert {"workbench", "workbench.capture", "workbench.rigging", "widgets"} <= set(modules)
    missing = []
    for module, names in modules.items():
        page = (site / "api" / f"{module}.html").read_text(encoding="utf-8")
        for name in names:
            if name.startswith("__"):
                continue
            anchor = hooks.object_path(module, name)
            if f'id="{anchor}"' not in page:
                missing.append(anchor)
    assert not missing, missing
    index = (site / "api" / "index.html").read_text(encoding="utf-8")
    assert all(f'href="{m}.html"' in index for m in modules)


def test_tutorials_render_from_the_stored_notebooks(site: Path, hooks: Any) -> None:
    notebooks = hooks.tutorials()
    assert len(notebooks) == len(list((ROOT / "notebooks").glob("*.ipynb"))) >= 10
    for nb in notebooks:
        html = (site / "tutorials" / f"{nb.stem}.html").read_text(encoding="utf-8")
        assert "jp-Notebook" in html or "jupyter-wrapper" in html, nb.name
        # the notebook's own markdown pictures resolve on the site
        for src in re.findall(r'<img[^>]+src="([^"]+\.png)"', html):
            assert (site / "tutorials" / src).resolve().is_file(), (nb.name, src)
    for img in (ROOT / "notebooks" / "images").glob("*.png"):
        assert (site / "tutorials" / "images" / img.name).is_file()


def test_one_page_per_tool_names_its_paper(site: Path) -> None:
    papers = {
        "handles": "Bickel", "wrinkles": "Bickel", "regions": "Joshi", "painting": "Pighin",
        "timeline": "Pighin", "rigging": "Li", "capture": "Bouaziz", "enhancement": "Bermano",
        "export": "", "batch": "",
    }
    for tool, author in papers.items():
        text = (DOCS / "tools" / f"{tool}.md").read_text(encoding="utf-8")
        assert author in text.split("\n\n")[1] if author else text
        assert (site / "tools" / f"{tool}.html").is_file()


def _is_listing(block: str) -> bool:
    """A block that only includes repository files (pymdownx.snippets)."""
    lines = [line for line in block.splitlines() if line.strip()]
    return bool(lines) and all(line.startswith("--8<--") for line in lines)


def _pages_with_code() -> list[Path]:
    return [p for p in sorted(DOCS.rglob("*.md"))
            if any(not _is_listing(b) for b in FENCE.findall(p.read_text(encoding="utf-8")))]


@pytest.mark.parametrize("page", _pages_with_code(), ids=lambda p: str(p.relative_to(DOCS)))
def test_code_blocks_run(page: Path, tmp_path: Path) -> None:
    blocks = FENCE.findall(page.read_text(encoding="utf-8"))
    code = "\n\n".join(b for b in blocks if not _is_listing(b))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "WORKBENCH_UI_THREAD_GUARD": "1",
           "WORKBENCH_RECOVERY_DIR": str(tmp_path / "recovery")}
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"{page.name}:\n{proc.stderr[-4000:]}"


def _modules_with_examples() -> list[str]:
    out = []
    for top in ("workbench", "widgets"):
        for path in sorted((ROOT / top).rglob("*.py")):
            if ">>> " in path.read_text(encoding="utf-8"):
                rel = path.with_suffix("").relative_to(ROOT)
                parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
                out.append(".".join(parts))
    return out


@pytest.mark.parametrize("module", _modules_with_examples())
def test_docstring_examples_run(module: str) -> None:
    mod = importlib.import_module(module)
    result = doctest.testmod(mod, optionflags=doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS,
                             report=True)
    assert result.attempted > 0 and result.failed == 0, result
