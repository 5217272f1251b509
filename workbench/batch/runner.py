"""Plan a job file into Dask tasks and run them on a cluster: :func:`plan` and :func:`run`.

:func:`plan` turns a :class:`~workbench.batch.jobfile.JobFile` into one chain of
:class:`~workbench.batch.tasks.TaskSpec` per (character, take) — one spec per step — with the
content address of every task computed on the client: the digests of the rig, the take, the
marker map and every file a step names, the step's options, the code version, chained through
the previous step's key. :func:`run` submits every spec as a Dask task whose input is the
previous step's future (so a take's steps run in order, takes and characters in parallel),
shows progress and returns a :class:`~workbench.batch.report.BatchReport`.

Without a ``client``, :func:`run` starts a ``LocalCluster`` bound to 127.0.0.1 (processes,
one thread each) or connects to ``scheduler`` (``tcp://host:8786``), and closes what it started.
Dask is imported here only, on first call: ``import workbench`` never imports it.
"""

from __future__ import annotations

import os
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from workbench.batch.cache import code_version, file_digest, task_key
from workbench.batch.jobfile import JobFile, load_jobs
from workbench.batch.report import BatchReport, TaskOutcome
from workbench.batch.tasks import RigSpec, TaskSpec, execute

__all__ = ["local_cluster", "plan", "run"]

#: how often Dask re-runs a task that raised (a lost worker is handled by the scheduler, which
#: re-runs its tasks up to ``distributed.scheduler.allowed-failures`` times)
RETRIES = 2


def _step_inputs(kind: str, options: dict[str, Any]) -> dict[str, Any]:
    """The options of a step with every file replaced by its digest (moving a project re-uses results)."""
    out = dict(options)
    if kind == "retime":
        out["database"] = [file_digest(p) for p in options["database"]]
    elif kind == "enhance":
        out["database"] = file_digest(options["database"])
    elif kind == "clone":
        out["onto"] = file_digest(options["onto"])
        if "landmarks" in options:
            out["landmarks"] = file_digest(options["landmarks"])
    elif kind == "transfer_rig":
        t = options.get("template", "head")
        out["template"] = file_digest(t) if os.path.exists(t) else f"sample:{t}"
        if "landmarks" in options:
            out["landmarks"] = file_digest(options["landmarks"])
    return out


def plan(jobs: JobFile, run_id: str | None = None) -> list[list[TaskSpec]]:
    """One list of task specs (the steps in order) per (character, take), characters outer.

    Reads every input file once to hash it (the content addresses).
    """
    run_id = run_id or uuid.uuid4().hex[:12]
    version = code_version()
    out = str(jobs.output)
    rigs = {c.name: file_digest(c.rig) for c in jobs.characters}
    takes = {t.name: file_digest(t.path) for t in jobs.takes}
    maps: dict[str, str] = {}
    steps = [(s.kind, s.options, _step_inputs(s.kind, s.options)) for s in jobs.steps]
    chains = []
    for ch in jobs.characters:
        for tk in jobs.takes:
            vmap = tk.vertex_map or ch.vertex_map
            if vmap is not None and str(vmap) not in maps:
                maps[str(vmap)] = file_digest(vmap)
            rig = RigSpec(str(ch.rig), rigs[ch.name], units=ch.units)
            key = task_key("input", version, out, ch.name, rigs[ch.name], ch.units, tk.name, takes[tk.name],
                           tk.fps, tk.units, None if vmap is None else maps[str(vmap)])
            chain = []
            for i, (kind, options, inputs) in enumerate(steps):
                rig_in = rig
                if kind == "transfer_rig":
                    t = options.get("template", "head")
                    rig = RigSpec(str(ch.rig), task_key("transfer", version, rig_in.digest, inputs),
                                  template=t, template_digest=inputs["template"],
                                  landmarks=options.get("landmarks"), base_digest=rig_in.digest, units=ch.units)
                key = task_key(key, i, kind, inputs)
                chain.append(TaskSpec(
                    label=f"{ch.name}/{tk.name}/{i:02d}-{kind}", character=ch.name, take=tk,
                    vertex_map=None if vmap is None else str(vmap), index=i, kind=kind, options=dict(options),
                    output=out, key=key, rig_in=rig_in, rig_out=rig, run_id=run_id,
                ))
            chains.append(chain)
    return chains


