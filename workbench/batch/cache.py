"""Content addresses, the on-disk record of finished tasks, and the per-worker memo of heavy set-ups.

* :func:`file_digest` — SHA-256 of a file's bytes (or of every file under a folder, by relative path);
* :func:`code_version` — the package version plus a hash of the ``workbench`` sources, so a code
  change re-runs everything;
* :func:`task_key` — the content address of a task: its inputs' digests, the step's options and the
  code version, chained through the previous step's key;
* :class:`TaskRecord` — ``<output>/.batch/tasks/<key>.json``: outputs with their digests and the
  timeline handed to the next step; a task whose record is present and whose outputs still hash
  the same is skipped;
* :func:`memo` — a per-process (so per-worker) cache of loaded rigs, transferred rigs and
  databases keyed by content digest: a heavy set-up is built once per worker, not once per task.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = [
    "MemoEntry",
    "TaskRecord",
    "atomic_write_text",
    "code_version",
    "file_digest",
    "memo",
    "memo_stats",
    "task_key",
]

_CHUNK = 1 << 20


def file_digest(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes; for a folder, of its files' relative paths and bytes."""
    p = Path(path)
    h = hashlib.sha256()
    files: Iterable[Path] = sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
    for f in files:
        if p.is_dir():
            h.update(f.relative_to(p).as_posix().encode() + b"\0")
        with open(f, "rb") as fh:
            while chunk := fh.read(_CHUNK):
                h.update(chunk)
    return h.hexdigest()


_CODE_VERSION: str | None = None


def code_version() -> str:
    """``<version>+<12 hex>``: the package version and a digest of every ``workbench/**/*.py``."""
    global _CODE_VERSION
    if _CODE_VERSION is None:
        import workbench

        root = Path(workbench.__file__).parent
        h = hashlib.sha256()
        for f in sorted(root.rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
        _CODE_VERSION = f"{workbench.__version__}+{h.hexdigest()[:12]}"
    return _CODE_VERSION


def task_key(*parts: Any) -> str:
    """SHA-256 (hex) of JSON-encoded ``parts`` (sorted keys: option order does not matter)."""
    text = json.dumps(parts, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to a temporary file next to ``path`` and ``os.replace`` it into place."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    finally:
        if tmp.exists():
            tmp.unlink()
    return p


@dataclass
class TaskRecord:
    """What a finished task left: ``outputs`` (path -> SHA-256) and the ``timeline`` it hands on.

    Attributes
    ----------
    key : str
        The task's content address (:func:`task_key`).
    label : str
        ``character/take/NN-kind``.
    outputs : dict of str to str
        Absolute output path -> SHA-256 of its bytes.
    timeline : dict or None
        :meth:`workbench.animation.tracks.Timeline.to_json` of the animation after this step
        (None: the take has not been read yet).
    rig_digest : str
        Content address of the rig the next step works on (changes after ``transfer_rig``).
    seconds : float
        Time the step took when it ran.
    run_id : str
        The run that produced it (a task recomputed after a lost worker in the same run is
        reported as done, not skipped).
    """

    key: str
    label: str
    outputs: dict[str, str] = field(default_factory=dict)
    timeline: dict[str, Any] | None = None
    rig_digest: str = ""
    seconds: float = 0.0
    run_id: str = ""

    @staticmethod
    def path(output: str | os.PathLike[str], key: str) -> Path:
        return Path(output) / ".batch" / "tasks" / key[:2] / f"{key}.json"

    def save(self, output: str | os.PathLike[str]) -> Path:
        # vars(), not dataclasses.asdict: asdict deep-copies the timeline (0.3 s for a 25k-key take)
        return atomic_write_text(self.path(output, self.key), json.dumps(vars(self)))

    @classmethod
    def load_valid(cls, output: str | os.PathLike[str], key: str) -> TaskRecord | None:
        """The record of ``key`` if it exists and every output still has its recorded digest."""
        p = cls.path(output, key)
        try:
            rec = cls(**json.loads(p.read_text(encoding="utf-8")))
        except (OSError, ValueError, TypeError):
            return None
        for out, digest in rec.outputs.items():
            if not Path(out).is_file() or file_digest(out) != digest:
                return None
        return rec


@dataclass
class MemoEntry:
    """A memoised value with a lock: hold ``lock`` while using a mutable value (a model)."""

    value: Any
    lock: threading.RLock = field(default_factory=threading.RLock)
    built: bool = False


_MEMO: OrderedDict[str, MemoEntry] = OrderedDict()
_MEMO_LOCK = threading.Lock()
_BUILDS: dict[str, int] = {}
#: entries kept per process (least recently used are dropped first)
MEMO_SIZE = 16


def memo(key: str, build: Callable[[], Any]) -> MemoEntry:
    """The value for ``key`` in this process, built by ``build()`` on first use (one build per key).

    ``key`` must be a content address (e.g. ``"rig:" + digest``): equal keys mean equal values.
    """
    with _MEMO_LOCK:
        entry = _MEMO.get(key)
        if entry is not None:
            _MEMO.move_to_end(key)
    if entry is not None:
        with entry.lock:  # wait for a build in progress on another thread
            if entry.built:
                return entry
    with _MEMO_LOCK:
        entry = MemoEntry(None)
        entry.lock.acquire()  # others asking for the same key wait for this build
        _MEMO[key] = entry
    try:
        entry.value = build()
        entry.built = True
        _BUILDS[key] = _BUILDS.get(key, 0) + 1
    except BaseException:
        with _MEMO_LOCK:
            _MEMO.pop(key, None)
        raise
    finally:
        entry.lock.release()
    with _MEMO_LOCK:
        while len(_MEMO) > MEMO_SIZE:
            _MEMO.popitem(last=False)
    return entry


def memo_stats() -> dict[str, int]:
    """How many times each key was built in this process (1 per key when the memo works)."""
    with _MEMO_LOCK:
        return dict(_BUILDS)
