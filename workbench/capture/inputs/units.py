"""Units of capture inputs: the unit a file is in, whether its data are face-sized, a model's unit.

Every reader returns **metres**, with the unit the data were in recorded
(``.units``). The unit of a file: ``units=`` wins, else the one the file
states; a file that states none is an error (a unit taken wrongly makes every
distance wrong by a factor of 10–1000). With ``check_units=True`` data whose
spread (the longest bounding-box side of a frame, median over frames) is
outside :data:`MARKER_SPAN` are refused with the unit that would make them
face-sized. The frame rate: ``fps=`` wins, else the file's, else
:data:`DEFAULT_FPS` with a warning. :func:`to_model_units` converts what a
reader returned to a model's unit (``model.metadata.units``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.inputs.clouds import PointCloudSequence
from workbench.capture.inputs.errors import CaptureInputError
from workbench.core.shapes import UNIT_TO_METRES
from workbench.io.markers import MarkerSequence
from workbench.io.units import unit_name

__all__ = ["DEFAULT_FPS", "MARKER_SPAN", "metres_per_unit", "to_model_units"]

log = logging.getLogger("workbench.capture")

#: (smallest, largest) plausible spread in metres of a capture (markers, landmarks, a
#: point cloud): the longest bounding-box side of one frame, median over frames
MARKER_SPAN: tuple[float, float] = (0.01, 10.0)
#: frames per second assumed (with a warning) when neither the caller nor the file gives a rate
DEFAULT_FPS = 30.0


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