def local_cluster(workers: int | None = None, *, dashboard: bool = True, **kwargs: Any) -> Any:
    """A ``LocalCluster`` of ``workers`` processes with one thread each, every server on 127.0.0.1.

    The dashboard listens on 127.0.0.1 on a free port; ``dashboard=False`` leaves only the
    scheduler's health/metrics routes on that port (Dask always starts its HTTP server).
    """
    from distributed import LocalCluster

    n = workers or os.cpu_count() or 1
    if not dashboard:
        kwargs["scheduler_kwargs"] = {**kwargs.get("scheduler_kwargs", {}), "dashboard": False}
    return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                        dashboard_address="127.0.0.1:0", **kwargs)


def _in_notebook() -> bool:
    """True inside a Jupyter kernel that has ipywidgets (checked without importing either)."""
    import importlib.util

    return "ipykernel" in sys.modules and importlib.util.find_spec("ipywidgets") is not None


def _outcome_of(future: Any, spec: TaskSpec) -> TaskOutcome:
    if future.status == "finished":
        result: TaskOutcome = future.result()
        return result
    exc = future.exception() if future.status == "error" else None
    return TaskOutcome(spec.label, "failed", error=f"{type(exc).__name__}: {exc}" if exc else future.status,
                       input=str(spec.take.path), log=str(spec.log_path), key=spec.key)


def run(
    jobs: JobFile | str | os.PathLike[str],
    client: Any = None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    dashboard: bool = True,
    echo: Callable[[str], None] | None = None,
) -> BatchReport:
    """Run every (character, take, step) of ``jobs`` as Dask tasks.

    Parameters
    ----------
    jobs : JobFile or path
        A checked job file, or the path of one (checked before anything runs:
        :class:`~workbench.batch.jobfile.JobFileError`).
    client : distributed.Client, optional
        Where to run. Default: connect to ``scheduler``, else start :func:`local_cluster`.
    scheduler : str, optional
        Address of a running scheduler, e.g. ``tcp://host:8786`` (ignored with ``client``).
    workers : int, optional
        Workers of the local cluster (default: one per CPU).
    progress : bool
        A progress bar: text in a terminal, Dask's widget in a notebook.
    dashboard : bool
        Start the local cluster's dashboard (127.0.0.1, a free port) and print its link.
    echo : callable, optional
        Where messages and the summary table go (default ``print``; ``progress=False`` and
        no ``echo``: silent).

    Returns
    -------
    BatchReport
        One outcome per task in job order; ``report.table()`` is the summary.
    """
    from distributed import Client, wait

    t0 = time.perf_counter()
    job = jobs if isinstance(jobs, JobFile) else load_jobs(jobs)
    say = echo or (print if progress else (lambda _msg: None))
    chains = plan(job)
    own_cluster = own_client = None
    if client is None:
        if scheduler is not None:
            client = own_client = Client(scheduler)
        else:
            own_cluster = local_cluster(workers, dashboard=dashboard, silence_logs=40)
            client = own_client = Client(own_cluster)
    try:
        link = None
        if dashboard:
            try:
                link = client.dashboard_link
            except Exception:  # no dashboard on this scheduler
                link = None
        n_workers = len(client.scheduler_info().get("workers", {}))
        say(f"workbench batch: {job.n_tasks} tasks ({len(job.characters)} characters x {len(job.takes)} takes x "
            f"{len(job.steps)} steps) on {n_workers} workers at {client.scheduler.address}"
            + (f"; dashboard {link}" if link else ""))
        futures, specs = [], []
        for chain in chains:
            previous = None
            for spec in chain:
                fut = client.submit(execute, spec, previous, key=f"{spec.label}-{spec.key[:12]}-{spec.run_id}",
                                    pure=False, retries=RETRIES)
                futures.append(fut)
                specs.append(spec)
                previous = fut
        if progress:
            from distributed import progress as dask_progress

            if _in_notebook():
                # Dask's widget displays itself (distributed imports IPython, the core does not); the
                # kernel is busy in wait() below, so it updates when the cell ends: the dashboard
                # link above is the live view
                bar = dask_progress(futures, notebook=True)
                show = getattr(bar, "_ipython_display_", None)
                if show is not None:
                    show()
            else:
                dask_progress(futures, notebook=False)  # a text bar; returns when all are finished
        wait(futures)
        outcomes = [_outcome_of(f, s) for f, s in zip(futures, specs, strict=True)]
        for f in futures:
            f.release()
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
    report = BatchReport(outcomes, time.perf_counter() - t0, link)
    if progress or echo:
        say("")
        say(report.table(str(job.output)))
    return report


def output_folder(jobs: JobFile | str | os.PathLike[str]) -> Path:
    """The output folder of a job file (for tools that list what a run wrote)."""
    return (jobs if isinstance(jobs, JobFile) else load_jobs(jobs)).output
