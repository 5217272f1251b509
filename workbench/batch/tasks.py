"""One (character, take, step) task, as it runs on a Dask worker.

:func:`execute` is the function every Dask task calls: it skips a task whose content address
(:mod:`.cache`) is recorded with intact outputs, otherwise runs the step with a per-task log
file (``<output>/.batch/logs/<character>/<take>/NN-kind.log``) and records what it wrote. Any
error becomes a ``failed`` :class:`~workbench.batch.report.TaskOutcome` naming the input (the
other tasks carry on); the later steps of that (character, take) are ``blocked``.

The steps call the existing core APIs:

* ``track`` — :func:`workbench.capture.inputs.read_markers`, ``read_vertex_map``,
  :func:`workbench.capture.track`, then ``model.capture.apply(result)``;
* ``transfer_rig`` — :class:`workbench.rigging.RigTransfer` (template → character), as ``workbench rig``;
* ``retime`` — ``model.enhance.retime(t0, t1, takes)``;
* ``enhance`` — ``PerformanceDatabase.load(path).enhance(frames)`` through the correspondence from the
  character's mesh (the same, a Loop subdivision, or closest points), written as a PC2 point cache at the
  database's resolution;
* ``clone`` — :class:`workbench.rigging.ExpressionCloner` (character → the ``onto`` face, built once per
  worker): the take's frames played on that face, written as ``<take>.cloned.pc2``;
* ``export`` — :func:`workbench.export.export` for each format, to ``<output>/<character>/<take>.<ext>``.

A take that no ``track`` step reads is imported as an animation
(:func:`workbench.io.animation.read_file_animation`) by the first step that needs one. Between
steps the animation travels as :meth:`Timeline.to_json` in the task's result (kilobytes); the
rig never travels: each worker loads it (and builds a transferred rig or a database) once,
keyed by content digest (:func:`workbench.batch.cache.memo`).
"""

from __future__ import annotations

import logging
import os
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.batch.cache import MemoEntry, TaskRecord, atomic_write_text, file_digest, memo
from workbench.batch.jobfile import Take
from workbench.batch.report import TaskOutcome

if TYPE_CHECKING:
    from workbench.animation.tracks import Timeline
    from workbench.model import FaceModel

__all__ = ["RigSpec", "TaskSpec", "execute"]


@dataclass(frozen=True)
class RigSpec:
    """How to get a rig: a file, optionally with the template's shapes transferred onto it.

    ``digest`` is the content address of the result (file digest, or a key over the base rig,
    the template and the landmarks).
    """

    path: str
    digest: str
    template: str | None = None
    template_digest: str | None = None
    landmarks: str | None = None
    base_digest: str | None = None
    units: str | None = None


@dataclass(frozen=True)
class TaskSpec:
    """Everything a worker needs for one task (plain data: it is pickled to the worker)."""

    label: str
    character: str
    take: Take
    vertex_map: str | None
    index: int
    kind: str
    options: dict[str, Any]
    output: str
    key: str
    rig_in: RigSpec
    rig_out: RigSpec
    run_id: str
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def log_path(self) -> Path:
        return Path(self.output) / ".batch" / "logs" / self.character / self.take.name / f"{self.index:02d}-{self.kind}.log"

    def output_path(self, suffix: str) -> Path:
        return Path(self.output) / self.character / f"{self.take.name}.{suffix}"


# ------------------------------------------------------------------ heavy set-ups, once per worker
def _load_rig(spec: RigSpec, output: str) -> FaceModel:
    from workbench.io import load

    if spec.template is None:
        model = load(spec.path, units=spec.units) if spec.units else load(spec.path)
        model.history.clear()
        return model
    saved = Path(output) / ".batch" / "rigs" / f"{spec.digest}.fwb"
    if saved.is_file():
        return load(saved)
    from workbench.rigging import RigTransfer

    base = rig_entry(RigSpec(spec.path, spec.base_digest or "", units=spec.units), output)
    with base.lock:
        template = _template(spec.template)
        pairs = None
        if spec.landmarks:  # template_vertex,target_vertex with a header row, as `workbench rig --landmarks`
            table = np.loadtxt(spec.landmarks, delimiter=",", skiprows=1, dtype=np.int64, ndmin=2)
            pairs = [(int(a), int(b)) for a, b in table[:, :2]]
        model = RigTransfer(template, base.value, landmarks=pairs).run().model
    model.history.clear()
    saved.parent.mkdir(parents=True, exist_ok=True)
    model.save(saved)  # atomic; another worker may write the same rig: the rename wins either way
    return model


