"""Autosave and crash recovery for a FaceModel.

:class:`Autosaver` watches the model's history (every undoable edit, undo and
redo emits ``events.history``; key edits too) and, once edits pause for
``delay`` seconds, saves the whole model atomically to a recovery file
(:func:`workbench.fileformat.save_model`: temp file + fsync + rename, so a
crash mid-save keeps the previous recovery file). Beside it an ``.owner``
JSON file records the process id and the start time.

After a kernel crash or restart the owner process is gone, so
:func:`find_recoverable` lists the file; :func:`recover` loads it. A clean
``Autosaver.close(discard=True)`` (the user saved properly, or asked to
discard) removes both files. Nothing the user did is lost beyond the last
``delay`` seconds.

Threads: the debounce timer and the snapshot run on the *scheduler's*
thread, the writing on a writer thread of its own. A notebook passes the
kernel's event loop as the scheduler (``Workbench`` does), so the snapshot is
taken on the UI thread between edits and the state changes (``changed``) are
delivered there too, while the slow part (hashing, zip, fsync) never blocks
the user. Without a scheduler (a script) a ``threading.Timer`` snapshots under
the model's lock.

Written here because it is glue between our model's events and our file
format; the timer is the standard library's or the event loop's.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from psygnal import Signal

from workbench.fileformat import ModelSnapshot, read_manifest, snapshot_model, write_snapshot

if TYPE_CHECKING:
    from workbench.model import FaceModel

_SUFFIX = ".recovery.fwb"


def recovery_dir() -> Path:
    """Folder of recovery files (``$WORKBENCH_RECOVERY_DIR`` or ``~/.cache/face-workbench/recovery``)."""
    env = os.environ.get("WORKBENCH_RECOVERY_DIR")
    d = Path(env) if env else Path.home() / ".cache" / "face-workbench" / "recovery"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@dataclass(frozen=True)
class Recoverable:
    """A recovery file left by a session that did not close cleanly."""

    name: str
    path: Path
    saved_at: float
    pid: int
    n_vertices: int
    n_shapes: int
    n_keys: int

    def describe(self) -> str:
        when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.saved_at))
        return (
            f"{self.name}: autosaved {when} ({self.n_vertices} vertices, {self.n_shapes} shapes, "
            f"{self.n_keys} keyed tracks)"
        )


class Cancellable(Protocol):
    def cancel(self) -> object: ...


class Scheduler(Protocol):
    """Where autosave's timer and state changes run: an asyncio loop fits (``call_later``, ``call_soon_threadsafe``)."""

    def call_later(self, delay: float, callback: Callable[[], Any], /) -> Cancellable: ...

    def call_soon_threadsafe(self, callback: Callable[[], Any], /) -> object: ...


class ThreadScheduler:
    """The scheduler of a script: ``threading.Timer``; state changes delivered on the writer thread."""

    def call_later(self, delay: float, callback: Callable[[], Any], /) -> Cancellable:
        timer = threading.Timer(delay, callback)
        timer.daemon = True
        timer.start()
        return timer

    def call_soon_threadsafe(self, callback: Callable[[], Any], /) -> None:
        callback()


