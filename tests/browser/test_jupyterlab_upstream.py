"""JupyterLab's own behaviour that our tests must respect, shown on minimal notebooks without our widgets.

* **Cells run before the kernel connects are skipped, silently.** JupyterLab's
  ``CodeCell.execute`` returns at once, clearing the cell, when the notebook's
  session has no kernel connection yet (``if (!code.trim() ||
  !sessionContext.session?.kernel) { clearExecution(); return; }`` in
  ``@jupyterlab/cells``; upstream issue jupyterlab/jupyterlab#8490, open).
  *Run ▸ Run All Cells* clicked while the status bar still says the kernel is
  starting therefore runs nothing and reports nothing. This is what made
  ``test_run_command_opens_the_workbench_notebook`` time out (1 run in 5 beside
  two CPU hogs: the failure screenshot shows every cell unexecuted, the kernel
  idle): the test, like a user, now waits for *Idle* before running.
"""

from __future__ import annotations

import json
import sys
import uuid
from typing import Any

import pytest
from harness import LabServer, NotebookPage, write_notebook

pytestmark = pytest.mark.browser

# the kernel process waits before starting ipykernel, so the page opens well before the
# server's session has a kernel connection: the window in which JupyterLab drops cells
_SLOW_KERNEL = {
    "argv": [sys.executable, "-c",
             "import sys, time; time.sleep(6); from ipykernel import kernelapp; "
             "sys.argv = ['ipykernel', '-f', sys.argv[1]]; kernelapp.launch_new_instance()",
             "{connection_file}"],
    "display_name": "Python 3 (slow start)",
    "language": "python",
}

# in one task of the page: if the notebook has no kernel connection yet, Run All Cells now
_RUN_ALL_BEFORE_CONNECT = """() => {
  const app = window.jupyterapp;
  const w = app && app.shell.currentWidget;
  if (!w || !w.sessionContext || !w.content || !w.content.model || w.content.model.cells.length === 0) return false;
  const s = w.sessionContext.session;
  if (s && s.kernel) return "connected-first";
  app.commands.execute("notebook:run-all-cells");
  return "ran-before-connect";
}"""


def test_jupyterlab_skips_cells_run_before_its_kernel_connects(lab: LabServer, browser: Any) -> None:
    spec = lab.base / "data" / "kernels" / "slow_python"
    spec.mkdir(parents=True, exist_ok=True)
    (spec / "kernel.json").write_text(json.dumps(_SLOW_KERNEL))
    name = f"t_{uuid.uuid4().hex[:10]}.ipynb"
    path = write_notebook(lab.root / name, ["ran = True\nprint('ran')"])
    nb_json = json.loads(path.read_text())
    nb_json["metadata"]["kernelspec"] = {"name": "slow_python", "display_name": _SLOW_KERNEL["display_name"],
                                         "language": "python"}
    path.write_text(json.dumps(nb_json))
    before = lab.kernel_ids()
    context = browser.new_context(viewport={"width": 1200, "height": 800})
    try:
        page = context.new_page()
        nb = NotebookPage(page, lab, lab.base, name)
        page.goto(f"{lab.url}/lab/workspaces/{uuid.uuid4().hex[:12]}/tree/{name}?reset")
        outcome = page.wait_for_function(_RUN_ALL_BEFORE_CONNECT, timeout=60_000, polling=20).json_value()
        assert outcome == "ran-before-connect", "the kernel connected before the notebook showed: nothing shown"
        nb.wait_kernel_idle(timeout=120)
        # the kernel is up and idle; the cell never reached it: no count, no output, no error shown
        state = nb.state()
        assert state is not None and state["counts"] == [None] and state["errors"] == [], state
        assert nb.kernel_eval("import json; print(json.dumps('ran' in globals()))", timeout=30) is False
        # the same command once the kernel is connected runs the cell
        nb.run_all()
        assert nb.state()["counts"] == [1]  # type: ignore[index]
        assert nb.kernel_eval("import json; print(json.dumps(ran))", timeout=30) is True
    finally:
        context.close()
        lab.shutdown_kernels(lab.kernel_ids() - before)
