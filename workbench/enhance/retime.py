"""Data-driven retiming of a key pair (Bermano et al. 2014, §6: temporal performance enhancement).

An animator keys two poses ``start`` and ``end``; linear or ease-in/out
in-betweens look mechanical. :func:`retime` finds the part of a captured
performance that moves from (near) ``start`` to (near) ``end`` and gives the
in-betweens that part's timing, keeping the keys themselves (the artist's
poses) untouched.

The matching — eq. 5–6's sequence projection, the key pair's placement and
the progress curve of §6.2 — is :mod:`workbench.enhance.projection`.

**Point caches on a rig** (§6's matching in a compressed space). Given the
rig's shapes (``basis``: a :class:`~workbench.enhance.rig_space.RigBasis`, or
``(deltas, neutral)``), mesh takes and keys are first projected onto the rig's
weights (bounded least squares, one factorisation for all frames,
:mod:`workbench.enhance.rig_space`) and the matching — eq. 5–6, §6.2 and
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

from workbench.enhance.projection import (
    at_time,
    extend_span,
    match_pair,
    progress_curve,
    segment_tables,
)
from workbench.enhance.rig_space import RigBasis
from workbench.enhance.transitions import transition_timing

__all__ = ["RetimeResult", "retime"]

_EPS = 1e-12
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
    for i, (T, E) in enumerate(segment_tables(keys, m_seqs)):
        m = match_pair(T, E, scale)
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
        err = float(np.linalg.norm(m_s - at_time(beta, tau0)) + np.linalg.norm(m_e - at_time(beta, tau1)))
        if extend:
            tau0, tau1 = extend_span(beta, tau0, tau1)
        matched = (i, int(np.floor(tau0)), min(int(np.ceil(tau1)), beta.shape[0] - 1))
        span = (float(tau0), float(tau1))
        if method == "closest" or (method == "auto" and err <= CLOSE_MATCH * scale):
            s, times = progress_curve(beta, tau0, tau1, n)
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
