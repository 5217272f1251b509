"""A Jupyter server that stalls during a Workbench build still shows every widget.

Clean-clone CI runs failed, rarely, with "Error displaying widget: model not found":
some ``comm_open`` messages of a Workbench build never reached the page, while the ones
around them did. The kernel's IOPub socket had dropped them because the server, busy on
a loaded machine, was more than ZeroMQ's default 1,000 messages behind
(``widgets._iopub``). Here the server is made exactly that busy: the cell stops it
(SIGSTOP) for 4 s while it builds a Workbench and 1,500 labels (about 6,000 messages),
then it resumes. Every widget must render, with no error in the page or the kernel.
"""

from __future__ import annotations

import os
import signal

_BURST = """
import os, signal, threading, json
import comm
import ipywidgets as W
import widgets, workbench
from ipykernel.kernelbase import Kernel
from widgets._iopub import MARK_ATTR

SERVER = {server}
# stop only the server this test started, which is this kernel's parent
assert os.getppid() == SERVER, (os.getppid(), SERVER)
before = len(comm.get_comm_manager().comms)
os.kill(SERVER, signal.SIGSTOP)
threading.Timer(4.0, os.kill, (SERVER, signal.SIGCONT)).start()
wb = widgets.Workbench(workbench.load_sample("head", resolution="base"))
labels = W.VBox([W.Label(f"label {{i}}") for i in range(1500)],
                layout=W.Layout(max_height="160px", overflow="auto"))
labels.add_class("fwb-burst-labels")
opened_while_stopped = len(comm.get_comm_manager().comms) - before
W.VBox([wb, labels])
"""

_FACTS = """
import json
print(json.dumps({"opened": opened_while_stopped,
                  "mark": getattr(Kernel.instance().iopub_thread, MARK_ATTR, None),
                  "errors": [o.get("text", "") for o in wb.errors.outputs]}))
"""


def test_a_server_stalled_during_the_build_still_gets_every_widget(lab, open_notebook) -> None:
    try:
        nb = open_notebook([_BURST.format(server=lab.proc.pid)])
    finally:
        os.kill(lab.proc.pid, signal.SIGCONT)  # whatever happened in the cell
    page = nb.page
    facts = nb.kernel_eval(_FACTS)
    assert facts["opened"] > 2_500, facts  # more widgets than ZeroMQ's default mark holds
    assert facts["mark"] == 100_000, facts
    assert facts["errors"] == [], facts
    nb.wait_viewports(1)
    page.wait_for_function(
        "() => document.querySelectorAll('.fwb-burst-labels .widget-label').length === 1500",
        timeout=60_000,
    )
    assert page.locator(".fwb-burst-labels .widget-label").last.inner_text() == "label 1499"
    assert page.locator(".fwb-workbench .fwb-wb-status").inner_text()
    shown = page.locator(".jp-OutputArea-output").all_inner_texts()
    assert not [t for t in shown if "Error displaying widget" in t or "model not found" in t], shown
    nb.screenshot("stalled-server-build")
