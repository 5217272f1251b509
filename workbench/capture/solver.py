"""Per-frame blendshape weights: bounded, sparse (L1) and temporally smooth (Bouaziz et al. 2013, §3.1).

One frame of tracking solves (eq. 2–3 of the paper, in this module's names)

    min_w  ||A w - c||²  +  l1 · Σ_j |w_j|  +  temporal · ||w - 2 w_prev + w_prev2||²
    s.t.   lo ≤ w ≤ hi

``A : (r, k)`` maps the ``k`` weights to ``r`` constraint rows (three per
visible marker), ``c : (r,)`` is the target. ``E_smooth`` is the second
difference of the weights over the last three frames, ``E_sparse`` the 1-norm;
with ``lo ≥ 0`` the 1-norm is the linear term ``l1 · Σ w_j``. Like the paper, the
minimiser is a **warm-started shooting method** (cyclic coordinate descent,
Fu 1998): each coordinate is minimised exactly (a soft threshold of its 1-D
quadratic) and projected onto ``[lo_j, hi_j]``; a sweep updates the gradient
``G w - h`` by one column per changed weight, so a sweep costs ``O(k²)`` and
never touches ``A``. Plain shooting converges only linearly, slowly on
correlated shapes (left/right pairs, jaw/mouth); so after each sweep the
weights that are free (inside their bounds, non-zero) take one Newton step of
the smooth problem on that set, cut at the first bound or sign change — an
active-set acceleration that never increases the objective and, once the
sweeps have found which weights are at a bound or 0, lands on the minimum.
Started from the previous frame's weights (the active set rarely changes
between frames) a frame then takes two or three sweeps. ``newton=False`` is
the paper's plain shooting (same minimum, more sweeps).

**Scale of the λ's.** With ``relative=True`` (the default) both penalties are
multiplied by ``s = ||A||_F² / k = trace(AᵀA) / k``, the squared norm of an
average column: a unit change of an average shape's weight costs ``s`` in the
fit term. The λ's are then unit-free (markers in mm or m, 10 or 100 of them,
give the same weights) and readable: for a shape of average size the
coordinate update is ``w_j = (ŵ_j + temporal · p_j − l1/2) / (1 + temporal)``
with ``ŵ_j`` the unregularised 1-D fit and ``p = 2 w_prev − w_prev2`` the
constant-velocity prediction; so ``l1 = 0.02`` shrinks each weight by 0.01
(and switches off those that would explain less), ``temporal = 1`` weighs
data and prediction equally. With ``relative=False`` the λ's multiply the
objective as written. :func:`workbench.capture.track` normalises the fit term
further (per visible marker, in units of the head size) and fixes ``s`` once
per take, so the balance does not move when markers are occluded.

Why hand-written: no kept library solves this bounded L1 + temporal QP
warm-started per frame at this rate. ``scipy.optimize.lsq_linear`` has bounds
but no L1 term and no warm start; a general QP solver (OSQP through
``qpsolvers``) handles the L1 term only through the linear term (``lo ≥ 0``)
and spends its time in set-up per frame; ``benchmarks/bench_capture.py``
measures both against this solver in the same run.

``numba`` is optional: without it the same loop runs in Python on numpy
arrays with identical arithmetic (and identical results), only slower.

Shapes: ``A : (r, k) float``, ``c : (r,) float``, ``G : (k, k) float``
(``AᵀA``), ``h : (k,) float`` (``Aᵀc``), weights ``(k,) float``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench._numba import NUMBA, njit

__all__ = ["NUMBA", "WeightSolver", "objective"]


def _shoot(Q, b, half_l1, lo, hi, w, g, max_iter, tol, newton, L, d, idx):  # pragma: no cover - compiled or looped
    """Cyclic coordinate descent ("shooting") in place, with active-set Newton steps; returns the sweeps.

    Minimises ``wᵀQw − 2bᵀw + 2·Σ half_l1_j |w_j|`` over the box. ``g = Q w − b`` on
    entry (kept up to date). After each sweep that moved, when ``newton``: the
    weights strictly inside their bounds and away from 0 (the free set) take the
    Newton step of the smooth problem on that set (a Cholesky solve of ``Q_FF``),
    cut where a weight would reach a bound or 0 — a convex quadratic decreases
    all along it, so the step never increases the objective; once the sweeps have
    found the active set, one step lands on the minimum and the next sweep
    confirms it. ``L (k, k)``, ``d (k,)``, ``idx (k,) int`` are scratch.
    Written with scalar loops so the Python fallback and the numba kernel do
    the same arithmetic in the same order.
    """
    k = w.shape[0]
    sweeps = 0
    for _sweep in range(max_iter):
        sweeps += 1
        change = 0.0
        for j in range(k):
            q = Q[j, j]
            wj = w[j]
            lam = half_l1[j]
            r = q * wj - g[j]  # b_j − Σ_{i≠j} Q_ji w_i
            if q > 0.0:
                if r > lam:
                    new = (r - lam) / q
                elif r < -lam:
                    new = (r + lam) / q
                else:
                    new = 0.0
            # a shape that moves no constraint and has no temporal term: the 1-D objective is linear
            elif r > lam:
                new = hi[j]
            elif r < -lam:
                new = lo[j]
            else:
                new = 0.0
            if new < lo[j]:
                new = lo[j]
            elif new > hi[j]:
                new = hi[j]
            dj = new - wj
            if dj != 0.0:
                w[j] = new
                for i in range(k):
                    g[i] += Q[i, j] * dj
                step = abs(dj) * np.sqrt(q) if q > 0.0 else abs(dj)
                if step > change:
                    change = step
        if change <= tol or not newton:
            if change <= tol:
                break
            continue
        # ---- Newton step on the free set
        nf = 0
        for j in range(k):
            if lo[j] < w[j] < hi[j] and w[j] != 0.0 and Q[j, j] > 0.0:
                idx[nf] = j
                nf += 1
        if nf == 0:
            continue
        ok = True
        for a in range(nf):  # Cholesky of Q_FF
            for c in range(a + 1):
                acc = Q[idx[a], idx[c]]
                for e in range(c):
                    acc -= L[a, e] * L[c, e]
                if a == c:
                    if acc <= 1e-12 * Q[idx[a], idx[a]]:
                        ok = False
                        break
                    L[a, a] = np.sqrt(acc)
                else:
                    L[a, c] = acc / L[c, c]
            if not ok:
                break
        if not ok:
            continue  # singular on the free set: the sweeps carry on alone
        for a in range(nf):  # L y = −(g_F + λ_F sign(w_F))
            j = idx[a]
            acc = -(g[j] + (half_l1[j] if w[j] > 0.0 else -half_l1[j]))
            for e in range(a):
                acc -= L[a, e] * d[e]
            d[a] = acc / L[a, a]
        for a in range(nf - 1, -1, -1):  # Lᵀ d = y
            acc = d[a]
            for e in range(a + 1, nf):
                acc -= L[e, a] * d[e]
            d[a] = acc / L[a, a]
        t = 1.0
        for a in range(nf):  # the longest step that keeps every weight in its box and its sign
            j = idx[a]
            if d[a] > 0.0:
                lim = hi[j]
                if w[j] < 0.0 and lim > 0.0:
                    lim = 0.0
                if (lim - w[j]) < t * d[a]:
                    t = (lim - w[j]) / d[a]
            elif d[a] < 0.0:
                lim = lo[j]
                if w[j] > 0.0 and lim < 0.0:
                    lim = 0.0
                if (lim - w[j]) > t * d[a]:
                    t = (lim - w[j]) / d[a]
        for a in range(nf):
            j = idx[a]
            step = t * d[a]
            if step != 0.0:
                w[j] += step
                if w[j] < lo[j]:
                    w[j] = lo[j]
                elif w[j] > hi[j]:
                    w[j] = hi[j]
                for i in range(k):
                    g[i] += Q[i, j] * step
    return sweeps


_shoot_py = _shoot
_shoot_nb = njit(cache=True, nogil=True)(_shoot) if NUMBA else _shoot


def _vector(value: ArrayLike | None, k: int, name: str) -> NDArray[np.float64] | None:
    if value is None:
        return None
    v = np.asarray(value, np.float64)
    if v.shape != (k,):
        raise ValueError(f"{name} must have shape ({k},), got {v.shape}")
    if not np.isfinite(v).all():
        raise ValueError(f"{name} has values that are not finite")
    return v


def objective(
    G: ArrayLike, h: ArrayLike, w: ArrayLike, *, l1: ArrayLike = 0.0, temporal: float = 0.0,
    w_prev: ArrayLike | None = None, w_prev2: ArrayLike | None = None, cc: float = 0.0,
) -> float:
    """The objective ``||Aw − c||² + l1·Σ|w| + temporal·||w − 2w_prev + w_prev2||²`` from the Gram form.

    ``G = AᵀA``, ``h = Aᵀc``, ``cc = cᵀc`` (the constant; 0 leaves it out). The λ's are
    absolute here (multiply by ``trace(G)/k`` for :class:`WeightSolver`'s relative ones).
    """
    G_ = np.asarray(G, np.float64)
    h_ = np.asarray(h, np.float64)
    w_ = np.asarray(w, np.float64)
    val = float(w_ @ G_ @ w_ - 2.0 * h_ @ w_ + cc + (np.asarray(l1, np.float64) * np.abs(w_)).sum())
    if temporal and w_prev is not None:
        p = _prediction(np.asarray(w_prev, np.float64),
                        None if w_prev2 is None else np.asarray(w_prev2, np.float64))
        val += float(temporal * np.sum((w_ - p) ** 2))
    return val


def _prediction(w_prev: NDArray[np.float64], w_prev2: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """``2 w_prev − w_prev2`` (constant velocity); with one previous frame, ``w_prev`` (constant)."""
    return w_prev.copy() if w_prev2 is None else 2.0 * w_prev - w_prev2


class WeightSolver:
    """Bounded, L1-sparse, temporally smooth per-frame weights by warm-started shooting (see the module).

    Parameters
    ----------
    lo, hi : float or (k,) float
        The box (the shapes' slider ranges; 0..1 by default). ``lo ≤ hi``.
    l1 : float or (k,) float
        Weight of ``Σ|w_j|`` (``E_sparse``); 0 gives the plain bounded least squares (the L2 variant).
        An array gives each weight its own penalty ``Σ l1_j |w_j|``.
    temporal : float
        Weight of ``||w − 2 w_prev + w_prev2||²`` (``E_smooth``); used when ``w_prev`` is given
        (with ``w_prev`` alone the prediction is ``w_prev``).
    relative : bool
        Scale both λ's by ``trace(AᵀA) / k`` (the module docstring: unit-free λ's). False: absolute.
    max_iter : int
        Most coordinate sweeps per frame.
    tol : float
        Stop when no weight moved by more than ``tol`` in a sweep (measured as ``|Δw_j|·||A_j||``,
        i.e. in the units of the residual, relative to the average column when ``relative``).
    newton : bool
        Accelerate the sweeps with active-set Newton steps (see ``_shoot``); False: the paper's plain
        shooting. Both converge to the same minimum.
    backend : {"auto", "numba", "numpy"}
        The numba kernel or the same loop in Python (identical results).

    Attributes
    ----------
    n_iter_ : int
        Sweeps used by the last solve.
    scale_ : float
        The multiplier applied to the λ's in the last solve (``trace(G)/k`` or 1).
    """

    def __init__(
        self,
        lo: ArrayLike = 0.0,
        hi: ArrayLike = 1.0,
        *,
        l1: ArrayLike = 0.0,
        temporal: float = 0.0,
        relative: bool = True,
        max_iter: int = 500,
        tol: float = 1e-7,
        newton: bool = True,
        backend: str = "auto",
    ) -> None:
        self.lo = lo
        self.hi = hi
        self.l1 = l1
        self.temporal = temporal
        self.relative = relative
        self.max_iter = max_iter
        self.tol = tol
        self.newton = newton
        self.backend = backend

    # ------------------------------------------------------------------ checks
    def _params(self, k: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]:
        lo = np.broadcast_to(np.asarray(self.lo, np.float64), (k,)).copy() if np.ndim(self.lo) == 0 \
            else np.asarray(self.lo, np.float64)
        hi = np.broadcast_to(np.asarray(self.hi, np.float64), (k,)).copy() if np.ndim(self.hi) == 0 \
            else np.asarray(self.hi, np.float64)
        if lo.shape != (k,):
            raise ValueError(f"lo must be a float or have shape ({k},), got {lo.shape}")
        if hi.shape != (k,):
            raise ValueError(f"hi must be a float or have shape ({k},), got {hi.shape}")
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise ValueError("lo and hi must be finite")
        if (lo > hi).any():
            j = int(np.flatnonzero(lo > hi)[0])
            raise ValueError(f"lo must be ≤ hi; weight {j} has lo={lo[j]} > hi={hi[j]}")
        l1 = np.asarray(self.l1, np.float64)
        if l1.ndim == 0:
            l1 = np.full(k, float(l1))
        temporal = float(self.temporal)
        if l1.shape != (k,):
            raise ValueError(f"l1 must be a number or have shape ({k},), got shape {l1.shape}")
        if not (np.isfinite(l1).all() and (l1 >= 0).all()):
            raise ValueError(f"l1 must be finite and ≥ 0, got {self.l1!r}")
        if not (np.isfinite(temporal) and temporal >= 0):
            raise ValueError(f"temporal must be a finite number ≥ 0, got {self.temporal!r}")
        if int(self.max_iter) < 1:
            raise ValueError(f"max_iter must be ≥ 1, got {self.max_iter!r}")
        if not (float(self.tol) >= 0):
            raise ValueError(f"tol must be ≥ 0, got {self.tol!r}")
        if self.backend not in ("auto", "numba", "numpy"):
            raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {self.backend!r}")
        if self.backend == "numba" and not NUMBA:
            raise ValueError("backend='numba': numba is not installed")
        return lo, hi, l1, temporal

    # ------------------------------------------------------------------ solving
    def solve(
        self,
        A: ArrayLike,
        c: ArrayLike,
        w_prev: ArrayLike | None = None,
        w_prev2: ArrayLike | None = None,
        w0: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """The weights of one frame.

        Parameters
        ----------
        A : (r, k) float
            Constraint rows (e.g. the shapes' displacements at the visible markers, posed).
        c : (r,) float
            Targets (marker minus neutral, in the same frame).
        w_prev, w_prev2 : (k,) float, optional
            The previous two frames' weights (temporal term; ``w_prev2`` may be missing).
        w0 : (k,) float, optional
            The warm start (default ``w_prev``, else ``lo`` clipped 0). Projected onto the box.

        Returns
        -------
        w : (k,) float
        """
        A_ = np.asarray(A, np.float64)
        c_ = np.asarray(c, np.float64)
        if A_.ndim != 2:
            raise ValueError(f"A must be (r, k), got shape {A_.shape}")
        if c_.shape != (A_.shape[0],):
            raise ValueError(f"c must have shape ({A_.shape[0]},) to match A {A_.shape}, got {c_.shape}")
        if not (np.isfinite(A_).all() and np.isfinite(c_).all()):
            raise ValueError("A and c must be finite (drop the rows of occluded markers first)")
        return self.solve_gram(A_.T @ A_, A_.T @ c_, w_prev, w_prev2, w0)

    def solve_gram(
        self,
        G: ArrayLike,
        h: ArrayLike,
        w_prev: ArrayLike | None = None,
        w_prev2: ArrayLike | None = None,
        w0: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """:meth:`solve` from the normal equations: ``G = AᵀA : (k, k)``, ``h = Aᵀc : (k,)``.

        Returns
        -------
        w : (k,) float
        """
        G_ = np.asarray(G, np.float64)
        if G_.ndim != 2 or G_.shape[0] != G_.shape[1]:
            raise ValueError(f"G must be square (k, k), got shape {G_.shape}")
        k = G_.shape[0]
        h_ = _vector(h, k, "h")
        assert h_ is not None
        if not np.isfinite(G_).all():
            raise ValueError("G must be finite")
        lo, hi, l1, temporal = self._params(k)
        wp = _vector(w_prev, k, "w_prev")
        wp2 = _vector(w_prev2, k, "w_prev2")
        if wp2 is not None and wp is None:
            raise ValueError("w_prev2 needs w_prev")
        start = _vector(w0, k, "w0")

        scale = float(np.trace(G_)) / k if (self.relative and k) else 1.0
        if not scale > 0:
            scale = 1.0
        self.scale_ = scale
        Q = np.array(G_, np.float64, order="C")
        b = h_.copy()
        if temporal > 0 and wp is not None:
            t = temporal * scale
            Q[np.diag_indices(k)] += t
            b += t * _prediction(wp, wp2)
        if start is None:
            start = wp if wp is not None else np.zeros(k)
        w = np.clip(start, lo, hi).astype(np.float64)
        g = Q @ w - b
        kernel = _shoot_py if (self.backend == "numpy" or not NUMBA) else _shoot_nb
        tol = float(self.tol) * (np.sqrt(scale) if self.relative else 1.0)
        self.n_iter_ = int(kernel(Q, b, 0.5 * scale * l1, lo, hi, w, g, int(self.max_iter), tol, bool(self.newton),
                                  np.empty((k, k)), np.empty(k), np.empty(k, np.int64)))
        return w
