"""The error every capture input reader raises: :class:`CaptureInputError`.

A :class:`~workbench.geometry.mesh_checks.MeshFormatError` (so a ``ValueError``)
whose message names the file, the line and/or frame, and the column or field,
and says what was expected.
"""

from __future__ import annotations

from pathlib import Path

from workbench.geometry.mesh_checks import MeshFormatError

__all__ = ["CaptureInputError"]


class CaptureInputError(MeshFormatError):
    """A capture input that cannot be read; the message names file, line/frame and column/field.

    Attributes
    ----------
    source : str
        The file (or ``"<array>"``, ``"<mapping>"`` for in-memory input).
    frame : int or None
        The frame (as numbered in the returned sequence), when one is at fault.
    line : int or None
        The 1-based line of a text file, when one is at fault.
    column : str or None
        The CSV column (or marker) at fault.
    field : str
        The column, or what else was at fault ("units", "intrinsics 'fx'", ...).
    detail : str
        The message without the file name.
    """

    def __init__(
        self,
        source: str | Path,
        detail: str,
        *,
        frame: int | None = None,
        line: int | None = None,
        column: str | None = None,
        field: str | None = None,
    ) -> None:
        where = []
        if line is not None and frame is not None:
            where.append(f"line {line} (frame {frame})")
        elif line is not None:
            where.append(f"line {line}")
        elif frame is not None:
            where.append(f"frame {frame}")
        if column is not None:
            where.append(f"column {column!r}")
        if field is not None:
            where.append(field)
        message = f"{', '.join(where)}: {detail}" if where else detail
        super().__init__(source, column or field or "", message)
        self.frame = frame
        self.line = line
        self.column = column
        self.detail = detail
