"""What each batch task did, and the summary table printed at the end of a run.

:class:`TaskOutcome` is what a task returns through Dask (small: paths, status, the timeline
handed to the next step). :class:`BatchReport` collects them and prints
``task | status | seconds | output`` with the totals; status is one of

* ``done`` — the step ran in this run;
* ``skipped`` — its content address was already recorded with intact outputs;
* ``failed`` — it raised; ``error`` names the input and the problem (the task log has the traceback);
* ``blocked`` — an earlier step of the same (character, take) failed.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

__all__ = ["STATUSES", "BatchReport", "TaskOutcome"]

STATUSES = ("done", "skipped", "failed", "blocked")


@dataclass
class TaskOutcome:
    """The result of one (character, take, step) task.

    Attributes
    ----------
    label : str
        ``character/take/NN-kind``.
    status : {"done", "skipped", "failed", "blocked"}
    seconds : float
        Wall time of the step in this run (0 when skipped or blocked).
    outputs : list of str
        Files the step wrote (recorded ones when skipped).
    error : str or None
        For ``failed``/``blocked``: which input and what went wrong.
    input : str
        The take file.
    log : str
        The task's log file.
    key : str
        The content address.
    timeline : dict or None
        The animation after this step (JSON), for the next step.
    rig_digest : str
        The rig the next step works on.
    worker : str
        Address of the worker that ran it.
    """

    label: str
    status: str
    seconds: float = 0.0
    outputs: list[str] = field(default_factory=list)
    error: str | None = None
    input: str = ""
    log: str = ""
    key: str = ""
    timeline: dict[str, Any] | None = None
    rig_digest: str = ""
    worker: str = ""


@dataclass
class BatchReport:
    """Every task's outcome, in job order; ``counts`` by status; :meth:`table` for printing."""

    outcomes: list[TaskOutcome]
    seconds: float = 0.0
    dashboard: str | None = None

    @property
    def counts(self) -> dict[str, int]:
        c = Counter(o.status for o in self.outcomes)
        return {s: c.get(s, 0) for s in STATUSES}

    @property
    def ok(self) -> bool:
        """True when nothing failed or was blocked."""
        return not any(o.status in ("failed", "blocked") for o in self.outcomes)

    def by_label(self) -> dict[str, TaskOutcome]:
        return {o.label: o for o in self.outcomes}

    def failures(self) -> list[TaskOutcome]:
        return [o for o in self.outcomes if o.status == "failed"]

    def table(self, relative_to: str | None = None) -> str:
        """The summary: one row per task, then the totals and every failure's message."""
        def short(path: str) -> str:
            if relative_to and path.startswith(relative_to.rstrip("/") + "/"):
                return path[len(relative_to.rstrip("/")) + 1:]
            return path

        rows = [("task", "status", "seconds", "output")]
        for o in self.outcomes:
            out = ", ".join(short(p) for p in o.outputs) if o.outputs else ("-" if o.error is None else "see below")
            rows.append((o.label, o.status, f"{o.seconds:.2f}", out))
        widths = [max(len(r[i]) for r in rows) for i in range(3)]
        lines = [f"{r[0]:<{widths[0]}}  {r[1]:<{widths[1]}}  {r[2]:>{widths[2]}}  {r[3]}" for r in rows]
        lines.insert(1, "-" * (sum(widths) + 6 + max(len(r[3]) for r in rows)))
        c = self.counts
        lines.append(f"{len(self.outcomes)} tasks: {c['done']} done, {c['skipped']} skipped, {c['failed']} failed, "
                     f"{c['blocked']} blocked in {self.seconds:.1f} s")
        for o in self.outcomes:
            if o.status == "failed":
                lines.append(f"FAILED {o.label} ({o.input}): {o.error}  [log: {short(o.log)}]")
        return "\n".join(lines)
