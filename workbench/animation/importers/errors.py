"""The one error every animation importer raises: it names the file, and its message the row and column."""

from __future__ import annotations

from pathlib import Path

__all__ = ["AnimationImportError"]


class AnimationImportError(ValueError):
    """An animation file that cannot be turned into keys; the message names file, row and column."""

    def __init__(self, source: str | Path, message: str) -> None:
        self.source = str(source)
        self.detail = message
        super().__init__(f"{Path(self.source).name}: {message}")
