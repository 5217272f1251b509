"""Sequence projection and the key pair's match (Bermano et al. 2014, §6.1–6.2), for :mod:`workbench.enhance.retime`.

**Sequence projection** (§6.1, eq. 5–6). An input sequence ``α`` of ``m``
frames is projected onto a database sequence ``β`` of ``n`` frames, treated as
a continuum sampled at its frames. Every input frame is projected onto every
segment ``{β_j, β_j+1}`` (eq. 5)::

    T[i, j] = clip(<α_i − β_j+1, β_j − β_j+1> / |β_j − β_j+1|², 0, 1)
    E[i, j] = |α_i − (T[i, j] β_j + (1 − T[i, j]) β_j+1)|

(``T`` is the blend weight of ``β_j``, so the projected point sits at time
``j + 1 − T[i, j]``), and a monotone assignment ``P`` of segments to input
frames minimises ``Σ_i E[i, P(i)]`` subject to ``P(i1) ≤ P(i2)`` for
``i1 < i2`` (eq. 6), by dynamic programming with a running prefix minimum:
``C[i, j] = E[i, j] + min_{j' ≤ j} C[i−1, j']`` — ``O(m · n)`` per sequence.
Every database sequence is tried; the one with the least error wins.

**Temporally driven interpolation** (§6.2). The key pair is projected as a
two-frame sequence; the paper's "valid mapping" means the end must land at a
*later* time than the start, so for this pair the constraint is applied
exactly (``P(0) < P(1)``, or the same segment with the end later in it). That
gives the matched sub-sequence ``[τ0, τ1]`` (continuous times). Among equally
good placements of the keys (holds, a take passing the end pose on the way
out and back) the tightest span wins. ``β̂``, the uniform interpolation of
the sub-sequence's ends ``β(τ0) → β(τ1)``, is projected onto the sub-sequence
(eq. 5–6 again), which time-stamps each ``β̂_i``: progress ``i / (N − 1)`` is
reached at time ``τ̂_i``. The paper samples ``β̂`` ``N = n_frames`` times;
here ``N`` is at least 4 per frame of the span (capped at ~4M table
entries), so that a small ``n_frames`` does not flatten the take's slow ends
— the piecewise-linear inverse is only as fine as this sampling. Read the
other way round the stamps are a piecewise-linear progress curve over the
sub-sequence's time; resampled at ``n_frames`` uniform times between ``τ0``
and ``τ1`` it is ``s``, and the in-betweens are ``start + s (end − start)``:
only the artist's keys, with the actor's timing. For meshes the paper's
result is likewise "composed solely of the artistically generated
keyframes" — the matched frames' shape off the start→end line is not added.

The direct match is sensitive where the take barely moves: a key whose pose
is a little off (the held-out tests use noise 0.01) lands early on a slow
ease-out tail and cuts the motion short (Fig. 7's cyan curve); ``extend=True``
times the keys by the whole motion (Fig. 7's purple).

``s`` is non-decreasing from exactly 0 to exactly 1 (time stamps are made
monotone by a running maximum; within one segment the DP does not order
them). A consequence, as in the paper: overshoot (the actor passing the end
pose and settling back) is not reproduced — the in-betweens never leave the
start→end segment.

Why hand-written: no kept library implements this projection. DTW libraries
(``dtw-python``, ``tslearn``, ``dtaidistance`` — none installed here) align
frame to frame with many-to-many warping and a fixed start/end; eq. 5–6
projects onto *segments* (continuous time), allows an open start and end
inside the database sequence, and assigns each input frame exactly one
segment. Eq. 5 is three inner products per batch of takes (``|β_j|²``,
``<β_j, β_j+1>``, ``<α_i, β_j>``, centred on the keys so the expansion does
not cancel far from the origin); the DP is a row-wise running minimum in numpy (``O(m · n)``, ``m`` = 2
for the match), so no numba kernel is needed; ``benchmarks/bench_retime.py``
measures it against a brute-force window search in the same run.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["project_segments", "sequence_projection"]

# placements of the keys whose errors differ by less than _TIE · (error + |end − start|) + _RES · |end − start|
# are ties (holds, a take passing the end pose twice). _RES is the resolution of eq. 5's distances near 0
# (from an inner-product expansion: √ε of the scale); larger values would trim real, if slow, motion
_TIE = 1e-9
_RES = 1e-7
_CHORD_BUDGET = 4_000_000  # entries of the (chord samples, segments) tables of §6.2


def project_segments(alpha: ArrayLike, beta: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Project every input frame onto every segment of a sequence (eq. 5).

    Parameters
    ----------
    alpha : (m, d) array_like
        Input frames.
    beta : (n, d) array_like
        Database sequence, ``n ≥ 2``.

    Returns
    -------
    T : (m, n - 1) ndarray
        Blend weight of ``β_j`` in the projection onto ``{β_j, β_j+1}``, in
        ``[0, 1]``; the projected point is at time ``j + 1 − T``.
    E : (m, n - 1) ndarray
        Distance of ``α_i`` from its projection.
    """
    a = np.asarray(alpha, dtype=np.float64)
    b = np.asarray(beta, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise ValueError(f"alpha (m, d) and beta (n, d) must share d, got {a.shape} and {b.shape}")
    if b.shape[0] < 2:
        raise ValueError(f"beta needs at least 2 frames (one segment), got {b.shape[0]}")
    # centred on the input, so the inner-product expansion below does not cancel far from the origin
    c = a.mean(axis=0)
    a = a - c
    b = b - c
    # everything from three inner products — |β_j|², <β_j, β_j+1>, <α_i, β_j> — so the database is read
    # three times and never differenced into a copy (a 10k-frame mesh take is memory-bound)
    g = np.einsum("jd,jd->j", b, b)
    cj = np.einsum("jd,jd->j", b[:-1], b[1:])
    p = a @ b.T  # (m, n)
    an = np.einsum("id,id->i", a, a)
    dd = g[:-1] - 2.0 * cj + g[1:]  # |β_j − β_j+1|²
    r2 = an[:, None] - 2.0 * p[:, 1:] + g[None, 1:]  # |α_i − β_j+1|²
    rd = p[:, :-1] - p[:, 1:] - (cj - g[1:])[None, :]  # <α_i − β_j+1, β_j − β_j+1>
    # a hold (β_j = β_j+1) is dd = 0 up to rounding of g: relative threshold; its t is irrelevant (0)
    moving = dd > 1e-12 * (g[:-1] + g[1:]) + 1e-300
    dd = np.where(moving, dd, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(moving, rd / np.where(moving, dd, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    e2 = r2 - 2.0 * t * rd + t * t * dd[None, :]
    E = np.sqrt(np.maximum(e2, 0.0))
    return t, E


def sequence_projection(alpha: ArrayLike, beta: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.float64], float]:
    """Project a sequence onto another: the monotone segment assignment of eq. 6.

    Parameters
    ----------
    alpha : (m, d) array_like
        Input sequence.
    beta : (n, d) array_like
        Database sequence, ``n ≥ 2``.

    Returns
    -------
    P : (m,) ndarray of int
        Segment of each input frame, non-decreasing, in ``[0, n - 2]``.
    times : (m,) ndarray
        Continuous time of each projection, ``P + 1 − T[i, P]`` (not
        necessarily monotone within one segment).
    error : float
        ``Σ_i E[i, P(i)]``, the minimum of eq. 6.
    """
    T, E = project_segments(alpha, beta)
    m, J = E.shape
    back = np.empty((m, J), dtype=np.intp)
    cost = E[0].copy()
    idx = np.arange(J)
    for i in range(1, m):
        run = np.minimum.accumulate(cost)
        # index of the last place the running minimum was attained: the argmin of the prefix
        back[i] = np.maximum.accumulate(np.where(cost <= run, idx, 0))
        cost = E[i] + run
    P = np.empty(m, dtype=np.intp)
    P[-1] = int(np.argmin(cost))
    for i in range(m - 1, 0, -1):
        P[i - 1] = back[i, P[i]]
    rows = np.arange(m)
    times = P + 1.0 - T[rows, P]
    return P, times, float(cost[P[-1]])


def segment_tables(
    keys: NDArray[np.float64], seqs: list[NDArray[np.float64]], batch: int = 1 << 15
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Eq. 5 of the keys on every segment of every take, ``(T, E)`` per take.

    Short takes are concatenated into batches of about ``batch`` numbers (one
    numpy pass per batch instead of one per take; small enough, 256 kB, to stay
    in cache through the passes of :func:`project_segments`); segments that
    would join two takes are sliced away.
    """
    out = []
    i = 0
    while i < len(seqs):
        j, size = i + 1, seqs[i].size
        while j < len(seqs) and size + seqs[j].size <= batch:
            size += seqs[j].size
            j += 1
        group = seqs[i:j]
        T, E = project_segments(keys, group[0] if len(group) == 1 else np.concatenate(group))
        off = 0
        for g in group:
            n = g.shape[0]
            out.append((T[:, off : off + n - 1], E[:, off : off + n - 1]))
            off += n
        i = j
    return out


def match_pair(T: NDArray[np.float64], E: NDArray[np.float64], scale: float) -> tuple[float, float, float] | None:
    """Best ``(error, τ0, τ1)`` of the two keys on one take with ``τ1 > τ0``, or None.

    ``T``, ``E`` : (2, n - 1), eq. 5 of the keys on the take. Among
    (numerically) equal minima — holds, or a take that passes the end pose on
    the way out and on the way back — the tightest span wins: the latest start
    and the earliest end.
    """
    J = E.shape[1]
    t0 = 1.0 - T[0]  # offset inside the segment
    t1 = 1.0 - T[1]
    cands: list[tuple[int, int]] = []
    if J > 1:
        # the start on an earlier segment than the end: strict prefix minimum of the start's error
        run = np.minimum.accumulate(E[0][:-1])
        cost = E[1][1:] + run
        mn = float(cost.min())
        tol = _TIE * (mn + scale) + _RES * scale
        k = int(np.flatnonzero(cost <= mn + tol)[0])  # the earliest end
        j0 = int(np.flatnonzero(E[0][: k + 1] <= run[k] + tol)[-1])  # the latest start before it
        cands.append((j0, k + 1))
    # the start and the end on one segment, the end later in it
    same = np.where(t1 > t0 + 1e-9, E[0] + E[1], np.inf)
    k = int(np.argmin(same))
    if np.isfinite(same[k]):
        cands.append((k, k))
    best: tuple[float, float, float] | None = None
    for j0, j1 in cands:
        tau0, tau1 = j0 + float(t0[j0]), j1 + float(t1[j1])
        if tau1 <= tau0:  # the start at the very end of its segment, the end at the very start of the next
            continue
        err = float(E[0, j0] + E[1, j1])
        tol = _TIE * (err + scale) + _RES * scale
        if best is None or err < best[0] - tol or (err <= best[0] + tol and tau1 - tau0 < best[2] - best[1]):
            best = (err, tau0, tau1)
    return best


def at_time(beta: NDArray[np.float64], tau: float) -> NDArray[np.float64]:
    """The sequence ``beta`` (n, d) at continuous time ``tau`` (linear between frames)."""
    j = min(int(np.floor(tau)), beta.shape[0] - 2)
    f = tau - j
    return (1.0 - f) * beta[j] + f * beta[j + 1]


def progress_curve(beta: NDArray[np.float64], tau0: float, tau1: float, n_frames: int) -> tuple[NDArray, NDArray]:
    """§6.2: time stamps of the uniform chord ``β(τ0) → β(τ1)`` on the sub-sequence, resampled uniformly."""
    inner = np.arange(int(np.floor(tau0)) + 1, int(np.ceil(tau1)))
    node_t = np.concatenate([[tau0], inner.astype(np.float64), [tau1]])
    sub = np.vstack([at_time(beta, tau0)[None], beta[inner], at_time(beta, tau1)[None]])
    # the paper samples the chord n_frames times; sampled 4x per frame of the sub-sequence the
    # piecewise-linear inverse keeps the take's slow ends when n_frames is small (same curve otherwise).
    # The eq. 5 tables are (n_chord, segments): the oversampling is capped at ~4M entries.
    n_seg = sub.shape[0] - 1
    n_chord = max(n_frames, min(int(np.ceil(4.0 * (tau1 - tau0))) + 1, _CHORD_BUDGET // n_seg))
    u = np.linspace(0.0, 1.0, n_chord)
    chord = sub[0] + u[:, None] * (sub[-1] - sub[0])
    P, local, _ = sequence_projection(chord, sub)
    frac = local - P  # offset inside segment P
    stamps = node_t[P] + frac * (node_t[P + 1] - node_t[P])
    stamps[0], stamps[-1] = tau0, tau1
    stamps = np.clip(np.maximum.accumulate(stamps), tau0, tau1)
    times = np.linspace(tau0, tau1, n_frames)
    # ties (several chord samples stamped at one time: a jump in progress) → keep the order of the samples
    stamps_strict = stamps + np.arange(n_chord) * (1e-9 * (tau1 - tau0))
    s = np.interp(times, stamps_strict, u)
    s[0], s[-1] = 0.0, 1.0
    return np.maximum.accumulate(s), times


def extend_span(beta: NDArray[np.float64], tau0: float, tau1: float) -> tuple[float, float]:
    """§6.2's *extend*: grow ``[τ0, τ1]`` while the take keeps moving along its own chord.

    Progress is measured along ``β(τ0) → β(τ1)``; the span grows backwards while
    the earlier frame has strictly less progress, forwards while the later frame
    has strictly more — to the rest pose before and the extreme after, stopping
    at holds and reversals.
    """
    b0 = at_time(beta, tau0)
    d = at_time(beta, tau1) - b0
    p = (beta - b0) @ d / float(d @ d)
    p0, p1 = 0.0, 1.0
    j = int(np.floor(tau0))
    if p[j] < p0:
        while j > 0 and p[j - 1] < p[j]:
            j -= 1
        tau0 = float(j)
    j = min(int(np.ceil(tau1)), beta.shape[0] - 1)
    if p[j] > p1:
        while j < beta.shape[0] - 1 and p[j + 1] > p[j]:
            j += 1
        tau1 = float(j)
    return tau0, tau1
