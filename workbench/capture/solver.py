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
never touches ``A``. Started from the previous frame's weights it needs only a
few sweeps per frame.

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

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

try:
    from numba import njit

    NUMBA = True
except ImportError:  # pragma: no cover - numba is optional
    NUMBA = False

    def njit(*args: Any, **kwargs: Any) -> Any:  # type: ignore[no-redef]
        def wrap(f: Any) -> Any:
            return f

        return wrap if not (len(args) == 1 and callable(args[0])) else args[0]


__all__ = ["NUMBA", "WeightSolver", "objective"]


def _shoot(Q, b, half_l1, lo, hi, w, g, max_iter, tol):  # pragma: no cover - compiled or looped
    """Cyclic coordinate descent ("shooting") in place; returns the number of sweeps.

    Minimises ``wᵀQw − 2bᵀw + 2·half_l1·Σ|w|`` over the box. ``g = Q w − b`` on
    entry (kept up to date). Written with scalar loops so the Python fallback
    and the numba kernel do the same arithmetic in the same order.
    """
    k = w.shape[0]
    sweeps = 0
    for _sweep in range(max_iter):
        sweeps += 1
        change = 0.0
        for j in range(k):
            q = Q[j, j]
            wj = w[j]
            r = q * wj - g[j]  # b_j − Σ_{i≠j} Q_ji w_i
            if q > 0.0:
                if r > half_l1:
                    new = (r - half_l1) / q
                elif r < -half_l1:
                    new = (r + half_l1) / q
                else:
                    new = 0.0
            # a shape that moves no constraint and has no temporal term: the 1-D objective is linear
            elif r > half_l1:
                new = hi[j]
            elif r < -half_l1:
                new = lo[j]
            else:
                new = 0.0
            if new < lo[j]:
                new = lo[j]
            elif new > hi[j]:
                new = hi[j]
            d = new - wj
            if d != 0.0:
                w[j] = new
                for i in range(k):
                    g[i] += Q[i, j] * d
                step = abs(d) * np.sqrt(q) if q > 0.0 else abs(d)
                if step > change:
                    change = step
        if change <= tol:
            break
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
    G: ArrayLike, h: ArrayLike, w: ArrayLike, *, l1: float = 0.0, temporal: float = 0.0,
    w_prev: ArrayLike | None = None, w_prev2: ArrayLike | None = None, cc: float = 0.0,
) -> float:
    """The objective ``||Aw − c||² + l1·Σ|w| + temporal·||w − 2w_prev + w_prev2||²`` from the Gram form.

    ``G = AᵀA``, ``h = Aᵀc``, ``cc = cᵀc`` (the constant; 0 leaves it out). The λ's are
    absolute here (multiply by ``trace(G)/k`` for :class:`WeightSolver`'s relative ones).
    """
    G_ = np.asarray(G, np.float64)
    h_ = np.asarray(h, np.float64)
    w_ = np.asarray(w, np.float64)
    val = float(w_ @ G_ @ w_ - 2.0 * h_ @ w_ + cc + l1 * np.abs(w_).sum())
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
    l1 : float
        Weight of ``Σ|w_j|`` (``E_sparse``); 0 gives the plain bounded least squares (the L2 variant).
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
        l1: float = 0.0,
        temporal: float = 0.0,
        relative: bool = True,
        max_iter: int = 500,
        tol: float = 1e-7,
        backend: str = "auto",
    ) -> None:
        self.lo = lo
        self.hi = hi
        self.l1 = l1
        self.temporal = temporal
        self.relative = relative
        self.max_iter = max_iter
        self.tol = tol
        self.backend = backend

    # ------------------------------------------------------------------ checks
    def _params(self, k: int) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
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
        l1 = float(self.l1)
        temporal = float(self.temporal)
        if not (np.isfinite(l1) and l1 >= 0):
            raise ValueError(f"l1 must be a finite number ≥ 0, got {self.l1!r}")
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
        self.n_iter_ = int(kernel(Q, b, 0.5 * l1 * scale, lo, hi, w, g, int(self.max_iter), tol))
        return w
