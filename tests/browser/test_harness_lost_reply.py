"""The harness tells JupyterLab's lost cell reply apart from a slow or failing notebook."""

from __future__ import annotations

from typing import Any

import pytest
from harness import LostCellReply, NotebookPage


class _FakePage:
    def __init__(self) -> None:
        self.handlers: dict[str, Any] = {}

    def on(self, event: str, fn: Any) -> None:
        self.handlers[event] = fn

    def evaluate(self, *_args: Any) -> None:
        return None


def _notebook(states: list[dict[str, Any]]) -> NotebookPage:
    nb = NotebookPage(_FakePage(), None, None, "fake.ipynb")  # type: ignore[arg-type]
    seq = iter(states)
    last: list[dict[str, Any]] = []

    def state() -> dict[str, Any]:
        nxt = next(seq, None)
        if nxt is not None:
            last[:] = [nxt]
        return last[0]

    nb.state = state  # type: ignore[method-assign]
    return nb


def _st(counts: list[int | None], kernel: str = "idle", pending: int = 0) -> dict[str, Any]:
    return {"kernel": kernel, "kernelId": "k", "counts": counts, "errors": [], "pending": pending}


def test_a_lost_first_reply_is_reported_as_such() -> None:
    nb = _notebook([_st([None, 2, 3], pending=1)])
    with pytest.raises(LostCellReply, match="reply never arrived"):
        nb.run_all(timeout=5, lost_after=0.5)


def test_a_busy_kernel_or_unrun_cells_are_not_a_lost_reply() -> None:
    # still running: not lost, and then it finishes
    nb = _notebook([_st([None, None, None], kernel="busy", pending=3)] * 3 + [_st([1, 2, 3])])
    assert nb.run_all(timeout=5, lost_after=0.1)["counts"] == [1, 2, 3]
    # nothing ran yet and the kernel idles: a plain time-out, not a lost reply
    nb = _notebook([_st([None, None])])
    with pytest.raises(AssertionError, match="did not finish"):
        nb.run_all(timeout=1, lost_after=0.1)


def test_the_probe_asks_the_kernel_on_a_connection_of_its_own(tmp_path) -> None:
    """A live kernel answers the probe's kernel_info_request (so a lost reply was lost upstream of it)."""
    from types import SimpleNamespace

    from jupyter_client import KernelManager

    runtime = tmp_path / "runtime"
    runtime.mkdir()
    km = KernelManager(connection_file=str(runtime / "kernel-abc123.json"))
    km.start_kernel()
    try:
        nb = NotebookPage(_FakePage(), SimpleNamespace(base=tmp_path, log_tail=lambda n: "log"),  # type: ignore[arg-type]
                          tmp_path / "artifacts", "fake.ipynb")
        nb.state = lambda: _st([1, 2])  # type: ignore[method-assign]
        out = nb.probe_kernel(_st([1, None], pending=1) | {"kernelId": "abc123"}, wait=1.0)
        assert out["kernel_info"].startswith("answered"), out
        assert out["counts_after"] == [1, 2]
        assert (tmp_path / "artifacts" / "lost-reply-probe.json").exists()
    finally:
        km.shutdown_kernel(now=True)