class Autosaver:
    """Debounced atomic autosave of ``model`` under ``name``.

    Parameters
    ----------
    model : FaceModel
    name : str
        Session name (file stem), e.g. the notebook's name.
    delay : float
        Seconds of quiet after the last edit before saving.
    folder : path, optional
        Default :func:`recovery_dir`.
    scheduler : Scheduler, optional
        Runs the timer, the snapshot and the ``changed`` signal (a notebook: the
        kernel's event loop, so all three happen on the UI thread). Default
        :class:`ThreadScheduler`.

    Attributes
    ----------
    state : str
        ``"idle"``, ``"pending"``, ``"saved"`` or ``"error: ..."``.
    last_saved : float or None
        ``time.time()`` of the last successful save.
    changed : psygnal.Signal(str)
        Emitted with the new state, on the scheduler's thread.
    """

    changed = Signal(str)

    def __init__(
        self,
        model: FaceModel,
        name: str,
        delay: float = 2.0,
        folder: str | Path | None = None,
        scheduler: Scheduler | None = None,
    ) -> None:
        if not name or any(c in name for c in "/\\\0"):
            raise ValueError(f"autosave name must be a plain file stem, got {name!r}")
        if delay < 0:
            raise ValueError(f"delay must be >= 0, got {delay}")
        self.model = model
        self.name = name
        self.delay = float(delay)
        self.folder = Path(folder) if folder is not None else recovery_dir()
        self.folder.mkdir(parents=True, exist_ok=True)
        self.path = self.folder / f"{name}{_SUFFIX}"
        self.owner_path = self.folder / f"{name}{_SUFFIX}.owner"
        self.scheduler: Scheduler = scheduler if scheduler is not None else ThreadScheduler()
        self.state = "idle"
        self.last_saved: float | None = None
        self.saves = 0
        self._timer: Cancellable | None = None
        self._lock = threading.Lock()  # the timer handle and the writer (ThreadScheduler: two threads)
        self._writer: ThreadPoolExecutor | None = None
        self._writing: Future[None] | None = None
        self._closed = False
        model.events.history.connect(self._on_edit)
        model.events.tracks.connect(self._on_edit)
        if self.path.exists():
            # This session takes the name over (it was just recovered, or the user chose
            # to start fresh): a second kernel must not offer the same file again.
            self._write_owner()

    def _write_owner(self) -> None:
        tmp = self.owner_path.with_suffix(".tmp")
        tmp.write_text(json.dumps({"pid": os.getpid(), "saved_at": time.time()}))
        os.replace(tmp, self.owner_path)

    def _set_state(self, state: str) -> None:
        self.state = state
        self.changed.emit(state)

    def _schedule(self) -> None:
        with self._lock:
            if self._closed:
                return
            if self._timer is not None:
                self._timer.cancel()
            self._timer = self.scheduler.call_later(self.delay, self._due)

    def _on_edit(self, *_: object) -> None:
        self._schedule()
        self._set_state("pending")

    def _due(self) -> None:
        """The timer fired (on the scheduler's thread): snapshot now, write on the writer thread."""
        with self._lock:
            self._timer = None
            if self._closed:
                return
        if self.model.interacting:  # mid-drag: try again when it settles
            self._schedule()
            return
        try:
            snapshot = snapshot_model(self.model)
        except Exception as exc:  # report, keep running: autosave must not break editing
            self._set_state(f"error: {exc}")
            return
        with self._lock:
            if self._closed:
                return
            if self._writer is None:
                self._writer = ThreadPoolExecutor(1, thread_name_prefix="autosave-writer")
            self._writing = self._writer.submit(self._write, snapshot)

    def _write(self, snapshot: ModelSnapshot) -> None:
        """On the writer thread: write, then hand the outcome back to the scheduler's thread."""
        error = self._store(snapshot)
        self.scheduler.call_soon_threadsafe(lambda: self._written(error))

    def _store(self, snapshot: ModelSnapshot) -> str:
        """Write ``snapshot`` and the owner file; the error text ("" when saved), never raised."""
        try:
            write_snapshot(snapshot, self.path)
            self._write_owner()
        except Exception as exc:  # report, keep running: autosave must not break editing
            return f"error: {exc}"
        return ""

    def _written(self, error: str) -> None:
        if not error:
            self.last_saved = time.time()
            self.saves += 1
        if not self._closed:
            self._set_state(error or "saved")

    def save_now(self) -> None:
        """Save immediately on this thread. Errors go to ``state``, never raised."""
        with self._lock:
            if self._closed:
                return
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
        self.wait()
        try:
            snapshot = snapshot_model(self.model)
        except Exception as exc:  # report, keep running: autosave must not break editing
            error = f"error: {exc}"
        else:
            error = self._store(snapshot)
        self._written(error)

    def wait(self, timeout: float | None = None) -> None:
        """Wait until a write in progress is on disk."""
        writing = self._writing
        if writing is not None:
            writing.result(timeout)

    def close(self, discard: bool = False) -> None:
        """Stop watching; ``discard=True`` also deletes the recovery file (a clean exit)."""
        with self._lock:
            self._closed = True
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            writer, self._writer = self._writer, None
        if writer is not None:
            writer.shutdown(wait=True)  # a write in progress finishes before the files go
        self.model.events.history.disconnect(self._on_edit)
        self.model.events.tracks.disconnect(self._on_edit)
        if discard:
            self.path.unlink(missing_ok=True)
            self.owner_path.unlink(missing_ok=True)


def find_recoverable(folder: str | Path | None = None, include_live: bool = False) -> list[Recoverable]:
    """Recovery files whose owner process is gone (newest first).

    ``include_live`` also lists files of running sessions (e.g. another notebook).
    """
    d = Path(folder) if folder is not None else recovery_dir()
    found = []
    for p in sorted(d.glob(f"*{_SUFFIX}")):
        owner = Path(str(p) + ".owner")
        try:
            info = json.loads(owner.read_text()) if owner.is_file() else {}
        except (OSError, json.JSONDecodeError):
            info = {}
        pid = int(info.get("pid", -1))
        if _pid_alive(pid) and not include_live and pid != -1:
            continue
        try:
            m = read_manifest(p)
        except (OSError, ValueError):
            continue  # unreadable: nothing to offer
        tracks = (m.get("tracks") or {}).get("tracks", {})
        found.append(
            Recoverable(
                name=p.name[: -len(_SUFFIX)],
                path=p,
                saved_at=float(info.get("saved_at", p.stat().st_mtime)),
                pid=pid,
                n_vertices=int(m["mesh"]["n_vertices"]),
                n_shapes=len(m["shapes"]),
                n_keys=len(tracks),
            )
        )
    return sorted(found, key=lambda r: r.saved_at, reverse=True)


def recover(item: Recoverable | str | Path) -> FaceModel:
    """Load a recovery file (a :class:`Recoverable` or a path)."""
    from workbench.fileformat import load_model

    return load_model(item.path if isinstance(item, Recoverable) else item)
