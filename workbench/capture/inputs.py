"""Capture inputs: markers/landmarks, marker→vertex maps, point clouds and depth frames (issue 17, item 1).

Everything a reader returns is in **metres**, with the unit the data were in
recorded (``.units``); :func:`to_model_units` converts to a model's unit
(``model.metadata.units``). Every problem with a file raises
:class:`CaptureInputError` (a :class:`~workbench.geometry.mesh_checks.MeshFormatError`,
so a ``ValueError``) whose message names the file, the line and/or frame, and
the column or field, and says what was expected. A reader returns everything
or raises: nothing is half-loaded.

Markers and landmarks → :class:`~workbench.io.markers.MarkerSequence`
------------------------------------------------------------------------
:func:`read_markers` picks the reader by suffix:

* ``.c3d`` — :func:`workbench.io.c3d.read_markers` (ezc3d, after a checked walk
  of the file's structure); ``POINT:UNITS`` gives the unit, a residual < 0 or
  a NaN coordinate a gap.
* ``.csv`` / ``.txt`` — :func:`read_marker_csv`, comma-separated, UTF-8:

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
* ``.npy`` — a (T, m, 3) float array; markers are named ``"0" .. "m-1"``.
* ``.npz`` — ``positions`` (T, m, 3), optional ``names`` (m,) str,
  ``fps`` and ``units`` (0-d), ``first_frame``; read with ``allow_pickle=False``.

An in-memory (T, m, 3) array becomes a sequence with :func:`as_marker_sequence`.

The unit: ``units=`` wins, else the file's (``POINT:UNITS``, the comment, the
Vicon units row, the NPZ ``units``); a CSV or NPY with no unit stated is an
error (a unit taken wrongly makes every distance wrong by a factor of 10–1000).
With ``check_units=True`` a face recording whose markers span less than 1 cm
or more than 10 m (median over frames) is refused with the unit that would
make it face-sized. The frame rate: ``fps=`` wins, else the file's, else the
time column's, else 30 with a warning.

Marker → vertex maps
--------------------
:func:`read_vertex_map` reads ``marker,vertex`` CSV, a JSON object
``{"marker": vertex}`` (or a list of ``{"marker": .., "vertex": ..}``), a dict,
or an (m,) integer array, and returns the (m,) vertex of every marker in the
sequence's order.

Point clouds → :class:`PointCloudSequence`
------------------------------------------
:func:`read_point_clouds` reads a folder of ``.ply`` files (one frame each,
sorted *naturally*: ``f2.ply`` before ``f10.ply``; read with trimesh; ``nx ny
nz`` vertex properties become normals; a ``comment units: mm`` header line
states the unit), one ``.ply`` (one frame), or one ``.npz`` holding either

* ``points_0000, points_0001, ...`` — one (p_t, 3) array per frame, numbered
  from 0 without gaps (any zero padding), optional ``normals_0000, ...``;
* ``points`` (P, 3) all frames concatenated, with ``counts`` (T,) points per
  frame *or* ``offsets`` (T+1,) (frame t is ``points[offsets[t]:offsets[t+1]]``),
  optional ``normals`` (P, 3);
* ``points`` (T, p, 3) — equal-sized frames, optional ``normals`` (T, p, 3);

plus optional ``fps`` and ``units`` (0-d). An empty frame is an error naming
it unless ``allow_empty=True`` (then :attr:`PointCloudSequence.empty` flags it).

Depth frames
------------
:func:`depth_to_points` back-projects one (H, W) depth image through a pinhole
camera (OpenCV convention: pixel ``(u, v)`` is column ``u``, row ``v``, integer
coordinates at pixel centres; ``x = (u − cx) z / fx``, ``y = (v − cy) z / fy``;
no lens distortion — give rectified depth). Zero (and NaN) depth is "no
measurement" and dropped. Returned axes: ``axes="y_up"`` (default) is the
workbench's frame, +x right, **+y up, +z toward the camera**, so a face looking
into the camera looks along +z like the sample head (``up_axis="+y"``,
``front_axis="+z"``); ``axes="opencv"`` is the camera's own frame, +x right,
+y down, +z forward (away from the camera); the two differ by the sign of y
and z. :func:`read_depth_frames` reads a folder of 16-bit single-channel PNGs
(Pillow) with :func:`read_intrinsics` (``fx, fy, cx, cy``, or Open3D's
``intrinsic_matrix``, or ``K``; optional ``width``, ``height``,
``depth_scale`` in metres per depth unit, ``fps``).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.shapes import UNIT_TO_METRES
from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.markers import MarkerSequence
from workbench.io.units import unit_name

__all__ = [
    "DEPTH_RANGE",
    "MARKER_SPAN",
    "CameraIntrinsics",
    "CaptureInputError",
    "MarkerSequence",
    "PointCloudSequence",
    "as_marker_sequence",
    "depth_to_points",
    "metres_per_unit",
    "read_depth_frames",
    "read_intrinsics",
    "read_marker_csv",
    "read_markers",
    "read_point_clouds",
    "read_vertex_map",
    "to_model_units",
]

log = logging.getLogger("workbench.capture")

#: (smallest, largest) plausible spread in metres of a capture (markers, landmarks, a
#: point cloud): the longest bounding-box side of one frame, median over frames
MARKER_SPAN: tuple[float, float] = (0.01, 10.0)
#: (smallest, largest) plausible median depth in metres of a depth frame
DEPTH_RANGE: tuple[float, float] = (0.02, 50.0)
DEFAULT_FPS = 30.0

_FRAME_NAMES = ("frame", "frame#", "frame_index", "frame number")
_TIME_NAMES = ("time", "time_s", "seconds", "time (seconds)")
_AXIS_COLUMN = re.compile(r"^(.+)[._]([xyz])$", re.IGNORECASE)
_COMMENT_KEY = re.compile(r"^#\s*([A-Za-z][A-Za-z _-]*?)\s*[:=]\s*(.*?)\s*$")
_PLY_UNITS = re.compile(rb"^comment\s+units?\s*[:=]?\s*(\S+)", re.IGNORECASE | re.MULTILINE)


# ---------------------------------------------------------------------------- errors
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


# ----------------------------------------------------------------------------- units
def metres_per_unit(units: str) -> float:
    """Metres in one ``units`` ("mm", "cm", "dm", "m", "in" or their names).

    Raises
    ------
    ValueError
        Not a length unit the workbench knows.
    """
    return UNIT_TO_METRES[unit_name(units)]


def _target_factor(model_or_units: Any) -> float:
    if isinstance(model_or_units, str):
        return 1.0 / metres_per_unit(model_or_units)
    meta = getattr(model_or_units, "metadata", None)
    units = getattr(meta, "units", None)
    if not isinstance(units, str):
        raise TypeError(
            "to_model_units: expected a unit name or a model with metadata.units, "
            f"got {type(model_or_units).__name__}"
        )
    return 1.0 / metres_per_unit(units)


@overload
def to_model_units(data: MarkerSequence, model_or_units: Any) -> NDArray[np.float64]: ...
@overload
def to_model_units(data: PointCloudSequence, model_or_units: Any) -> list[NDArray[np.float64]]: ...
@overload
def to_model_units(data: ArrayLike, model_or_units: Any) -> NDArray[np.float64]: ...
def to_model_units(data: Any, model_or_units: Any) -> Any:
    """Positions in metres → the model's unit.

    Parameters
    ----------
    data : MarkerSequence, PointCloudSequence or array_like
        What a reader returned, or any array of positions in metres.
    model_or_units : FaceModel or str
        A model (its ``metadata.units``) or a unit name.

    Returns
    -------
    (T, m, 3) float64 for a MarkerSequence (NaN gaps kept), a list of (p_t, 3)
    float64 for a PointCloudSequence, else an array of ``data``'s shape.

    Examples
    --------
    >>> to_model_units(np.array([[0.1, 0.2, 0.0]]), "cm")
    array([[10., 20.,  0.]])
    """
    f = _target_factor(model_or_units)
    if isinstance(data, MarkerSequence):
        return np.asarray(data.positions, np.float64) * f
    if isinstance(data, PointCloudSequence):
        return [np.asarray(fr, np.float64) * f for fr in data.frames]
    return np.asarray(data, np.float64) * f


def _resolve_unit(src: str, given: str | None, stated: str | None, where: str) -> tuple[str, float]:
    """(short unit, metres per unit): ``given`` wins, then ``stated``; neither is an error."""
    if given is not None:
        try:
            u = unit_name(given)
        except ValueError as exc:
            raise CaptureInputError(src, str(exc), field="units") from None
        if stated is not None and stated.strip().lower() != given.strip().lower():
            log.info("%s: units=%r given; the file states %r", Path(src).name, given, stated)
        return u, UNIT_TO_METRES[u]
    if stated is None:
        raise CaptureInputError(
            src,
            f"the file does not state its length unit: pass units='mm' (or 'cm', 'm', 'in', 'dm'), "
            f"or {where}",
            field="units",
        )
    try:
        u = unit_name(stated)
    except ValueError:
        raise CaptureInputError(
            src, f"unknown unit {stated!r}; expected one of {sorted(UNIT_TO_METRES)}", field="units"
        ) from None
    return u, UNIT_TO_METRES[u]


def _suggest(span_m: float, mpu: float) -> str:
    """The unit in which a span of ``span_m`` metres (read with ``mpu``) is about 0.2 m."""
    raw = span_m / mpu
    best = min(
        UNIT_TO_METRES, key=lambda u: abs(math.log(max(raw * UNIT_TO_METRES[u], 1e-300) / 0.2))
    )
    return best


def _frame_spans(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T,) longest bounding-box side of each frame's finite points of P (T, m, 3); NaN with < 3."""
    if P.shape[1] == 0:
        return np.full(P.shape[0], np.nan)
    ok = np.asarray(np.isfinite(P).all(axis=2), dtype=bool)
    ok3 = ok.reshape(*ok.shape, 1)
    lo = np.where(ok3, P, np.inf).min(axis=1)
    hi = np.where(ok3, P, -np.inf).max(axis=1)
    with np.errstate(invalid="ignore"):
        span = (hi - lo).max(axis=1)
    return np.where(ok.sum(axis=1) >= 3, span, np.nan)


