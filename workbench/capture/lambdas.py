"""The tracker's λ's chosen by the take itself: held-out markers on a few stretches of the take.

Why: the sparsity prior ``l1`` and the temporal prior ``temporal`` of
:func:`workbench.capture.track` (Bouaziz et al. 2013, eq. 3: ``λ₂ E_sparse`` and
``λ₁ E_smooth``) suit some takes and hurt others. A clean generated take has a few
shapes active at a time and L1 helps; a real phone take has ~33 of 52 shapes active
at once and a rest pose that is not zero, and the same L1 shrinks every weight (the
weight error doubles). No single pair of numbers wins on both, so the take decides.

How (K-fold cross-validation over markers): on up to three stretches of the take
(:data:`STRETCHES` × :data:`STRETCH_FRAMES` frames, spread over it), the head pose
of each frame is found once (the tracker's own alternation, at mild λ's); the
markers that move with the expression are split into :data:`FOLDS` folds; for a
``(l1, temporal)`` pair and every fold, the stretches are tracked online
(warm-started, with the temporal term, by the solver's own kernel, exactly as the
tracker does) on the other markers, and the held-out markers' squared distance to
the tracked face is summed. The pairs tried: a coordinate search over the grids
:data:`L1_GRID` and :data:`TEMPORAL_GRID` (0 and the old defaults among them),
started at the paper's values — ``λ₁ = 10`` (smooth), ``λ₂ = 20`` (sparse), read
as weights on a fit term in mm² summed over the markers' coordinates
(:func:`paper_lambdas`), converted into the tracker's relative units and added to
both grids: the best ``l1`` at the paper's ``temporal``, then the best ``temporal``
at that ``l1``, then ``l1`` again. The pair with the least held-out error wins.
Rigid markers (forehead, nose bridge) are never held out: they carry no
expression and fix the pose.

Cost: ``folds × pairs × frames`` one-frame solves (3 × ≤ 17 × ≤ 75 ≈ 3.8k), under
a second on a shared 2-core machine for any take length.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench._numba import njit
from workbench.capture.pose import PoseError, fit_rigid_robust
from workbench.capture.solver import NUMBA, _prediction, _shoot_nb, _shoot_py

if TYPE_CHECKING:
    from workbench.capture.track import MarkerSetup

__all__ = ["FOLDS", "L1_GRID", "PAPER_SMOOTH", "PAPER_SPARSE", "STRETCHES", "STRETCH_FRAMES", "TEMPORAL_GRID",
           "LambdaChoice", "choose_lambdas", "paper_lambdas"]

#: Bouaziz et al. 2013, §4: λ₁ (E_smooth) and λ₂ (E_sparse), on a fit term in mm² (see :func:`paper_lambdas`)
PAPER_SMOOTH = 10.0
PAPER_SPARSE = 20.0
#: relative sparsity λ's tried (the paper's value is added)
L1_GRID = (0.0, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2)
#: relative temporal λ's tried (the paper's value is added)
TEMPORAL_GRID = (0.03, 0.1, 0.25, 1.0)
#: folds of the moving markers
FOLDS = 3
#: stretches of the take and their length (frames)
STRETCHES = 3
STRETCH_FRAMES = 25


@dataclass(frozen=True)
class LambdaChoice:
    """What :func:`choose_lambdas` tried and chose.

    Attributes
    ----------
    l1, temporal : float
        The chosen relative λ's.
    paper : (float, float)
        The paper's ``(l1, temporal)`` in the tracker's relative units for this take.
    grid : tuple of (float, float, float)
        Every ``(l1, temporal, held-out RMS error)`` tried; the error is per held-out marker, model units.
    heldout : float
        The chosen pair's held-out RMS marker error (model units).
    frames : int
        Frames of the take the choice was made on.
    folds : int
    seconds : float
        Time the choice took.
    """

    l1: float
    temporal: float
    paper: tuple[float, float]
    grid: tuple[tuple[float, float, float], ...]
    heldout: float
    frames: int
    folds: int
    seconds: float

    def as_info(self) -> dict[str, Any]:
        """A plain dict for :attr:`TrackResult.info` (``info["lambda_choice"]``)."""
        return {"l1": self.l1, "temporal": self.temporal, "paper": self.paper, "grid": self.grid,
                "heldout": self.heldout, "frames": self.frames, "folds": self.folds, "seconds": self.seconds}


def paper_lambdas(setup: MarkerSetup, metres_per_unit: float) -> tuple[float, float]:
    """The paper's ``(λ₂ sparse, λ₁ smooth) = (20, 10)`` in the tracker's relative units for these markers.

    The paper adds them to ``E_fit`` in its own units; read here as a fit term in mm²
    summed over every marker coordinate. The tracker's fit term is that divided by
    ``(1000 · metres_per_unit · head_size)² · m`` and its λ's are relative to ``ref``
    (an average shape's squared motion per marker in head sizes²), so
    ``λ_relative = λ_paper / ((1000 · mpu · size)² · m · ref)``.
    """
    m = max(setup.fit_weight(), 1e-300)  # the markers' total weight (their count when unweighted)
    mm = 1000.0 * float(metres_per_unit) * float(setup.space.size)
    denom = mm * mm * m * float(setup.ref)
    if not (math.isfinite(denom) and denom > 0):
        return 0.0, 0.0
    return PAPER_SPARSE / denom, PAPER_SMOOTH / denom


def _heldout(G_tr, h_tr, G_ho, h_ho, cc_ho, start, l1h, t_abs, lo, hi, tol, L, d, idx):  # pragma: no cover
    """Track every frame online on the training markers; the summed held-out squared error.

    Per frame ``f``: ``G_tr[f], h_tr[f]`` the training normal equations, ``G_ho[f], h_ho[f],
    cc_ho[f]`` the held-out markers' (so their error is ``wᵀG w − 2hᵀw + cc``); ``start[f]``
    begins a stretch (no previous frames). ``l1h`` is half the absolute L1 per weight, ``t_abs``
    the absolute temporal λ. The solver's own kernel, so the weights are the tracker's.
    """
    n, k = h_tr.shape
    w = np.zeros(k)
    wp = np.zeros(k)
    wp2 = np.zeros(k)
    n_prev = 0
    err = 0.0
    Q = np.empty((k, k))
    b = np.empty(k)
    g = np.empty(k)
    for f in range(n):
        if start[f]:
            for j in range(k):
                w[j] = 0.0
            n_prev = 0
        for i in range(k):
            b[i] = h_tr[f, i]
            for j in range(k):
                Q[i, j] = G_tr[f, i, j]
        if t_abs > 0.0 and n_prev > 0:
            for j in range(k):
                Q[j, j] += t_abs
                p = 2.0 * wp[j] - wp2[j] if n_prev > 1 else wp[j]
                b[j] += t_abs * p
        for j in range(k):
            if w[j] < lo[j]:
                w[j] = lo[j]
            elif w[j] > hi[j]:
                w[j] = hi[j]
        for i in range(k):
            acc = -b[i]
            for j in range(k):
                acc += Q[i, j] * w[j]
            g[i] = acc
        _shoot_nb(Q, b, l1h, lo, hi, w, g, 500, tol, True, L, d, idx)
        e = cc_ho[f]
        for i in range(k):
            acc = 0.0
            for j in range(k):
                acc += G_ho[f, i, j] * w[j]
            e += w[i] * acc - 2.0 * h_ho[f, i] * w[i]
        err += e
        for j in range(k):
            wp2[j] = wp[j]
            wp[j] = w[j]
        n_prev += 1
    return err


_heldout_nb = njit(cache=True, nogil=True)(_heldout) if NUMBA else _heldout


def _stretches(good: NDArray[np.bool_]) -> list[NDArray[np.intp]]:
    """Up to :data:`STRETCHES` runs of :data:`STRETCH_FRAMES` solvable frames spread over the take."""
    idx = np.flatnonzero(good)
    n = idx.size
    if n <= STRETCHES * STRETCH_FRAMES:
        return [idx]
    starts = np.linspace(0, n - STRETCH_FRAMES, STRETCHES).round().astype(int)
    return [idx[s : s + STRETCH_FRAMES] for s in starts]


def _gram_across(setup: MarkerSetup, sel: NDArray[np.bool_], d: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """The markers ``sel``'s Gram across the frame's depth direction ``d`` (all three coordinates when None)."""
    G = setup.gram(sel)
    return G if d is None else G - setup.depth_gram(sel, d)


def choose_lambdas(setup: MarkerSetup, Y: NDArray[np.float64], visible: NDArray[np.bool_],
                   good: NDArray[np.bool_], *, metres_per_unit: float = 1.0, fix_l1: float | None = None,
                   fix_temporal: float | None = None, iterations: int = 2) -> LambdaChoice:
    """Choose ``(l1, temporal)`` by held-out markers (the module docstring); ``fix_*`` keep one of them given.

    ``setup`` is the tracker's per-take set-up, ``Y (T, m, 3)`` the markers, ``visible (T, m)``
    and ``good (T,)`` as in :func:`~workbench.capture.track.track_markers`.
    """
    t_start = time.perf_counter()
    space = setup.space
    kp = space.plain.size
    paper = paper_lambdas(setup, metres_per_unit)
    l1s = sorted(set(L1_GRID) | {paper[0]}) if fix_l1 is None else [float(fix_l1)]
    temps = sorted(set(TEMPORAL_GRID) | {paper[1]}) if fix_temporal is None else [float(fix_temporal)]
    lo, hi = np.asarray(space.lo, np.float64), np.asarray(space.hi, np.float64)
    kernel = _shoot_nb if NUMBA else _shoot_py
    ref = setup.ref
    tol = 1e-6 * math.sqrt(ref)
    L, d, ix = np.empty((kp, kp)), np.empty(kp), np.empty(kp, np.int64)
    m = setup.ids.size

    def solve(G: NDArray[np.float64], h: NDArray[np.float64], l1: float, temporal: float,
              wp: NDArray[np.float64] | None, wp2: NDArray[np.float64] | None, w0: NDArray[np.float64]
              ) -> NDArray[np.float64]:
        Q = np.array(G, order="C")
        b = h.copy()
        if temporal > 0 and wp is not None:
            t = temporal * ref
            Q[np.diag_indices(kp)] += t
            b += t * _prediction(wp, wp2)
        w = np.clip(w0, lo, hi)
        g = Q @ w - b
        kernel(Q, b, np.full(kp, 0.5 * l1 * ref), lo, hi, w, g, 500, tol, True, L, d, ix)
        return w

    # 1. each stretch frame's markers in the model frame, posed as the tracker does (reference λ's)
    l1_ref = paper[0] if fix_l1 is None else float(fix_l1)
    t_ref = paper[1] if fix_temporal is None else float(fix_temporal)
    l1_ref, t_ref = min(l1_ref, 3e-3), min(max(t_ref, 0.03), 0.25)  # a mild start when the paper's are extreme
    # per stretch, each frame's (visible markers, their offsets across the depth, the depth direction or None)
    runs: list[list[tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64] | None]]] = []
    for frames in _stretches(good):
        w = np.zeros(kp)
        wp = wp2 = None
        run = []
        for f in frames:
            vis = visible[f]
            nv = int(vis.sum())
            sw = setup.fit_weight(vis)
            G0 = setup.gram(vis)
            Dv = setup.Dh[vis].reshape(-1, kp)
            rig = vis & setup.is_rigid
            M = np.eye(4)
            c = np.zeros((nv, 3))
            depth = None
            for _it in range(int(iterations)):
                wf = space.full_weights(w)
                X = setup.marker_positions(w, wf)
                sel = rig if rig.sum() >= 3 else vis
                try:
                    M = fit_rigid_robust(X[sel], Y[f, sel], max_iter=10, tol=1e-6).matrix
                except PoseError:
                    pass
                c = (Y[f, vis] - M[:3, 3]) @ M[:3, :3] - setup.X0[vis]
                if space.derived:
                    c = c - setup.derived_offset(wf, vis)
                depth = setup.depth_in_rig(M[:3, :3])  # fitted across the camera's axis, as the tracker does
                G = G0 if depth is None else G0 - setup.depth_gram(vis, depth)
                c = setup.across(c, depth)
                w = solve(G * (setup.norm / sw), Dv.T @ c.reshape(-1) * (setup.norm / sw), l1_ref, t_ref, wp, wp2, w)
            wp2, wp = wp, w.copy()
            full = np.full((m, 3), np.nan)
            full[vis] = c
            run.append((vis, full, depth))
        runs.append(run)

    # 2. folds of the markers that move with the expression
    moving = np.flatnonzero(~setup.is_rigid)
    if moving.size < 2 * FOLDS:
        moving = np.arange(m)
    rng = np.random.default_rng(0)
    fold_of = np.full(m, -1)
    fold_of[rng.permutation(moving)] = np.arange(moving.size) % FOLDS
    n_folds = min(FOLDS, moving.size)

    # 3. per fold, the training and held-out normal equations of every stretch frame
    frames_all = [(vis, c, depth) for run in runs for vis, c, depth in run]
    starts = np.zeros(len(frames_all), bool)
    pos = 0
    for run in runs:
        starts[pos] = True
        pos += len(run)
    nf = len(frames_all)
    Dm = setup.Dh  # (m, 3, kp), weighted rows
    sm = setup.marker_weights
    folds = []
    count = 0.0
    for fo in range(n_folds):
        held = fold_of == fo
        G_tr = np.zeros((nf, kp, kp))
        h_tr = np.zeros((nf, kp))
        G_ho = np.zeros((nf, kp, kp))
        h_ho = np.zeros((nf, kp))
        cc_ho = np.zeros(nf)
        for i, (vis, c, depth) in enumerate(frames_all):
            tr = vis & ~held
            ho = vis & held
            if int(tr.sum()) < 3:  # too few markers to fit this frame on: it is tracked on all, and not scored
                tr, ho = vis, np.zeros_like(vis)
            str_ = float(sm[tr].sum())
            G_tr[i] = _gram_across(setup, tr, depth) * (setup.norm / str_)
            h_tr[i] = np.einsum("mck,mc->k", Dm[tr], c[tr]) * (setup.norm / str_)
            G_ho[i] = _gram_across(setup, ho, depth)
            h_ho[i] = np.einsum("mck,mc->k", Dm[ho], c[ho])
            cc_ho[i] = float((sm[ho] * (c[ho] ** 2).sum(1)).sum())
            count += float(sm[ho].sum())
        folds.append((G_tr, h_tr, G_ho, h_ho, cc_ho))

    scored: dict[tuple[float, float], float] = {}

    def score(l1: float, temporal: float) -> float:
        """Held-out RMS marker error (model units; weighted by the markers' weights) of one λ pair, over every fold."""
        key = (float(l1), float(temporal))
        if key not in scored:
            l1h = np.full(kp, 0.5 * l1 * ref)
            total = sum(max(float(_heldout_nb(*fold, starts, l1h, temporal * ref, lo, hi, tol, L, d, ix)), 0.0)
                        for fold in folds)
            scored[key] = math.sqrt(total / max(count, 1e-300))
        return scored[key]

    # coordinate search from the paper's values: the l1 line, the temporal line, the l1 line again
    best = (paper[0] if fix_l1 is None else l1s[0], paper[1] if fix_temporal is None else temps[0])
    for line in ("l1", "temporal", "l1"):
        if line == "l1":
            best = min(((a, best[1]) for a in l1s), key=lambda p: score(*p))
        else:
            best = min(((best[0], t) for t in temps), key=lambda p: score(*p))
    grid = tuple((a, t, e) for (a, t), e in sorted(scored.items()))
    ia_l1, ib_t = best
    return LambdaChoice(float(ia_l1), float(ib_t), (float(paper[0]), float(paper[1])), grid, float(scored[best]),
                        int(sum(len(r) for r in runs)), int(n_folds), time.perf_counter() - t_start)