def _template(name: str) -> FaceModel:
    if os.path.exists(name):
        from workbench.io import load

        return load(name)
    import workbench

    return workbench.load_sample(name)


def rig_entry(spec: RigSpec, output: str) -> MemoEntry:
    """The rig of ``spec`` in this worker (loaded or transferred on first use)."""
    return memo(f"rig:{spec.digest}", lambda: _load_rig(spec, output))


def _animation_takes(paths: list[str], shape_names: list[str]) -> list[Timeline]:
    from workbench.batch.cache import task_key
    from workbench.io.animation import read_file_animation

    key = "retime-db:" + task_key([file_digest(p) for p in paths], shape_names)
    return memo(key, lambda: [read_file_animation(p, shape_names) for p in paths]).value


def _performance_database(path: str) -> Any:
    from workbench.enhance import PerformanceDatabase

    return memo(f"enhance-db:{file_digest(path)}", lambda: PerformanceDatabase.load(path)).value


# ------------------------------------------------------------------ the steps
@dataclass
class _Context:
    spec: TaskSpec
    model: FaceModel
    timeline: Timeline | None
    log: logging.Logger

    def animation(self) -> Timeline:
        """The animation so far, reading the take as an animation when no step has yet."""
        if self.timeline is None:
            from workbench.io.animation import read_file_animation

            take, md = self.spec.take, self.model.metadata
            self.log.info("reading the take %s as an animation", take.path)
            kw: dict[str, Any] = {"up_axis": md.up_axis, "front_axis": md.front_axis}
            if take.fps is not None:
                kw["fps"] = take.fps
            self.timeline = read_file_animation(take.path, self.model.shape_names, **kw)
        return self.timeline

    @contextmanager
    def on_model(self, timeline: Timeline) -> Iterator[FaceModel]:
        """The shared rig with ``timeline`` installed, restored (and its undo history dropped) after."""
        m = self.model
        before = m.tracks
        m.timeline.set(timeline, "batch: the take's animation")
        try:
            yield m
        finally:
            m.timeline.set(before, "batch: restore")
            m.history.clear()


def _step_track(c: _Context) -> list[Path]:
    from workbench.capture import track
    from workbench.capture.inputs import read_markers, read_vertex_map, to_model_units

    take, o = c.spec.take, c.spec.options
    if c.spec.vertex_map is None:
        raise ValueError("track needs a vertex_map (marker -> vertex) on the take or the character")
    seq = read_markers(take.path, units=take.units, fps=take.fps)
    ids = read_vertex_map(c.spec.vertex_map, seq, c.model.n_vertices)
    frames = to_model_units(seq, c.model)
    c.log.info("tracking %d frames x %d markers at %g fps", seq.n_frames, len(seq.names), seq.fps)
    kw = {k: o[k] for k in ("l1", "temporal", "adapt") if k in o}
    result = track(c.model, frames, vertex_ids=ids, fps=seq.fps, **kw)
    c.log.info("%s", result)
    with c.on_model(c.timeline if c.timeline is not None else c.model.tracks) as m:
        m.capture.apply(result, tolerance=float(o.get("tolerance", 0.01)))
        c.timeline = m.tracks
    return []


def _step_transfer_rig(c: _Context) -> list[Path]:
    # the rig is built (once per worker) before the step runs: c.model is the transferred rig;
    # the animation so far keeps the tracks of shapes the new rig has
    if c.timeline is not None:
        names = {f"weights/{n}" for n in c.model.shape_names}
        kept = {k: t for k, t in c.timeline.tracks.items() if not k.startswith("weights/") or k in names}
        dropped = sorted(set(c.timeline.tracks) - set(kept))
        if dropped:
            c.log.warning("the transferred rig has no shapes for %s", ", ".join(dropped[:10]))
        c.timeline = c.timeline.replace(tracks=kept)
    c.log.info("rig %s: %d vertices, %d shapes", c.spec.rig_out.digest[:12], c.model.n_vertices,
               len(c.model.shapes))
    return []


