"""Comma-separated text with ``#`` comment lines, as cells line by line (marker CSV, vertex maps)."""

from __future__ import annotations

import csv
from collections.abc import Sequence


def _csv_rows(text: str) -> list[list[str]]:
    """Cells of every line (comments and blank lines → []), one entry per line."""
    lines = text.splitlines()
    masked = ["" if ln.lstrip().startswith("#") else ln for ln in lines]
    rows = list(csv.reader(masked))
    if len(rows) != len(lines):  # a quoted field spanning lines: fall back to line by line
        rows = [next(csv.reader([ln])) if ln else [] for ln in masked]
    return rows


def _blank(cells: Sequence[str]) -> bool:
    return not any(c.strip() for c in cells)


def _trim(cells: list[str]) -> list[str]:
    while cells and not cells[-1].strip():
        cells = cells[:-1]
    return cells
