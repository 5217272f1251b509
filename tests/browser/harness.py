"""Helpers of the real-browser harness (see conftest.py): JupyterLab process, notebook page, pixels.

Kept out of conftest.py so that tests can import them (``from harness import ...``).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
# tests/ holds ci_env.py; benchmarks import this module with only tests/browser on the path
sys.path.insert(0, str(REPO / "tests"))
from ci_env import in_ci  # noqa: E402

__all__ = ["in_ci"]  # re-exported: the browser tests import it from here
CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = REPO / "test-artifacts"
OVERRIDES = REPO / "widgets" / "jupyter_settings" / "overrides.json"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
# On top of whichever settings file a test starts from (the shipped overrides have them too): no
# news/update pop-ups.
TEST_SETTINGS = {
    "@jupyterlab/apputils-extension:notification": {
        "fetchNews": "false",
        "checkForUpdates": False,
    },
}




def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# --------------------------------------------------------------------------- JupyterLab
#: the Jupyter front ends LabServer can start (``python -m <app>``) and the config classes that
#: get the private dirs: Notebook 7's pages read their settings (overrides.json) from
#: /lab/api/settings, which the JupyterLab extension in the same server answers from LabApp's
#: dirs, so both get them
APPS = {"jupyterlab": ("LabApp",), "notebook": ("LabApp", "JupyterNotebookApp")}


class LabServer:
    """A JupyterLab (or Notebook 7) process started by this harness (and the only one it stops).

    By default: JupyterLab from this interpreter with the checkout on ``PYTHONPATH``.
    ``python``: the interpreter whose ``-m <app>`` serves (and whose kernels run);
    ``app``: ``"jupyterlab"`` or ``"notebook"`` (Notebook 7, same private dirs and
    settings); ``repo_on_path=False``: no ``PYTHONPATH`` at all and the working
    directory ``base`` (an installed package is served, not the checkout);
    ``settings``: the overrides.json put into the app settings dir; ``env``: more
    environment variables for the server and its kernels.
    """

    def __init__(
        self,
        base: Path,
        *,
        python: str | Path = sys.executable,
        app: str = "jupyterlab",
        repo_on_path: bool = True,
        settings: Path = OVERRIDES,
        env: dict[str, str] | None = None,
    ) -> None:
        if app not in APPS:
            raise ValueError(f"app must be one of {sorted(APPS)}, not {app!r}")
        self.base = base
        self.root = base / "root"
        self.python = str(python)
        self.app = app
        self.repo_on_path = repo_on_path
        self.settings = settings
        self.extra_env = dict(env or {})
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log_path = base / f"{app}.log"
        self.proc: subprocess.Popen[bytes] | None = None

    def notebook_url(self, name: str) -> str:
        """The page that opens notebook ``name`` of the root (JupyterLab: in a fresh workspace)."""
        if self.app == "notebook":
            return f"{self.url}/notebooks/{name}"
        return f"{self.url}/lab/workspaces/{uuid.uuid4().hex[:12]}/tree/{name}?reset"

    def start(self, timeout: float = 90.0) -> None:
        b = self.base
        dirs = {
            name: b / name
            for name in (
                "root",
                "config",
                "data",
                "runtime",
                "workspaces",
                "user_settings",
                "app_settings",
                "ipython",
            )
        }
        for d in dirs.values():
            d.mkdir(parents=True, exist_ok=True)
        settings = json.loads(self.settings.read_text())
        for plugin, values in TEST_SETTINGS.items():
            settings.setdefault(plugin, {}).update(values)
        (dirs["app_settings"] / "overrides.json").write_text(json.dumps(settings, indent=1))
        env = dict(os.environ)
        env.update(
            JUPYTER_CONFIG_DIR=str(dirs["config"]),
            JUPYTER_DATA_DIR=str(dirs["data"]),
            JUPYTER_RUNTIME_DIR=str(dirs["runtime"]),
            IPYTHONDIR=str(dirs["ipython"]),
            JUPYTER_PLATFORM_DIRS="1",
            VTK_DEFAULT_OPENGL_WINDOW="vtkEGLRenderWindow",
            # autosave/recovery files of test kernels stay in this server's temp dirs
            WORKBENCH_RECOVERY_DIR=str(self.base / "recovery"),
            # kernels raise, and record, any widget change off their UI thread (HEALTH)
            WORKBENCH_UI_THREAD_GUARD="1",
        )
        if self.repo_on_path:
            env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH", "")) if p)
        else:
            env.pop("PYTHONPATH", None)
        env.update(self.extra_env)
        # notebooks/workbench.ipynb opens the 25k head by default; the tests that drive it
        # check features on the 5k one (test_run_command checks the default, not via this)
        env.setdefault("WORKBENCH_RESOLUTION", "base")
        cmd = [
            self.python, "-m", self.app,
            "--no-browser",
            "--ServerApp.ip=127.0.0.1",
            f"--ServerApp.port={self.port}",
            "--ServerApp.port_retries=0",
            "--IdentityProvider.token=",
            "--ServerApp.password=",
            "--ServerApp.disable_check_xsrf=True",
            "--allow-root",
            f"--ServerApp.root_dir={dirs['root']}",
            "--LabApp.news_url=None",
            "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
        ]  # fmt: skip
        for cls in APPS[self.app]:
            cmd += [
                f"--{cls}.workspaces_dir={dirs['workspaces']}",
                f"--{cls}.user_settings_dir={dirs['user_settings']}",
                f"--{cls}.app_settings_dir={dirs['app_settings']}",
                f"--{cls}.expose_app_in_browser=True",
            ]
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            cmd, stdout=self._log, stderr=subprocess.STDOUT, env=env,
            cwd=None if self.repo_on_path else self.base,
        )  # fmt: skip
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(
                    f"JupyterLab exited with {self.proc.returncode}; log:\n{self.log_tail()}"
                )
            try:
                self.api("GET", "/api/status")
                return
            except (urllib.error.URLError, ConnectionError, OSError):
                time.sleep(0.25)
        raise RuntimeError(f"JupyterLab did not answer within {timeout} s; log:\n{self.log_tail()}")

    def log_tail(self, n: int = 60) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return "(no log)"

    def api(self, method: str, path: str, body: Any = None) -> Any:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, method=method)
        req.add_header("Content-Type", "application/json")
        with urllib.request.urlopen(req, timeout=10) as resp:
            raw = resp.read()
        return json.loads(raw) if raw else None

    def kernel_ids(self) -> set[str]:
        return {k["id"] for k in self.api("GET", "/api/kernels")}

    def shutdown_kernels(self, ids: set[str] | None = None) -> None:
        for kid in self.kernel_ids() if ids is None else ids:
            with contextlib.suppress(Exception):
                self.api("DELETE", f"/api/kernels/{kid}")

    def stop(self) -> None:
        if self.proc is None:
            return
        with contextlib.suppress(Exception):
            self.shutdown_kernels()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        self._log.close()
        self.proc = None


# --------------------------------------------------------------------------- notebook page
class KernelError(RuntimeError):
    """Python code run through :meth:`NotebookPage.kernel_eval` raised."""


class LostCellReply(RuntimeError):
    """JupyterLab never got a cell's execute reply although the kernel ran on.

    Seen about once in 35 notebook opens on this machine, always on the first cell
    right after the kernel started: counts like ``[None, 2, 3]``, the kernel idle and
    the first cell still "running". It is JupyterLab's messaging, not the notebook's
    code (the kernel numbered the later cells 2 and 3). The harness reopens the
    notebook once in a fresh kernel so the test shows what else it finds, then fails
    it (:func:`conftest.open_notebook`; the ``browser health`` line counts reopens).
    """


_JS_EXECUTE = """
async ([code, timeoutMs]) => {
  const kernel = window.jupyterapp.shell.currentWidget.sessionContext.session.kernel;
  const out = {stdout: "", stderr: "", error: null};
  const future = kernel.requestExecute({code, silent: false, store_history: false});
  future.onIOPub = (msg) => {
    const t = msg.header.msg_type;
    if (t === "stream") out[msg.content.name] += msg.content.text;
    else if (t === "error") out.error = msg.content.ename + ": " + msg.content.evalue + "\\n" +
      (msg.content.traceback || []).join("\\n").replace(/\\u001b\\[[0-9;]*m/g, "");
  };
  const timer = new Promise((_, rej) => setTimeout(() => rej(new Error("timeout")), timeoutMs));
  await Promise.race([future.done, timer]);
  return out;
}
"""

_JS_NOTEBOOK_STATE = """
() => {
  const w = window.jupyterapp && window.jupyterapp.shell.currentWidget;
  if (!w || !w.sessionContext || !w.content || !w.content.model) return null;
  const s = w.sessionContext.session;
  const cells = w.content.model.cells;
  const out = {kernel: s && s.kernel ? s.kernel.status : null,
               kernelId: s && s.kernel ? s.kernel.id : null,
               counts: [], errors: [], pending: 0};
  for (let i = 0; i < cells.length; i++) {
    const c = cells.get(i);
    if (c.type !== "code") continue;
    out.counts.push(c.executionCount);
    if (c.executionState === "running") out.pending += 1;
    const outputs = c.outputs;
    for (let k = 0; k < outputs.length; k++) {
      const o = outputs.get(k).toJSON();
      if (o.output_type === "error") out.errors.push(o.ename + ": " + o.evalue);
    }
  }
  return out;
}
"""


#: what the session's browser tests saw go wrong between page and kernel (printed at the end;
#: the page's kernel connection: its status and the messages JupyterLab holds back until connected
_JS_KERNEL_CONNECTION = """() => {
  const w = window.jupyterapp && window.jupyterapp.shell.currentWidget;
  const k = w && w.sessionContext && w.sessionContext.session && w.sessionContext.session.kernel;
  if (!k) return null;
  return {status: k.status, connectionStatus: k.connectionStatus,
          pendingMessages: k._pendingMessages ? k._pendingMessages.length : null,
          futures: k._futures ? k._futures.size : null,
          wsReadyState: k._ws ? k._ws.readyState : null};
}"""

#: every count but "checked" must stay 0): notebooks reopened after a lost cell reply, full
#: updates a page asked for, widget changes off the kernel's UI thread
HEALTH = {"checked": 0, "reopens": 0, "resyncs": 0, "thread_violations": 0}

_JS_RESYNCS = "() => globalThis.fwbResyncs || []"

#: what each viewport in the kernel sent last (a resync report is read against it)
_PY_SENT_LOGS = """
import json, gc
from widgets.viewport import Viewport as _V
print(json.dumps([{"uid": _o._uid, "version": _o._version, "mode": _o._gpu_mode, "sent": list(_o.sync.sent_log),
                   "resyncs": list(_o.resyncs)} for _o in gc.get_objects() if isinstance(_o, _V)]))
"""

#: console errors that mean a widget model missed part of a state update (ipywidgets logs them
#: and goes on; a change handler that threw skips the change events after it)
_LOST_STATE_ERRORS = ("Error setting state", "Could not process update msg")

#: Installed in each test kernel before its cells run: a log of the comm traffic of every widget
#: (opens, updates with the model ids they reference, closes), read when a model missed an update
_PY_COMM_LOG_INSTALL = """
def _fwb_install_comm_log():
    # everything local: the test's cells own the kernel's global names
    import collections, time, ipywidgets
    W = ipywidgets.Widget
    if hasattr(W, "_fwb_comm_log"):
        return
    log = W._fwb_comm_log = collections.deque(maxlen=50000)

    def refs(obj, out):
        if isinstance(obj, str):
            if obj.startswith("IPY_MODEL_"):
                out.append(obj[10:])
        elif isinstance(obj, dict):
            for v in obj.values():
                refs(v, out)
        elif isinstance(obj, (list, tuple)):
            for v in obj:
                refs(v, out)
        return out

    send0, open0, close0 = W._send, W.open, W.close

    def _send(self, msg, buffers=None):
        st = msg.get("state", {}) if isinstance(msg, dict) else {}
        log.append([time.monotonic(), getattr(self.comm, "comm_id", None), "send " + str(msg.get("method")),
                    sorted(st), refs(st, [])])
        return send0(self, msg, buffers)

    def _open(self):
        r = open0(self)
        log.append([time.monotonic(), getattr(self.comm, "comm_id", None), "open " + type(self).__name__,
                    [], refs(self.get_state(), [])])
        return r

    def _close(self):
        if getattr(self, "comm", None) is not None:
            log.append([time.monotonic(), self.comm.comm_id, "close " + type(self).__name__, [], []])
        return close0(self)

    W._send, W.open, W.close = _send, _open, _close

_fwb_install_comm_log()
del _fwb_install_comm_log
"""

#: the comm log's story of one model: its messages and, for every model they name, its open/close
_PY_COMM_LOG_REPORT = """
def _fwb_comm_story(mid):
    import json, ipywidgets
    log = list(getattr(ipywidgets.Widget, "_fwb_comm_log", []))
    mine = [e for e in log if e[1] == mid]
    named = {r for e in mine for r in e[4]}
    life = [e for e in log if e[1] in named and not e[2].startswith("send")]
    opened = {e[1] for e in log if e[2].startswith("open")}
    print(json.dumps({"model": mid, "messages": mine[-40:], "named_models_open_close": life[-200:],
                      "named_never_opened": sorted(named - opened)}))

_fwb_comm_story(MODEL_ID)
del _fwb_comm_story
"""

_PY_VIOLATIONS = """
import sys, json
_g = sys.modules.get("widgets._threading")
print(json.dumps(list(_g.thread_violations) if _g else []))
"""


#: Added to every test page before JupyterLab loads: notes when the widget manager's restore
#: from the kernel has been answered. On connecting to a kernel, the JupyterLab widget manager
#: asks it for every live widget (a "request_states" control message, or comm_info_request on
#: a kernel that has not imported ipywidgets) and builds models for those it does not know.
#: Cells run before that answer arrives create widgets the answer also lists: the manager then
#: builds some models twice in parallel, and a container can look up a child model before it
#: is registered ("Error: widget model not found" in _make_model; the view never renders).
#: That race is the widget manager's own (jupyter-widgets/ipywidgets PR #2570, PR #3549 and
#: the analysis in jupyter-widgets/ipyleaflet PR #968): a person who runs a cell a moment
#: after opening a notebook can meet it too. The tests start running cells once it is over.
WATCH_WIDGET_RESTORE = r"""
(() => {
  const Native = window.WebSocket;
  const text = new TextDecoder();
  // the comm messages the page received, in order (a lost update's report asks when the models
  // it names arrived): [ms since load, msg_type, comm_id]
  const received = (window.__fwbCommsReceived = []);
  const commType = /"msg_type":\s*"(comm_open|comm_msg|comm_close)"/;
  const commId = /"comm_id":\s*"([0-9a-zA-Z_-]+)"/;
  // the kernel session of every message (the header's comes first): JupyterLab drops, silently,
  // a message whose session is not the one of the message it received last
  const session = /"session":\s*"([^"]+)"/;
  const sessions = (window.__fwbSessions = {});
  const seen = (data) => {
    const s = typeof data === "string" ? data : text.decode(data);
    if (s.includes('"comm_info_reply"') || s.includes('"update_states"')) window.__fwbWidgetsRestored = true;
    const ses = session.exec(s);
    if (ses) sessions[ses[1]] = (sessions[ses[1]] || 0) + 1;
    const t = commType.exec(s);
    if (t) {
      const id = commId.exec(s);
      received.push([Math.round(performance.now()), t[1], id ? id[1] : "?"]);
      if (received.length > 50000) received.splice(0, 10000);
    }
  };
  window.WebSocket = class extends Native {
    constructor(...args) {
      super(...args);
      this.addEventListener("message", (e) => { try { seen(e.data); } catch (err) { /* not ours */ } });
    }
  };
  // ipywidgets logs a failed state update as a bare Error("Could not process update msg ...")
  // from inside a promise's catch handler and rethrows the cause, which JupyterLab's message
  // chain then drops. Remember the reason each catch handler is given, so the logged line can
  // be paired with its cause (older ipywidgets: a WrappedError carrying error_stack).
  const nativeCatch = Promise.prototype.catch;
  Promise.prototype.catch = function (handler) {
    if (typeof handler !== "function") return nativeCatch.call(this, handler);
    return nativeCatch.call(this, function (reason) {
      window.__fwbLastRejection = reason;
      return handler.call(this, reason);
    });
  };
  const describe = (x) => String((x && x.stack) || x);
  const error = console.error;
  console.error = function (...args) {
    try {
      for (const a of args) {
        const text = String((a && a.message) || a);
        if (a && a.error_stack) {
          (window.__fwbWrappedErrors = window.__fwbWrappedErrors || []).push(
            a.error_stack.map(describe).join(" ==> "));
        } else if (text.includes("Could not process update msg")) {
          (window.__fwbWrappedErrors = window.__fwbWrappedErrors || []).push(
            text + " <== cause: " + describe(window.__fwbLastRejection));
        } else if (text.includes("Error setting state")) {  // the handler's message is in the line
          (window.__fwbWrappedErrors = window.__fwbWrappedErrors || []).push(text);
        }
      }
    } catch (err) { /* never break the page's own logging */ }
    return error.apply(this, args);
  };
})();
"""


class NotebookPage:
    """One notebook open in JupyterLab in a fresh browser context."""

    def __init__(self, page: Any, lab: LabServer, artifacts: Path, name: str) -> None:
        self.page = page
        self.lab = lab
        self.artifacts = artifacts
        self.name = name
        #: full updates this test makes the page ask for on purpose
        self.expected_resyncs = 0
        #: a cell's reply was lost in this page (the notebook was reopened; the test fails)
        self.lost_reply = False
        self.console: list[str] = []
        page.on("console", lambda m: self.console.append(f"{m.type}: {m.text}"))
        page.on("pageerror", lambda e: self.console.append(f"pageerror: {e}"))

    # ---- health: nothing repaired, nothing off the UI thread
    def health_problems(self) -> list[str]:
        """What went wrong between this page and its kernel (empty when all is well); counted in HEALTH."""
        HEALTH["checked"] += 1
        problems = []
        resyncs = self.page.evaluate(_JS_RESYNCS)
        unexpected = len(resyncs) - self.expected_resyncs
        if unexpected > 0:
            HEALTH["resyncs"] += unexpected
            report = self.resync_report(resyncs)
            problems.append(f"{self.name}: the page asked for {len(resyncs)} full updates "
                            f"({[r.get('why') for r in resyncs]}); {report}")
        lost = [line for line in self.console if any(e in line for e in _LOST_STATE_ERRORS)]
        if lost:
            problems.append(f"{self.name}: a widget model missed part of a state update: {lost[:1]}; "
                            + self.lost_update_report(lost))
        violations = self.kernel_eval(_PY_VIOLATIONS, timeout=30)
        if violations:
            HEALTH["thread_violations"] += len(violations)
            problems.append(f"{self.name}: widgets changed off the UI thread: {violations[:3]}")
        return problems

    def lost_update_report(self, lost: list[str]) -> str:
        """Save why the page lost a state update and when the models it names arrived; a short summary.

        ``lost-state-updates.txt``: the rejections paired with the logged lines (the cause
        ipywidgets does not log); ``lost-state-comm-log.json``: per failed model, the
        kernel's messages of it and the open/close of every model they name, the models
        never opened, when the page received each of them and the kernel sessions it saw.
        """
        causes = self.page.evaluate("() => window.__fwbWrappedErrors || []")
        self.artifacts.mkdir(parents=True, exist_ok=True)
        (self.artifacts / "lost-state-updates.txt").write_text("\n\n=====\n\n".join(causes) or "no cause kept")
        ids = sorted(set(re.findall(r"model id: ([0-9a-zA-Z_-]+)", " ".join(lost))))
        stories = []
        for mid in ids:
            try:
                stories.append(self.kernel_eval(_PY_COMM_LOG_REPORT.replace("MODEL_ID", repr(mid)), timeout=30))
            except Exception as exc:  # the report must not hide the problem it reports
                stories.append({"model": mid, "error": f"{type(exc).__name__}: {exc}"})
        # when the page received the models the failed updates name, against the updates themselves
        flat = sorted(set(ids) | {r for st in stories for m in st.get("messages", []) for r in m[4]})
        arrivals = self.page.evaluate(
            "(ids) => { const want = new Set(ids); return (window.__fwbCommsReceived || [])"
            ".filter((r) => want.has(r[2])); }", flat)
        sessions = self.page.evaluate("() => window.__fwbSessions || {}")
        for st in stories:
            st["page_received"] = [a for a in arrivals if a[2] == st.get("model") or
                                   any(a[2] in m[4] for m in st.get("messages", []))]
            st["page_sessions"] = sessions  # more than one: JupyterLab may have dropped messages
        (self.artifacts / "lost-state-comm-log.json").write_text(json.dumps(stories, indent=1))
        closed = [e for st in stories for e in st.get("named_models_open_close", []) if e[2].startswith("close")]
        return (f"cause: {causes[:1] if causes else 'not kept'} (all in lost-state-updates.txt); "
                f"models its messages name that the kernel closed: {closed[-5:]}, never opened: "
                f"{[st.get('named_never_opened') for st in stories]}, kernel sessions the page saw: "
                f"{len(sessions)} (lost-state-comm-log.json)")

    def resync_report(self, resyncs: list[dict[str, Any]]) -> str:
        """Save what the page saw and the kernel sent around each resync; a short summary."""
        try:
            sent = self.kernel_eval(_PY_SENT_LOGS, timeout=30)
        except Exception as exc:  # the report must not hide the failure it explains
            sent = f"kernel not asked: {exc}"
        self.artifacts.mkdir(parents=True, exist_ok=True)
        path = self.artifacts / "resyncs.json"
        path.write_text(json.dumps({"page": resyncs, "kernel": sent}, indent=1, default=str))
        last = resyncs[-1]
        return (f"last: have {last.get('have')}, model {last.get('model')}, held {last.get('held')}, "
                f"page saw {last.get('trace', [])[-6:]}; kernel sent "
                f"{[v.get('sent', [])[-6:] for v in sent] if isinstance(sent, list) else sent} (all in {path})")

    # ---- notebook / kernel
    def state(self) -> dict[str, Any] | None:
        return self.page.evaluate(_JS_NOTEBOOK_STATE)  # type: ignore[no-any-return]

    def wait_kernel_idle(self, timeout: float = 90.0) -> None:
        self.page.wait_for_function(
            """() => { const w = window.jupyterapp && window.jupyterapp.shell.currentWidget;
                 return !!(w && w.sessionContext && w.sessionContext.session &&
                   w.sessionContext.session.kernel &&
                   w.sessionContext.session.kernel.status === 'idle'); }""",
            timeout=timeout * 1000,
        )

    def wait_widgets_restored(self, timeout: float = 30.0) -> None:
        """Wait until the widget manager's restore from the kernel was answered (WATCH_WIDGET_RESTORE)."""
        self.page.wait_for_function("() => window.__fwbWidgetsRestored === true", timeout=timeout * 1000)

    def run_all(self, timeout: float = 180.0, lost_after: float = 15.0) -> dict[str, Any]:
        """Run every cell; wait until all ran and the kernel is idle; fail on errors.

        Raises :class:`LostCellReply` when, for ``lost_after`` seconds, the kernel idles
        and nothing moves while a cell has no reply (later cells finished, or cells are
        still queued).
        """
        # Fire and poll: the command's promise settles only when every cell has run, and a
        # page.evaluate awaiting it has no timeout (a lost reply hung a CI run for 40 min).
        self.page.evaluate(
            "() => { window.jupyterapp.commands.execute('notebook:run-all-cells'); }"
        )
        deadline = time.monotonic() + timeout
        st: dict[str, Any] | None = None
        stalled_since: float | None = None
        stalled_counts: list[Any] | None = None
        while time.monotonic() < deadline:
            st = self.state()
            if st and st["errors"]:
                raise AssertionError(f"notebook {self.name} raised: {st['errors']}")
            if (
                st
                and st["kernel"] == "idle"
                and st["pending"] == 0
                and all(c is not None for c in st["counts"])
            ):
                return st
            # a cell without a count while a LATER cell has one and the kernel idles, or
            # cells still queued while the kernel idles and nothing moves (their replies
            # were lost: seen once in CI, counts [1, None, None] for 180 s)
            lost = bool(
                st
                and st["kernel"] == "idle"
                and (
                    any(
                        c is None and any(d is not None for d in st["counts"][i + 1 :])
                        for i, c in enumerate(st["counts"])
                    )
                    or st["pending"] > 0
                )
            )
            if not lost:
                stalled_since = None
            elif stalled_since is None or stalled_counts != st["counts"]:  # type: ignore[index]
                stalled_since, stalled_counts = time.monotonic(), st["counts"]  # type: ignore[index]
            elif time.monotonic() - stalled_since > lost_after:
                probe = self.probe_kernel(st)  # type: ignore[arg-type]
                raise LostCellReply(f"notebook {self.name}: a cell reply never arrived: {st}; probe: {probe}")
            time.sleep(0.2)
        raise AssertionError(f"notebook {self.name} did not finish in {timeout} s: {st}")

    def probe_kernel(self, st: dict[str, Any], wait: float = 10.0) -> dict[str, Any]:
        """Which side lost a reply: ask the kernel directly on a shell connection of our own.

        A kernel that answers our ``kernel_info_request`` has a live shell loop, so the
        page's requests never reached it (JupyterLab or the server lost them); a kernel
        that does not answer is wedged. Whether the stuck cells then complete tells
        whether a new connection woke it (ipykernel#1554's symptom). Saved as
        ``lost-reply-probe.json`` in the test's artifacts with the server log's tail.
        """
        out: dict[str, Any] = {"kernel_id": st.get("kernelId"), "counts_before": st.get("counts")}
        try:
            from jupyter_client import BlockingKernelClient

            runtime = self.lab.base / "runtime"
            cf = next(runtime.glob(f"kernel-{st.get('kernelId')}*.json"), None)
            if cf is None:
                out["kernel_info"] = f"no connection file in {runtime}"
            else:
                kc = BlockingKernelClient(connection_file=str(cf))
                kc.load_connection_file()
                kc.start_channels()
                try:
                    t0 = time.monotonic()
                    reply = kc.kernel_info(reply=True, timeout=10)
                    out["kernel_info"] = f"answered in {time.monotonic() - t0:.2f} s ({reply['content']['status']})"
                except Exception as exc:  # any failure is the finding
                    out["kernel_info"] = f"no answer: {type(exc).__name__}: {exc}"
                finally:
                    kc.stop_channels()
            deadline = time.monotonic() + wait
            after = st
            while time.monotonic() < deadline:
                after = self.state() or after
                if all(c is not None for c in after["counts"]):
                    break
                time.sleep(0.2)
            out["counts_after"] = after.get("counts")
            out["page_connection"] = self.page.evaluate(_JS_KERNEL_CONNECTION)
        except Exception as exc:  # the probe must not hide the lost reply
            out["probe_error"] = f"{type(exc).__name__}: {exc}"
        if self.artifacts is not None:
            with contextlib.suppress(OSError):
                self.artifacts.mkdir(parents=True, exist_ok=True)
                (self.artifacts / "lost-reply-probe.json").write_text(json.dumps(out, indent=1, default=str))
                (self.artifacts / "jupyterlab-log-tail.txt").write_text(self.lab.log_tail(200))
        return out

    def install_comm_log(self) -> None:
        """Log the kernel's widget comm traffic from now on (read when a model misses an update)."""
        self.kernel_eval(_PY_COMM_LOG_INSTALL, timeout=60)

    def kernel_eval(self, code: str, timeout: float = 60.0) -> Any:
        """Run ``code`` in the notebook's kernel; return the JSON it prints last.

        The code must ``print(json.dumps(...))`` as its final output line (or print
        nothing: then None is returned). A Python exception becomes KernelError.
        """
        out = self.page.evaluate(_JS_EXECUTE, [code, int(timeout * 1000)])
        if out["error"]:
            raise KernelError(f"{out['error']}\n--- code ---\n{code}")
        lines = [ln for ln in out["stdout"].splitlines() if ln.strip()]
        return json.loads(lines[-1]) if lines else None

    def kernel_id(self) -> str | None:
        st = self.state()
        return st["kernelId"] if st else None

    # ---- viewport hooks
    def viewports(self) -> Any:
        return self.page.locator(".fwb-viewport")

    def viewport(self, index: int = 0) -> Any:
        return self.viewports().nth(index)

    def wait_viewports(self, count: int = 1, timeout: float = 60.0) -> None:
        """Wait until ``count`` viewports have drawn their first geometry."""
        self.page.wait_for_function(
            """(n) => { const els = document.querySelectorAll('.fwb-viewport');
                 return els.length >= n &&
                   Array.from(els).slice(0, n).every(e => e.getAttribute('data-ready') === '1'); }""",
            arg=count,
            timeout=timeout * 1000,
        )

    def frame(self, index: int = 0) -> int:
        return int(self.viewport(index).get_attribute("data-frame") or 0)

    def wait_frame_after(self, index: int, previous: int, timeout: float = 30.0) -> int:
        """Wait until viewport ``index`` rendered a geometry update after ``previous``."""
        self.page.wait_for_function(
            """([i, prev]) => { const e = document.querySelectorAll('.fwb-viewport')[i];
                 return e && Number(e.getAttribute('data-frame')) > prev; }""",
            arg=[index, previous],
            timeout=timeout * 1000,
        )
        return self.frame(index)

    def project(self, ids: list[int] | np.ndarray, index: int = 0) -> np.ndarray:
        """(k, 3) page (x, y, in_front) of vertex ``ids`` in viewport ``index``."""
        pts = self.viewport(index).evaluate("(e, ids) => e.fwbProject(ids)", [int(i) for i in ids])
        return np.array([p if p is not None else [np.nan] * 3 for p in pts], dtype=float)

    def canvas_box(self, index: int = 0) -> dict[str, float]:
        box = self.viewport(index).locator("canvas").bounding_box()
        assert box is not None, "viewport canvas is not visible"
        return box  # type: ignore[no-any-return]

    # ---- pixels
    def wait_full_detail(self, timeout: float = 30.0) -> None:
        """Wait until no viewport shows a fast-interaction draft.

        On a slow machine (software WebGL under load) a view draws a simplified face while
        parameters change and the full mesh ~0.14 s after the last change
        (widgets/js/src/viewport/gpu_draft.js); pictures compare full-detail frames.
        """
        self.page.wait_for_function(
            """() => Array.from(document.querySelectorAll('.fwb-viewport'))
                 .every(e => e.getAttribute('data-detail') !== 'draft')""",
            timeout=timeout * 1000,
        )

    def screenshot(
        self, name: str, clip: dict[str, float] | None = None, full_detail: bool = True
    ) -> np.ndarray:
        """Save ``test-artifacts/<test>/<name>.png``; return (h, w, 3) uint8 pixels.

        ``full_detail``: first wait until every view shows full detail (not a draft);
        False for a picture taken while a clip plays (it drafts until it stops).
        """
        from PIL import Image

        if full_detail:
            self.wait_full_detail()
        self.artifacts.mkdir(parents=True, exist_ok=True)
        path = self.artifacts / f"{name}.png"
        png = self.page.screenshot(path=str(path), clip=clip)
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def canvas_shot(self, name: str, index: int = 0) -> np.ndarray:
        return self.screenshot(name, clip=self.canvas_box(index))