def _step_retime(c: _Context) -> list[Path]:
    o = c.spec.options
    takes = _animation_takes(list(o["database"]), list(c.model.shape_names))
    with c.on_model(c.animation()) as m:
        res = m.enhance.retime(float(o["t0"]), float(o["t1"]), takes,
                               n_frames=o.get("n_frames"), extend=bool(o.get("extend", False)),
                               method=str(o.get("method", "auto")))
        c.log.info("retimed %g-%g s: %s", o["t0"], o["t1"], res.describe())
        c.timeline = m.tracks
    return []


def _step_enhance(c: _Context) -> list[Path]:
    from workbench.enhance.bake import EnhancedTake
    from workbench.enhance.facet import default_correspondence

    database = _performance_database(c.spec.options["database"])
    tl = c.animation()
    times = np.asarray(tl.frame_times(), np.float64)
    frames = np.stack([c.model.evaluate_at(float(t), tl) for t in times]).astype(np.float64)
    # the character's mesh → the database's: the same mesh, a Loop subdivision of it, or closest points
    corr = default_correspondence(c.model, database)
    c.log.info("enhancing %d frames of %d vertices (%s correspondence to %d vertices)", len(times),
               c.model.n_vertices, corr.kind, database.neutral_.shape[0])
    res = database.enhance_result(frames, correspondence=corr)
    md = c.model.metadata
    take = EnhancedTake(res.frames, times, database.faces_, res.weights, tl.fps, md.metres_per_unit, md,
                        c.spec.character)
    path = c.spec.output_path("enhanced.pc2")
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    return list(take.export(path))


def _step_clone(c: _Context) -> list[Path]:
    from workbench.export import export

    o = c.spec.options
    cloner = _expression_cloner(c.model, c.spec.rig_out.digest, o["onto"], o.get("landmarks"))
    tl = c.animation()
    times = np.asarray(tl.frame_times(), np.float64)
    frames = np.stack([c.model.evaluate_at(float(t), tl) for t in times]).astype(np.float64)
    c.log.info("cloning %d frames of %d vertices onto %s (%d vertices)", len(times), c.model.n_vertices,
               o["onto"], cloner.target.n_vertices)
    face = cloner.clone_face(frames, times, fps=tl.fps)
    path = c.spec.output_path("cloned.pc2")
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    return [Path(p) for p in export(face, face.tracks, path)]


def _expression_cloner(model: FaceModel, rig_digest: str, onto: str, landmarks: str | None) -> Any:
    """The cloner from the character's rig onto ``onto``, built once per worker (keyed by content)."""
    from workbench.io import load
    from workbench.rigging import ExpressionCloner
    from workbench.rigging.landmarks import read_landmark_pairs

    def build() -> Any:
        target = load(onto)
        pairs = (read_landmark_pairs(landmarks, model.n_vertices, target.n_vertices, what="clone: landmarks")
                 if landmarks else None)
        return ExpressionCloner(model, target, landmarks=pairs)

    key = f"clone:{rig_digest}:{file_digest(onto)}:{file_digest(landmarks) if landmarks else ''}"
    return memo(key, build).value


def _step_export(c: _Context) -> list[Path]:
    from workbench.export import export

    o = c.spec.options
    tl = c.animation()
    written: list[Path] = []
    for suffix in o["formats"]:
        path = c.spec.output_path(suffix)
        path.parent.mkdir(parents=True, exist_ok=True)
        _remove_stale_temporaries(path)
        kw: dict[str, Any] = {"fps": o.get("fps"), "bake": bool(o.get("bake", False))}
        if suffix == "csv" and "style" in o:
            kw["style"] = o["style"]
        result = export(c.model, tl, path, **kw)
        for note in getattr(result, "notes", ()):
            c.log.info("note: %s", note)
        c.log.info("wrote %s", ", ".join(str(p) for p in result))
        written += [Path(p) for p in result]
    return written


def _remove_stale_temporaries(path: Path) -> None:
    """Delete temporaries of ``path`` a killed worker left (``atomic_path`` names them ``.<name>.*.tmp*``).

    Only this task writes ``path``, and Dask runs it again only after the worker that ran it is
    gone, so no live writer owns them.
    """
    for stale in path.parent.glob(f".{path.name}.*.tmp*"):
        stale.unlink(missing_ok=True)


