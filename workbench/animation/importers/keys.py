"""From sampled weights to keys: time checks, frame-rate estimate, key reduction, the timeline.

Sampled rows become one linear key per frame; ``tolerance`` > 0 removes keys
that linear interpolation of the kept ones reproduces within ``tolerance``
(Ramer–Douglas–Peucker on each weight curve, vertical error), so the result
differs from every input sample by at most ``tolerance``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.animation.curves import Key, Track, weight_track_name
from workbench.animation.importers.errors import AnimationImportError
from workbench.animation.tracks import Timeline

__all__ = ["reduce_keys", "reduce_keys_jointly", "timeline_from_samples"]


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


def reduce_keys_jointly(times: ArrayLike, values: ArrayLike, tolerances: ArrayLike) -> NDArray[np.intp]:
    """Samples to keep so every column of ``values`` stays within its tolerance (a vector track's keys).

    Parameters
    ----------
    times : (F,) float
    values : (F, c) float
    tolerances : float or (c,) float
        Per column (one number: all columns).

    Returns
    -------
    (K,) int
        The union of :func:`reduce_keys` over the columns, sorted.
    """
    V = np.asarray(values, np.float64)
    V = V.reshape(V.shape[0], -1)
    tol = np.broadcast_to(np.asarray(tolerances, np.float64), (V.shape[1],))
    keep = np.zeros(V.shape[0], bool)
    for c in range(V.shape[1]):
        keep[reduce_keys(times, V[:, c], float(tol[c]))] = True
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


def _check_times(times: NDArray[np.float64], labels: Sequence[str], src: str) -> None:
    bad = np.flatnonzero(np.diff(times) <= 0)
    if bad.size:
        i = int(bad[0])
        raise AnimationImportError(
            src,
            f"{labels[i + 1]}: time {times[i + 1]:.6g} s does not come after {labels[i]} "
            f"({times[i]:.6g} s); times must be strictly increasing",
        )


def _estimate_fps(times: NDArray[np.float64]) -> float:
    if times.size < 2:
        return 30.0
    dt = float(np.median(np.diff(times)))
    return round(1.0 / dt, 3) if dt > 0 else 30.0
