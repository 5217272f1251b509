"""Markers and landmarks from comma-separated text: :func:`read_marker_csv`.

Comma-separated, UTF-8 (an optional BOM), in one of two layouts:

- **flat layout**: one header row, then one row per frame. Header cells
  (case and surrounding spaces ignored): an optional frame-number column
  ``frame`` (also ``frame#``, ``frame_index``, ``frame number``), an optional
  time column in seconds ``time`` (also ``time_s``, ``seconds``,
  ``time (seconds)``), and three columns per marker named
  ``<name>_x, <name>_y, <name>_z`` or ``<name>.X, <name>.Y, <name>.Z`` (split
  at the *last* ``_`` or ``.``; any order; a marker's three columns must all
  be there). Any other column is an error.
- **Vicon Nexus "Trajectories" layout**: a row ``Trajectories``, a row with
  the frame rate, a row with each marker's name above its X column, a row
  ``Frame, Sub Frame, X, Y, Z, X, Y, Z, ...``, an optional row of units
  (``mm``), then the frames, up to the first blank row (other sections such
  as ``Devices`` are skipped).

Lines starting with ``#`` are comments; ``# units: mm`` and ``# fps: 120``
(also ``key = value``) before the header state the unit and the frame rate.
An **empty cell** or ``NaN`` is an occluded marker; a marker with some but
not all of x, y, z empty is an error. With a frame column, frame numbers
must increase; skipped frame numbers become frames with every marker
occluded.

The unit: ``units=`` wins, else ``# units:``, else the Vicon units row; none
is an error. The frame rate: ``fps=`` wins, else ``# fps:`` or the Vicon rate
row, else the time column's, else 30 with a warning.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.capture.inputs.csv_text import _blank, _csv_rows, _trim
from workbench.capture.inputs.errors import CaptureInputError
from workbench.capture.inputs.units import (
    DEFAULT_FPS,
    _check_span,
    _frame_spans,
    _resolve_unit,
)
from workbench.io.markers import MarkerSequence

__all__ = ["read_marker_csv"]

log = logging.getLogger("workbench.capture")

_FRAME_NAMES = ("frame", "frame#", "frame_index", "frame number")
_TIME_NAMES = ("time", "time_s", "seconds", "time (seconds)")
_AXIS_COLUMN = re.compile(r"^(.+)[._]([xyz])$", re.IGNORECASE)
_COMMENT_KEY = re.compile(r"^#\s*([A-Za-z][A-Za-z _-]*?)\s*[:=]\s*(.*?)\s*$")


@dataclass
class _CsvLayout:
    names: list[str]
    cols: list[tuple[int, int, int]]  # (x, y, z) column index per marker
    frame_col: int | None
    time_col: int | None
    header: list[str]
    rows: list[tuple[int, list[str]]]  # (line, cells)
    units: str | None
    fps: float | None


def _comment_meta(lines: Sequence[str], stop: int) -> dict[str, tuple[str, int]]:
    meta: dict[str, tuple[str, int]] = {}
    for i in range(stop):
        m = _COMMENT_KEY.match(lines[i].strip())
        if m:
            key = m.group(1).strip().lower().replace("_", " ")
            meta[key] = (m.group(2), i + 1)
    return meta


def _flat_layout(src: str, rows: list[list[str]], hi: int) -> _CsvLayout:
    header = [c.strip() for c in _trim(rows[hi])]
    frame_col = time_col = None
    axes: dict[str, dict[str, int]] = {}
    order: list[str] = []
    for i, h in enumerate(header):
        low = h.lower()
        if not h:
            raise CaptureInputError(src, f"header cell {i + 1} is empty", line=hi + 1)
        if low in _FRAME_NAMES:
            if frame_col is not None:
                raise CaptureInputError(src, "a second frame column", line=hi + 1, column=h)
            frame_col = i
            continue
        if low in _TIME_NAMES:
            if time_col is not None:
                raise CaptureInputError(src, "a second time column", line=hi + 1, column=h)
            time_col = i
            continue
        m = _AXIS_COLUMN.match(h)
        if not m:
            raise CaptureInputError(
                src,
                "is neither a frame/time column nor a marker coordinate: expected "
                "'<name>_x/_y/_z' or '<name>.X/.Y/.Z' (or frame, time)",
                line=hi + 1,
                column=h,
            )
        name, ax = m.group(1).strip(), m.group(2).lower()
        key = name
        if key not in axes:
            axes[key] = {}
            order.append(key)
        if ax in axes[key]:
            raise CaptureInputError(
                src,
                f"marker {name!r} has a second {ax} column (the first is {header[axes[key][ax]]!r})",
                line=hi + 1,
                column=h,
            )
        axes[key][ax] = i
    if not order:
        raise CaptureInputError(
            src, "the header names no marker columns ('<name>_x', ...)", line=hi + 1
        )
    cols = []
    for name in order:
        have = axes[name]
        missing = [a for a in "xyz" if a not in have]
        if missing:
            seen = header[next(iter(have.values()))]
            raise CaptureInputError(
                src,
                f"marker {name!r} has no {', '.join(missing)} column (next to {seen!r})",
                line=hi + 1,
                column=seen,
            )
        cols.append((have["x"], have["y"], have["z"]))
    data = [(i + 1, r) for i, r in enumerate(rows) if i > hi and not _blank(r)]
    return _CsvLayout(order, cols, frame_col, time_col, header, data, None, None)


def _vicon_layout(src: str, rows: list[list[str]], si: int) -> _CsvLayout:
    """The section after the 'Trajectories' row at index ``si``."""

    def nxt(i: int, what: str) -> int:
        if i >= len(rows) or _blank(rows[i]):
            raise CaptureInputError(
                src, f"the Trajectories section ends before its {what} row", line=i + 1
            )
        return i

    ri = nxt(si + 1, "frame-rate")
    rate_txt = rows[ri][0].strip() if rows[ri] else ""
    try:
        rate = float(rate_txt)
    except ValueError:
        raise CaptureInputError(
            src, f"expected the frame rate after 'Trajectories', got {rate_txt!r}", line=ri + 1
        ) from None
    if not (math.isfinite(rate) and rate > 0):
        raise CaptureInputError(src, f"frame rate {rate_txt!r} must be > 0", line=ri + 1)
    ni = nxt(ri + 1, "marker-name")
    ai = nxt(ni + 1, "'Frame, Sub Frame, X, Y, Z' axis")
    names_row = rows[ni]
    axis_row = [c.strip() for c in _trim(rows[ai])]
    header = list(axis_row)
    frame_col = None
    names: list[str] = []
    cols: list[tuple[int, int, int]] = []
    marker_at = {i: c.strip() for i, c in enumerate(names_row) if c.strip()}
    covered: set[int] = set()
    for i, name in sorted(marker_at.items()):
        trip = [axis_row[k].lower() if k < len(axis_row) else "" for k in (i, i + 1, i + 2)]
        if trip != ["x", "y", "z"]:
            raise CaptureInputError(
                src,
                f"marker {name!r} (line {ni + 1}) should head columns X, Y, Z, got {trip}",
                line=ai + 1,
                column=name,
            )
        names.append(name)
        cols.append((i, i + 1, i + 2))
        covered.update((i, i + 1, i + 2))
        for k in range(3):
            header[i + k] = f"{name}.{'XYZ'[k]}"
    for i, h in enumerate(axis_row):
        if i in covered or not h:
            continue
        if h.lower() in _FRAME_NAMES and frame_col is None:
            frame_col = i
        elif h.lower() == "sub frame":
            pass
        else:
            raise CaptureInputError(
                src,
                "is not under a marker name and is not Frame or Sub Frame",
                line=ai + 1,
                column=h,
            )
    if not names:
        raise CaptureInputError(src, "no marker names in the Trajectories section", line=ni + 1)
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise CaptureInputError(src, f"marker names repeat: {dup[:5]}", line=ni + 1)
    di = ai + 1
    units = None
    if di < len(rows) and not _blank(rows[di]):
        ux = rows[di][cols[0][0]].strip() if cols[0][0] < len(rows[di]) else ""
        if ux and not _is_number(ux):  # a units row
            found = {
                rows[di][c].strip()
                for trip in cols
                for c in trip
                if c < len(rows[di]) and rows[di][c].strip()
            }
            if len(found) > 1:
                raise CaptureInputError(
                    src, f"marker columns have different units {sorted(found)}", line=di + 1
                )
            units = found.pop() if found else None
            di += 1
    data = []
    for i in range(di, len(rows)):
        if _blank(rows[i]):
            break
        data.append((i + 1, rows[i]))
    return _CsvLayout(names, cols, frame_col, None, header, data, units, rate)


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def read_marker_csv(
    path: str | Path,
    *,
    units: str | None = None,
    fps: float | None = None,
    check_units: bool = True,
) -> MarkerSequence:
    """Read markers or landmarks from a CSV file (layouts in the module docstring).

    Parameters
    ----------
    path : str or Path
        The CSV file (comma-separated, UTF-8, optional BOM).
    units : str, optional
        Unit of the coordinates; wins over a ``# units:`` comment or the Vicon
        units row. One of them is required.
    fps : float, optional
        Frames per second; wins over ``# fps:``, the Vicon rate row and the
        time column (30 with a warning when none gives it).
    check_units : bool
        Refuse markers whose spread is not face-sized in the unit.

    Returns
    -------
    MarkerSequence
        ``positions`` (T, m, 3) in metres, NaN for empty/NaN cells;
        ``first_frame`` is the first frame number (0 without a frame column).

    Raises
    ------
    FileNotFoundError
        No such file.
    CaptureInputError
        Naming the file, the line (and frame) and the column: unknown or
        incomplete columns, ragged rows, a cell that is not a number, an
        infinite value, a marker with some coordinates missing, frame numbers
        or times that do not increase, no unit.

    Examples
    --------
    A file ``markers.csv``::

        # units: mm
        frame,time,nose_x,nose_y,nose_z,chin_x,chin_y,chin_z
        0,0.0,1.5,20.0,95.0,0.0,-60.0,80.0
        1,0.033,1.6,20.1,95.2,,,
    """
    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CaptureInputError(src, f"not UTF-8 text (byte {exc.start})", field="file") from None
    except OSError as exc:
        raise CaptureInputError(src, f"cannot read: {exc}", field="file") from None
    lines = text.splitlines()
    rows = _csv_rows(text)
    first = next((i for i, r in enumerate(rows) if not _blank(r)), None)
    if first is None:
        raise CaptureInputError(
            src, "no header and no data (empty file or only comments)", field="file"
        )
    vicon = next(
        (
            i
            for i, r in enumerate(rows)
            if r and r[0].strip().lower() == "trajectories" and _blank(r[1:])
        ),
        None,
    )
    lay = _vicon_layout(src, rows, vicon) if vicon is not None else _flat_layout(src, rows, first)
    meta = _comment_meta(lines, first)
    stated_units = lay.units
    if "units" in meta or "unit" in meta:
        stated_units = (meta.get("units") or meta["unit"])[0]
    stated_fps = lay.fps
    for key in ("fps", "frame rate", "rate"):
        if key in meta:
            txt, ln = meta[key]
            try:
                stated_fps = float(txt)
            except ValueError:
                raise CaptureInputError(
                    src, f"'# {key}:' value {txt!r} is not a number", line=ln
                ) from None
            if not (math.isfinite(stated_fps) and stated_fps > 0):
                raise CaptureInputError(src, f"'# {key}:' must be > 0, got {txt!r}", line=ln)
            break
    unit, mpu = _resolve_unit(
        src, units, stated_units, "add a '# units: mm' line before the header"
    )
    if not lay.rows:
        raise CaptureInputError(src, "a header but no data rows", field="file")
    return _csv_to_sequence(src, lay, unit, mpu, fps, stated_fps, check_units)


def _csv_to_sequence(
    src: str,
    lay: _CsvLayout,
    unit: str,
    mpu: float,
    fps: float | None,
    stated_fps: float | None,
    check_units: bool,
) -> MarkerSequence:
    n = len(lay.rows)
    width = len(lay.header)
    cells: list[list[str]] = []
    for lineno, r in lay.rows:
        if len(r) > width:
            if not _blank(r[width:]):
                raise CaptureInputError(
                    src, f"has {len(r)} fields, the header has {width}", line=lineno
                )
            r = r[:width]
        elif len(r) < width:
            raise CaptureInputError(
                src, f"has {len(r)} fields, the header has {width}", line=lineno
            )
        cells.append(r)
    # frame numbers first: later messages name the frame
    if lay.frame_col is not None:
        fc = lay.frame_col
        frames = np.empty(n, np.int64)
        for i, ((lineno, _), r) in enumerate(zip(lay.rows, cells, strict=True)):
            txt = r[fc].strip()
            try:
                x = float(txt)
            except ValueError:
                x = math.nan
            if not (math.isfinite(x) and x == int(x)):
                raise CaptureInputError(
                    src,
                    f"{txt!r:.30} is not a whole frame number",
                    line=lineno,
                    column=lay.header[fc],
                )
            frames[i] = int(x)
            if i and frames[i] <= frames[i - 1]:
                raise CaptureInputError(
                    src,
                    f"frame number {frames[i]} does not come after {frames[i - 1]} (line "
                    f"{lay.rows[i - 1][0]}); frame numbers must increase",
                    line=lineno,
                    column=lay.header[fc],
                )
    else:
        frames = np.arange(n, dtype=np.int64)
    used = [c for trip in lay.cols for c in trip]
    flat = [r[c].strip() or "nan" for r in cells for c in used]
    try:
        V = np.fromiter(map(float, flat), np.float64, len(flat)).reshape(n, len(used))
    except ValueError:
        for k, txt in enumerate(flat):
            try:
                float(txt)
            except ValueError:
                i, j = divmod(k, len(used))
                raise CaptureInputError(
                    src,
                    f"{txt!r:.30} is not a number (an occluded marker is an empty cell or NaN)",
                    line=lay.rows[i][0],
                    frame=int(frames[i]),
                    column=lay.header[used[j]],
                ) from None
        raise
    inf = np.isinf(V)
    if inf.any():
        i, j = (int(x) for x in np.argwhere(inf)[0])
        raise CaptureInputError(
            src,
            "value is infinite",
            line=lay.rows[i][0],
            frame=int(frames[i]),
            column=lay.header[used[j]],
        )
    P = V.reshape(n, len(lay.names), 3)
    nan = np.isnan(P)
    partial = nan.any(axis=2) & ~nan.all(axis=2)
    if partial.any():
        i, j = (int(x) for x in np.argwhere(partial)[0])
        a = int(np.flatnonzero(nan[i, j])[0])
        raise CaptureInputError(
            src,
            f"marker {lay.names[j]!r} has this coordinate empty/NaN but not all of x, y, z "
            f"(an occluded marker has all three empty)",
            line=lay.rows[i][0],
            frame=int(frames[i]),
            column=lay.header[lay.cols[j][a]],
        )
    times = None
    if lay.time_col is not None:
        tc = lay.time_col
        times = np.empty(n)
        for i, ((lineno, _), r) in enumerate(zip(lay.rows, cells, strict=True)):
            txt = r[tc].strip()
            try:
                times[i] = float(txt)
            except ValueError:
                times[i] = math.nan
            if not math.isfinite(times[i]):
                raise CaptureInputError(
                    src,
                    f"{txt!r:.30} is not a time in seconds",
                    line=lineno,
                    frame=int(frames[i]),
                    column=lay.header[tc],
                )
            if i and times[i] <= times[i - 1]:
                raise CaptureInputError(
                    src,
                    f"time {times[i]:.6g} s does not come after {times[i - 1]:.6g} s (line "
                    f"{lay.rows[i - 1][0]}); times must increase",
                    line=lineno,
                    frame=int(frames[i]),
                    column=lay.header[tc],
                )
    # skipped frame numbers: frames with every marker occluded
    span = int(frames[-1] - frames[0]) + 1
    if span != n:
        full = np.full((span, len(lay.names), 3), np.nan)
        full[frames - frames[0]] = P
        log.info(
            "%s: %d frame numbers are skipped; those frames have every marker occluded",
            Path(src).name,
            span - n,
        )
        P = full
    rate = fps if fps is not None else stated_fps
    if rate is None and times is not None and n >= 2:
        df = float(frames[-1] - frames[0])
        rate = df / float(times[-1] - times[0])
        if abs(rate - round(rate)) < 1e-3 * rate:
            rate = float(round(rate))
        steps = np.diff(times) / np.diff(frames)
        if steps.max() > 1.5 * steps.min():
            log.warning(
                "%s: time steps vary from %.4g to %.4g s per frame; %.4g fps taken from the whole take",
                Path(src).name,
                steps.min(),
                steps.max(),
                rate,
            )
    if rate is None:
        log.warning(
            "%s: no frame rate (no fps=, '# fps:' or time column); %g fps assumed",
            Path(src).name,
            DEFAULT_FPS,
        )
        rate = DEFAULT_FPS
    if not (math.isfinite(rate) and rate > 0):
        raise CaptureInputError(src, f"fps must be > 0, got {rate!r}", field="fps")
    P = P * mpu
    if check_units and len(lay.names) >= 3:
        _check_span(src, _frame_spans(P).tolist(), unit, mpu, "markers")
    return MarkerSequence(tuple(lay.names), P, float(rate), unit, int(frames[0]), src)
