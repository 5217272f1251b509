"""Point caches as the rig's weights: the compressed space in which :func:`~workbench.enhance.retime` matches them.

§6 of Bermano et al. 2014 matches sequences in a compressed space, not in raw
vertices. For a point cache ``(T, n, 3)`` on a model that has blendshapes the
natural compressed space is the rig's own weights: every frame ``x_t`` is
projected onto the shapes by bounded least squares::

    w_t = argmin |x_t − neutral − Σ_i w_i Δ_i|²   s.t.  lower ≤ w ≤ upper

(the sliders' ranges). In mesh space a take's "rest" (a low percentile of every
coordinate) means nothing — vertices move both ways — and distances are
dominated by the jaw, so :mod:`workbench.enhance.transitions` cuts the take into
the wrong transitions; in weight space both mean what they do for weight takes.

Solved once for all frames: the normal equations ``G w = b`` with
``G = D Dᵀ`` (``k × k``, ``D`` the ``(k, 3n)`` deltas; Cholesky-factored once
when the basis is made, with a ridge of ``1e-10 · trace(G) / k`` so that
duplicate or empty shapes do not make it singular) and ``b = D (x − neutral)``
— one matrix product over all frames (in chunks of ``_CHUNK`` frames, so a long
take is not copied whole). Frames whose solution leaves the box are solved
again as box-constrained QPs, all at once, by a primal–dual active set
(Hintermüller, Ito & Kunisch 2003): each pass fixes the variables the
multipliers push onto a bound and solves the free ones, every frame's reduced
system in one batched ``numpy.linalg.solve``; it stops when no frame's sets
change (the KKT conditions then hold). The rare frame it does not settle in
``_PDAS_ITERATIONS`` passes is solved by ``scipy.optimize.lsq_linear``
(``method="bvls"``) on the Cholesky factor — exact, but ~1 ms a frame in
Python, against ~0.1 ms for the batch.

Why hand-written: ``lsq_linear`` and ``nnls`` solve one right-hand side at a
time (a 335-frame take: 0.35 s with BVLS, 0.07 s with the NNLS active set of
:mod:`workbench.methods.regions.blend.lsq`); every frame here shares ``G``, so
the factorisation and the products are shared and the active-set passes are
batched.

Shapes: ``deltas`` ``(k, n, 3)``, ``neutral`` ``(n, 3)``, ``lower``/``upper``
``(k,)``; :meth:`RigBasis.project` ``(T, n, 3)`` → ``(T, k)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_solve, solve_triangular
from scipy.optimize import lsq_linear

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["RigBasis"]

_CHUNK = 256  # frames per matrix product (a chunk of a 20k-vertex take is ~120 MB of float64)
_PDAS_ITERATIONS = 30
_RIDGE = 1e-10


class RigBasis:
    """A rig's shapes as a basis for point caches: bounded least-squares weights of mesh frames.

    Parameters
    ----------
    deltas : (k, n, 3) array_like
        Displacement of every vertex at weight 1, per shape (vertex masks applied).
    neutral : (n, 3) array_like
        The rig's neutral.
    lower, upper : float or (k,) array_like, default 0 and 1
        The sliders' ranges; ``lower ≤ upper``. ``-inf`` / ``inf`` leave a side open.
    names : sequence of str, optional
        The shapes' names (for messages and for the caller's bookkeeping).

    Raises
    ------
    ValueError
        Naming the argument: shapes that differ, NaN/inf in ``deltas`` or
        ``neutral``, no shapes, ``lower > upper``.

    Examples
    --------
    >>> import numpy as np
    >>> from workbench.enhance import RigBasis
    >>> rng = np.random.default_rng(0)
    >>> basis = RigBasis(rng.normal(size=(4, 30, 3)), np.zeros((30, 3)))
    >>> w = np.array([[0.2, 0.0, 1.0, 0.5]])
    >>> frames = np.einsum("tk,kvc->tvc", w, basis.deltas)
    >>> bool(np.allclose(basis.project(frames), w))
    True
    """

    def __init__(
        self, deltas: ArrayLike, neutral: ArrayLike, lower: ArrayLike = 0.0, upper: ArrayLike = 1.0,
        names: Sequence[str] | None = None,
    ) -> None:
        D = np.asarray(deltas, dtype=np.float64)
        N = np.asarray(neutral, dtype=np.float64)
        if N.ndim != 2 or N.shape[1] != 3 or N.shape[0] == 0:
            raise ValueError(f"neutral must be (n, 3) vertices, got shape {N.shape}")
        if D.ndim != 3 or D.shape[1:] != N.shape:
            raise ValueError(f"deltas must be (k, {N.shape[0]}, 3) on the neutral's mesh, got shape {D.shape}")
        if D.shape[0] == 0:
            raise ValueError("deltas: the rig has no shapes")
        if not (np.all(np.isfinite(D)) and np.all(np.isfinite(N))):
            raise ValueError("deltas and neutral must be finite (NaN or inf found)")
        k = D.shape[0]
        lo = np.broadcast_to(np.asarray(lower, dtype=np.float64), (k,)).copy()
        hi = np.broadcast_to(np.asarray(upper, dtype=np.float64), (k,)).copy()
        if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
            raise ValueError(f"lower must be ≤ upper for every shape, got {lo} and {hi}")
        if names is not None and len(names) != k:
            raise ValueError(f"names must name the {k} shapes, got {len(names)}")
        self.deltas: NDArray[np.float64] = D
        self.neutral: NDArray[np.float64] = N
        self.lower: NDArray[np.float64] = lo
        self.upper: NDArray[np.float64] = hi
        self.names: tuple[str, ...] | None = None if names is None else tuple(str(n) for n in names)
        self._D = D.reshape(k, -1)
        G = self._D @ self._D.T
        G[np.diag_indices(k)] += _RIDGE * max(float(np.trace(G)) / k, 1e-300)
        self._G = G
        self._L = np.linalg.cholesky(G)
        self._Ginv = cho_solve((self._L, True), np.eye(k))  # k × k: every frame's solve is one small product

    @classmethod
    def from_model(cls, model: FaceState, names: Sequence[str] | None = None) -> RigBasis:
        """The basis of a model's shapes (``names``, default all), bounded by their sliders.

        Raises
        ------
        ValueError
            The model has no shapes, or ``names`` names one it does not have.
        """
        shapes = list(model.shapes)
        index = {s.name: s for s in shapes}
        chosen = list(index) if names is None else list(names)
        missing = [n for n in chosen if n not in index]
        if missing:
            raise ValueError(f"names: the model has no shapes {missing[:5]}")
        if not chosen:
            raise ValueError("model: it has no blendshapes to project point caches onto")
        picked = [index[n] for n in chosen]
        return cls(
            np.stack([np.asarray(s.effective_delta(), np.float64) for s in picked]),
            np.asarray(model.vertices, np.float64),
            [s.slider_min for s in picked],
            [s.slider_max for s in picked],
            names=chosen,
        )

    @property
    def n_shapes(self) -> int:
        return int(self.deltas.shape[0])

    @property
    def n_vertices(self) -> int:
        return int(self.neutral.shape[0])

    def __repr__(self) -> str:
        return f"<RigBasis: {self.n_shapes} shapes on {self.n_vertices} vertices>"

    def project(self, frames: ArrayLike, *, name: str = "frames") -> NDArray[np.float64]:
        """Bounded least-squares weights of every frame (module docstring).

        Parameters
        ----------
        frames : (T, n, 3) or (n, 3) array_like
            Mesh frames on the basis's mesh.
        name : str
            The argument's name in error messages.

        Returns
        -------
        (T, k) or (k,) ndarray
            Weights within ``[lower, upper]``.
        """
        return self.fit(frames, name=name)[0]

    def fit(self, frames: ArrayLike, *, name: str = "frames") -> tuple[NDArray[np.float64], float]:
        """:meth:`project`, and the RMS distance of the fitted vertices from the frames' (the rig's misfit).

        Returns
        -------
        weights : (T, k) or (k,) ndarray
        rms : float
            ``sqrt(mean over frames and vertices of |x − neutral − Σ w_i Δ_i|²)``;
            near 0 for a cache the rig made.
        """
        X = np.asarray(frames, dtype=np.float64)
        one = X.ndim == 2
        if one:
            X = X[None]
        if X.ndim != 3 or X.shape[1:] != self.neutral.shape:
            raise ValueError(
                f"{name} must be (T, {self.n_vertices}, 3) or ({self.n_vertices}, 3) on the rig's mesh "
                f"({self.n_vertices} vertices), got shape {np.shape(frames)}"
            )
        T = X.shape[0]
        k = self.n_shapes
        B = np.empty((T, k))
        sq = 0.0
        n0 = self.neutral.reshape(-1)
        for i in range(0, T, _CHUNK):
            Y = X[i : i + _CHUNK].reshape(-1, n0.size) - n0
            B[i : i + _CHUNK] = Y @ self._D.T
            sq += float(np.einsum("ij,ij->", Y, Y))
        W = B @ self._Ginv
        out = np.any((W < self.lower) | (W > self.upper), axis=1)
        if out.any():
            W[out] = self._box(B[out], W[out])
        # |x − n − wD|² = |x − n|² − 2 wᵀb + wᵀGw (G without the ridge's share, negligible)
        res = sq - 2.0 * float(np.einsum("tk,tk->", W, B)) + float(np.einsum("tk,kl,tl->", W, self._G, W))
        rms = float(np.sqrt(max(res, 0.0) / max(T * self.n_vertices, 1)))
        return (W[0] if one else W), rms

    def _box(self, B: NDArray[np.float64], W0: NDArray[np.float64]) -> NDArray[np.float64]:
        """``argmin ½ wᵀGw − bᵀw`` over the box for every row of ``B``: a batched primal–dual active set."""
        G, lo, hi = self._G, self.lower, self.upper
        m, k = B.shape
        c = np.diag(G)[None, :]  # per-coordinate scale of the dual update
        at_lo = W0 < lo
        at_hi = W0 > hi
        W = np.clip(W0, lo, hi)
        done = np.zeros(m, bool)
        eye = np.eye(k, dtype=bool)
        for _ in range(_PDAS_ITERATIONS):
            free = ~(at_lo | at_hi)
            fixed = np.where(at_lo, lo, np.where(at_hi, hi, 0.0))
            rhs = B - fixed @ G  # G symmetric
            rhs = np.where(free, rhs, fixed)
            M = np.where(free[:, :, None] & free[:, None, :], G[None], 0.0)
            M[:, eye] = np.where(free, np.diag(G)[None, :], 1.0)
            W = np.linalg.solve(M, rhs[:, :, None])[:, :, 0].astype(np.float64, copy=False)
            mu = W @ G - B  # gradient: ≥ 0 at the lower bound, ≤ 0 at the upper, 0 when free
            new_lo = mu + c * (lo - W) > 0.0
            new_hi = -mu + c * (W - hi) > 0.0
            new_lo &= ~new_hi | (W - lo < hi - W)
            new_hi &= ~new_lo
            same = np.all(new_lo == at_lo, axis=1) & np.all(new_hi == at_hi, axis=1)
            at_lo, at_hi = new_lo, new_hi
            if same.all():
                done[:] = True
                break
            done = same
        W = np.clip(W, lo, hi)
        if not done.all():
            C = solve_triangular(self._L, B[~done].T, lower=True).T
            box_hi = np.where(hi <= lo, lo + 1e-12, hi)  # lsq_linear needs lo < hi strictly
            W[~done] = [
                np.clip(lsq_linear(self._L.T, cj, bounds=(lo, box_hi), method="bvls", lsmr_tol=None).x, lo, hi)
                for cj in C
            ]
        return W