def clip_around(points: np.ndarray, pad: float = 20.0) -> dict[str, float]:
    """Screenshot clip (page coordinates) around projected points (k, >=2)."""
    p = points[np.isfinite(points[:, 0])]
    x0, y0 = p[:, 0].min() - pad, p[:, 1].min() - pad
    x1, y1 = p[:, 0].max() + pad, p[:, 1].max() + pad
    return {"x": max(x0, 0.0), "y": max(y0, 0.0), "width": x1 - x0, "height": y1 - y0}


def pixel_change(a: np.ndarray, b: np.ndarray, threshold: int = 12) -> float:
    """Fraction of pixels whose largest channel difference exceeds ``threshold``."""
    if a.shape != b.shape:
        h, w = min(a.shape[0], b.shape[0]), min(a.shape[1], b.shape[1])
        a, b = a[:h, :w], b[:h, :w]
    diff = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=2)
    return float((diff > threshold).mean())


def write_notebook(path: Path, cells: list[str]) -> Path:
    """Write a minimal nbformat-4 notebook of code cells (python3 kernel)."""
    nb = {
        "cells": [
            {
                "cell_type": "code",
                "execution_count": None,
                "id": uuid.uuid4().hex[:8],
                "metadata": {},
                "outputs": [],
                "source": src,
            }
            for src in cells
        ],
        "metadata": {
            "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
            "language_info": {"name": "python"},
        },
        "nbformat": 4,
        "nbformat_minor": 5,
    }
    path.write_text(json.dumps(nb, indent=1))
    return path


def wait_until(what: str, get: Callable[[], Any], ok: Callable[[Any], bool], timeout: float = 60.0) -> Any:
    """Poll ``get()`` until ``ok(value)`` holds and return the value (no fixed sleeps).

    Raises AssertionError naming ``what`` and the last value after ``timeout`` seconds.
    """
    deadline = time.monotonic() + timeout
    value = get()
    while not ok(value):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}: {value!r}")
        time.sleep(0.05)
        value = get()
    return value