def _frame_span(P: NDArray[np.float64]) -> float | None:
    """Longest bounding-box side of the finite rows of P (n, 3); None with < 3 such rows."""
    s = float(_frame_spans(P[None])[0])
    return None if math.isnan(s) else s


def _check_span(src: str, spans: Iterable[float | None], unit: str, mpu: float, what: str) -> None:
    s = [x for x in spans if x is not None and x > 0]  # NaN (too few points) fails x > 0
    if not s:
        return
    span = float(np.median(s))
    lo, hi = MARKER_SPAN
    if lo <= span <= hi:
        return
    better = _suggest(span, mpu)
    hint = (
        f"if the coordinates are in {better}, pass units={better!r}"
        if better != unit
        else "check the unit"
    )
    raise CaptureInputError(
        src,
        f"the {what} span {span:.4g} m read in {unit} (longest side of a frame, median over "
        f"frames), not the {lo:g}-{hi:g} m of a face capture: {hint} (or check_units=False)",
        field="units",
    )


# --------------------------------------------------------------------------- markers
def as_marker_sequence(
    positions: ArrayLike,
    *,
    names: Sequence[str] | None = None,
    fps: float = DEFAULT_FPS,
    units: str = "m",
    first_frame: int = 0,
    source: str = "<array>",
    check_units: bool = True,
) -> MarkerSequence:
    """A (T, m, 3) array of marker or landmark positions → a :class:`MarkerSequence` in metres.

    Parameters
    ----------
    positions : (T, m, 3) array_like
        Positions in ``units``; NaN marks an occluded marker (all three
        coordinates, or none).
    names : sequence of str, optional
        Marker names; ``"0" .. "m-1"`` when not given.
    fps : float
        Frames per second.
    units : str
        Unit of ``positions``.
    first_frame : int
        Number of the first frame (used in messages and ``.first_frame``).
    source : str
        Named in errors.
    check_units : bool
        Refuse a spread that is not face-sized in ``units`` (see module docstring).

    Raises
    ------
    CaptureInputError
        Wrong shape, non-numeric data, an infinite coordinate or a partly
        NaN marker (naming frame and marker), duplicate names, wrong units.
    """
    src = str(source)
    try:
        P = np.array(positions, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CaptureInputError(
            src, f"positions are not numeric: {exc}", field="positions"
        ) from None
    if P.ndim != 3 or P.shape[2] != 3:
        raise CaptureInputError(
            src, f"expected a (frames, markers, 3) array, got shape {P.shape}", field="positions"
        )
    T, m = P.shape[:2]
    if T == 0 or m == 0:
        raise CaptureInputError(src, f"no data: shape {P.shape}", field="positions")
    nm = [str(j) for j in range(m)] if names is None else [str(n).strip() for n in names]
    if len(nm) != m:
        raise CaptureInputError(src, f"{len(nm)} names for {m} markers", field="names")
    _check_names(src, nm)
    u, mpu = _resolve_unit(src, units, None, "")
    _check_marker_values(src, P, nm, first_frame)
    if not (np.isfinite(fps) and fps > 0):
        raise CaptureInputError(src, f"fps must be > 0, got {fps!r}", field="fps")
    P *= mpu
    if check_units and m >= 3:
        _check_span(src, _frame_spans(P).tolist(), u, mpu, "markers")
    return MarkerSequence(tuple(nm), P, float(fps), u, int(first_frame), src)


def _check_names(src: str, names: Sequence[str]) -> None:
    seen: dict[str, int] = {}
    for j, n in enumerate(names):
        if not n:
            raise CaptureInputError(src, f"marker {j} has an empty name", field="names")
        if n in seen:
            raise CaptureInputError(
                src, f"marker name {n!r} repeats (markers {seen[n]} and {j})", field="names"
            )
        seen[n] = j


def _check_marker_values(
    src: str, P: NDArray[np.float64], names: Sequence[str], first_frame: int
) -> None:
    """Infinite coordinates and partly-NaN markers are errors naming frame and marker."""
    inf = np.isinf(P)
    if inf.any():
        f, j, a = (int(x) for x in np.argwhere(inf)[0])
        raise CaptureInputError(
            src, f"coordinate {'xyz'[a]} is infinite", frame=f + first_frame, column=names[j]
        )
    nan = np.isnan(P)
    partial = nan.any(axis=2) & ~nan.all(axis=2)
    if partial.any():
        f, j = (int(x) for x in np.argwhere(partial)[0])
        miss = [ax for ax, b in zip("xyz", nan[f, j], strict=True) if b]
        raise CaptureInputError(
            src,
            f"marker has {', '.join(miss)} missing but not all of x, y, z (an occluded marker "
            f"has all three empty/NaN)",
            frame=f + first_frame,
            column=names[j],
        )


def read_markers(
    path: str | Path,
    *,
    units: str | None = None,
    fps: float | None = None,
    check_units: bool = True,
) -> MarkerSequence:
    """Read markers or landmarks from ``.c3d``, ``.csv``/``.txt``, ``.npy`` or ``.npz`` (module docstring).

    Parameters
    ----------
    path : str or Path
        The file.
    units : str, optional
        The unit of the coordinates in the file; overrides what the file
        states (for a C3D whose ``POINT:UNITS`` is wrong). Required when the
        file states none.
    fps : float, optional
        Frames per second; overrides the file's.
    check_units : bool
        Refuse a recording whose spread is not face-sized in its unit.

    Returns
    -------
    MarkerSequence
        ``positions`` (T, m, 3) in metres, NaN where occluded.

    Raises
    ------
    FileNotFoundError
        No such file.
    CaptureInputError, MeshFormatError
        Naming the file, frame/line and column/field.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    suf = p.suffix.lower()
    if suf == ".c3d":
        return _read_c3d(p, units, fps, check_units)
    if suf in (".csv", ".txt"):
        return read_marker_csv(p, units=units, fps=fps, check_units=check_units)
    if suf in (".npy", ".npz"):
        return _read_marker_array(p, units, fps, check_units)
    raise CaptureInputError(
        str(p),
        f"unknown marker file type {p.suffix!r}; expected .c3d, .csv, .txt, .npy or .npz",
        field="file",
    )


def _read_c3d(p: Path, units: str | None, fps: float | None, check_units: bool) -> MarkerSequence:
    from workbench.io import c3d

    seq = c3d.read_markers(p)
    src = str(p)
    P = np.array(seq.positions, np.float64)
    unit = seq.units
    stated_mpu = c3d.UNITS_TO_METRES[unit.strip().lower()]
    mpu = stated_mpu
    if units is not None:
        unit, mpu = _resolve_unit(src, units, seq.units, "")
        P *= mpu / stated_mpu
    if check_units and seq.n_markers >= 3:
        _check_span(src, _frame_spans(P).tolist(), unit, mpu, "markers")
    rate = seq.fps if fps is None else float(fps)
    if not (np.isfinite(rate) and rate > 0):
        raise CaptureInputError(src, f"fps must be > 0, got {fps!r}", field="fps")
    return MarkerSequence(seq.names, P, rate, unit, seq.first_frame, src)


_NPZ_MARKER_KEYS = ("positions", "names", "fps", "units", "first_frame")


def _npz_scalar(src: str, z: Any, key: str, kind: type) -> Any:
    a = z[key]
    if a.shape not in ((), (1,)):
        raise CaptureInputError(
            src, f"expected a single value, got shape {a.shape}", field=f"array {key!r}"
        )
    v = a.reshape(())[()]
    try:
        return kind(v.item() if hasattr(v, "item") else v)
    except (TypeError, ValueError):
        raise CaptureInputError(
            src, f"expected {kind.__name__}, got {v!r}", field=f"array {key!r}"
        ) from None


def _open_npz(p: Path) -> Any:
    try:
        return np.load(p, allow_pickle=False)
    except Exception as exc:
        raise CaptureInputError(str(p), f"cannot read as .npz/.npy: {exc}", field="file") from None


def _npz_array(src: str, z: Any, key: str) -> NDArray[Any]:
    try:
        return np.asarray(z[key])
    except ValueError as exc:  # object arrays need pickle, refused
        raise CaptureInputError(src, f"cannot read: {exc}", field=f"array {key!r}") from None


def _read_marker_array(
    p: Path, units: str | None, fps: float | None, check_units: bool
) -> MarkerSequence:
    src = str(p)
    data = _open_npz(p)
    names: list[str] | None = None
    first = 0
    stated_units: str | None = None
    stated_fps: float | None = None
    if isinstance(data, np.ndarray):
        P = data
    else:
        with data as z:
            keys = list(z.files)
            extra = [k for k in keys if k not in _NPZ_MARKER_KEYS]
            if extra or "positions" not in keys:
                raise CaptureInputError(
                    src,
                    f"expected arrays 'positions' (T, m, 3) and optionally {list(_NPZ_MARKER_KEYS[1:])}; "
                    f"the file has {keys}",
                    field="arrays",
                )
            P = _npz_array(src, z, "positions")
            if "names" in keys:
                nm = _npz_array(src, z, "names")
                if nm.dtype.kind not in "US" or nm.ndim != 1:
                    raise CaptureInputError(
                        src,
                        f"expected a (m,) string array, got {nm.dtype} {nm.shape}",
                        field="array 'names'",
                    )
                names = [str(x) for x in nm]
            if "units" in keys:
                stated_units = _npz_scalar(src, z, "units", str)
            if "fps" in keys:
                stated_fps = _npz_scalar(src, z, "fps", float)
            if "first_frame" in keys:
                first = _npz_scalar(src, z, "first_frame", int)
    if P.dtype.kind not in "fiu":
        raise CaptureInputError(
            src, f"expected a float array, got dtype {P.dtype}", field="array 'positions'"
        )
    u, _ = _resolve_unit(src, units, stated_units, "store a 'units' array in the .npz")
    rate = fps if fps is not None else stated_fps
    if rate is None:
        log.warning(
            "%s: no frame rate in the file; %g fps assumed (pass fps=)", p.name, DEFAULT_FPS
        )
        rate = DEFAULT_FPS
    return as_marker_sequence(
        P, names=names, fps=rate, units=u, first_frame=first, source=src, check_units=check_units
    )


# ------------------------------------------------------------------------------- CSV
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


def _csv_rows(text: str) -> list[list[str]]:
    """Cells of every line (comments and blank lines → []), one entry per line."""
    lines = text.splitlines()
    masked = ["" if ln.lstrip().startswith("#") else ln for ln in lines]
    rows = list(csv.reader(masked))
    if len(rows) != len(lines):  # a quoted field spanning lines: fall back to line by line
        rows = [next(csv.reader([ln])) if ln else [] for ln in masked]
    return rows


def _comment_meta(lines: Sequence[str], stop: int) -> dict[str, tuple[str, int]]:
    meta: dict[str, tuple[str, int]] = {}
    for i in range(stop):
        m = _COMMENT_KEY.match(lines[i].strip())
        if m:
            key = m.group(1).strip().lower().replace("_", " ")
            meta[key] = (m.group(2), i + 1)
    return meta


def _blank(cells: Sequence[str]) -> bool:
    return not any(c.strip() for c in cells)


def _trim(cells: list[str]) -> list[str]:
    while cells and not cells[-1].strip():
        cells = cells[:-1]
    return cells


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


# ---------------------------------------------------------------------- vertex map
def _as_int(v: Any) -> int | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, str):
        s = v.strip()
        if re.fullmatch(r"[+-]?\d+", s):
            return int(s)
    return None


def _map_from_csv(p: Path) -> tuple[dict[str, int], dict[str, str]]:
    src = str(p)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CaptureInputError(src, f"not UTF-8 text (byte {exc.start})", field="file") from None
    rows = _csv_rows(text)
    out: dict[str, int] = {}
    where: dict[str, str] = {}
    header_seen = False
    cols = ("marker", "vertex")
    for i, r in enumerate(rows):
        if _blank(r):
            continue
        r = _trim(r)
        if len(r) != 2:
            raise CaptureInputError(
                src, f"expected 2 fields (marker, vertex), got {len(r)}", line=i + 1
            )
        name, vtxt = r[0].strip(), r[1].strip()
        if not header_seen and not out and _as_int(vtxt) is None:
            header_seen = True  # a header row such as "marker,vertex"
            cols = (name or "marker", vtxt or "vertex")
            continue
        if not name:
            raise CaptureInputError(src, "empty marker name", line=i + 1, column=cols[0])
        v = _as_int(vtxt)
        if v is None:
            raise CaptureInputError(
                src, f"{vtxt!r:.30} is not a whole vertex index", line=i + 1, column=cols[1]
            )
        if name in out:
            raise CaptureInputError(
                src,
                f"marker {name!r} is mapped twice (also {where[name]})",
                line=i + 1,
                column=cols[0],
            )
        out[name] = v
        where[name] = f"line {i + 1}"
    return out, where


def _map_from_json(p: Path) -> tuple[dict[str, int], dict[str, str]]:
    src = str(p)
    try:
        obj = json.loads(p.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise CaptureInputError(src, f"not UTF-8 text (byte {exc.start})", field="file") from None
    except json.JSONDecodeError as exc:
        raise CaptureInputError(src, f"not JSON: {exc.msg}", line=exc.lineno) from None
    return _map_from_obj(src, obj)


def _map_from_obj(src: str, obj: Any) -> tuple[dict[str, int], dict[str, str]]:
    out: dict[str, int] = {}
    where: dict[str, str] = {}
    if isinstance(obj, Mapping):
        items = [(str(k), v, f"key {str(k)!r}") for k, v in obj.items()]
    elif isinstance(obj, list):
        items = []
        for i, e in enumerate(obj):
            if not (isinstance(e, Mapping) and "marker" in e and "vertex" in e):
                raise CaptureInputError(
                    src, 'expected an object {"marker": name, "vertex": index}', field=f"entry {i}"
                )
            items.append((str(e["marker"]), e["vertex"], f"entry {i}"))
    else:
        raise CaptureInputError(
            src,
            f"expected an object {{marker: vertex}} or a list of {{marker, vertex}}, got {type(obj).__name__}",
            field="file",
        )
    for name, v, label in items:
        iv = _as_int(v) if not isinstance(v, str) else None
        if iv is None:
            raise CaptureInputError(src, f"vertex {v!r:.30} is not a whole number", field=label)
        if name in out:
            raise CaptureInputError(
                src, f"marker {name!r} is mapped twice (also {where[name]})", field=label
            )
        out[name] = iv
        where[name] = label
    return out, where


def read_vertex_map(
    source: str | Path | Mapping[str, int] | ArrayLike,
    marker_names: Sequence[str] | MarkerSequence,
    n_vertices: int,
    *,
    allow_extra: bool = False,
) -> NDArray[np.int64]:
    """The vertex each marker sits on, in the order of ``marker_names``.

    Parameters
    ----------
    source : str, Path, mapping or (m,) array_like of int
        A ``.csv`` file of ``marker,vertex`` rows (an optional header row; ``#``
        comments), a ``.json`` file holding ``{"marker": vertex, ...}`` or
        ``[{"marker": .., "vertex": ..}, ...]``, a dict, or the (m,) vertex
        indices already in marker order.
    marker_names : sequence of str or MarkerSequence
        The markers, e.g. ``MarkerSequence.names``.
    n_vertices : int
        Number of vertices of the model (valid indices are 0 .. n_vertices-1).
    allow_extra : bool
        Accept map entries for markers the sequence does not have (ignored).

    Returns
    -------
    (m,) int64
        ``ids[j]`` is the vertex of ``marker_names[j]``.

    Raises
    ------
    CaptureInputError
        Naming the file (or ``<mapping>``), the line or key: names the sequence
        does not have (unless ``allow_extra``), markers with no vertex, an index
        that is not a whole number or not in ``[0, n_vertices)``, a marker mapped
        twice, repeated marker names.
    """
    names = list(marker_names.names if isinstance(marker_names, MarkerSequence) else marker_names)
    n_vertices = int(n_vertices)
    where: dict[str, str]
    if isinstance(source, (str, Path)):
        p = Path(source)
        src = str(p)
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no such file")
        suf = p.suffix.lower()
        if suf in (".csv", ".txt"):
            mapping, where = _map_from_csv(p)
        elif suf == ".json":
            mapping, where = _map_from_json(p)
        else:
            raise CaptureInputError(
                src, f"unknown map file type {p.suffix!r}; expected .csv or .json", field="file"
            )
    elif isinstance(source, Mapping):
        src = "<mapping>"
        mapping, where = _map_from_obj(src, source)
    else:
        src = "<array>"
        a = np.asarray(source)
        if a.ndim != 1 or a.shape[0] != len(names) or (a.size and a.dtype.kind not in "iu"):
            raise CaptureInputError(
                src,
                f"expected ({len(names)},) integer vertex indices, got {a.dtype} {a.shape}",
                field="vertex_ids",
            )
        mapping = {n: int(v) for n, v in zip(names, a, strict=True)}
        where = {n: f"entry {j}" for j, n in enumerate(names)}
    _check_names(src, [str(n) for n in names])
    extra = [k for k in mapping if k not in set(names)]
    if extra and not allow_extra:
        raise CaptureInputError(
            src,
            f"{len(extra)} mapped name(s) are not markers of the sequence: {extra[:8]}"
            f"{'...' if len(extra) > 8 else ''} (markers: {names[:8]}{'...' if len(names) > 8 else ''}; "
            f"pass allow_extra=True to ignore them)",
            field=where[extra[0]],
        )
    missing = [n for n in names if n not in mapping]
    if missing:
        raise CaptureInputError(
            src,
            f"{len(missing)} marker(s) have no vertex: {missing[:8]}{'...' if len(missing) > 8 else ''}",
            field="markers",
        )
    ids = np.array([mapping[n] for n in names], np.int64)
    bad = np.flatnonzero((ids < 0) | (ids >= n_vertices))
    if bad.size:
        j = int(bad[0])
        raise CaptureInputError(
            src,
            f"marker {names[j]!r}: vertex {int(ids[j])} is out of range; the model has "
            f"{n_vertices} vertices (0..{n_vertices - 1})",
            field=where[names[j]],
        )
    if len(set(ids.tolist())) != len(ids):
        log.info("%s: several markers share a vertex", Path(src).name)
    return ids


# ----------------------------------------------------------------------- point clouds
@dataclass(frozen=True)
class PointCloudSequence:
    """Point clouds per frame, without correspondences.

    Attributes
    ----------
    frames : tuple of (p_t, 3) float64
        Points of each frame in **metres**, finite, read-only; ``p_t`` may differ
        between frames (and be 0 for an empty frame).
    fps : float
        Frames per second.
    units : str
        The unit the data were in ("mm", "m", ...); positions are in metres.
    normals : tuple of (p_t, 3) float64 or None
        Unit normals per point (zero where the file's normal was zero), or None.
    labels : tuple of str
        What each frame was read from (file names), or empty.
    source : str
        The file or folder read.
    first_frame : int
        Number of the first frame.
    """

    frames: tuple[NDArray[np.float64], ...]
    fps: float
    units: str
    normals: tuple[NDArray[np.float64], ...] | None = None
    labels: tuple[str, ...] = ()
    source: str = ""
    first_frame: int = 0

    def __post_init__(self) -> None:
        frames = []
        for t, f in enumerate(self.frames):
            F = np.array(f, dtype=np.float64)
            if F.shape == (0,):
                F = F.reshape(0, 3)
            if F.ndim != 2 or F.shape[1] != 3:
                raise ValueError(f"PointCloudSequence: frame {t} must be (p, 3), got {F.shape}")
            if not np.isfinite(F).all():
                raise ValueError(f"PointCloudSequence: frame {t} has non-finite points")
            F.setflags(write=False)
            frames.append(F)
        object.__setattr__(self, "frames", tuple(frames))
        if self.normals is not None:
            if len(self.normals) != len(frames):
                raise ValueError(
                    f"PointCloudSequence: {len(self.normals)} normal sets for {len(frames)} frames"
                )
            ns = []
            for t, (n, F) in enumerate(zip(self.normals, frames, strict=True)):
                N = np.array(n, np.float64)
                if N.shape == (0,):
                    N = N.reshape(0, 3)
                if N.shape != F.shape or not np.isfinite(N).all():
                    raise ValueError(
                        f"PointCloudSequence: frame {t} normals must be finite {F.shape}, got {N.shape}"
                    )
                N.setflags(write=False)
                ns.append(N)
            object.__setattr__(self, "normals", tuple(ns))
        if self.labels and len(self.labels) != len(frames):
            raise ValueError(
                f"PointCloudSequence: {len(self.labels)} labels for {len(frames)} frames"
            )
        object.__setattr__(self, "labels", tuple(self.labels))
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"PointCloudSequence: fps must be > 0, got {self.fps!r}")
        object.__setattr__(self, "units", unit_name(self.units))

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def counts(self) -> NDArray[np.int64]:
        """(T,) points per frame."""
        return np.array([f.shape[0] for f in self.frames], np.int64)

    @property
    def empty(self) -> NDArray[np.bool_]:
        """(T,) True where a frame has no points."""
        return np.asarray(self.counts == 0)

    @property
    def times(self) -> NDArray[np.float64]:
        """(T,) seconds from the first frame."""
        return np.arange(self.n_frames, dtype=np.float64) / self.fps


def _natural_key(name: str) -> tuple[tuple[int, int, str], ...]:
    return tuple(
        (0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", name.lower()) if t
    )


def _unit_normals(N: NDArray[np.float64]) -> NDArray[np.float64]:
    n = np.linalg.norm(N, axis=1, keepdims=True)
    return np.divide(N, n, out=np.zeros_like(N), where=n > 0)


def _check_points(src: str, P: NDArray[Any], frame: int, field: str) -> NDArray[np.float64]:
    if P.dtype.kind not in "fiu":
        raise CaptureInputError(
            src, f"expected numbers, got dtype {P.dtype}", frame=frame, field=field
        )
    Q = np.asarray(P, np.float64)
    if Q.shape == (0,):
        Q = Q.reshape(0, 3)
    if Q.ndim != 2 or Q.shape[1] != 3:
        raise CaptureInputError(
            src, f"expected (points, 3), got shape {Q.shape}", frame=frame, field=field
        )
    bad = ~np.isfinite(Q).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise CaptureInputError(
            src,
            f"point {i} is not finite ({Q[i].tolist()}); {int(bad.sum())} such point(s)",
            frame=frame,
            field=field,
        )
    return Q


def _read_ply(
    p: Path, frame: int
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, str | None]:
    """(points, normals or None, the header's unit or None) of one PLY file, in its unit."""
    src = str(p)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise CaptureInputError(src, f"cannot read: {exc}", frame=frame, field="file") from None
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise CaptureInputError(
            src, "not a PLY file (no 'ply' ... 'end_header' header)", frame=frame, field="header"
        )
    head = data[:end]
    m = re.search(rb"^element\s+vertex\s+(\d+)", head, re.MULTILINE)
    if not m:
        raise CaptureInputError(
            src, "the header declares no 'element vertex'", frame=frame, field="header"
        )
    n_declared = int(m.group(1))
    vblock = head[m.end() :]
    nxt = re.search(rb"^element\s", vblock, re.MULTILINE)
    vprops = re.findall(
        rb"^property\s+\S+\s+(\S+)", vblock[: nxt.start()] if nxt else vblock, re.MULTILINE
    )
    names = [v.decode("ascii", "replace") for v in vprops]
    for ax in "xyz":
        if ax not in names:
            raise CaptureInputError(
                src,
                f"the vertex element has no '{ax}' property (has {names})",
                frame=frame,
                field="element vertex",
            )
    um = _PLY_UNITS.search(head)
    unit = um.group(1).decode("ascii", "replace") if um else None
    if n_declared == 0:
        return np.zeros((0, 3)), None, unit
    from trimesh.exchange.ply import load_ply

    try:
        kw = load_ply(io.BytesIO(data), fix_texture=False, skip_materials=True)
    except Exception as exc:  # trimesh raises ValueError, IndexError, struct errors ...
        raise CaptureInputError(
            src, f"trimesh cannot read the PLY (truncated or damaged?): {exc}", frame=frame, field="file"
        ) from None
    V = np.asarray(kw.get("vertices", np.zeros((0, 3))), np.float64)
    if V.shape != (n_declared, 3):
        raise CaptureInputError(
            src,
            f"read {V.shape[0]} vertices, the header declares {n_declared} (truncated?)",
            frame=frame,
            field="element vertex",
        )
    P = _check_points(src, V, frame, "element vertex")
    N = None
    if all(k in names for k in ("nx", "ny", "nz")) and "vertex_normals" in kw:
        N = np.asarray(kw["vertex_normals"], np.float64).reshape(-1, 3)
        if N.shape != P.shape or not np.isfinite(N).all():
            raise CaptureInputError(
                src, "normals (nx, ny, nz) are not finite", frame=frame, field="element vertex"
            )
        N = _unit_normals(N)
    return P, N, unit


_NPZ_CLOUD_META = ("fps", "units")


def _read_cloud_npz(
    p: Path,
) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]] | None, str | None, float | None]:
    src = str(p)
    data = _open_npz(p)
    if isinstance(data, np.ndarray):
        raise CaptureInputError(
            src, "a .npy holds one array; point clouds need an .npz (see layouts)", field="file"
        )
    with data as z:
        keys = list(z.files)
        units = _npz_scalar(src, z, "units", str) if "units" in keys else None
        fps = _npz_scalar(src, z, "fps", float) if "fps" in keys else None
        per = {k for k in keys if re.fullmatch(r"(points|normals)_\d+", k)}
        rest = [k for k in keys if k not in per and k not in _NPZ_CLOUD_META]
        layouts = (
            "'points_0000', 'points_0001', ... (optional 'normals_0000', ...); or 'points' (P, 3) with "
            "'counts' (T,) or 'offsets' (T+1,) (optional 'normals'); or 'points' (T, p, 3); "
            "plus optional 'fps', 'units'"
        )
        if per:
            if rest:
                raise CaptureInputError(
                    src,
                    f"unexpected arrays {rest} next to 'points_NNNN'; expected {layouts}",
                    field="arrays",
                )
            idx = {int(k.split("_")[1]): k for k in per if k.startswith("points_")}
            nidx = {int(k.split("_")[1]): k for k in per if k.startswith("normals_")}
            if len(idx) != sum(k.startswith("points_") for k in per) or len(nidx) != sum(
                k.startswith("normals_") for k in per
            ):
                raise CaptureInputError(
                    src,
                    "two arrays have the same frame number (e.g. points_1 and points_001)",
                    field="arrays",
                )
            T = max(idx) + 1 if idx else 0
            missing = [t for t in range(T) if t not in idx]
            if missing:
                raise CaptureInputError(
                    src,
                    f"the arrays 'points_NNNN' must number the frames 0, 1, 2, ... without gaps; "
                    f"there is none for frame {missing[0]} (frames found: {sorted(idx)[:10]})",
                    frame=missing[0],
                    field="arrays",
                )
            if nidx and set(nidx) != set(idx):
                t = min(set(nidx) ^ set(idx))
                raise CaptureInputError(
                    src,
                    "normals are given for some frames but not this one",
                    frame=t,
                    field="arrays",
                )
            frames: list[NDArray[np.float64]] = [
                _check_points(src, _npz_array(src, z, idx[t]), t, f"array {idx[t]!r}")
                for t in range(T)
            ]
            normals: list[NDArray[np.float64]] | None = None
            if nidx:
                normals = []
                for t in range(T):
                    N = _check_points(src, _npz_array(src, z, nidx[t]), t, f"array {nidx[t]!r}")
                    if N.shape != frames[t].shape:
                        raise CaptureInputError(
                            src,
                            f"normals {N.shape} do not match points {frames[t].shape}",
                            frame=t,
                            field=f"array {nidx[t]!r}",
                        )
                    normals.append(_unit_normals(N))
            return frames, normals, units, fps
        if "points" not in keys:
            raise CaptureInputError(
                src, f"no point arrays; expected {layouts}; the file has {keys}", field="arrays"
            )
        extra = [k for k in rest if k not in ("points", "counts", "offsets", "normals")]
        if extra:
            raise CaptureInputError(
                src, f"unexpected arrays {extra}; expected {layouts}", field="arrays"
            )
        P = _npz_array(src, z, "points")
        Nall = _npz_array(src, z, "normals") if "normals" in keys else None
        if P.dtype.kind not in "fiu":
            raise CaptureInputError(
                src, f"expected numbers, got dtype {P.dtype}", field="array 'points'"
            )
        if Nall is not None and Nall.shape != P.shape:
            raise CaptureInputError(
                src, f"normals {Nall.shape} do not match points {P.shape}", field="array 'normals'"
            )
        if "counts" in keys and "offsets" in keys:
            raise CaptureInputError(src, "give 'counts' or 'offsets', not both", field="arrays")
        if P.ndim == 3:
            if "counts" in keys or "offsets" in keys:
                raise CaptureInputError(
                    src, "(T, p, 3) points take no counts/offsets", field="array 'points'"
                )
            if P.shape[2] != 3:
                raise CaptureInputError(
                    src, f"expected (T, p, 3), got {P.shape}", field="array 'points'"
                )
            bounds = np.arange(P.shape[0] + 1) * P.shape[1]
            P = P.reshape(-1, 3)
            Nall = None if Nall is None else Nall.reshape(-1, 3)
        else:
            if P.ndim != 2 or P.shape[1] != 3:
                raise CaptureInputError(
                    src, f"expected (P, 3) or (T, p, 3), got {P.shape}", field="array 'points'"
                )
            if "counts" in keys:
                c = _npz_array(src, z, "counts")
                if c.ndim != 1 or c.dtype.kind not in "iu" or (c < 0).any():
                    raise CaptureInputError(
                        src,
                        f"expected (T,) non-negative integers, got {c.dtype} {c.shape}",
                        field="array 'counts'",
                    )
                if int(c.sum()) != P.shape[0]:
                    raise CaptureInputError(
                        src,
                        f"counts sum to {int(c.sum())}, 'points' has {P.shape[0]} rows",
                        field="array 'counts'",
                    )
                bounds = np.concatenate([[0], np.cumsum(c)])
            elif "offsets" in keys:
                o = _npz_array(src, z, "offsets")
                if o.ndim != 1 or o.dtype.kind not in "iu" or o.size < 2:
                    raise CaptureInputError(
                        src,
                        f"expected (T+1,) integers, got {o.dtype} {o.shape}",
                        field="array 'offsets'",
                    )
                if o[0] != 0 or o[-1] != P.shape[0]:
                    raise CaptureInputError(
                        src,
                        f"must start at 0 and end at {P.shape[0]} (rows of 'points'), got {int(o[0])} .. {int(o[-1])}",
                        field="array 'offsets'",
                    )
                dec = np.flatnonzero(np.diff(o) < 0)
                if dec.size:
                    raise CaptureInputError(
                        src, "offsets decrease", frame=int(dec[0]), field="array 'offsets'"
                    )
                bounds = o.astype(np.int64)
            else:
                raise CaptureInputError(
                    src,
                    "(P, 3) points need 'counts' or 'offsets' to split them into frames",
                    field="array 'points'",
                )
        frames = []
        normals = [] if Nall is not None else None
        for t in range(len(bounds) - 1):
            a, b = int(bounds[t]), int(bounds[t + 1])
            frames.append(_check_points(src, P[a:b], t, "array 'points'"))
            if normals is not None and Nall is not None:
                normals.append(_unit_normals(_check_points(src, Nall[a:b], t, "array 'normals'")))
        return frames, normals, units, fps


