"""Markers and landmarks → :class:`~workbench.io.markers.MarkerSequence`.

:func:`read_markers` picks the reader by suffix:

* ``.c3d`` — :func:`workbench.io.c3d.read_markers` (ezc3d, after a checked walk
  of the file's structure); ``POINT:UNITS`` gives the unit, a residual < 0 or
  a NaN coordinate a gap.
* ``.csv`` / ``.txt`` — :func:`~workbench.capture.inputs.marker_csv.read_marker_csv`
  (the flat and the Vicon Nexus "Trajectories" layouts, described in
  :mod:`workbench.capture.inputs.marker_csv`).
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
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.inputs.errors import CaptureInputError
from workbench.capture.inputs.marker_csv import read_marker_csv
from workbench.capture.inputs.npz import _npz_array, _npz_scalar, _open_npz
from workbench.capture.inputs.units import (
    DEFAULT_FPS,
    _check_span,
    _frame_spans,
    _resolve_unit,
)
from workbench.io.markers import MarkerSequence

__all__ = ["MarkerSequence", "as_marker_sequence", "read_markers"]

log = logging.getLogger("workbench.capture")


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
