"""Reading weight CSVs: Live Link Face, plain "time + one column per shape", and Face Cap text.

* **Live Link Face CSV** (:mod:`workbench.animation.importers.livelink`):
  times are made relative to the first row; the head columns become the
  ``head_pose`` track (see :func:`livelink_head_rotation`; one linear key per
  row, translation 0; no track when the file has no head column or they are
  all 0); the eye angles are skipped (the eyes are the ``eyeLook*`` shapes).
* **Plain weight CSV** (what :mod:`workbench.export.csv` writes; also the common
  "time + one column per shape" layout): a first column named ``time``,
  ``Time``, ``seconds`` (seconds) or ``time_ms``/``timestamp_ms`` (milliseconds),
  then one column per shape.
* **Face Cap text** (Bannaflak's iOS app, ``.txt``/``.csv``): a ``bs,<names>``
  line and ``k,<milliseconds>,<3 head position>,<3 head rotation>,
  <4 eye angles>,<weights>`` lines; ``info`` lines are ignored. (Layout as
  documented by the app; not checked against a recording here.)

Hand-written because the csv module gives strings only.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from workbench.animation.curves import HEAD_POSE, Key, Track
from workbench.animation.importers.errors import AnimationImportError
from workbench.animation.importers.keys import _check_times, _estimate_fps, timeline_from_samples
from workbench.animation.importers.livelink import (
    _LLF_EYES,
    _LLF_HEAD,
    _parse_timecode,
    livelink_fps,
    livelink_head_rotation,
)
from workbench.animation.importers.names import _resolve_columns, map_columns_to_rig
from workbench.animation.tracks import Timeline

__all__ = ["read_weights_csv"]


_TIME_SECONDS = ("time", "seconds", "time_s", "t")
_TIME_MS = ("time_ms", "timestamp_ms", "timestamp", "milliseconds")


def _parse_float(text: str, src: str, row_label: str, col: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise AnimationImportError(
            src, f"{row_label}, column {col!r}: {text!r:.30} is not a number"
        ) from None
    if not math.isfinite(x):
        raise AnimationImportError(src, f"{row_label}, column {col!r}: value is {text.strip()} (NaN/inf)")
    return x


def read_weights_csv(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    fps: float | None = None,
    tolerance: float = 0.0,
    on_unknown: str = "error",
    up_axis: str = "+y",
    front_axis: str = "+z",
) -> Timeline:
    """Read a Live Link Face / plain / Face Cap weight CSV into a timeline of linear keys.

    Parameters
    ----------
    path : str or Path
    shape_names : sequence of str
        The model's shape names (``model.shape_names``); columns are mapped to
        them (exact, else ARKit meaning on any rig: :func:`map_columns_to_rig`).
    fps : float, optional
        Frame rate of Live Link Face timecodes and of the returned timeline
        (default: inferred from the timecodes, :func:`livelink_fps`, for Live
        Link Face; else estimated from the median sample spacing, else 30).
    tolerance : float
        Key reduction of the weight curves (see :func:`reduce_keys`); 0 keeps
        one key per row. The head pose keeps one key per row.
    on_unknown : {"error", "ignore"}
        What to do with columns that match no shape (and ARKit columns with
        non-zero weights the rig has no shape for).
    up_axis, front_axis : str
        The model's axes (``model.metadata``), for the Live Link Face head
        rotation columns.

    Returns
    -------
    Timeline
        Tracks ``"weights/<shape>"`` (and ``"head_pose"`` from Live Link Face
        head columns); range = first..last time (first row at 0 for Live Link
        Face timecodes and Face Cap milliseconds).

    Raises
    ------
    AnimationImportError
        Unknown columns, non-numeric/NaN values, non-increasing times, ragged
        rows — each naming the line and column.
    """
    p = Path(path)
    src = str(p)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise AnimationImportError(src, f"not UTF-8 text (byte {exc.start})") from None
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(text.splitlines())) if any(c.strip() for c in r)]
    if not rows:
        raise AnimationImportError(src, "empty file")
    first = [c.strip() for c in rows[0][1]]
    if first and first[0].lower() in ("bs", "info", "k"):
        return _read_facecap(rows, shape_names, src, fps, tolerance, on_unknown)
    header = first
    lower = [h.lower() for h in header]
    head_cols: dict[int, int] = {}  # column index -> 0 yaw, 1 pitch, 2 roll
    if "timecode" in lower:
        tcol = lower.index("timecode")
        skip = {"timecode", "blendshapecount", *_LLF_EYES}
        head_cols = {i: _LLF_HEAD.index(h) for i, h in enumerate(lower) if h in _LLF_HEAD}
        kind = "timecode"
    elif lower[0] in _TIME_SECONDS or lower[0] in _TIME_MS:
        tcol = 0
        skip = {lower[0]}
        kind = "ms" if lower[0] in _TIME_MS else "s"
    else:
        raise AnimationImportError(
            src,
            f"line {rows[0][0]}: header must start with a time column ('time' in seconds, "
            f"'time_ms') or contain 'Timecode' (Live Link Face), got {header[:3]}",
        )
    candidates = [
        h if (h.lower() not in skip and i != tcol and i not in head_cols) else "" for i, h in enumerate(header)
    ]
    drives, missing, unknown = map_columns_to_rig(candidates, shape_names, src)
    if unknown and on_unknown != "ignore":
        names = [header[i] for i in unknown]
        raise AnimationImportError(
            src,
            f"unknown shape names in columns {names[:10]}{'...' if len(names) > 10 else ''} "
            f"(the model has no shape of that name or ARKit meaning; pass on_unknown='ignore' "
            f"to skip them)",
        )
    if not drives:
        raise AnimationImportError(src, "no column matches a shape of the model")
    n = len(rows) - 1
    if n < 1:
        raise AnimationImportError(src, "header but no data rows")
    value_cols = sorted({ci for ci, _, _ in drives} | set(missing) | set(head_cols))
    col_pos = {ci: j for j, ci in enumerate(value_cols)}
    seconds = np.zeros(n, np.int64)
    times = np.empty(n)
    V = np.empty((n, len(value_cols)))
    labels = []
    for r, (lineno, row) in enumerate(rows[1:]):
        label = f"line {lineno}"
        labels.append(label)
        if len(row) != len(header):
            raise AnimationImportError(
                src, f"{label}: has {len(row)} fields, the header has {len(header)}"
            )
        if kind == "timecode":
            seconds[r], times[r] = _parse_timecode(row[tcol], src, label)
        else:
            times[r] = _parse_float(row[tcol], src, label, header[tcol])
        for j, ci in enumerate(value_cols):
            V[r, j] = _parse_float(row[ci], src, label, header[ci])
    lost = [header[ci] for ci in missing if np.any(V[:, col_pos[ci]] != 0.0)]
    if lost and on_unknown != "ignore":
        raise AnimationImportError(
            src,
            f"columns {lost[:10]}{'...' if len(lost) > 10 else ''} have non-zero weights but the "
            f"model has no shape of that ARKit meaning (no spelling, split half or left/right pair "
            f"of it); pass on_unknown='ignore' to skip them",
        )
    if kind == "timecode":
        rate = float(fps) if fps is not None else livelink_fps(seconds, times)
        times = (seconds - seconds[0]) + (times - times[0]) / rate
        fps = rate
    elif kind == "ms":
        times = times / 1000.0
    _check_times(times, labels, src)
    if fps is None:
        fps = _estimate_fps(times)
    shapes = list(dict.fromkeys(shape for _, shape, _ in drives))
    W = np.zeros((n, len(shapes)))
    for ci, shape, coef in drives:
        W[:, shapes.index(shape)] += coef * V[:, col_pos[ci]]
    tl = timeline_from_samples(times, W, shapes, fps=float(fps), tolerance=tolerance)
    if head_cols:
        angles = np.zeros((n, 3))
        for ci, axis in head_cols.items():
            angles[:, axis] = V[:, col_pos[ci]]
        if np.any(angles != 0.0):
            keys = []
            for t, (yaw, pitch, roll) in zip(times, angles, strict=True):
                q = livelink_head_rotation(yaw, pitch, roll, up_axis=up_axis, front_axis=front_axis)
                keys.append(Key(float(t), np.concatenate([np.zeros(3), q]), "linear"))
            tl = tl.with_track(Track(HEAD_POSE, tuple(keys)))
    return tl


def _read_facecap(
    rows: list[tuple[int, list[str]]],
    shape_names: Sequence[str],
    src: str,
    fps: float | None,
    tolerance: float,
    on_unknown: str,
) -> Timeline:
    names: list[str] | None = None
    times: list[float] = []
    values: list[list[float]] = []
    labels: list[str] = []
    n_pre = 12  # "k", ms, head position (3), head rotation (3), eye angles (4)
    for lineno, row in rows:
        tag = row[0].strip().lower()
        label = f"line {lineno}"
        if tag == "bs":
            names = [c.strip() for c in row[1:]]
        elif tag == "k":
            if names is None:
                raise AnimationImportError(src, f"{label}: 'k' line before the 'bs' names line")
            if len(row) != n_pre + len(names):
                raise AnimationImportError(
                    src,
                    f"{label}: has {len(row)} fields, expected {n_pre + len(names)} "
                    f"(k, ms, 10 head/eye values, {len(names)} weights)",
                )
            times.append(_parse_float(row[1], src, label, "time (ms)") / 1000.0)
            values.append(
                [_parse_float(row[n_pre + j], src, label, names[j]) for j in range(len(names))]
            )
            labels.append(label)
    if names is None or not times:
        raise AnimationImportError(src, "Face Cap file without 'bs' names and 'k' key lines")
    cols = _resolve_columns(names, shape_names, src, on_unknown)
    t = np.array(times)
    t = t - t[0]
    _check_times(t, labels, src)
    W = np.array(values)[:, [ci for ci, _ in cols]]
    return timeline_from_samples(
        t, W, [s for _, s in cols], fps=float(fps or _estimate_fps(t)), tolerance=tolerance
    )