def read_point_clouds(
    path: str | Path,
    *,
    units: str | None = None,
    fps: float | None = None,
    allow_empty: bool = False,
    check_units: bool = True,
) -> PointCloudSequence:
    """Read a point-cloud sequence: a folder of PLY files, one PLY, or one NPZ (module docstring).

    Parameters
    ----------
    path : str or Path
        A folder of ``.ply`` files (sorted naturally), a ``.ply`` or an ``.npz``.
    units : str, optional
        Unit of the coordinates; wins over the file's (``comment units: mm`` in
        a PLY header, ``units`` in the NPZ). One of them is required.
    fps : float, optional
        Frames per second; wins over the NPZ ``fps`` (30 with a warning when
        none is given).
    allow_empty : bool
        Accept frames without points (flagged by ``.empty``); else an empty
        frame is an error naming it.
    check_units : bool
        Refuse clouds whose spread is not 1 cm – 10 m in the unit.

    Returns
    -------
    PointCloudSequence
        Frames (p_t, 3) in metres, unit normals when the files have them.

    Raises
    ------
    FileNotFoundError
        No such file or folder.
    CaptureInputError
        Naming the file, the frame and the array/element at fault.
    """
    p = Path(path)
    src = str(p)
    labels: list[str]
    if p.is_dir():
        files = sorted(
            (f for f in p.iterdir() if f.is_file() and f.suffix.lower() == ".ply"),
            key=lambda f: _natural_key(f.name),
        )
        if not files:
            raise CaptureInputError(src, "the folder has no .ply files", field="folder")
        frames, nlist, file_units = [], [], []
        for t, f in enumerate(files):
            P, N, u = _read_ply(f, t)
            frames.append(P)
            nlist.append(N)
            file_units.append(u)
        stated = _agree_units([(files[t], t, u) for t, u in enumerate(file_units)], units is None)
        normals: list[NDArray[np.float64]] | None = None
        lacking = [
            t
            for t, (N, P) in enumerate(zip(nlist, frames, strict=True))
            if N is None and P.shape[0]
        ]
        if any(N is not None for N in nlist):
            if lacking:
                t = lacking[0]
                log.warning(
                    "%s: frame %d (%s) has no normals, other frames do; normals dropped",
                    p.name,
                    t,
                    files[t].name,
                )
            else:
                normals = [N if N is not None else np.zeros((0, 3)) for N in nlist]
        labels = [f.name for f in files]
        file_fps = None
        err_src = {t: str(files[t]) for t in range(len(files))}
    elif p.is_file() and p.suffix.lower() == ".ply":
        P, N, stated = _read_ply(p, 0)
        frames, normals, labels, file_fps = [P], (None if N is None else [N]), [p.name], None
        err_src = {0: src}
    elif p.is_file() and p.suffix.lower() == ".npz":
        frames, normals, stated, file_fps = _read_cloud_npz(p)
        labels = []
        err_src = {}
    elif not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    else:
        raise CaptureInputError(
            src, f"expected a folder of .ply files, a .ply or an .npz, got {p.name!r}", field="file"
        )
    if not frames:
        raise CaptureInputError(src, "no frames", field="file")
    u, mpu = _resolve_unit(
        src,
        units,
        stated,
        "add a 'comment units: mm' line to the PLY header / a 'units' array to the .npz",
    )
    counts = [f.shape[0] for f in frames]
    if not allow_empty and 0 in counts:
        t = counts.index(0)
        raise CaptureInputError(
            err_src.get(t, src),
            "the point cloud is empty (pass allow_empty=True to keep such frames, flagged)",
            frame=t,
            field="points",
        )
    frames = [f * mpu for f in frames]
    if check_units:
        _check_span(src, (_frame_span(f) for f in frames), u, mpu, "point clouds")
    rate = fps if fps is not None else file_fps
    if rate is None:
        log.warning("%s: no frame rate given; %g fps assumed (pass fps=)", p.name, DEFAULT_FPS)
        rate = DEFAULT_FPS
    if not (math.isfinite(rate) and rate > 0):
        raise CaptureInputError(src, f"fps must be > 0, got {rate!r}", field="fps")
    return PointCloudSequence(
        tuple(frames),
        float(rate),
        u,
        None if normals is None else tuple(normals),
        tuple(labels),
        src,
    )


