"""The point clouds a take gives: checked, NaN rows dropped, and in the model's units."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.capture.result import CloudTrackError

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["UNITS_FACTOR", "check_clouds", "check_units"]

#: the cloud's extent must be within this factor of the face's, else it is in other units (a factor of 10
#: is caught; a cloud of head and shoulders, ~4x the face, is not mistaken for one)
UNITS_FACTOR = 6.0


def check_clouds(clouds: Any) -> list[NDArray[np.float64]]:
    """One (p_t, 3) float64 cloud per frame (finite rows only; empty clouds stay empty); raises on bad input."""
    if isinstance(clouds, np.ndarray):
        if clouds.ndim != 3 or clouds.shape[2] != 3:
            raise CloudTrackError(
                f"clouds must be a sequence of (p, 3) point clouds or a (T, p, 3) array, got shape {clouds.shape}")
        seq: Sequence[Any] = list(clouds)
    elif isinstance(clouds, Sequence) and not isinstance(clouds, str | bytes):
        seq = clouds
    else:
        raise CloudTrackError(f"clouds must be a sequence of (p, 3) point clouds, got {type(clouds).__name__}")
    if len(seq) == 0:
        raise CloudTrackError("clouds: the take has no frames")
    out = []
    for f, c in enumerate(seq):
        try:
            P = np.asarray(c, np.float64)
        except (TypeError, ValueError) as exc:
            raise CloudTrackError(f"clouds[{f}] is not an array of points: {exc}") from None
        if P.size == 0:
            out.append(np.zeros((0, 3)))
            continue
        if P.ndim != 2 or P.shape[1] != 3:
            raise CloudTrackError(f"clouds[{f}] must be (p, 3) points, got shape {P.shape}")
        if np.isinf(P).any():
            i = int(np.flatnonzero(np.isinf(P).any(1))[0])
            raise CloudTrackError(f"clouds[{f}][{i}] is infinite")
        out.append(P[np.isfinite(P).all(1)])
    return out


def check_units(clouds: list[NDArray[np.float64]], X: NDArray[np.float64], model: FaceState) -> None:
    """Raise when the clouds' spread is far from the face's (another unit)."""
    ref = float(np.sqrt(((X - X.mean(0)) ** 2).sum(1).mean()))
    ratios = []
    step = max(1, len(clouds) // 50)
    for P in clouds[::step]:
        if P.shape[0] < 10:
            continue
        med = np.median(P, axis=0)
        r = np.sqrt(((P - med) ** 2).sum(1))
        ratios.append(float(np.sqrt(np.mean(np.minimum(r, np.quantile(r, 0.9)) ** 2))) / ref)
    if not ratios or ref <= 0:
        return
    q = float(np.median(ratios))
    if not (1.0 / UNITS_FACTOR <= q <= UNITS_FACTOR):
        units = getattr(getattr(model, "metadata", None), "units", "") or "model units"
        raise CloudTrackError(
            f"clouds: the points spread {q:.3g}× as far as the model's face (the model is in {units}); "
            f"they look like another unit — scale them by about {1.0 / q:.3g}" if q > 0 else
            "clouds: all points coincide; they cannot be tracked")
