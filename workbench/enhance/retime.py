"""Data-driven retiming of a key pair (Bermano et al. 2014, §6: temporal performance enhancement).

An animator keys two poses ``start`` and ``end``; linear or ease-in/out
in-betweens look mechanical. :func:`retime` finds the part of a captured
performance that moves from (near) ``start`` to (near) ``end`` and gives the
in-betweens that part's timing, keeping the keys themselves (the artist's
poses) untouched.

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

**Point caches on a rig** (§6's matching in a compressed space). Given the
rig's shapes (``basis``: a :class:`~workbench.enhance.rig_space.RigBasis`, or
``(deltas, neutral)``), mesh takes and keys are first projected onto the rig's
weights (bounded least squares, one factorisation for all frames,
:mod:`workbench.enhance.rig_space`) and everything above — eq. 5–6, §6.2 and
the take's transitions — runs on those weights (``space="weights"``, the
default when a basis is given). The timing found there drives the mesh keys'
in-betweens exactly as mesh-space matching does: ``start + s (end − start)`` in
vertices. In raw vertices a take's rest (a low percentile of every coordinate)
means nothing, since vertices move both ways, and distances are dominated by the
jaw, so the take is cut into the wrong transitions: on held-out transitions of
realistic point caches (``benchmarks/bench_retime_realistic.py``) mesh-space
timing is about 0.94× straight in-betweens, rig weights about 0.84×.

Differences from the paper. Matching uses the raw vectors (weights, the
rig's weights of point caches, or the flattened ``(n, 3)`` vertices), not the
compressed per-region shape space of §4 (that is :class:`PerformanceDatabase`'s
job), and the whole face is one region. The paper's *extend to the full matched sequence* (``extend=True``)
is not specified further in the paper; here the span grows while the take
keeps moving along the matched chord (strictly), i.e. to the rest before and
the extreme after, stopping at holds and reversals.

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

Shapes: ``database`` — a sequence of ``(T_i, k)`` weight sequences or
``(T_i, n, 3)`` mesh sequences; ``start``, ``end`` — ``(k,)`` or ``(n, 3)``;
``basis`` — ``(k', n, 3)`` deltas and an ``(n, 3)`` neutral; results
``(n_frames,)`` and ``(n_frames, k)`` / ``(n_frames, n, 3)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.enhance.rig_space import RigBasis
from workbench.enhance.transitions import transition_timing

__all__ = ["RetimeResult", "project_segments", "retime", "sequence_projection"]

_EPS = 1e-12
# placements of the keys whose errors differ by less than _TIE · (error + |end − start|) + _RES · |end − start|
# are ties (holds, a take passing the end pose twice). _RES is the resolution of eq. 5's distances near 0
# (from an inner-product expansion: √ε of the scale); larger values would trim real, if slow, motion
_TIE = 1e-9
_RES = 1e-7
_CHORD_BUDGET = 4_000_000  # entries of the (chord samples, segments) tables of §6.2
#: method="auto" keeps the closest match when its eq. 6 error is within this share of |end − start|
#: (the same transition, up to noise); realistic takes' closest matches sit at 0.25–1.0 of it
CLOSE_MATCH = 0.15
METHODS = ("auto", "closest", "take")
SPACES = ("auto", "mesh", "weights")


@dataclass(frozen=True)
class RetimeResult:
    """Retimed in-betweens of a key pair.

    Attributes
    ----------
    s : (n_frames,) float
        Progress along start→end, non-decreasing, ``s[0] = 0``, ``s[-1] = 1``.
    frames : (n_frames, k) or (n_frames, n, 3) float
        ``start + s (end − start)``; ``frames[0]`` is ``start``, ``frames[-1]`` is ``end``.
    matched : tuple of int
        ``(sequence, first, last)``: index into ``database`` and the frames
        ``first ≤ τ0``, ``last ≥ τ1`` that cover the matched sub-sequence.
    error : float
        The eq. 6 objective of the match: distance of ``start`` plus distance
        of ``end`` to the matched points of the database sequence.
    span : tuple of float
        ``(τ0, τ1)``: continuous times (in frames of the matched sequence)
        where ``start`` and ``end`` project.
    times : (n_frames,) float
        The uniform times between ``τ0`` and ``τ1`` at which ``s`` is sampled.
    choice : str
        Where ``s`` comes from: ``"match"`` (the closest match, §6.2), ``"take"``
        (blended from the take's transitions, :mod:`workbench.enhance.transitions`)
        or ``"ease"`` (smoothstep: the database has no transition to learn from).
        ``matched``, ``error``, ``span`` and ``times`` always describe the closest
        match (``(-1, -1, -1)``, ``inf``, NaN when none moves forward in time).
    sources : tuple of (int, int, int, float)
        For ``"take"``: ``(sequence, first, last, weight)`` of every transition blended.
    space : {"weights", "mesh", "rig"}
        What was matched: weight takes as given, point caches as vertices, or
        point caches projected onto the rig's weights (``basis``); ``error`` is
        in those units.
    fit_rms : float
        For ``"rig"``: RMS distance of the rig's fit from the point caches' and
        keys' vertices (:meth:`~workbench.enhance.rig_space.RigBasis.fit`; near 0
        when the rig made them); NaN otherwise.
    """

    s: NDArray[np.float64]
    frames: NDArray[np.float64]
    matched: tuple[int, int, int]
    error: float
    span: tuple[float, float]
    times: NDArray[np.float64]
    choice: str = "match"
    sources: tuple[tuple[int, int, int, float], ...] = ()
    space: str = "weights"
    fit_rms: float = float("nan")

    def describe(self) -> str:
        """Where the timing came from, in words (for a status line)."""
        where = {"rig": f", matched in the rig's weights (fit RMS {self.fit_rms:.3g})",
                 "mesh": ", matched in mesh space"}.get(self.space, "")
        if self.choice == "match":
            i, first, last = self.matched
            return f"the timing of take {i}, frames {first}–{last} (match error {self.error:.3g}){where}"
        if self.choice == "take":
            takes = sorted({src[0] for src in self.sources})
            return f"the timing of {len(self.sources)} transitions of {len(takes)} take(s) blended{where}"
        return "an ease curve (the takes hold no transition to learn from)"


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


def _as_frames(x: ArrayLike, name: str) -> NDArray[np.float64]:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array: {exc}") from None
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf")
    return a


def _validate(
    database: Sequence[ArrayLike], start: ArrayLike, end: ArrayLike, n_frames: int
) -> tuple[list[NDArray[np.float64]], NDArray[np.float64], NDArray[np.float64], tuple[int, ...]]:
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)):
        raise ValueError(f"n_frames must be an integer, got {n_frames!r}")
    if n_frames < 2:
        raise ValueError(f"n_frames must be at least 2 (the two keys), got {n_frames}")
    s = _as_frames(start, "start")
    e = _as_frames(end, "end")
    if s.ndim == 1:
        pass
    elif s.ndim == 2 and s.shape[1] == 3:
        pass
    else:
        raise ValueError(f"start must be (k,) weights or (n, 3) vertices, got shape {s.shape}")
    if e.shape != s.shape:
        raise ValueError(f"end must have the shape of start {s.shape}, got {e.shape}")
    if s.size == 0:
        raise ValueError("start is empty")
    if isinstance(database, np.ndarray) and database.ndim == s.ndim + 1:
        database = [database]  # one sequence passed as an array, not as a list of one
    try:
        n_seq = len(database)
    except TypeError:
        raise ValueError(f"database must be a sequence of (T_i, ...) arrays, got {type(database).__name__}") from None
    if n_seq == 0:
        raise ValueError("database is empty: give at least one sequence")
    seqs = []
    for i, seq in enumerate(database):
        a = _as_frames(seq, f"database[{i}]")
        if a.ndim != s.ndim + 1 or a.shape[1:] != s.shape:
            raise ValueError(
                f"database[{i}] must be (T, {', '.join(map(str, s.shape))}) to match start, got shape {a.shape}"
            )
        if a.shape[0] < 2:
            raise ValueError(f"database[{i}] needs at least 2 frames, got {a.shape[0]}")
        seqs.append(a.reshape(a.shape[0], -1))
    if np.allclose(s, e, rtol=0.0, atol=_EPS):
        raise ValueError("end equals start: there is no transition to retime")
    return seqs, s.reshape(-1), e.reshape(-1), s.shape


def _segment_tables(
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


def _match_pair(T: NDArray[np.float64], E: NDArray[np.float64], scale: float) -> tuple[float, float, float] | None:
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


def _at(beta: NDArray[np.float64], tau: float) -> NDArray[np.float64]:
    j = min(int(np.floor(tau)), beta.shape[0] - 2)
    f = tau - j
    return (1.0 - f) * beta[j] + f * beta[j + 1]


def _progress_curve(beta: NDArray[np.float64], tau0: float, tau1: float, n_frames: int) -> tuple[NDArray, NDArray]:
    """§6.2: time stamps of the uniform chord ``β(τ0) → β(τ1)`` on the sub-sequence, resampled uniformly."""
    inner = np.arange(int(np.floor(tau0)) + 1, int(np.ceil(tau1)))
    node_t = np.concatenate([[tau0], inner.astype(np.float64), [tau1]])
    sub = np.vstack([_at(beta, tau0)[None], beta[inner], _at(beta, tau1)[None]])
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


def _extend(beta: NDArray[np.float64], tau0: float, tau1: float) -> tuple[float, float]:
    """§6.2's *extend*: grow ``[τ0, τ1]`` while the take keeps moving along its own chord.

    Progress is measured along ``β(τ0) → β(τ1)``; the span grows backwards while
    the earlier frame has strictly less progress, forwards while the later frame
    has strictly more — to the rest pose before and the extreme after, stopping
    at holds and reversals.
    """
    b0 = _at(beta, tau0)
    d = _at(beta, tau1) - b0
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


def _rig_basis(basis: RigBasis | tuple[ArrayLike, ArrayLike] | None, space: str,
               shape: tuple[int, ...]) -> RigBasis | None:
    """The basis to match point caches in, or None to match the raw vectors; checks ``basis`` against the keys."""
    if basis is not None and not isinstance(basis, RigBasis):
        try:
            deltas, neutral = basis
        except (TypeError, ValueError):
            raise ValueError(f"basis must be a RigBasis or a (deltas, neutral) pair, got {type(basis).__name__}") from None
        try:
            basis = RigBasis(deltas, neutral)
        except ValueError as exc:
            raise ValueError(f"basis: {exc}") from None
    if len(shape) == 1:  # weight takes: already the rig's space
        if basis is not None or space == "mesh":
            raise ValueError("basis/space apply to point caches ((n, 3) keys); start and end are (k,) weights")
        return None
    if space == "mesh":
        return None
    if basis is None:
        if space == "weights":
            raise ValueError('basis: space="weights" needs the rig\'s shapes (a RigBasis or (deltas, neutral))')
        return None
    if basis.neutral.shape != shape:
        raise ValueError(f"basis is on a mesh of {basis.n_vertices} vertices; start, end and the database are "
                         f"{shape[0]} vertices a frame")
    return basis


def retime(
    database: Sequence[ArrayLike], start: ArrayLike, end: ArrayLike, n_frames: int, *, extend: bool = False,
    method: str = "auto", basis: RigBasis | tuple[ArrayLike, ArrayLike] | None = None, space: str = "auto",
) -> RetimeResult:
    """Retime the in-betweens of a key pair after the closest database transition (§6).

    Parameters
    ----------
    database : sequence of (T_i, k) or (T_i, n, 3) array_like
        Captured performances (weights or vertices), ``T_i ≥ 2``; all must
        have the shape of ``start`` per frame. One ``(T, ...)`` array is taken
        as a one-sequence database.
    start, end : (k,) or (n, 3) array_like
        The two keys; different from each other.
    n_frames : int
        Length of the result including both keys, ``≥ 2``.
    extend : bool, default False
        The paper's *extend to the full matched sequence* (§6.2, Fig. 7): grow
        the matched sub-sequence backwards and forwards while the take keeps
        moving along it (to its rest and its extreme), and time the keys by
        the whole motion. Without it a key that lands on a slow tail (an
        ease-out the actor barely finishes) cuts the motion short.
    method : {"auto", "closest", "take"}
        ``"closest"``: the paper's single closest match. ``"take"``: the take's
        transitions blended (:func:`workbench.enhance.transitions.transition_timing`),
        which times real takes better than the closest chord when no transition
        of the take passes near both keys. ``"auto"`` (default): the closest
        match when its error is within ``CLOSE_MATCH`` (15 %) of ``|end − start|``,
        else the take's transitions; ``RetimeResult.choice`` says which.
    basis : RigBasis or (deltas, neutral), optional
        For point caches: the rig's shapes, ``(k', n, 3)`` deltas on the keys'
        mesh and its ``(n, 3)`` neutral (a pair is bounded to ``[0, 1]``; a
        :class:`~workbench.enhance.rig_space.RigBasis`, e.g.
        ``RigBasis.from_model(model)``, carries the sliders' ranges). Takes and
        keys are projected onto its weights and matched there (module docstring).
    space : {"auto", "mesh", "weights"}
        Where point caches are matched: ``"weights"`` — the rig's weights
        (needs ``basis``); ``"mesh"`` — the raw vertices (the behaviour without
        a basis); ``"auto"`` (default) — the rig's weights when ``basis`` is
        given (falling back to vertices when the keys' projections coincide),
        else vertices. ``RetimeResult.space`` says which. Weight takes are
        matched as they are.

    Returns
    -------
    RetimeResult
        ``s`` (n_frames,), ``frames`` (n_frames, k) or (n_frames, n, 3),
        ``matched`` ``(sequence, first, last)``, ``error``, ``span``, ``times``.

    Raises
    ------
    ValueError
        Naming the argument: empty ``database``, a sequence of the wrong shape
        or with < 2 frames, NaN/inf anywhere, ``start``/``end`` shapes that
        differ, ``end == start``, ``n_frames < 2``, an unknown ``method`` or
        ``space``, a ``basis`` on another mesh than the keys (or given with
        weight keys), ``space="weights"`` without a ``basis`` or with keys whose
        projections coincide; or, for ``method="closest"``, no database sequence
        moves forward in time from the start's projection to the end's.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if space not in SPACES:
        raise ValueError(f"space must be one of {SPACES}, got {space!r}")
    seqs, s_vec, e_vec, shape = _validate(database, start, end, n_frames)
    rig = _rig_basis(basis, space, shape)
    where, fit_rms = ("weights" if len(shape) == 1 else "mesh"), float("nan")
    # the vectors matched: the inputs, or their rig weights (the in-betweens are always the inputs' keys)
    m_seqs, m_s, m_e = seqs, s_vec, e_vec
    if rig is not None:
        m_keys, rms = rig.fit(np.vstack([s_vec, e_vec]).reshape(2, *shape), name="start and end")
        sq = 2 * rms * rms  # squared misfit summed over frames (per vertex), for fit_rms
        if np.linalg.norm(m_keys[1] - m_keys[0]) > _EPS:
            m_seqs = []
            for i, x in enumerate(seqs):
                w, r = rig.fit(x.reshape(x.shape[0], *shape), name=f"database[{i}]")
                m_seqs.append(w)
                sq += r * r * x.shape[0]
            m_s, m_e = m_keys[0], m_keys[1]
            where = "rig"
            fit_rms = float(np.sqrt(sq / (2 + sum(x.shape[0] for x in seqs))))
        elif space == "weights":
            raise ValueError("end: its projection onto the rig's weights equals start's (the keys differ only where "
                             'the shapes do not reach); match in mesh space (space="mesh")')
    keys = np.vstack([m_s, m_e])
    scale = float(np.linalg.norm(m_e - m_s))
    best: tuple[float, int, float, float] | None = None
    for i, (T, E) in enumerate(_segment_tables(keys, m_seqs)):
        m = _match_pair(T, E, scale)
        if m is not None and (best is None or m[0] < best[0]):
            best = (m[0], i, m[1], m[2])
    if best is None and method == "closest":
        raise ValueError("database: no sequence moves from start towards end (every match is backwards in time)")
    n = int(n_frames)
    matched, err, span, times = (-1, -1, -1), float("inf"), (float("nan"), float("nan")), np.full(n, np.nan)
    s: NDArray[np.float64] | None = None
    choice = "match"
    sources: tuple[tuple[int, int, int, float], ...] = ()
    if best is not None:
        _, i, tau0, tau1 = best
        beta = m_seqs[i]
        # the reported error exactly (eq. 5's inner-product expansion is only used to choose)
        err = float(np.linalg.norm(m_s - _at(beta, tau0)) + np.linalg.norm(m_e - _at(beta, tau1)))
        if extend:
            tau0, tau1 = _extend(beta, tau0, tau1)
        matched = (i, int(np.floor(tau0)), min(int(np.ceil(tau1)), beta.shape[0] - 1))
        span = (float(tau0), float(tau1))
        if method == "closest" or (method == "auto" and err <= CLOSE_MATCH * scale):
            s, times = _progress_curve(beta, tau0, tau1, n)
        else:
            times = np.linspace(tau0, tau1, n)  # what §6.2 would have sampled; its curve is not needed
    if s is None:
        blended = transition_timing(m_seqs, m_s, m_e, n)
        if blended is not None:
            s, choice, sources = blended.s, "take", blended.sources
        else:
            u = np.linspace(0.0, 1.0, n)
            s, choice, sources = u * u * (3.0 - 2.0 * u), "ease", ()
    frames = s_vec[None, :] + s[:, None] * (e_vec - s_vec)[None, :]
    frames[0], frames[-1] = s_vec, e_vec
    return RetimeResult(
        s=s,
        frames=frames.reshape((n, *shape)),
        matched=matched,
        error=err,
        span=span,
        times=times,
        choice=choice,
        sources=sources,
        space=where,
        fit_rms=fit_rms,
    )