def _agree_units(found: list[tuple[Path, int, str | None]], needed: bool) -> str | None:
    """The unit the PLY headers state; they must agree (when the caller gave none)."""
    stated = [(f, t, u) for f, t, u in found if u is not None]
    if not stated or not needed:
        return stated[0][2] if stated else None
    f0, t0, u0 = stated[0]
    for f, t, u in stated[1:]:
        if u is not None and u.lower() != u0.lower():
            raise CaptureInputError(
                str(f),
                f"the header states units {u!r}, frame {t0} ({f0.name}) states {u0!r}",
                frame=t,
                field="header",
            )
    return u0


# ----------------------------------------------------------------------- depth frames
@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole depth camera (OpenCV convention, pixels).

    Attributes
    ----------
    fx, fy : float
        Focal lengths in pixels (> 0).
    cx, cy : float
        Principal point in pixels (column, row of the optical axis).
    width, height : int or None
        Image size the intrinsics are for, if known (checked against the images).
    depth_scale : float or None
        Metres per depth unit (0.001 for millimetre depth), if the file gives it.
    fps : float or None
        Frame rate, if the file gives it.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int | None = None
    height: int | None = None
    depth_scale: float | None = None
    fps: float | None = None

    @property
    def K(self) -> NDArray[np.float64]:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def _num(src: str, v: Any, name: str, *, positive: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise CaptureInputError(
            src, f"expected a number, got {v!r:.30}", field=f"intrinsics {name!r}"
        )
    x = float(v)
    if not math.isfinite(x) or (positive and x <= 0):
        raise CaptureInputError(
            src,
            f"expected a finite {'positive ' if positive else ''}number, got {x!r}",
            field=f"intrinsics {name!r}",
        )
    return x


def read_intrinsics(
    source: str | Path | Mapping[str, Any] | ArrayLike | CameraIntrinsics,
) -> CameraIntrinsics:
    """Pinhole intrinsics from a JSON file, a dict, ``(fx, fy, cx, cy)`` or a (3, 3) matrix.

    JSON / dict keys: ``fx, fy, cx, cy``; or ``intrinsic_matrix`` (9 numbers,
    column-major, as Open3D's ``PinholeCameraIntrinsic`` JSON); or ``K`` (3x3,
    row-major). Optional: ``width``, ``height`` (pixels), ``depth_scale``
    (metres per depth unit, ≤ 1; Open3D's ``depth_scale`` is the inverse,
    units per metre), ``fps``.

    Raises
    ------
    CaptureInputError
        Naming the file and the field: missing or non-numeric values, a
        non-positive focal length, a matrix that is not a pinhole camera.
    """
    if isinstance(source, CameraIntrinsics):
        return source
    if isinstance(source, (str, Path)):
        p = Path(source)
        src = str(p)
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no such file")
        try:
            obj = json.loads(p.read_text(encoding="utf-8-sig"))
        except UnicodeDecodeError as exc:
            raise CaptureInputError(
                src, f"not UTF-8 text (byte {exc.start})", field="file"
            ) from None
        except json.JSONDecodeError as exc:
            raise CaptureInputError(src, f"not JSON: {exc.msg}", line=exc.lineno) from None
        if not isinstance(obj, Mapping):
            raise CaptureInputError(
                src, f"expected a JSON object, got {type(obj).__name__}", field="file"
            )
    elif isinstance(source, Mapping):
        src, obj = "<intrinsics>", source
    else:
        src = "<intrinsics>"
        a = np.asarray(source, dtype=np.float64)
        if a.shape == (4,):
            return read_intrinsics(dict(zip(("fx", "fy", "cx", "cy"), a.tolist(), strict=True)))
        if a.shape == (3, 3):
            return read_intrinsics({"K": a.tolist()})
        raise CaptureInputError(
            src,
            f"expected (fx, fy, cx, cy) or a (3, 3) matrix, got shape {a.shape}",
            field="intrinsics",
        )
    if all(k in obj for k in ("fx", "fy", "cx", "cy")):
        vals = [obj[k] for k in ("fx", "fy", "cx", "cy")]
        names = ["fx", "fy", "cx", "cy"]
    elif "intrinsic_matrix" in obj or "K" in obj:
        key = "intrinsic_matrix" if "intrinsic_matrix" in obj else "K"
        try:
            M = np.asarray(obj[key], dtype=np.float64)
        except (TypeError, ValueError):
            raise CaptureInputError(src, "expected numbers", field=f"intrinsics {key!r}") from None
        if key == "intrinsic_matrix":
            if M.size != 9:
                raise CaptureInputError(
                    src,
                    f"expected 9 numbers (column-major 3x3), got {M.size}",
                    field="intrinsics 'intrinsic_matrix'",
                )
            M = M.reshape(3, 3).T
        elif M.shape != (3, 3):
            raise CaptureInputError(
                src, f"expected a 3x3 matrix, got shape {M.shape}", field="intrinsics 'K'"
            )
        if (
            not np.isfinite(M).all()
            or abs(M[0, 1]) > 1e-9
            or np.any(np.abs(M[2] - [0, 0, 1]) > 1e-9)
            or abs(M[1, 0]) > 1e-9
        ):
            raise CaptureInputError(
                src,
                f"not a pinhole camera matrix [[fx,0,cx],[0,fy,cy],[0,0,1]]: {M.tolist()}",
                field=f"intrinsics {key!r}",
            )
        vals = [M[0, 0], M[1, 1], M[0, 2], M[1, 2]]
        names = [f"{key}[fx]", f"{key}[fy]", f"{key}[cx]", f"{key}[cy]"]
    else:
        raise CaptureInputError(
            src,
            f"expected fx, fy, cx, cy (or 'intrinsic_matrix' / 'K'); the object has {sorted(obj)[:10]}",
            field="intrinsics",
        )
    fx = _num(src, vals[0], names[0], positive=True)
    fy = _num(src, vals[1], names[1], positive=True)
    cx = _num(src, vals[2], names[2])
    cy = _num(src, vals[3], names[3])
    size: list[int | None] = []
    for k in ("width", "height"):
        if k in obj and obj[k] is not None:
            v = _num(src, obj[k], k, positive=True)
            if v != int(v):
                raise CaptureInputError(
                    src, f"expected whole pixels, got {v}", field=f"intrinsics {k!r}"
                )
            size.append(int(v))
        else:
            size.append(None)
    ds = None
    if obj.get("depth_scale") is not None:
        ds = _num(src, obj["depth_scale"], "depth_scale", positive=True)
        _check_depth_scale(src, ds, "intrinsics 'depth_scale'")
    rate = _num(src, obj["fps"], "fps", positive=True) if obj.get("fps") is not None else None
    return CameraIntrinsics(fx, fy, cx, cy, size[0], size[1], ds, rate)


def _check_depth_scale(src: str, ds: float, field: str) -> None:
    if not (math.isfinite(ds) and 0 < ds <= 1):
        hint = f" ({ds:g} looks like Open3D's units per metre: use {1 / ds:g})" if ds > 1 else ""
        raise CaptureInputError(
            src,
            f"depth_scale is metres per depth unit, 0 < depth_scale <= 1, got {ds:g}{hint}",
            field=field,
        )


_AXES = ("y_up", "opencv")


def depth_to_points(
    depth: ArrayLike,
    intrinsics: CameraIntrinsics | Mapping[str, Any] | ArrayLike,
    *,
    depth_scale: float = 0.001,
    stride: int = 1,
    max_depth: float | None = None,
    min_depth: float = 0.0,
    roi: tuple[int, int, int, int] | None = None,
    axes: str = "y_up",
) -> NDArray[np.float64]:
    """Back-project a depth image through a pinhole camera (module docstring for conventions).

    Parameters
    ----------
    depth : (H, W) array_like of unsigned int or float
        Depth along the optical axis (not the ray length) in depth units; 0 or
        NaN = no measurement.
    intrinsics : CameraIntrinsics, mapping, (fx, fy, cx, cy) or (3, 3)
        Pinhole intrinsics in pixels (see :func:`read_intrinsics`).
    depth_scale : float
        Metres per depth unit (0.001: millimetres, as Kinect / RealSense PNGs).
    stride : int
        Use every ``stride``-th pixel in both directions (rows and columns
        0, stride, 2 stride, ...).
    max_depth, min_depth : float
        Keep points with ``min_depth < z <= max_depth`` metres (``max_depth``
        None: no limit).
    roi : (u0, v0, u1, v1), optional
        Keep pixels with ``u0 <= u < u1`` and ``v0 <= v < v1`` (e.g. the face box).
    axes : {"y_up", "opencv"}
        "y_up": +x right, +y up, +z toward the camera (the workbench's frame);
        "opencv": +x right, +y down, +z forward.

    Returns
    -------
    (p, 3) float64
        Points in metres, in row-major pixel order (row by row, left to right).

    Raises
    ------
    ValueError
        ``depth`` not 2-D or not numeric, negative depth, bad intrinsics,
        ``depth_scale``, ``stride``, ``roi`` or ``axes``.

    Examples
    --------
    >>> d = np.full((2, 2), 1000, np.uint16)              # a wall 1 m away
    >>> depth_to_points(d, (100.0, 100.0, 0.5, 0.5), axes="opencv")
    array([[-0.005, -0.005,  1.   ],
           [ 0.005, -0.005,  1.   ],
           [-0.005,  0.005,  1.   ],
           [ 0.005,  0.005,  1.   ]])
    """
    K = read_intrinsics(intrinsics)
    D = np.asarray(depth)
    if D.ndim != 2:
        raise ValueError(f"depth: expected an (H, W) image, got shape {D.shape}")
    if D.dtype.kind not in "uif" or D.dtype == np.bool_:
        raise ValueError(f"depth: expected unsigned integers or floats, got dtype {D.dtype}")
    _check_depth_scale("<depth>", float(depth_scale), "depth_scale")
    if axes not in _AXES:
        raise ValueError(f"axes: expected one of {_AXES}, got {axes!r}")
    if int(stride) != stride or stride < 1:
        raise ValueError(f"stride: expected a whole number >= 1, got {stride!r}")
    H, W = D.shape
    box = (0, 0, W, H) if roi is None else tuple(int(x) for x in roi)
    if len(box) != 4:
        raise ValueError(f"roi: expected (u0, v0, u1, v1), got {roi!r}")
    u0, v0, u1, v1 = box
    if not (0 <= u0 < u1 <= W and 0 <= v0 < v1 <= H):
        raise ValueError(f"roi: expected 0 <= u0 < u1 <= {W} and 0 <= v0 < v1 <= {H}, got {roi}")
    s = int(stride)
    sub = D[v0:v1:s, u0:u1:s].astype(np.float64)
    if D.dtype.kind in "if":
        neg = np.nan_to_num(sub, nan=0.0) < 0
        if neg.any():
            r, c = (int(x) for x in np.argwhere(neg)[0])
            raise ValueError(
                f"depth: negative value {sub[r, c]:g} at row {v0 + r * s}, column {u0 + c * s}"
            )
        if np.isinf(sub).any():
            r, c = (int(x) for x in np.argwhere(np.isinf(sub))[0])
            raise ValueError(f"depth: infinite value at row {v0 + r * s}, column {u0 + c * s}")
    z = sub * float(depth_scale)
    ok = np.isfinite(z) & (z > max(float(min_depth), 0.0))
    if max_depth is not None:
        ok &= z <= float(max_depth)
    vv, uu = np.nonzero(ok)
    zz = z[vv, uu]
    u = (u0 + uu * s).astype(np.float64)
    v = (v0 + vv * s).astype(np.float64)
    x = (u - K.cx) * zz / K.fx
    y = (v - K.cy) * zz / K.fy
    if axes == "y_up":
        return np.column_stack([x, -y, -zz])
    return np.column_stack([x, y, zz])


def _read_depth_png(f: Path, t: int) -> NDArray[np.uint16]:
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - pillow is in the ui extra
        raise ImportError(
            "reading depth PNGs needs Pillow: pip install pillow (or the workbench's [ui] extra)"
        ) from None
    try:
        with Image.open(f) as im:
            im.load()
            mode = im.mode
            fmt = im.format
            a = np.asarray(im)
    except Exception as exc:  # PIL raises UnidentifiedImageError, OSError, SyntaxError ...
        raise CaptureInputError(
            str(f), f"cannot read the image: {exc}", frame=t, field="file"
        ) from None
    if fmt != "PNG":
        raise CaptureInputError(str(f), f"expected a PNG, got {fmt}", frame=t, field="file")
    if mode in ("I;16", "I;16B", "I;16L"):
        return np.asarray(a, np.uint16)
    if (
        mode == "I" and a.size and a.min() >= 0 and a.max() <= 65535
    ):  # older Pillow opens 16-bit grey as I
        return a.astype(np.uint16)
    raise CaptureInputError(
        str(f),
        f"expected a 16-bit single-channel (grayscale) depth PNG, got mode {mode!r}"
        f"{' (8-bit: depth would be quantised to 256 levels)' if mode == 'L' else ''}",
        frame=t,
        field="image mode",
    )


def read_depth_frames(
    folder: str | Path,
    intrinsics: str | Path | Mapping[str, Any] | ArrayLike | CameraIntrinsics,
    *,
    depth_scale: float | None = None,
    stride: int = 1,
    max_depth: float | None = None,
    min_depth: float = 0.0,
    roi: tuple[int, int, int, int] | None = None,
    axes: str = "y_up",
    fps: float | None = None,
    allow_empty: bool = False,
    check_units: bool = True,
) -> PointCloudSequence:
    """A folder of 16-bit depth PNGs (sorted naturally) → point clouds in metres.

    Parameters
    ----------
    folder : str or Path
        Folder of ``.png`` depth images, one per frame, all the same size.
    intrinsics : str, Path, mapping, (fx, fy, cx, cy), (3, 3) or CameraIntrinsics
        See :func:`read_intrinsics` (a JSON file path is typical).
    depth_scale : float, optional
        Metres per depth unit; wins over the intrinsics' ``depth_scale``;
        0.001 (millimetres) when neither gives it.
    stride, max_depth, min_depth, roi, axes
        As :func:`depth_to_points`.
    fps : float, optional
        Frames per second; wins over the intrinsics' ``fps`` (else 30, warned).
    allow_empty : bool
        Accept frames with no valid depth (flagged by ``.empty``).
    check_units : bool
        Refuse frames whose median depth is not 2 cm – 50 m (a wrong
        ``depth_scale``), naming the frame.

    Returns
    -------
    PointCloudSequence
        ``units`` is "mm" for ``depth_scale=0.001`` (the unit of the depth
        values: "m" for 1, "cm" for 0.01, ...; "m" for any other scale).

    Raises
    ------
    FileNotFoundError
        No such folder.
    CaptureInputError
        Naming the file, the frame and what is wrong: not a 16-bit
        single-channel PNG, a size other than the intrinsics' or the first
        frame's, an empty frame, an implausible depth.
    """
    p = Path(folder)
    src = str(p)
    if not p.is_dir():
        raise FileNotFoundError(f"{p}: no such folder")
    K = read_intrinsics(intrinsics)
    ds = (
        depth_scale
        if depth_scale is not None
        else (K.depth_scale if K.depth_scale is not None else 0.001)
    )
    _check_depth_scale(src, float(ds), "depth_scale")
    if axes not in _AXES:
        raise ValueError(f"axes: expected one of {_AXES}, got {axes!r}")
    files = sorted(
        (f for f in p.iterdir() if f.is_file() and f.suffix.lower() == ".png"),
        key=lambda f: _natural_key(f.name),
    )
    if not files:
        raise CaptureInputError(src, "the folder has no .png files", field="folder")
    frames = []
    size: tuple[int, int] | None = None
    lo, hi = DEPTH_RANGE
    for t, f in enumerate(files):
        D = _read_depth_png(f, t)
        H, W = D.shape
        if (K.width is not None and W != K.width) or (K.height is not None and H != K.height):
            raise CaptureInputError(
                str(f),
                f"the image is {W}x{H} pixels, the intrinsics are for {K.width}x{K.height}",
                frame=t,
                field="image size",
            )
        if size is not None and (H, W) != size:
            raise CaptureInputError(
                str(f),
                f"the image is {W}x{H} pixels, frame 0 ({files[0].name}) is {size[1]}x{size[0]}",
                frame=t,
                field="image size",
            )
        size = (H, W)
        try:
            P = depth_to_points(
                D,
                K,
                depth_scale=float(ds),
                stride=stride,
                max_depth=max_depth,
                min_depth=min_depth,
                roi=roi,
                axes=axes,
            )
        except ValueError as exc:
            raise CaptureInputError(str(f), str(exc), frame=t, field="depth") from None
        if P.shape[0] == 0 and not allow_empty:
            raise CaptureInputError(
                str(f),
                "no pixel has a valid depth (pass allow_empty=True to keep such frames, flagged)",
                frame=t,
                field="depth",
            )
        if check_units and P.shape[0]:
            med = float(np.median(np.abs(P[:, 2])))
            if not lo <= med <= hi:
                raw = med / float(ds)
                raise CaptureInputError(
                    str(f),
                    f"median depth {med:.4g} m with depth_scale={float(ds):g} ({raw:.4g} depth units), not "
                    f"{lo:g}-{hi:g} m: is depth_scale right? (0.001 for millimetre depth; or check_units=False)",
                    frame=t,
                    field="depth_scale",
                )
        frames.append(P)
    unit = next((u for u, m in UNIT_TO_METRES.items() if math.isclose(m, float(ds))), "m")
    rate = fps if fps is not None else K.fps
    if rate is None:
        log.warning("%s: no frame rate given; %g fps assumed (pass fps=)", p.name, DEFAULT_FPS)
        rate = DEFAULT_FPS
    if not (math.isfinite(rate) and rate > 0):
        raise CaptureInputError(src, f"fps must be > 0, got {rate!r}", field="fps")
    return PointCloudSequence(
        tuple(frames), float(rate), unit, None, tuple(f.name for f in files), src
    )
