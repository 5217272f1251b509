"""Batch jobs on Dask: many characters × takes × steps, locally or on a cluster (issue 20).

* :func:`run` — ``workbench.batch.run(jobs, client=None)``: every (character, take, step) as
  a Dask task (:mod:`.runner`); ``workbench batch JOBS.toml`` on the command line;
* :func:`load_jobs` / :class:`JobFile` — the TOML job file, checked before anything runs
  (:mod:`.jobfile`, :class:`JobFileError` names the line and the field);
* :mod:`.tasks` — the steps (``track``, ``transfer_rig``, ``retime``, ``enhance``, ``export``)
  on the existing core APIs; :mod:`.cache` — content addresses, task records, the per-worker
  memo of heavy set-ups; :mod:`.report` — outcomes and the summary table.

Dask (the ``batch`` extra) is imported when :func:`run` is called, never by ``import workbench``
nor by ``import workbench.batch``.
"""

from __future__ import annotations

from typing import Any

from workbench.batch.jobfile import STEP_FIELDS, JobFile, JobFileError, load_jobs, parse_jobs
from workbench.batch.report import BatchReport, TaskOutcome

__all__ = ["STEP_FIELDS", "BatchReport", "JobFile", "JobFileError", "TaskOutcome", "load_jobs", "parse_jobs",
           "plan", "run"]


def run(jobs: Any, client: Any = None, **kwargs: Any) -> BatchReport:
    """Run a job file on Dask; see :func:`workbench.batch.runner.run`."""
    from workbench.batch.runner import run as _run

    return _run(jobs, client, **kwargs)


def plan(jobs: JobFile, run_id: str | None = None) -> Any:
    """The task specs of a job file; see :func:`workbench.batch.runner.plan`."""
    from workbench.batch.runner import plan as _plan

    return _plan(jobs, run_id)
