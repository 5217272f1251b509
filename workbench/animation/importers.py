"""Import animation: per-frame ARKit weight CSVs and glTF weight animations → a Timeline.

Supported inputs
----------------
* **Live Link Face CSV** (Epic's iPhone app; also what
  :mod:`workbench.export.csv` writes with ``style="livelink"``): header
  ``Timecode,BlendShapeCount,EyeBlinkLeft,...,TongueOut`` (the 52 ARKit
  columns, :data:`LIVELINK_SHAPE_COLUMNS`), then ``HeadYaw,HeadPitch,HeadRoll``
  and six eye angles (:data:`LIVELINK_HEADER`). ``Timecode`` is
  ``HH:MM:SS:FF.mmm``: frame number ``FF`` plus thousandths of a frame, as
  Epic's ``LiveLinkFaceImporter`` reads it; times are made relative to the
  first row. The recording rate is ``fps`` if given, else inferred from the
  frame numbers (:func:`livelink_fps`, after Epic's importer, which reads 60
  when a frame number exceeds 30 and 30 otherwise): 60 when a frame number
  reaches 30, 30 when the take crosses a second boundary without one, else 60
  (the app's default; a take within one second cannot tell 30 from 60 — pass
  ``fps``). The head columns become
  the ``head_pose`` track (see :func:`livelink_head_rotation`; one linear key
  per row, translation 0; no track when the file has no head column or they
  are all 0); the eye angles are skipped (the eyes are the ``eyeLook*``
  shapes).
* **Plain weight CSV** (what :mod:`workbench.export.csv` writes; also the common
  "time + one column per shape" layout): a first column named ``time``,
  ``Time``, ``seconds`` (seconds) or ``time_ms``/``timestamp_ms`` (milliseconds),
  then one column per shape.
* **Face Cap text** (Bannaflak's iOS app, ``.txt``/``.csv``): a ``bs,<names>``
  line and ``k,<milliseconds>,<3 head position>,<3 head rotation>,
  <4 eye angles>,<weights>`` lines; ``info`` lines are ignored. (Layout as
  documented by the app; not checked against a recording here.)
* **glTF/GLB weight animations**: every ``weights`` channel of an animation;
  ``LINEAR`` → linear keys, ``STEP`` → step keys, ``CUBICSPLINE`` → Bézier keys
  with user tangents (exact: glTF's Hermite tangents are our slopes).

Column names are matched to the model's shapes exactly first, then by ARKit
meaning (:func:`workbench.arkit.canonical_arkit_name`, so ``EyeBlinkLeft``,
``eyeBlink_L`` and ``eyeBlinkLeft`` agree). Live Link Face and plain CSV
columns reach any rig
(:func:`map_columns_to_rig`, :func:`workbench.arkit.rig_weights`): an ARKit
column drives the rig's shape of that meaning in any spelling, *both* halves
of a split shape (``BrowInnerUp`` → ``browInnerUp_L`` and ``browInnerUp_R``)
and, for a rig with one shape for a left/right pair (``mouthSmile``), the
mean of the pair. An ARKit column the rig has no shape for is skipped when it
is 0 in every row (nothing is lost) and is an error otherwise, like a column
that means nothing to the rig (``on_unknown="ignore"`` skips both). Every
problem raises :class:`AnimationImportError` naming the file, the row/line
and the column.

CSV rows become one linear key per frame; ``tolerance`` > 0 removes keys that
linear interpolation of the kept ones reproduces within ``tolerance``
(Ramer–Douglas–Peucker on each weight curve, vertical error), so the result
differs from every input sample by at most ``tolerance``.

Hand-written because the csv module gives strings only, and the glTF decoding
reuses the checked accessor reader of :mod:`workbench.io.gltf` (pygltflib has
no accessor decoding).
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import (
    HEAD_POSE,
    Interpolation,
    Key,
    Track,
    TrackError,
    head_euler_from_rotation,
    head_rotation_from_euler,
    weight_track_name,
)
from workbench.animation.tracks import Timeline
from workbench.arkit import canonical_arkit_name, rig_weights

__all__ = [
    "LIVELINK_ANGLE_UNIT",
    "LIVELINK_EYE_COLUMNS",
    "LIVELINK_HEADER",
    "LIVELINK_HEAD_COLUMNS",
    "LIVELINK_SHAPE_COLUMNS",
    "AnimationImportError",
    "livelink_fps",
    "livelink_head_angles",
    "livelink_head_rotation",
    "map_columns_to_rig",
    "map_shape_names",
    "read_animation",
    "read_gltf_animation",
    "read_weights_csv",
    "reduce_keys",
]

#: The 52 blendshape columns of a Live Link Face CSV, in the app's order and spelling.
#: The order is that of a recorded take's header (e.g. the header pinned byte for byte
#: in public Live Link Face tools): Unreal's ``EARFaceBlendShape`` order except that
#: ``JawRight`` comes before ``JawLeft`` and ``MouthRight`` before ``MouthLeft``.
LIVELINK_SHAPE_COLUMNS: tuple[str, ...] = (
    "EyeBlinkLeft", "EyeLookDownLeft", "EyeLookInLeft", "EyeLookOutLeft", "EyeLookUpLeft",
    "EyeSquintLeft", "EyeWideLeft",
    "EyeBlinkRight", "EyeLookDownRight", "EyeLookInRight", "EyeLookOutRight", "EyeLookUpRight",
    "EyeSquintRight", "EyeWideRight",
    "JawForward", "JawRight", "JawLeft", "JawOpen",
    "MouthClose", "MouthFunnel", "MouthPucker", "MouthRight", "MouthLeft",
    "MouthSmileLeft", "MouthSmileRight", "MouthFrownLeft", "MouthFrownRight",
    "MouthDimpleLeft", "MouthDimpleRight", "MouthStretchLeft", "MouthStretchRight",
    "MouthRollLower", "MouthRollUpper", "MouthShrugLower", "MouthShrugUpper",
    "MouthPressLeft", "MouthPressRight", "MouthLowerDownLeft", "MouthLowerDownRight",
    "MouthUpperUpLeft", "MouthUpperUpRight",
    "BrowDownLeft", "BrowDownRight", "BrowInnerUp", "BrowOuterUpLeft", "BrowOuterUpRight",
    "CheekPuff", "CheekSquintLeft", "CheekSquintRight", "NoseSneerLeft", "NoseSneerRight",
    "TongueOut",
)
#: Head rotation columns (normalised angles, see :data:`LIVELINK_ANGLE_UNIT`)
LIVELINK_HEAD_COLUMNS: tuple[str, ...] = ("HeadYaw", "HeadPitch", "HeadRoll")
#: Eye rotation columns (not read: the eyes are the ``eyeLook*`` shapes)
LIVELINK_EYE_COLUMNS: tuple[str, ...] = (
    "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll",
)
#: The whole header row: 2 + 52 + 3 + 6 = 63 columns, ``BlendShapeCount`` = 61
LIVELINK_HEADER: tuple[str, ...] = (
    "Timecode", "BlendShapeCount", *LIVELINK_SHAPE_COLUMNS, *LIVELINK_HEAD_COLUMNS, *LIVELINK_EYE_COLUMNS,
)
#: Degrees per unit of the head/eye angle columns: Unreal's ARKit face support maps
#: the -180..180 degree range onto -1..1 (``ToBlendShapeMap``: ``HeadYaw = Yaw / 180``).
LIVELINK_ANGLE_UNIT = 180.0

_LLF_HEAD = tuple(c.lower() for c in LIVELINK_HEAD_COLUMNS)
_LLF_EYES = tuple(c.lower() for c in LIVELINK_EYE_COLUMNS)
_TIME_SECONDS = ("time", "seconds", "time_s", "t")
_TIME_MS = ("time_ms", "timestamp_ms", "timestamp", "milliseconds")
_TIMECODE = re.compile(r"^(\d+):(\d\d):(\d\d)[:;](\d+)(?:\.(\d+))?$")


class AnimationImportError(ValueError):
    """An animation file that cannot be turned into keys; the message names file, row and column."""

    def __init__(self, source: str | Path, message: str) -> None:
        self.source = str(source)
        self.detail = message
        super().__init__(f"{Path(self.source).name}: {message}")


# -------------------------------------------------------------------- name mapping
def map_shape_names(
    columns: Sequence[str], shape_names: Sequence[str], source: str | Path = "<columns>"
) -> dict[str, str | None]:
    """Map file column/target names to model shape names.

    Exact matches win; otherwise two names match if they have the same
    canonical ARKit name. Returns ``{column: shape or None}``.

    Raises
    ------
    AnimationImportError
        If two columns map to the same shape.
    """
    by_arkit: dict[str, str] = {}
    for s in shape_names:
        c = canonical_arkit_name(s)
        if c is not None:
            by_arkit.setdefault(c, s)
    exact = set(shape_names)
    out: dict[str, str | None] = {}
    used: dict[str, str] = {}
    for col in columns:
        target: str | None = None
        if col in exact:
            target = col
        else:
            c = canonical_arkit_name(col)
            if c is not None:
                target = by_arkit.get(c)
        if target is not None:
            if target in used:
                raise AnimationImportError(
                    source, f"columns {used[target]!r} and {col!r} both map to shape {target!r}"
                )
            used[target] = col
        out[col] = target
    return out


def map_columns_to_rig(
    columns: Sequence[str], shape_names: Sequence[str], source: str | Path = "<columns>"
) -> tuple[list[tuple[int, str, float]], list[int], list[int]]:
    """How file columns drive the shapes of any rig (see the module docstring).

    A column named exactly like a shape drives it; any other column with an
    ARKit meaning is put on the rig by :func:`workbench.arkit.rig_weights`
    (other spellings, split halves, one shape for a left/right pair).

    Parameters
    ----------
    columns : sequence of str
        Column names (empty names are skipped).
    shape_names : sequence of str
        The rig's shapes.

    Returns
    -------
    drives : list of (int, str, float)
        ``(column index, shape, coefficient)``: the shape's weight is the sum
        of coefficient x column over its entries (1 per column, except 0.5 for
        each side of a left/right pair driving one unsided shape).
    missing : list of int
        Columns with an ARKit meaning the rig has no shape for.
    unknown : list of int
        Columns with no shape of that name and no ARKit meaning.

    Raises
    ------
    AnimationImportError
        Two columns with the same ARKit meaning, or a column aimed at a shape
        another column names exactly.
    """
    exact = set(shape_names)
    drives: list[tuple[int, str, float]] = []
    missing: list[int] = []
    unknown: list[int] = []
    by_exact: dict[str, str] = {}
    by_meaning: dict[str, str] = {}
    arkit_cols: list[tuple[int, str]] = []
    for i, col in enumerate(columns):
        if not col.strip():
            continue
        if col in exact:
            by_exact[col] = col
            drives.append((i, col, 1.0))
            continue
        c = canonical_arkit_name(col)
        if c is None:
            unknown.append(i)
            continue
        if c in by_meaning:
            raise AnimationImportError(
                source, f"columns {by_meaning[c]!r} and {col!r} both mean ARKit shape {c!r}"
            )
        by_meaning[c] = col
        arkit_cols.append((i, c))
    for i, c in arkit_cols:
        on_rig, _ = rig_weights({c: 1.0}, shape_names)
        if not on_rig:
            missing.append(i)
            continue
        for shape, coef in on_rig.items():
            if shape in by_exact:
                raise AnimationImportError(
                    source, f"columns {by_exact[shape]!r} and {columns[i]!r} both map to shape {shape!r}"
                )
            drives.append((i, shape, float(coef)))
    return drives, missing, unknown


# ------------------------------------------------------------- Live Link head angles
def livelink_head_rotation(
    yaw: float, pitch: float, roll: float, *, up_axis: str = "+y", front_axis: str = "+z"
) -> NDArray[np.float64]:
    """Unit quaternion ``(x, y, z, w)`` of Live Link Face ``HeadYaw/HeadPitch/HeadRoll`` values.

    The values are angles divided by :data:`LIVELINK_ANGLE_UNIT` (180 degrees,
    so -1..1; Unreal's ARKit face support writes ``Yaw / 180``). Signs and
    order are those of :func:`workbench.animation.curves.head_rotation_from_euler`
    about the model's own axes: positive yaw turns the face toward the
    subject's left, positive pitch nods it down, positive roll tilts the top of
    the head toward the subject's right. (That is what Unreal's conversion
    gives for ARKit's face frame — x the subject's left, y up, z out of the
    face — in its unmirrored mode, derived from the code rather than checked
    against a recording; the phone's orientation can flip signs in the app.)
    """
    u = LIVELINK_ANGLE_UNIT
    return head_rotation_from_euler(
        float(yaw) * u, float(pitch) * u, float(roll) * u, up_axis=up_axis, front_axis=front_axis
    )


def livelink_head_angles(
    rotation: ArrayLike, *, up_axis: str = "+y", front_axis: str = "+z"
) -> tuple[float, float, float]:
    """Inverse of :func:`livelink_head_rotation`: ``(HeadYaw, HeadPitch, HeadRoll)`` in -1..1."""
    yaw, pitch, roll = head_euler_from_rotation(rotation, up_axis=up_axis, front_axis=front_axis)
    u = LIVELINK_ANGLE_UNIT
    return yaw / u, pitch / u, roll / u


# -------------------------------------------------------------------- key reduction
def reduce_keys(times: ArrayLike, values: ArrayLike, tolerance: float) -> NDArray[np.intp]:
    """Indices of the samples to keep so linear interpolation stays within ``tolerance``.

    Parameters
    ----------
    times : (F,) float
        Strictly increasing.
    values : (F,) float
    tolerance : float
        Maximum absolute difference, at every input sample, between the input
        and the piecewise-linear curve through the kept samples (>= 0).

    Returns
    -------
    (K,) int
        Sorted indices, always including the first and last sample.
    """
    t = np.asarray(times, np.float64)
    v = np.asarray(values, np.float64)
    n = t.size
    if n <= 2 or tolerance < 0:
        return np.arange(n)
    keep = np.zeros(n, bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg_t = t[a + 1 : b]
        line = v[a] + (v[b] - v[a]) * (seg_t - t[a]) / (t[b] - t[a])
        err = np.abs(v[a + 1 : b] - line)
        i = int(np.argmax(err))
        if err[i] > tolerance:
            m = a + 1 + i
            keep[m] = True
            stack.append((a, m))
            stack.append((m, b))
    return np.flatnonzero(keep)


def _linear_track(name: str, times: NDArray[np.float64], values: NDArray[np.float64]) -> Track:
    return Track(
        name,
        tuple(Key(float(t), float(v), "linear") for t, v in zip(times, values, strict=True)),
    )


def timeline_from_samples(
    times: ArrayLike,
    weights: ArrayLike,
    shape_names: Sequence[str],
    *,
    fps: float = 30.0,
    tolerance: float = 0.0,
) -> Timeline:
    """A timeline with one linear key per sample (optionally reduced) for every shape.

    Parameters
    ----------
    times : (F,) float
        Strictly increasing seconds.
    weights : (F, k) float
        Finite weights, one column per name in ``shape_names``.
    shape_names : sequence of str
        Model shape names (length k).
    fps : float
        Timeline frame rate.
    tolerance : float
        Key-reduction tolerance (0 keeps every sample).
    """
    t = np.asarray(times, np.float64).reshape(-1)
    W = np.asarray(weights, np.float64).reshape(t.size, -1)
    tracks = {}
    for j, s in enumerate(shape_names):
        idx = reduce_keys(t, W[:, j], tolerance) if tolerance > 0 else np.arange(t.size)
        name = weight_track_name(s)
        tracks[name] = _linear_track(name, t[idx], W[idx, j])
    return Timeline(fps=fps, start=float(t[0]), end=float(t[-1]), tracks=tracks)


# ----------------------------------------------------------------------- CSV
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


def _parse_timecode(text: str, src: str, row_label: str) -> tuple[int, float]:
    """``(whole seconds, frame number with its fraction)`` of ``HH:MM:SS:FF(.mmm)``."""
    m = _TIMECODE.match(text.strip())
    if not m:
        raise AnimationImportError(
            src, f"{row_label}, column 'Timecode': {text!r:.30} is not HH:MM:SS:FF(.fff)"
        )
    h, mi, sec, ff = (int(g) for g in m.groups()[:4])
    frac = float("0." + m.group(5)) if m.group(5) else 0.0
    return h * 3600 + mi * 60 + sec, ff + frac


def livelink_fps(seconds: ArrayLike, frames: ArrayLike) -> float:
    """The recording rate of Live Link Face timecodes, inferred as Epic's importer does.

    60 when a frame number reaches 30 (Epic's ``InferFrameRate``: above 30),
    30 when the rows cross a second boundary without one, else 60 (the app's
    default: rows within one second cannot tell 30 from 60).
    """
    f = np.asarray(frames, np.float64)
    s = np.asarray(seconds)
    if f.size and float(f.max()) >= 30.0:
        return 60.0
    if s.size and int(np.max(s)) != int(np.min(s)):
        return 30.0
    return 60.0


def _check_times(times: NDArray[np.float64], labels: Sequence[str], src: str) -> None:
    bad = np.flatnonzero(np.diff(times) <= 0)
    if bad.size:
        i = int(bad[0])
        raise AnimationImportError(
            src,
            f"{labels[i + 1]}: time {times[i + 1]:.6g} s does not come after {labels[i]} "
            f"({times[i]:.6g} s); times must be strictly increasing",
        )


def _resolve_columns(
    columns: Sequence[str],
    shape_names: Sequence[str],
    src: str,
    on_unknown: str,
    skip: Iterable[str] = (),
) -> list[tuple[int, str]]:
    """(column index, shape name) pairs; unknown columns raise unless ``on_unknown="ignore"``."""
    skip_l = {s.lower() for s in skip}
    mapping = map_shape_names(columns, shape_names, src)
    out: list[tuple[int, str]] = []
    unknown: list[str] = []
    for i, col in enumerate(columns):
        if col.strip().lower() in skip_l or not col.strip():
            continue
        target = mapping[col]
        if target is None:
            unknown.append(col)
        else:
            out.append((i, target))
    if unknown and on_unknown != "ignore":
        raise AnimationImportError(
            src,
            f"unknown shape names in columns {unknown[:10]}{'...' if len(unknown) > 10 else ''} "
            f"(the model has no shape of that name or ARKit meaning; pass on_unknown='ignore' "
            f"to skip them)",
        )
    if not out:
        raise AnimationImportError(src, "no column matches a shape of the model")
    return out


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


def _estimate_fps(times: NDArray[np.float64]) -> float:
    if times.size < 2:
        return 30.0
    dt = float(np.median(np.diff(times)))
    return round(1.0 / dt, 3) if dt > 0 else 30.0


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


# ----------------------------------------------------------------------- glTF
def read_gltf_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    animation: int | str | None = None,
    fps: float = 30.0,
    on_unknown: str = "error",
) -> Timeline:
    """Read the morph-weight channels of a glTF animation into keys.

    Parameters
    ----------
    path : str or Path
        .glb or .gltf.
    shape_names : sequence of str
        The model's shape names; targets are matched by ``mesh.extras.targetNames``
        (exact, else ARKit meaning). Targets named ``handle:...`` (the handle
        layer written by :mod:`workbench.export.gltf`) are skipped.
    animation : int or str, optional
        Animation index or name (default: the first one with a weights channel).
    fps : float
        Frame rate of the returned timeline.
    on_unknown : {"error", "ignore"}
        What to do with targets that match no shape.

    Raises
    ------
    AnimationImportError
        No weights animation, unnamed targets, unknown names, NaN values,
        non-increasing times, output counts that do not match.
    """
    from workbench.geometry.mesh_checks import MeshFormatError
    from workbench.io.gltf.container import read_container
    from workbench.io.gltf.document import Gltf

    p = Path(path)
    src = str(p)
    try:
        doc, bin_chunk = read_container(p)
        g = Gltf(doc, src, bin_chunk, p.parent)
        return _gltf_timeline(g, src, shape_names, animation, fps, on_unknown)
    except MeshFormatError as exc:
        raise AnimationImportError(src, exc.detail) from None


def _same_keys(a: Track, b: Track) -> bool:
    """Keys equal in time, value, interpolation and tangents."""
    return len(a.keys) == len(b.keys) and all(
        ka.time == kb.time
        and ka.interpolation == kb.interpolation
        and np.array_equal(ka.value, kb.value)
        and np.array_equal(ka.in_tangent, kb.in_tangent)
        and np.array_equal(ka.out_tangent, kb.out_tangent)
        for ka, kb in zip(a.keys, b.keys, strict=True)
    )


def _fallback_target_names(mesh: Any, mesh_index: Any, shape_names: Sequence[str]) -> list[str]:
    """Names the glTF reader gives targets without ``extras.targetNames``.

    ``target_<i>``, or ``<mesh>_target_<i>`` when several meshes had unnamed
    targets (:mod:`workbench.io.gltf.reader`); the one the model has wins.
    """
    targets = (mesh.get("primitives") or [{}])[0].get("targets") or []
    label = mesh.get("name") if isinstance(mesh.get("name"), str) else f"mesh_{mesh_index}"
    known = set(shape_names)
    out = []
    for i in range(len(targets)):
        plain, prefixed = f"target_{i}", f"{label}_target_{i}"
        out.append(prefixed if prefixed in known and plain not in known else plain)
    return out


def _gltf_timeline(
    g: Any,
    src: str,
    shape_names: Sequence[str],
    animation: int | str | None,
    fps: float,
    on_unknown: str,
) -> Timeline:
    anims = g.array("animations")
    if not anims:
        raise AnimationImportError(src, "the file has no animations")
    ai: int | None = None
    if isinstance(animation, int):
        ai = animation
    elif isinstance(animation, str):
        names = [a.get("name") if isinstance(a, dict) else None for a in anims]
        if animation not in names:
            raise AnimationImportError(src, f"no animation named {animation!r}; names: {names}")
        ai = names.index(animation)
    else:
        for i, a in enumerate(anims):
            chans = a.get("channels", []) if isinstance(a, dict) else []
            if any(isinstance(c, dict) and (c.get("target") or {}).get("path") == "weights" for c in chans):
                ai = i
                break
        if ai is None:
            raise AnimationImportError(src, "no animation has a 'weights' channel")
    anim = g.item("animations", ai, "animations")
    afield = f"animations[{ai}]"
    samplers = anim.get("samplers", [])
    tracks: dict[str, Track] = {}
    found = False
    for c, ch in enumerate(anim.get("channels", [])):
        cfield = f"{afield}.channels[{c}]"
        target = ch.get("target") if isinstance(ch, dict) else None
        if not isinstance(target, dict) or target.get("path") != "weights":
            continue
        found = True
        node = g.item("nodes", target.get("node"), f"{cfield}.target.node")
        mesh_index = node.get("mesh")
        mesh = g.item("meshes", mesh_index, f"{cfield} node.mesh")
        extras = mesh.get("extras")
        tnames = extras.get("targetNames") if isinstance(extras, dict) else None
        if tnames is None:
            tnames = _fallback_target_names(mesh, mesh_index, shape_names)
        if not isinstance(tnames, list) or not all(isinstance(s, str) for s in tnames):
            raise AnimationImportError(
                src, f"{cfield}: the animated mesh's extras.targetNames is not a list of names"
            )
        si = ch.get("sampler")
        if not isinstance(si, int) or not 0 <= si < len(samplers):
            raise AnimationImportError(src, f"{cfield}.sampler: {si!r} is not a sampler index")
        s = samplers[si]
        sfield = f"{afield}.samplers[{si}]"
        interp = s.get("interpolation", "LINEAR")
        if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise AnimationImportError(src, f"{sfield}.interpolation: unknown {interp!r}")
        T = g.accessor(s.get("input"), f"{sfield}.input", types=("SCALAR",))[:, 0]
        out = g.accessor(s.get("output"), f"{sfield}.output", types=("SCALAR",))[:, 0]
        nk, nt = T.size, len(tnames)
        per = 3 if interp == "CUBICSPLINE" else 1
        if out.size != nk * nt * per:
            raise AnimationImportError(
                src,
                f"{sfield}.output: has {out.size} values, expected {nk} keys x {nt} targets"
                f"{' x 3' if per == 3 else ''} = {nk * nt * per}",
            )
        if not np.isfinite(T).all() or not np.isfinite(out).all():
            raise AnimationImportError(src, f"{sfield}: NaN/inf in input times or output weights")
        bad = np.flatnonzero(np.diff(T) <= 0)
        if bad.size:
            i = int(bad[0])
            raise AnimationImportError(
                src,
                f"{sfield}.input: key {i + 1} time {T[i + 1]:.6g} s does not come after key {i} "
                f"({T[i]:.6g} s); times must be strictly increasing",
            )
        out = out.reshape(nk, per, nt)
        cols = [n for n in tnames if not n.startswith("handle:")]
        mapping = _resolve_columns(cols, shape_names, src, on_unknown)
        mode: Interpolation = "step" if interp == "STEP" else "linear"
        for ci, shape in mapping:
            t_idx = tnames.index(cols[ci])
            if per == 3:
                keys = tuple(
                    Key(
                        float(T[k]),
                        float(out[k, 1, t_idx]),
                        "bezier",
                        float(out[k, 0, t_idx]),
                        float(out[k, 2, t_idx]),
                        "user",
                    )
                    for k in range(nk)
                )
            else:
                keys = tuple(Key(float(T[k]), float(out[k, 0, t_idx]), mode) for k in range(nk))
            name = weight_track_name(shape)
            try:
                track = Track(name, keys)
            except TrackError as exc:
                raise AnimationImportError(src, f"{sfield}: {exc}") from None
            # head, teeth and eyes as separate meshes animate a shared shape once each
            if name in tracks and not _same_keys(tracks[name], track):
                raise AnimationImportError(
                    src,
                    f"{cfield}: animates {shape!r} differently from an earlier channel; "
                    "meshes that share a shape must key it alike",
                )
            tracks[name] = track
    if not found:
        raise AnimationImportError(src, f"{afield} has no 'weights' channel")
    tl = Timeline(fps=fps, tracks=tracks)
    return tl.fit_range()


def read_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    up_axis: str = "+y",
    front_axis: str = "+z",
    **kw: Any,
) -> Timeline:
    """Dispatch by suffix: .glb/.gltf → :func:`read_gltf_animation`, else :func:`read_weights_csv`.

    ``up_axis``/``front_axis`` (the model's, for Live Link Face head columns)
    only matter to CSVs.
    """
    p = Path(path)
    if p.suffix.lower() in (".glb", ".gltf"):
        return read_gltf_animation(p, shape_names, **kw)
    return read_weights_csv(p, shape_names, up_axis=up_axis, front_axis=front_axis, **kw)
