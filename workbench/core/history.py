"""Undo/redo as a bounded command history.

Every edit made through :class:`workbench.FaceModel` methods becomes a
:class:`Command` that stores only what changed (old and new values of the
touched fields), never a snapshot of the model. The history is bounded by step
count and by bytes: the oldest steps are dropped first, like Blender's
``Undo Steps`` / memory limit.

No kept library offers a numpy-aware bounded command stack, hence this module.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np


def payload_nbytes(obj: Any) -> int:
    """Rough size in bytes of a command payload (arrays dominate)."""
    if isinstance(obj, np.ndarray):
        return int(obj.nbytes)
    if isinstance(obj, dict):
        return sum(payload_nbytes(k) + payload_nbytes(v) for k, v in obj.items())
    if isinstance(obj, list | tuple):
        return sum(payload_nbytes(v) for v in obj)
    if hasattr(obj, "__dataclass_fields__"):
        return sum(payload_nbytes(getattr(obj, f)) for f in obj.__dataclass_fields__)
    return 16


@dataclass
class Command:
    """One undoable step.

    Parameters
    ----------
    label : str
        What the user sees in the undo list ("Set jawOpen", "Drag handle 12").
    undo, redo : callable
        Apply the old / new values. They must not push history themselves.
    nbytes : int
        Memory held by the step, for the byte budget.
    """

    label: str
    undo: Callable[[], None]
    redo: Callable[[], None]
    nbytes: int = 0
    children: list[Command] = field(default_factory=list)


def compound(label: str, commands: list[Command]) -> Command:
    """Group commands into one step; undo runs them in reverse order."""
    cmds = list(commands)

    def undo() -> None:
        for c in reversed(cmds):
            c.undo()

    def redo() -> None:
        for c in cmds:
            c.redo()

    return Command(label, undo, redo, sum(c.nbytes for c in cmds), cmds)


class History:
    """Bounded undo/redo stacks.

    Parameters
    ----------
    max_steps : int
        Oldest steps beyond this count are forgotten.
    max_bytes : int
        Oldest steps are forgotten while the stored payloads exceed this.
    """

    def __init__(self, max_steps: int = 256, max_bytes: int = 512 * 2**20) -> None:
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        self.max_steps = max_steps
        self.max_bytes = max_bytes
        self._undo: deque[Command] = deque()
        self._redo: list[Command] = []
        self._lock = threading.RLock()
        self._group: list[Command] | None = None

    @property
    def nbytes(self) -> int:
        return sum(c.nbytes for c in self._undo) + sum(c.nbytes for c in self._redo)

    @property
    def undo_labels(self) -> list[str]:
        """Labels, most recent last."""
        return [c.label for c in self._undo]

    @property
    def redo_labels(self) -> list[str]:
        """Labels, next redo last."""
        return [c.label for c in self._redo]

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    def push(self, command: Command) -> None:
        """Record an already-applied command; clears the redo stack."""
        with self._lock:
            if self._group is not None:
                self._group.append(command)
                return
            self._undo.append(command)
            self._redo.clear()
            self._trim()

    def _trim(self) -> None:
        while len(self._undo) > self.max_steps:
            self._undo.popleft()
        total = self.nbytes
        while len(self._undo) > 1 and total > self.max_bytes:
            total -= self._undo.popleft().nbytes

    @contextmanager
    def group(self, label: str) -> Iterator[None]:
        """Record every command pushed inside as one step (undone in reverse order).

        If the body raises, the commands pushed so far are undone and nothing is recorded.
        """
        with self._lock:
            if self._group is not None:  # nested: join the outer group
                yield
                return
            self._group = []
            try:
                yield
            except BaseException:
                cmds, self._group = self._group, None
                for c in reversed(cmds):
                    c.undo()
                raise
            cmds, self._group = self._group, None
            if cmds:
                self.push(compound(label, cmds))

    def undo(self) -> Command | None:
        """Undo the most recent step; returns it, or None when there is nothing to undo."""
        with self._lock:
            if not self._undo:
                return None
            cmd = self._undo.pop()
            cmd.undo()
            self._redo.append(cmd)
            return cmd

    def redo(self) -> Command | None:
        """Redo the most recently undone step; returns it, or None."""
        with self._lock:
            if not self._redo:
                return None
            cmd = self._redo.pop()
            cmd.redo()
            self._undo.append(cmd)
            self._trim()
            return cmd

    def clear(self) -> None:
        with self._lock:
            self._undo.clear()
            self._redo.clear()
