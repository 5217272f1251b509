"""Timing of a key pair from the take's own transitions, when no captured moment matches the keys.

§6 of Bermano et al. 2014 times the in-betweens of two keys by the one place in
a captured performance that moves from (near) the start key to (near) the end
key (:func:`workbench.enhance.retime`, ``method="closest"``). On real takes such
a place rarely exists: an actor seldom passes through both keys of another
transition, expressions co-articulate and stop short, and the closest chord then
times the in-betweens *worse* than straight interpolation (measured on a phone
take, and on :func:`workbench.testing.takes.realistic_weights`). What a take
still holds is how this actor moves: how long transitions take and how their
progress unfolds over time, and that differs between an *onset* (the face moving
away from its rest) and a *release* (back towards it).

:func:`take_transitions` cuts each database sequence into its monotone
transitions (runs of the distance from the take's rest, the 5th percentile of
every number, smoothed over 3 frames, that change by more than a share of the
keyed motion; each run's ends moved back from the holds the smoothing reaches into). :func:`transition_timing` blends the time-normalised progress
curves of all of them (progress along each transition's own chord, resampled to
``n_frames``) with weights that favour

* transitions whose ends are near the keys (a Gaussian of the eq. 5 distance of
  the keys to the transition's ends, its width the median of those distances, so
  that when nothing is near every transition counts alike),
* a similar length (``exp(−2 |log(L / n_frames)|)``),
* the same kind of motion: an onset for an onset, a release for a release
  (others count a fifth).

The result is non-decreasing from exactly 0 to 1 (each curve clipped to
``[0, 1]``, then a running maximum), so the in-betweens stay on the keys'
chord as §6.2's do. The weights and the number of transitions are reported.

Measured (``benchmarks/bench_retime_realistic.py``, held-out transitions of
realistic takes): timing RMSE about 0.7× straight in-betweens, where the single
closest match is about 1.1–1.3×.

Why hand-written: segmenting a take into monotone runs and averaging
time-normalised curves is a few lines of numpy; DTW packages (``tslearn``'s
barycentres, ``dtaidistance``) align whole sequences frame to frame and are not
kept here (see :mod:`workbench.enhance.retime`).

Shapes: ``database`` — sequences of ``(T_i, d)`` float (weights, or flattened
vertices); ``start``, ``end`` — ``(d,)``; results ``(n_frames,)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["TransitionTiming", "take_transitions", "transition_timing"]

#: a transition moves by more than this share of the keyed motion |end − start| (chosen on realistic
#: takes: 0.25 left too few transitions in an 11 s take, 0.03–0.1 time alike)
MIN_CHANGE = 0.1
#: weight of a transition of the other kind (an onset timing a release, or the reverse)
OTHER_KIND = 0.2
#: sharpness of the length kernel exp(−LENGTH · |log(L / n_frames)|)
LENGTH = 2.0


@dataclass(frozen=True)
class TransitionTiming:
    """A progress curve blended from a take's transitions.

    Attributes
    ----------
    s : (n_frames,) float
        Non-decreasing progress, ``s[0] = 0``, ``s[-1] = 1``.
    sources : tuple of (int, int, int, float)
        ``(sequence, first, last, weight)`` for every transition used, weights summing to 1.
    """

    s: NDArray[np.float64]
    sources: tuple[tuple[int, int, int, float], ...]


def take_transitions(seq: NDArray[np.float64], rest: NDArray[np.float64], min_change: float) -> list[tuple[int, int]]:
    """Monotone runs ``(first, last)`` of a sequence's distance from ``rest`` that change by more than ``min_change``.

    Parameters
    ----------
    seq : (T, d) float
    rest : (d,) float
        The take's rest (e.g. the 5th percentile of every number).
    min_change : float
        In the units of ``seq``.
    """
    T = seq.shape[0]
    if T < 4:
        return []
    raw = np.linalg.norm(seq - rest, axis=1)
    mag = np.convolve(np.pad(raw, 1, mode="edge"), np.ones(3) / 3.0, mode="valid")
    step = np.sign(np.diff(mag))
    runs: list[tuple[int, int]] = []
    a = 0
    for f in range(1, step.size + 1):
        if f == step.size or step[f] != step[a]:
            if abs(mag[f] - mag[a]) > min_change:
                runs.append(_unsmoothed(raw, a, f))
            a = f
    return runs


def _unsmoothed(raw: NDArray[np.float64], a: int, f: int) -> tuple[int, int]:
    """The run ``a → f`` of the smoothed distance, its ends moved to the raw distance's extremes nearby.

    The 3-frame smoothing starts a run up to a frame early and ends it a frame late (into the holds
    around it); the raw distance's last minimum near the start and first maximum near the end (for a
    rising run; the reverse for a falling one) are where the face starts and stops.
    """
    if f - a < 4:
        return a, f
    sign = 1.0 if raw[f] >= raw[a] else -1.0
    r = sign * raw
    lo = np.arange(a, min(a + 2, f - 2) + 1)
    first = int(lo[np.flatnonzero(r[lo] <= r[lo].min())[-1]])
    hi = np.arange(max(f - 2, first + 2), f + 1)
    last = int(hi[np.flatnonzero(r[hi] >= r[hi].max())[0]])
    return first, last


def _curve(frames: NDArray[np.float64], n: int) -> NDArray[np.float64] | None:
    """Progress of ``frames`` along their own chord, resampled to ``n`` uniform times, clipped to [0, 1]."""
    d = frames[-1] - frames[0]
    dd = float(d @ d)
    if dd <= 0.0:
        return None
    p = (frames - frames[0]) @ d / dd
    return np.clip(np.interp(np.linspace(0.0, 1.0, n), np.linspace(0.0, 1.0, frames.shape[0]), p), 0.0, 1.0)


def transition_timing(
    database: Sequence[NDArray[np.float64]], start: NDArray[np.float64], end: NDArray[np.float64], n_frames: int
) -> TransitionTiming | None:
    """Blend the progress curves of the database's transitions for the keys ``start`` → ``end`` (module docstring).

    Parameters
    ----------
    database : sequence of (T_i, d) float
    start, end : (d,) float
        Different from each other.
    n_frames : int
        ``≥ 2``.

    Returns
    -------
    TransitionTiming or None
        None when the database holds no transition of at least ``MIN_CHANGE`` of the keyed motion.
    """
    scale = float(np.linalg.norm(end - start))
    rest = np.percentile(np.concatenate(list(database)), 5, axis=0)

    def kind(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
        return float(np.sign(np.linalg.norm(b - rest) - np.linalg.norm(a - rest)))

    keyed = kind(start, end)
    found: list[tuple[int, int, int]] = []
    curves: list[NDArray[np.float64]] = []
    errors: list[float] = []
    prior: list[float] = []
    for i, seq in enumerate(database):
        for a, b in take_transitions(seq, rest, MIN_CHANGE * scale):
            c = _curve(seq[a : b + 1], int(n_frames))
            if c is None:
                continue
            found.append((i, a, b))
            curves.append(c)
            errors.append(float(np.linalg.norm(seq[a] - start) + np.linalg.norm(seq[b] - end)))
            same = kind(seq[a], seq[b]) == keyed
            length = np.exp(-LENGTH * abs(np.log((b - a + 1) / float(n_frames))))
            prior.append(float(length) * (1.0 if same else OTHER_KIND))
    if not curves:
        return None
    err = np.asarray(errors)
    width = max(float(np.median(err)), 1e-12 * scale, 1e-300)
    w = np.exp(-0.5 * (err / width) ** 2) * np.asarray(prior)
    if not w.sum() > 0.0:  # every transition far (the Gaussian underflows): the prior alone
        w = np.asarray(prior)
    w = w / w.sum()
    s = np.maximum.accumulate(np.clip(w @ np.asarray(curves), 0.0, 1.0))
    s[0], s[-1] = 0.0, 1.0
    sources = tuple((i, a, b, float(x)) for (i, a, b), x in zip(found, w, strict=True) if x > 0.0)
    return TransitionTiming(s=s, sources=sources)
