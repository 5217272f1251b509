"""Every tutorial notebook in ``notebooks/`` runs headless, top to bottom, without errors.

Each ``notebooks/*.ipynb`` is executed with nbclient in a fresh ``python3``
kernel of this venv (jupyter_client starts ``sys.executable -m ipykernel``),
the way CI's full test run has it. So that executing a notebook can never
rewrite a file tracked in git (e.g. ``wrinkles_comparison.ipynb`` saves PNGs
into ``notebooks/images/``), the ``notebooks/`` folder is copied into a
temporary directory and the copy is executed there (cwd = the copy). The
kernel also gets a private ``TMPDIR`` and ``WORKBENCH_RECOVERY_DIR`` (the
workbench notebook autosaves) and renders through EGL
(``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``).

The executed notebooks and a table of run times are kept in
``test-artifacts/tutorials/``.

Every tutorial (each notebook but the ``workbench.ipynb`` app) must show
pictures a reader can see without a live kernel: an image output when it runs
(e.g. ``IPython.display.Image`` of a ``render_png`` PNG, or a matplotlib figure)
or a markdown image of a file that exists in ``notebooks/``. Live widgets do
not count: they render neither in a static view nor on a docs page.

Lives in ``tests/ui`` because it needs the ``ui`` and ``test`` extras (nbclient,
ipykernel, pyvista); the core-only CI job does not collect ``tests/ui``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]
NOTEBOOKS = REPO / "notebooks"
ARTIFACTS = REPO / "test-artifacts" / "tutorials"
#: one cell may take this long (the slowest cells fit WPSD on the 100k head)
CELL_TIMEOUT_S = 900

#: notebooks that are apps rather than tutorials: live widgets only, no pictures required
NOT_TUTORIALS = frozenset({"workbench.ipynb"})
#: ``![alt](path "title")`` or ``<img src="path">`` in a markdown cell
_MARKDOWN_IMAGE = re.compile(
    r"!\[[^\]]*\]\(\s*<?([^)\s>]+)>?[^)]*\)|<img\b[^>]*\bsrc\s*=\s*[\"']([^\"']+)[\"']",
    re.IGNORECASE,
)

pytestmark = [pytest.mark.ui, pytest.mark.slow]


def _notebooks() -> list[Path]:
    return sorted(NOTEBOOKS.glob("*.ipynb"))


def _markdown_images(nb: Any) -> list[str]:
    """Local image paths referenced by the markdown cells (URLs and data: URIs left out)."""
    refs = []
    for cell in nb.cells:
        if cell.cell_type != "markdown":
            continue
        for m in _MARKDOWN_IMAGE.finditer(cell.source):
            ref = m.group(1) or m.group(2)
            # http:, https:, data:, ... are not files of the repository
            if not re.match(r"^[a-z][a-z0-9+.-]*:", ref, re.IGNORECASE):
                refs.append(ref)
    return refs


def _pictures(nb: Any, folder: Path) -> list[str]:
    """What a reader sees as pictures: image outputs, and markdown images of existing files.

    ``folder`` is where the notebook lives (markdown paths are relative to it).
    """
    found = [
        f"output {mime} of code cell {i}"
        for i, cell in enumerate(nb.cells)
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if out.get("output_type") in ("display_data", "execute_result")
        for mime in out.get("data", {})
        if mime.startswith("image/")
    ]
    found += [f"markdown image {ref}" for ref in _markdown_images(nb) if (folder / ref).is_file()]
    return found


@pytest.fixture(scope="module")
def timings() -> Iterator[dict[str, float]]:
    found: dict[str, float] = {}
    yield found
    if found:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        lines = [f"{name:40s} {secs:7.1f} s" for name, secs in sorted(found.items())]
        (ARTIFACTS / "timings.txt").write_text("\n".join(lines) + "\n")
        print("\ntutorial notebook run times:\n" + "\n".join(lines))


def test_there_are_tutorials() -> None:
    names = {p.name for p in _notebooks()}
    for required in ("quick_start.ipynb", "workbench.ipynb", "timeline_export.ipynb"):
        assert required in names, f"notebooks/{required} is missing"


@pytest.mark.parametrize("notebook", _notebooks(), ids=lambda p: p.stem)
def test_notebook_runs_without_errors(
    notebook: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, timings: dict[str, float]
) -> None:
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError

    work = tmp_path / "notebooks"
    shutil.copytree(NOTEBOOKS, work, ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
    private_tmp = tmp_path / "tmp"
    private_tmp.mkdir()
    # The kernel inherits this process's environment when nbclient starts it.
    monkeypatch.setenv("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    monkeypatch.setenv("WORKBENCH_RECOVERY_DIR", str(tmp_path / "recovery"))
    monkeypatch.setenv("TMPDIR", str(private_tmp))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
    )
    vtk_wasm = tmp_path / "vtk-wasm"  # trame-vtklocal must not try to download anything
    vtk_wasm.mkdir()
    monkeypatch.setenv("VTK_WASM_DIR_OVERRIDE", str(vtk_wasm))

    nb = nbformat.read(work / notebook.name, as_version=4)
    client = NotebookClient(
        nb,
        timeout=CELL_TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": str(work)}},
    )
    t0 = time.perf_counter()
    error: CellExecutionError | None = None
    try:
        client.execute()
    except CellExecutionError as exc:
        error = exc
    finally:
        elapsed = time.perf_counter() - t0
        timings[notebook.name] = elapsed
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        nbformat.write(nb, ARTIFACTS / notebook.name)
    if error is not None:
        pytest.fail(f"{notebook.name} raised after {elapsed:.0f} s:\n{error}", pytrace=False)

    code = [c for c in nb.cells if c.cell_type == "code" and c.source.strip()]
    outputs = [o for c in code for o in c.get("outputs", [])]
    errors = [f"{o.get('ename')}: {o.get('evalue')}" for o in outputs if o.output_type == "error"]
    assert errors == [], f"{notebook.name}: {errors}"
    # a traceback printed by a callback (widgets report errors instead of raising)
    tracebacks = [
        o.text for o in outputs if o.output_type == "stream" and "Traceback (most recent" in o.text
    ]
    assert tracebacks == [], f"{notebook.name} printed tracebacks:\n" + "\n".join(tracebacks)
    unexecuted = [i for i, c in enumerate(code) if c.get("execution_count") is None]
    assert unexecuted == [], f"{notebook.name}: code cells {unexecuted} did not run"
    if notebook.name not in NOT_TUTORIALS:
        # markdown images must exist in the repository, not only in the executed copy
        assert _pictures(nb, NOTEBOOKS), (
            f"{notebook.name} shows no pictures: no image output when executed and no markdown "
            "image of an existing file (live widgets do not render in a static view)"
        )


@pytest.mark.parametrize("notebook", _notebooks(), ids=lambda p: p.stem)
def test_markdown_images_exist(notebook: Path) -> None:
    import nbformat

    nb = nbformat.read(notebook, as_version=4)
    missing = [ref for ref in _markdown_images(nb) if not (NOTEBOOKS / ref).is_file()]
    assert missing == [], f"{notebook.name} shows images that do not exist: {missing}"


@pytest.mark.parametrize("notebook", _notebooks(), ids=lambda p: p.stem)
def test_every_cell_has_an_id(notebook: Path) -> None:
    """nbformat 4.5 cell ids (JupyterLab's collaboration and links need them; nbformat will refuse files without)."""
    cells = json.loads(notebook.read_text())["cells"]
    assert [i for i, c in enumerate(cells) if not c.get("id")] == [], notebook.name


def test_picture_check_fails_without_pictures() -> None:
    """The picture check counts image outputs and existing markdown images, nothing else."""
    import nbformat
    from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

    widget = {"application/vnd.jupyter.widget-view+json": {"model_id": "x"}, "text/plain": "VBox()"}
    nb = new_notebook(
        cells=[
            new_markdown_cell("# Text only\n\n![gone](images/no_such_picture.png)"),
            new_code_cell("print(1)", outputs=[new_output("stream", name="stdout", text="1\n")]),
            new_code_cell("W.VBox()", outputs=[new_output("display_data", data=widget)]),
        ]
    )
    assert _pictures(nb, NOTEBOOKS) == []
    png = {"image/png": "iVBORw0KGgo=", "text/plain": "<IPython.core.display.Image object>"}
    nb.cells.append(new_code_cell("show()", outputs=[new_output("display_data", data=png)]))
    assert _pictures(nb, NOTEBOOKS) == ["output image/png of code cell 3"]
    existing = next(NOTEBOOKS.glob("images/*.png")).relative_to(NOTEBOOKS).as_posix()
    nb = new_notebook(cells=[new_markdown_cell(f"![a picture]({existing})")])
    assert _pictures(nb, NOTEBOOKS) == [f"markdown image {existing}"]
    nbformat.validate(nb)
