"""Temporary files left beside a workbench file by killed saves, and their removal.

A save writes a temporary file ``.<name>.<pid>.<random>.tmp`` beside the
target; the next save or load of the file removes temporaries whose writer no
longer runs (:func:`remove_stale_temporaries`).
"""

from __future__ import annotations

import glob
import logging
import os
import time
from pathlib import Path

logger = logging.getLogger("workbench.fileformat")


#: a temporary file of a writer whose pid cannot be read is stale after this many seconds
_STALE_AFTER_S = 600.0


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def remove_stale_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Delete what killed saves of ``path`` left beside it; returns the removed files.

    A save writes ``.<name>.<pid>.<random>.tmp`` and renames it over ``path``;
    killed mid-write (SIGKILL, power loss) the partial file stays. It is stale
    when its writer's process no longer runs (or, for a name without a pid,
    when it is older than ten minutes); a save in progress elsewhere is left
    alone. Called by every save and load of ``path``.
    """
    path = Path(path)
    removed: list[Path] = []
    try:
        candidates = list(path.parent.glob(f".{glob.escape(path.name)}.*.tmp"))
    except OSError:
        return removed
    now = time.time()
    for tmp in candidates:
        rest = tmp.name[len(path.name) + 2 : -len(".tmp")]
        pid_text = rest.split(".", 1)[0]
        try:
            if pid_text.isdigit() and "." in rest:
                stale = not _pid_alive(int(pid_text))
            else:
                stale = now - tmp.stat().st_mtime > _STALE_AFTER_S
            if stale:
                tmp.unlink()
                removed.append(tmp)
        except OSError:
            continue
    if removed:
        logger.info("%s: removed %d temporary file(s) left by interrupted saves", path.name, len(removed))
    return removed
