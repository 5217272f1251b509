"""MkDocs hooks: pages made from the repository rather than written under ``docs/``.

* **Tutorials** — every ``notebooks/*.ipynb`` as ``tutorials/<name>.ipynb`` (rendered by
  mkdocs-jupyter with ``execute: false``: the stored cells and outputs, no kernel) and
  ``notebooks/images/*`` as ``tutorials/images/*``, where the notebooks' own Markdown
  points; the tool pages show the same pictures from there.
* **API reference** — one page per package that declares ``__all__`` under ``workbench/``
  and ``widgets/``, with a ``:::`` mkdocstrings block for each name in it (read from the
  source with :mod:`ast`, nothing is imported), and an index of them all.
* **Changelog** — the repository's ``CHANGELOG.md``.

The navigation's "Tutorials" and "API reference" sections are filled in here too, so a new
notebook or a new public package gets its page without editing ``mkdocs.yml``.
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path
from typing import Any

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = ROOT / "notebooks"
PACKAGES = ("workbench", "widgets")

#: the tutorials in reading order (others follow alphabetically)
TUTORIAL_ORDER = [
    "quick_start", "workbench", "handles_and_wrinkles", "wrinkles_comparison",
    "regions_and_markers", "painterly_blending", "timeline_export", "rig_your_face",
    "clone_a_performance", "transfer_details", "capture", "live_capture", "replay_markers",
    "performance_enhancement", "batch",
]


def public_modules() -> dict[str, list[str]]:
    """Package name -> its ``__all__``, for every package under ``PACKAGES`` that has one."""
    out: dict[str, list[str]] = {}
    for top in PACKAGES:
        for init in sorted((ROOT / top).rglob("__init__.py")):
            rel = init.parent.relative_to(ROOT)
            if any(part.startswith("_") for part in rel.parts):
                continue
            names = _static_all(init)
            if names:
                out[".".join(rel.parts)] = names
    return out


def _static_all(path: Path) -> list[str]:
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        target = (node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1
                  else node.target if isinstance(node, ast.AnnAssign) else None)
        if isinstance(target, ast.Name) and target.id == "__all__" and node.value is not None:
            return [str(n) for n in ast.literal_eval(node.value)]
    return []


def _bound_names(path: Path) -> set[str]:
    """Names a module binds at its top level (imports, defs, classes, assignments)."""
    out: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, ast.Assign):
            out |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out.add(node.target.id)
    return out


def object_path(module: str, name: str) -> str:
    """Where mkdocstrings finds ``module.name``: there, or in the submodule defining it.

    A package may export a name lazily (a module ``__getattr__`` importing an optional
    extra on first use, as ``workbench.capture`` does for the video names); static analysis
    sees no binding in the package, so the name is documented where a submodule defines it.
    """
    init = ROOT.joinpath(*module.split(".")) / "__init__.py"
    if name in _bound_names(init):
        return f"{module}.{name}"
    for sub in sorted(init.parent.rglob("*.py")):
        if sub.name != "__init__.py" and name in _bound_names(sub):
            rel = sub.with_suffix("").relative_to(ROOT)
            return ".".join(rel.parts) + f".{name}"
    raise LookupError(f"{module}.__all__ names {name!r}, which no module under it defines")


def _title(path: Path) -> str:
    nb = json.loads(path.read_text(encoding="utf-8"))
    for cell in nb.get("cells", []):
        if cell.get("cell_type") == "markdown":
            for line in "".join(cell.get("source", [])).splitlines():
                if line.startswith("# "):
                    return line[2:].strip()
    return path.stem.replace("_", " ")


def tutorials() -> list[Path]:
    """The notebooks in reading order."""
    found = {p.stem: p for p in NOTEBOOKS.glob("*.ipynb")}
    order = [n for n in TUTORIAL_ORDER if n in found] + sorted(set(found) - set(TUTORIAL_ORDER))
    return [found[n] for n in order]


def api_page(module: str, names: list[str]) -> str:
    """The Markdown of one API page: the package's docstring, then each public name."""
    lines = [f"# `{module}`", "", f"::: {module}", "    options:", "      members: false",
             "      show_root_heading: false", "      show_root_toc_entry: false", ""]
    for name in names:
        if name.startswith("__"):
            continue  # __version__ and friends: said on the package's own page
        lines += [f"::: {object_path(module, name)}", "    options:",
                  "      show_root_heading: true", "      heading_level: 2", ""]
    return "\n".join(lines)


def api_index(modules: dict[str, list[str]]) -> str:
    lines = [
        "# API reference",
        "",
        "Every public name: what each package lists in its `__all__`. Names are documented",
        "where they are exported (``workbench.load`` is `workbench.io.load`). The headless core",
        "is `workbench`; the notebook views are `widgets` (the `ui` extra).",
        "",
        "| package | public names |",
        "|---|---|",
    ]
    for module, names in modules.items():
        page = f"{module}.md"
        shown = ", ".join(f"[`{n}`]({page}#{object_path(module, n)})"
                          for n in names if not n.startswith("__"))
        lines.append(f"| [`{module}`]({page}) | {shown} |")
    return "\n".join(lines) + "\n"


def on_config(config: Any) -> Any:
    """Fill the navigation's Tutorials and API reference sections."""
    nav = config["nav"]
    for entry in nav:
        if not isinstance(entry, dict):
            continue
        if "Tutorials" in entry:
            entry["Tutorials"] = [{_title(p): f"tutorials/{p.name}"} for p in tutorials()]
        if "API reference" in entry:
            entry["API reference"] = [{"Index": "api/index.md"}] + [
                {m: f"api/{m}.md"} for m in public_modules()]
    return config


def on_nav(nav: Any, config: Any, files: Files) -> Any:
    """Give the notebook pages their source path back.

    mkdocs-jupyter wraps each notebook ``File`` in its ``NotebookFile``, whose
    ``abs_src_path`` (a cached property) is computed from ``src_dir``, which a file added
    by a hook does not have; the wrapped file knows the notebook's path.
    """
    for f in files:
        inner = f.__dict__.get("file")
        if inner is not None and f.__dict__.get("abs_src_path") is None and inner.abs_src_path:
            f.__dict__["abs_src_path"] = inner.abs_src_path
    return nav


#: a Sphinx role before inline code, as the numpydoc docstrings write cross-references
#: (``:func:`track` ``, ``:class:`~workbench.x.Y` ``): mkdocstrings renders the code, the role
#: would stay as text
_ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const|ref|term):(<code>)~?")


def on_page_content(html: str, page: Any, config: Any, files: Files) -> str:
    """Drop Sphinx roles left in front of rendered inline code (the docstrings' cross-references)."""
    return _ROLE.sub(r"\1", html)


@event_priority(100)  # before mkdocs-jupyter's on_files turns .ipynb files into notebook pages
def on_files(files: Files, config: Any) -> Files:
    """Add the tutorials, their pictures, the API pages and the changelog."""
    for nb in tutorials():
        files.append(File.generated(config, f"tutorials/{nb.name}", abs_src_path=str(nb)))
    for img in sorted((NOTEBOOKS / "images").glob("*")):
        files.append(File.generated(config, f"tutorials/images/{img.name}", abs_src_path=str(img)))
    modules = public_modules()
    files.append(File.generated(config, "api/index.md", content=api_index(modules)))
    for module, names in modules.items():
        files.append(File.generated(config, f"api/{module}.md", content=api_page(module, names)))
    files.append(File.generated(config, "changelog.md", abs_src_path=str(ROOT / "CHANGELOG.md")))
    return files