STEPS = {"track": _step_track, "transfer_rig": _step_transfer_rig, "retime": _step_retime,
         "enhance": _step_enhance, "clone": _step_clone, "export": _step_export}


# ------------------------------------------------------------------ the task
@contextmanager
def _task_log(spec: TaskSpec) -> Iterator[tuple[logging.Logger, list[str]]]:
    """A logger whose records (and the core's ``workbench.*`` records) go to the task's log file."""
    lines: list[str] = []

    class _Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            lines.append(f"{time.strftime('%H:%M:%S')} {record.levelname:<7} {record.name}: {record.getMessage()}")

    handler = _Collect(logging.INFO)
    root = logging.getLogger("workbench")
    log = logging.getLogger(f"workbench.batch.task.{os.getpid()}")
    old_level = root.level
    root.addHandler(handler)
    if root.level == logging.NOTSET or root.level > logging.INFO:
        root.setLevel(logging.INFO)
    try:
        yield log, lines
    finally:
        root.removeHandler(handler)
        root.setLevel(old_level)
        atomic_write_text(spec.log_path, "\n".join(lines) + "\n")


def _error_message(source: Path | str, exc: BaseException) -> str:
    """``<Type>: <source>: <message>``, ``source`` left out when the message names it already."""
    msg = str(exc) or type(exc).__name__
    if Path(source).name not in msg:
        msg = f"{source}: {msg}"
    return f"{type(exc).__name__}: {msg}"


def _failed(outcome: TaskOutcome, source: Path | str, exc: BaseException, lines: list[str], log: logging.Logger,
            t0: float) -> TaskOutcome:
    lines.append(traceback.format_exc())
    outcome.status, outcome.error, outcome.input = "failed", _error_message(source, exc), str(source)
    outcome.seconds = time.perf_counter() - t0
    log.error("%s", outcome.error)
    return outcome


def execute(spec: TaskSpec, previous: TaskOutcome | None = None) -> TaskOutcome:
    """Run (or skip) one task; never raises for a problem with its inputs.

    Parameters
    ----------
    spec : TaskSpec
    previous : TaskOutcome, optional
        The outcome of the previous step of the same (character, take): its timeline is this
        step's input. ``failed``/``blocked`` there makes this one ``blocked``.
    """
    worker = _worker_address()
    base = TaskOutcome(spec.label, "done", input=str(spec.take.path), log=str(spec.log_path), key=spec.key,
                       rig_digest=spec.rig_out.digest, worker=worker)
    if previous is not None and previous.status in ("failed", "blocked"):
        base.status, base.error = "blocked", f"not run: {previous.label} {previous.status}"
        return base
    record = TaskRecord.load_valid(spec.output, spec.key)
    if record is not None:
        base.status = "done" if record.run_id == spec.run_id else "skipped"
        base.seconds = record.seconds if base.status == "done" else 0.0
        base.outputs, base.timeline = list(record.outputs), record.timeline
        return base
    t0 = time.perf_counter()
    with _task_log(spec) as (log, lines):
        log.info("%s on %s (key %s)", spec.label, worker or "this process", spec.key[:16])
        try:
            entry = rig_entry(spec.rig_out, spec.output)
        except Exception as exc:  # the rig (or the transfer onto it) is the bad input
            return _failed(base, spec.rig_out.path, exc, lines, log, t0)
        try:
            from workbench.animation.tracks import Timeline

            timeline = None if previous is None or previous.timeline is None else Timeline.from_json(previous.timeline)
            with entry.lock:
                ctx = _Context(spec, entry.value, timeline, log)
                written = STEPS[spec.kind](ctx)
            out_tl = None if ctx.timeline is None else ctx.timeline.to_json()
        except Exception as exc:  # a bad input fails this task only; the traceback goes to its log
            return _failed(base, spec.take.path, exc, lines, log, t0)
        base.seconds = time.perf_counter() - t0
        log.info("done in %.2f s", base.seconds)
    base.outputs, base.timeline = [str(p) for p in written], out_tl
    TaskRecord(spec.key, spec.label, {str(p): file_digest(p) for p in written}, out_tl, spec.rig_out.digest,
               base.seconds, spec.run_id).save(spec.output)
    return base


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return ""
