"""The dynamic expression model: the rig adapted to the actor while tracking (Bouaziz et al. 2013, §2, §3.2).

A template rig ``B* = [b0*, b1*, ..., bk*]`` (the model's neutral and its
shapes) is adapted online to the face that is being tracked, as in the
paper's *adaptive DEM*:

* **Identity** — the neutral ``b0 = b0* + ℓ E z0``: a smooth offset in a
  low-dimensional spectral basis ``E`` (the first ``n_basis`` eigenvectors of
  the skin's cotangent Laplacian, ``-L e = λ M e`` with the mass matrix ``M``,
  per coordinate). There is no identity PCA model here (the paper's
  ``m + P y`` needs a database of scanned faces), so **E doubles as the
  identity basis**: ``z0`` plays both the paper's ``y`` and ``z0``, and it is
  regularised with ``β1`` (the PCA term's weight) on the bending
  ``||D_E z0||²`` plus ``β3 ||z0||²``.
* **Expression transfer** — ``b_i = T_i* b0`` with the paper's linear
  operator (appendix, eq. 7): the affine map ``S_t = S_i S_0⁻¹`` of every
  template triangle (the tetrahedron spanned by two edges and the scaled
  normal, Sumner & Popović 2004) is applied to the three edges of the same
  triangle of ``b0``, and the vertices are the least-squares fit to those
  edges (a graph Laplacian ``GᵀG``: unit weight per edge, independent of
  ``b0``, so ``T_i*`` is linear in ``b0``). The paper's soft pins ``μ F`` are
  hard here: vertices that the template shape does not move at all keep the
  neutral's position (``μ → ∞``). This is exact on the template: with
  ``b0 = b0*`` the operator returns ``b_i*`` (``tests/test_capture_adapt.py``).
  Non-skin parts (eyeballs, teeth, tongue, lashes) carry the template's deltas
  unchanged; the identity basis moves them with their nearest skin vertex.
  Step 3's :class:`~workbench.rigging.RigTransfer` is not reused: it conjugates
  the gradients by the fit's Jacobian (not linear in ``b0``) and maps across
  topologies, which the DEM does not need.
* **Correctives** — ``b_i = T_i* b0 + ℓ E z_i``: a smooth per-shape field.

All coefficients ``u = [z0, z1, ..., zk]`` are unit-free: ``ℓ`` is the RMS
radius of the template skin (:attr:`AdaptiveModel.length_scale_`) and the
columns of ``E`` have unit RMS over the skin vertices, so ``z = 0.01`` is an
offset of about 1 % of the head size.

**Refinement (§3.2).** A frame's constraints ``A (b0 + ΔB x) ≈ c`` (``m`` rows
over the stacked vertex coordinates, in the model's frame) with weights ``x``
give ``E_fit = ||Ā u − c̄||²`` with (normalised per row and by ``ℓ``)

    Ā = A [(x̄ I + Σ x_i T_i*) E, x_1 E, ..., x_k E] / √m,
    c̄ = (c − A (b0* + ΔB* x)) / (√m ℓ),         x̄ = 1 − Σ x_i,

and the refinement energy (eq. 4) adds ``β ||D_E z||² + β3 ||z||²`` with
``D_E = diag(λ_j / λ_K)`` (the eigenvalues over the largest one, so the
penalty does not depend on the units or the mesh resolution). Statistics are
aggregated over frames with the decay ``γ`` (Algorithm 1):
``s^t = γ s^{t−1} + 1``, ``M^t = (γ s^{t−1} M^{t−1} + ĀᵀĀ) / s^t``,
``y^t = (γ s^{t−1} y^{t−1} + Āᵀc̄) / s^t``, and ``u^t`` is a warm-started
Gauss–Seidel solve of ``(M^t + D) u = y^t`` — here *block* Gauss–Seidel (one
150 × 150 block per shape, each solved exactly), over the neutral and the
shapes with non-zero weight in the frame, as the paper does. ``M`` is kept in
blocks: the ``(i, j)`` block of a frame is ``x_i x_j (AE)ᵀ(AE)`` for two
shapes, so only pairs that were active together are stored.

**Coverage.** ``σ_i = Σ_t x_i^t``; a shape with ``σ_i > σ̄`` (``coverage``) is
saturated and stays fixed; the neutral is optimised until ``Σ_t max(x̄^t, 0)``
passes ``σ̄``.

Transfer rows (``Δ_i E = (T_i* − I) E`` at the constraint vertices, one sparse
solve per shape on the vertices it moves, CHOLMOD when installed) are computed
once in the constructor: 5–8 s on the 20k-vertex sample head on a shared
2-core machine, 1 s on the 5k one (``benchmarks/bench_capture.py``); reuse the
object across takes of one model. Per frame the cost is a few products of
``(m, 3K)`` matrices and one Cholesky of a ``3K × 3K`` block per optimised block.

Shapes: ``n`` vertices, ``k`` shapes, ``K = n_basis``; constraint matrices
``A : (m, 3n)`` over ``[x0, y0, z0, x1, ...]``; weights ``(k,)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from workbench._blas import one_blas_thread
from workbench.capture.result import TrackError
from workbench.geometry.frames import triangle_frames
from workbench.geometry.masks import skin_or_all_mask
from workbench.geometry.operators import cotangent_laplacian, mass_matrix
from workbench.geometry.sparse_cholesky import SparseSPDSolver
from workbench.model import BlendShape, FaceModel

__all__ = ["AdaptiveModel", "ExpressionTransfer", "adaptive_model", "laplacian_basis", "point_to_plane_rows"]

#: a template vertex moving less than this (times the length scale) in a shape is pinned in its transfer
PIN_TOL = 1e-7
#: below this many vertices the basis comes from a dense eigendecomposition
_DENSE_EIG = 600


def _sub_faces(F: NDArray[np.int64], ids: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """Faces with all corners in ``ids``, renumbered into ``ids``."""
    local = np.full(n, -1, np.int64)
    local[ids] = np.arange(ids.size)
    Fl = local[F]
    return Fl[(Fl >= 0).all(1)]


def laplacian_basis(vertices: ArrayLike, faces: ArrayLike, n_basis: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The smoothest ``n_basis`` eigenvectors of a surface: ``-L e = λ M e`` (cotangent ``L``, mass ``M``).

    Shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) with the shifted matrix
    factored once by :class:`SparseSPDSolver` (CHOLMOD when installed); a dense
    ``scipy.linalg.eigh`` below a few hundred vertices.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    n_basis : int
        ``1 <= n_basis < n``.

    Returns
    -------
    E : (n, n_basis) float64
        Columns with unit RMS over the vertices (``||e||² = n``), ascending λ.
    eigenvalues : (n_basis,) float64
        ``λ`` (``≥ 0``; the first is ~0, the constant).
    """
    V = np.asarray(vertices, np.float64)
    F = np.asarray(faces, np.int64)
    n = V.shape[0]
    if not (1 <= n_basis < n):
        raise ValueError(f"n_basis must be in 1..{n - 1} for a surface of {n} vertices, got {n_basis}")
    L = cotangent_laplacian(V, F)
    M = mass_matrix(V, F)
    m = np.asarray(M.diagonal(), np.float64)
    m = np.where(m > 0, m, max(float(m[m > 0].min()) if (m > 0).any() else 1.0, 1e-300))
    K = sp.csr_matrix(-L)
    Md = sp.diags(m)
    if n <= _DENSE_EIG:
        w, E = sla.eigh(K.toarray(), np.diag(m), subset_by_index=[0, n_basis - 1])
    else:
        area = float(m.sum())
        sigma = -4.0 * math.pi / area  # below the first non-zero eigenvalue (8π/area on a sphere)
        fac = SparseSPDSolver(sp.csc_matrix(K - sigma * Md))
        op = spla.LinearOperator(K.shape, matvec=fac.solve, dtype=np.float64)
        w, E = spla.eigsh(K, k=n_basis, M=Md, sigma=sigma, which="LM", OPinv=op)
    order = np.argsort(w)
    w = np.maximum(np.asarray(w, np.float64)[order], 0.0)
    E = np.asarray(E, np.float64)[:, order]
    E /= np.maximum(np.sqrt((E**2).mean(0)), 1e-300)
    return E, w


def point_to_plane_rows(vertex_ids: ArrayLike, normals: ArrayLike, n_vertices: int) -> sp.csr_matrix:
    """Constraint rows ``nᵀ v_i`` as a sparse ``(m, 3 n_vertices)`` matrix over ``[x0, y0, z0, x1, ...]``.

    A point-to-plane row: ``nᵀ (v_i − c) = 0`` is ``row · b = nᵀ c``. Markers
    are three rows with the unit axes as normals.

    Parameters
    ----------
    vertex_ids : (m,) int
    normals : (m, 3) float
    n_vertices : int
    """
    ids = np.asarray(vertex_ids, np.int64).reshape(-1)
    N = np.asarray(normals, np.float64)
    if N.shape != (ids.size, 3):
        raise ValueError(f"normals must be ({ids.size}, 3) to match vertex_ids, got {N.shape}")
    if ids.size and (ids.min() < 0 or ids.max() >= n_vertices):
        raise ValueError(f"vertex_ids must be in 0..{n_vertices - 1}")
    m = ids.size
    indptr = np.arange(0, 3 * m + 1, 3)
    cols = (3 * ids[:, None] + np.arange(3)).reshape(-1)
    return sp.csr_matrix((N.reshape(-1), cols, indptr), shape=(m, 3 * n_vertices))


class ExpressionTransfer:
    """The paper's linear expression-transfer operators ``T_i*`` of a template rig (appendix, eq. 7).

    ``T_i* b0`` minimises ``Σ_t Σ_edges |S_t e_t(b0) − e_t(b_i)|²`` over the skin
    triangles (``S_t`` the template triangle's affine map from ``b0*`` to
    ``b_i*``, built on the tetrahedron of two edges and the normal scaled by
    ``1/√|n|``), with the vertices that the template shape leaves in place held
    at ``b0`` (hard pins). Vertices off the skin get the template's delta.

    Parameters
    ----------
    vertices : (n, 3) float
        The template neutral ``b0*``.
    faces : (T, 3) int
    deltas : (k, n, 3) float
        The template shapes ``b_i* − b0*``.
    skin : (s,) int, optional
        Vertex ids of the skin (default all).
    length_scale : float, optional
        For the pin tolerance (default the RMS radius of the skin).

    Attributes
    ----------
    skin : (s,) int64
    n_shapes : int
    """

    def __init__(self, vertices: ArrayLike, faces: ArrayLike, deltas: ArrayLike, *, skin: ArrayLike | None = None,
                 length_scale: float | None = None) -> None:
        V = np.asarray(vertices, np.float64)
        F = np.asarray(faces, np.int64)
        D = np.asarray(deltas, np.float64)
        n = V.shape[0]
        if D.ndim != 3 or D.shape[1:] != (n, 3):
            raise ValueError(f"deltas must be (k, {n}, 3), got {D.shape}")
        self.n_vertices = n
        self.n_shapes = D.shape[0]
        self.skin = np.arange(n, dtype=np.int64) if skin is None else np.unique(np.asarray(skin, np.int64))
        self._deltas = D
        Fs = _sub_faces(F, self.skin, n)
        ns, T = self.skin.size, Fs.shape[0]
        self._T = T
        # G: three edges per triangle, row j*T + t = v[(j+1)%3] − v[j]
        rows = np.repeat(np.arange(3 * T), 2)
        a = np.concatenate([Fs[:, 0], Fs[:, 1], Fs[:, 2]])
        b = np.concatenate([Fs[:, 1], Fs[:, 2], Fs[:, 0]])
        cols = np.stack([b, a], 1).reshape(-1)
        self._G = sp.csr_matrix((np.tile([1.0, -1.0], 3 * T), (rows, cols)), shape=(3 * T, ns))
        self._GtG = sp.csr_matrix(self._G.T @ self._G)
        # where each edge's four Laplacian entries land in the CSR pattern of GᵀG (for _rhs)
        self._pattern = self._GtG
        self._pattern.sort_indices()
        ea = np.concatenate([a, b, a, b])
        eb = np.concatenate([a, b, b, a])
        key = ea * ns + eb
        pr = np.repeat(np.arange(ns), np.diff(self._pattern.indptr))
        pkey = pr * ns + self._pattern.indices
        slot = np.searchsorted(pkey, key)
        self._scatter = sp.csr_matrix((np.ones(slot.size), (slot, np.arange(slot.size))),
                                      shape=(self._pattern.nnz, slot.size))
        Vs = V[self.skin]
        inv0, ok0 = self._frames_inverse(Vs, Fs)
        self._Fs = Fs
        self._inv0 = inv0
        self._ok0 = ok0
        Ds = D[:, self.skin]
        if length_scale is None:
            length_scale = float(np.sqrt(((Vs - Vs.mean(0)) ** 2).sum(1).mean())) if ns else 1.0
        mag = np.linalg.norm(Ds, axis=2)
        #: (k, s) bool: skin vertices each shape moves (the rest are pinned to the neutral)
        self.free = mag > PIN_TOL * max(length_scale, 1e-300)
        self._Vs = Vs

    def _frames_inverse(self, X: NDArray[np.float64], F: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        S0 = triangle_frames(X, F)
        det = np.linalg.det(S0)
        scale = float(np.median(np.abs(det))) if det.size else 1.0
        ok = np.abs(det) > 1e-12 * max(scale, 1e-300)
        inv = np.zeros_like(S0)
        inv[ok] = np.linalg.inv(S0[ok])
        return inv, ok

    def strain(self, i: int) -> NDArray[np.float64]:
        """``S_t − I`` of shape ``i`` per skin triangle, (T, 3, 3) (zero on degenerate template triangles)."""
        Si = triangle_frames(self._Vs + self._deltas[i, self.skin], self._Fs)
        C = Si @ self._inv0 - np.eye(3)
        C[~self._ok0] = 0.0
        return C

    def _system(self, i: int) -> tuple[NDArray[np.int64], SparseSPDSolver | None]:
        free = np.flatnonzero(self.free[i])
        if free.size == 0:
            return free, None
        K = self._GtG[free][:, free]
        diag = K.diagonal()
        ridge = 1e-10 * float(diag.mean()) if diag.size else 1e-10
        return free, SparseSPDSolver(sp.csc_matrix(K + ridge * sp.identity(free.size)))

    def _rhs(self, C: NDArray[np.float64], fields: NDArray[np.float64], rows: NDArray[np.int64]) -> NDArray[np.float64]:
        """Rows ``rows`` of ``Gᵀ (H − I) G f`` for scalar fields ``f`` (s, q) along each axis → (r, 3 coords, q, 3 axes).

        ``Gᵀ diag(C_cd) G`` is a weighted graph Laplacian per pair of axes ``(c, d)``;
        the nine share the sparsity pattern of ``GᵀG``.
        """
        Ct = np.concatenate([C, C, C]).reshape(3 * self._T, 9)  # the triangle of each edge row
        data9 = np.asarray(self._scatter @ np.concatenate([Ct, Ct, -Ct, -Ct]))  # (nnz, 9)
        P = self._pattern
        starts, lens = P.indptr[rows], np.diff(P.indptr)[rows]
        offs = np.concatenate([[0], np.cumsum(lens)])
        idx = np.repeat(starts - offs[:-1], lens) + np.arange(offs[-1])
        sub_indices = P.indices[idx]
        f = np.ascontiguousarray(fields, dtype=np.float64)
        s, q = f.shape
        out = np.empty((rows.size, 3, q, 3), order="F")  # Fortran: columns contiguous for the solver
        for cd in range(9):
            Lcd = sp.csr_matrix((data9[idx, cd], sub_indices, offs), shape=(rows.size, s))
            out[:, cd // 3, :, cd % 3] = Lcd @ f
        return out

    def delta(self, i: int, neutral: ArrayLike) -> NDArray[np.float64]:
        """``T_i* b0 − b0`` for a neutral ``b0`` (n, 3): the transferred delta of shape ``i``, (n, 3)."""
        b0 = np.asarray(neutral, np.float64)
        if b0.shape != (self.n_vertices, 3):
            raise ValueError(f"neutral must be ({self.n_vertices}, 3), got {b0.shape}")
        out = self._deltas[i].copy()
        out[self.skin] = 0.0
        free, solver = self._system(i)
        if solver is None:
            return out
        C = self.strain(i)
        Gb = (self._G @ b0[self.skin]).reshape(3, self._T, 3)  # edges per triangle
        CGb = np.einsum("tcd,jtd->jtc", C, Gb).reshape(3 * self._T, 3)
        rhs = self._G.T @ CGb
        res = np.zeros((self.skin.size, 3))
        res[free] = solver.solve(rhs[free])
        out[self.skin] = res
        return out

    def apply(self, neutral: ArrayLike) -> NDArray[np.float64]:
        """All transferred deltas ``T_i* b0 − b0``, (k, n, 3)."""
        return np.stack([self.delta(i, neutral) for i in range(self.n_shapes)]) if self.n_shapes else \
            np.zeros((0, self.n_vertices, 3))

    def basis_rows(self, i: int, fields: ArrayLike, rows: ArrayLike) -> NDArray[np.float64]:
        """``(T_i* − I)`` applied to the vector fields ``f_q ⊗ axis_d`` at some skin vertices.

        Parameters
        ----------
        i : int
            Shape.
        fields : (s, q) float
            Scalar fields on the skin (one value per skin vertex).
        rows : (r,) int
            Positions in :attr:`skin` where the result is wanted.

        Returns
        -------
        X : (r, 3, q, 3) float64
            ``X[v, c, j, d]``: coordinate ``c`` at vertex ``rows[v]`` of ``(T_i* − I)(f_j axis_d)``.
        """
        f = np.asarray(fields, np.float64)
        r = np.asarray(rows, np.int64)
        q = f.shape[1]
        out = np.zeros((r.size, 3, q, 3))
        free, solver = self._system(i)
        if solver is None or r.size == 0:
            return out
        pos = np.full(self.skin.size, -1, np.int64)
        pos[free] = np.arange(free.size)
        want = pos[r] >= 0
        if not want.any():
            return out
        rhs = self._rhs(self.strain(i), f, free)  # (f, 3, q, 3)
        sol = solver.solve(rhs.reshape(free.size, -1, order="F")).reshape(free.size, 3, q, 3, order="F")
        out[want] = sol[pos[r[want]]]
        return out


def _check_fraction(name: str, value: float, lo: float, hi: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise ValueError(f"{name} must be in [{lo}, {hi}], got {value!r}")
    return v


class AdaptiveModel:
    """A rig adapted online to the tracked face: identity, expression transfer, correctives (module docstring).

    Parameters
    ----------
    model : FaceModel
        The template rig ``B*`` (neutral and shapes; effective deltas, i.e. with vertex masks).
    n_basis : int, default 50
        Laplacian eigenvectors per coordinate (``K``): each of the neutral and the
        shapes has ``3 K`` unknowns.
    gamma : float, default 0.9
        Temporal decay of the aggregated statistics (``0 < γ ≤ 1``).
    betas : (float, float, float), default (0.5, 0.1, 0.001)
        ``β1`` (identity bending), ``β2`` (corrective bending), ``β3`` (magnitude).
    coverage : float, default 10.0
        ``σ̄``: a shape whose weights summed over the frames pass it stays fixed
        (``inf`` never saturates).
    vertex_ids : (p,) int, optional
        The vertices constraints may touch (the transfer rows are kept only
        there). Default: up to ``max_vertices`` skin vertices that the shapes move.
    sweeps : int, default 2
        Block Gauss–Seidel sweeps per frame.
    max_vertices : int, default 2000
        Size of the default ``vertex_ids``.
    progress : callable, optional
        ``progress(fraction, message)`` while the basis and the transfer rows are built.

    Attributes
    ----------
    vertex_ids_ : (p,) int64
        The constraint vertices.
    length_scale_ : float
        ``ℓ``, the RMS radius of the template skin (model units).
    basis_ : (n, K) float64
        ``E`` (unit RMS on the skin; non-skin vertices copy their nearest skin vertex).
    eigenvalues_ : (K,) float64
    coefficients_ : (k + 1, K, 3) float64
        ``u = [z0, z1, ..., zk]`` (unit-free; the offset is ``ℓ E z``).
    coverage_ : (k + 1,) float64
        ``σ`` of the neutral (``Σ max(x̄, 0)``) and of every shape.
    saturated_ : (k + 1,) bool
    n_frames_ : int
    transfer_ : ExpressionTransfer
    setup_seconds_ : float
    """

    def __init__(
        self,
        model: FaceModel,
        *,
        n_basis: int = 50,
        gamma: float = 0.9,
        betas: Sequence[float] = (0.5, 0.1, 0.001),
        coverage: float = 10.0,
        vertex_ids: ArrayLike | None = None,
        sweeps: int = 2,
        max_vertices: int = 2000,
        progress: Callable[[float, str], Any] | None = None,
    ) -> None:
        import time

        t0 = time.perf_counter()
        if not isinstance(model, FaceModel):
            raise TypeError(f"model must be a FaceModel, got {type(model).__name__}")
        if model.faces.shape[0] == 0:
            raise ValueError("model: the mesh has no triangles; the spectral basis needs a surface")
        if isinstance(n_basis, bool) or not isinstance(n_basis, int | np.integer) or n_basis < 1:
            raise ValueError(f"n_basis must be a positive integer, got {n_basis!r}")
        self.gamma = _check_fraction("gamma", gamma, 0.0, 1.0)
        if self.gamma == 0.0:
            raise ValueError("gamma must be > 0 (0 would forget every frame at once)")
        b = tuple(float(v) for v in betas)
        if len(b) != 3 or not all(math.isfinite(v) and v >= 0 for v in b):
            raise ValueError(f"betas must be three finite numbers ≥ 0 (β1, β2, β3), got {betas!r}")
        if not (float(coverage) > 0):
            raise ValueError(f"coverage must be > 0 (inf never saturates), got {coverage!r}")
        if isinstance(sweeps, bool) or not isinstance(sweeps, int | np.integer) or sweeps < 1:
            raise ValueError(f"sweeps must be a positive integer, got {sweeps!r}")
        self.model = model
        self.n_basis = int(n_basis)
        self.betas = b
        self.coverage = float(coverage)
        self.sweeps = int(sweeps)
        self.max_vertices = int(max_vertices)

        n = model.n_vertices
        V = np.asarray(model.vertices, np.float64)
        F = np.asarray(model.faces, np.int64)
        D = np.asarray(model.effective_deltas, np.float64)
        self._names = list(model.shape_names)
        k = D.shape[0]
        skin = np.flatnonzero(skin_or_all_mask(model)).astype(np.int64)
        Fs = _sub_faces(F, skin, n)
        if Fs.shape[0] == 0:
            raise ValueError("model: the skin has no triangles")
        if self.n_basis >= skin.size:
            raise ValueError(f"n_basis must be below the number of skin vertices ({skin.size}), got {n_basis}")
        say = progress if progress is not None else (lambda f, msg: None)
        say(0.0, "adaptive model: Laplacian eigenvectors of the skin")
        Vs = V[skin]
        ell = float(np.sqrt(((Vs - Vs.mean(0)) ** 2).sum(1).mean()))
        if not ell > 0:
            raise ValueError("model: the skin has no extent")
        self.length_scale_ = ell
        E_skin, lam = laplacian_basis(Vs, Fs, self.n_basis)
        E = np.empty((n, self.n_basis))
        E[skin] = E_skin
        rest = np.setdiff1d(np.arange(n), skin)
        if rest.size:
            _, near = cKDTree(Vs).query(V[rest])
            E[rest] = E_skin[near]
        self.basis_ = E
        self.eigenvalues_ = lam
        self.transfer_ = ExpressionTransfer(V, F, D, skin=skin, length_scale=ell)
        self._skin = skin
        self._V0 = V
        self._D0 = D

        # the constraint vertices
        if vertex_ids is None:
            moved = np.linalg.norm(D[:, skin], axis=2).max(0) > 1e-3 * ell if k else np.ones(skin.size, bool)
            cand = skin[moved] if moved.any() else skin
            if cand.size > self.max_vertices:
                cand = np.sort(np.random.default_rng(0).choice(cand, self.max_vertices, replace=False))
            S = cand
        else:
            S = np.asarray(vertex_ids, np.int64).reshape(-1)
            if S.size == 0:
                raise ValueError("vertex_ids is empty")
            if S.min() < 0 or S.max() >= n:
                raise ValueError(f"vertex_ids must be in 0..{n - 1}")
            if np.unique(S).size != S.size:
                raise ValueError("vertex_ids has repeated vertices")
        self.vertex_ids_ = S
        p = S.size
        self._col_of = np.full(n, -1, np.int64)
        self._col_of[S] = np.arange(p)
        self._E_S = E[S]  # (p, K)
        self._E3 = np.kron(self._E_S, np.eye(3))  # (3p, 3K)
        # transfer rows (T_i* − I) E at S, kept only where shape i is free (zero elsewhere): shape i's rows
        # are self._te[self._te_off[i]:self._te_off[i + 1]] at local rows self._te_rows[i] of the (3p, 3K) block
        local = np.full(n, -1, np.int64)
        local[skin] = np.arange(skin.size)
        sl = local[S]
        K3 = 3 * self.n_basis
        blocks, rows_of = [], []
        for i in range(k):
            say(0.1 + 0.9 * i / max(k, 1), f"adaptive model: transfer rows of {self._names[i]} ({i + 1} of {k})")
            on = np.flatnonzero(sl >= 0)
            on = on[self.transfer_.free[i][sl[on]]]
            X = self.transfer_.basis_rows(i, E_skin, sl[on])  # (r, 3, K, 3)
            blocks.append(X.reshape(3 * on.size, K3).astype(np.float32))
            rows_of.append((3 * on[:, None] + np.arange(3)).reshape(-1))
        self._te = np.concatenate(blocks) if blocks else np.zeros((0, K3), np.float32)
        self._te_rows = rows_of
        self._te_off = np.concatenate([[0], np.cumsum([r.size for r in rows_of])]).astype(np.int64)
        self._te_flat = np.concatenate([i * 3 * p + r for i, r in enumerate(rows_of)]) if rows_of else \
            np.zeros(0, np.int64)
        self._b0S = V[S].copy()
        self._D0S = D[:, S].copy()

        # the regularisation diagonal
        dE = lam / lam[-1] if lam[-1] > 0 else np.zeros_like(lam)
        bend = np.repeat(dE**2, 3)
        self._reg = np.stack([b[0] * bend + b[2]] + [b[1] * bend + b[2]] * k) if k else \
            (b[0] * bend + b[2])[None]
        self.reset()
        self.setup_seconds_ = time.perf_counter() - t0
        say(1.0, f"adaptive model ready ({self.setup_seconds_:.1f} s)")

    # ------------------------------------------------------------------ state
    def reset(self) -> AdaptiveModel:
        """Forget every frame: back to the template (``u = 0``), no statistics."""
        k = len(self._names)
        K3 = 3 * self.n_basis
        self._u = np.zeros((k + 1, K3))
        self._M: dict[tuple[int, int], NDArray[np.float64]] = {}
        self._nbr: list[set[int]] = [set() for _ in range(k + 1)]
        self._y = np.zeros((k + 1, K3))
        self._g = 1.0  # stored statistics × g = Σ_j γ^{t-j} (frame j's)
        self._s = 0.0
        self.coverage_ = np.zeros(k + 1)
        self.saturated_ = np.zeros(k + 1, bool)
        self.n_frames_ = 0
        self._refresh()
        return self

    @property
    def shape_names(self) -> list[str]:
        return list(self._names)

    @property
    def coefficients_(self) -> NDArray[np.float64]:
        return self._u.reshape(len(self._names) + 1, self.n_basis, 3).copy()

    def _refresh(self) -> None:
        """Current neutral and deltas at the constraint vertices."""
        p = self.vertex_ids_.size
        ell = self.length_scale_
        U = self._u.reshape(-1, self.n_basis, 3)
        self._cur_b0S = self._b0S + ell * (self._E_S @ U[0])
        k = len(self._names)
        if k:
            tr = np.zeros(k * 3 * p)
            tr[self._te_flat] = self._te @ self._u[0].astype(np.float32)
            K = self.n_basis
            corr = (self._E_S @ U[1:].transpose(1, 0, 2).reshape(K, 3 * k)).reshape(p, k, 3).transpose(1, 0, 2)
            self._cur_DS = self._D0S + ell * (tr.reshape(k, p, 3) + corr)
        else:
            self._cur_DS = np.zeros((0, p, 3))

    def neutral_at(self) -> NDArray[np.float64]:
        """The current neutral at :attr:`vertex_ids_`, (p, 3)."""
        return self._cur_b0S.copy()

    def deltas_at(self) -> NDArray[np.float64]:
        """The current deltas ``b_i − b0`` at :attr:`vertex_ids_`, (k, p, 3)."""
        return self._cur_DS.copy()

    @property
    def neutral_(self) -> NDArray[np.float64]:
        """The adapted neutral ``b0* + ℓ E z0``, (n, 3)."""
        U0 = self._u[0].reshape(self.n_basis, 3)
        return self._V0 + self.length_scale_ * (self.basis_ @ U0)

    @property
    def shapes_(self) -> NDArray[np.float64]:
        """The adapted deltas ``T_i* b0 − b0 + ℓ E z_i``, (k, n, 3) (one sparse solve per shape)."""
        b0 = self.neutral_
        ell = self.length_scale_
        U = self._u.reshape(-1, self.n_basis, 3)
        k = len(self._names)
        out = np.empty((k, self.model.n_vertices, 3))
        for i in range(k):
            out[i] = self.transfer_.delta(i, b0) + ell * (self.basis_ @ U[i + 1])
        return out

    def to_model(self, name: str | None = None) -> FaceModel:
        """The adapted rig as a new :class:`FaceModel` (same mesh, parts, names and slider ranges).

        Vertex masks are baked into the deltas. The metadata gains a provenance
        entry with the adaptation's settings and frame count.
        """
        m = self.model
        D = self.shapes_
        shapes = [BlendShape(s.name, D[i], slider_min=s.slider_min, slider_max=s.slider_max, mute=s.mute)
                  for i, s in enumerate(m.shapes)]
        meta = m.metadata.with_provenance({
            "step": "capture.AdaptiveModel",
            "frames": int(self.n_frames_),
            "n_basis": self.n_basis,
            "gamma": self.gamma,
            "betas": list(self.betas),
            "coverage": self.coverage,
        })
        if name is not None:
            import dataclasses

            meta = dataclasses.replace(meta, name=name)
        return FaceModel(self.neutral_, m.faces, shapes, polygons=m.polygons, component_labels=m.component_labels,
                         component_names=m.component_names, metadata=meta)

    # ------------------------------------------------------------------ frames
    def _check_x(self, x: ArrayLike) -> NDArray[np.float64]:
        k = len(self._names)
        xv = np.asarray(x, np.float64).reshape(-1)
        if xv.shape != (k,):
            raise ValueError(f"x must have one weight per shape ({k},), got {np.shape(x)}")
        if not np.isfinite(xv).all():
            raise ValueError("x has values that are not finite")
        return xv

    def _local_rows(self, A: Any, c: ArrayLike) -> tuple[sp.csr_matrix, NDArray[np.float64]]:
        """``A`` over all vertex coordinates → its columns at :attr:`vertex_ids_` (m, 3p), checked."""
        n = self.model.n_vertices
        As = sp.csr_matrix(A) if sp.issparse(A) else sp.csr_matrix(np.asarray(A, np.float64))
        if As.ndim != 2 or As.shape[1] != 3 * n:
            raise ValueError(f"A must be (m, {3 * n}) over the stacked vertex coordinates, got {As.shape}")
        m = As.shape[0]
        cv = np.asarray(c, np.float64).reshape(-1)
        if cv.shape != (m,):
            raise ValueError(f"c must have shape ({m},) to match A, got {np.shape(c)}")
        if not (np.isfinite(cv).all() and np.isfinite(As.data).all()):
            raise ValueError("A and c must be finite")
        cols = (3 * self.vertex_ids_[:, None] + np.arange(3)).reshape(-1)
        AS = sp.csr_matrix(As[:, cols])
        total = float(As.multiply(As).sum())
        if abs(float(AS.multiply(AS).sum()) - total) > 1e-9 * max(total, 1e-300):
            raise ValueError("A touches vertices outside vertex_ids_ (pass them as vertex_ids when building the model)")
        return AS, cv

    def _frame_blocks(self, AS: sp.csr_matrix, cv: NDArray[np.float64], xv: NDArray[np.float64]) -> tuple[
        NDArray[np.intp], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
    ]:
        """A frame's rows at the constraint vertices → (active shapes, Q, P, c̄), with ``Ā = [Q, x_1 P, ...]``."""
        k = len(self._names)
        m = AS.shape[0]
        active = np.flatnonzero(xv != 0.0)
        rho = 1.0 / math.sqrt(max(m, 1))
        P = np.asarray(AS @ self._E3) * rho
        if active.size:
            TEx = np.zeros(self._E3.shape)
            for i in active:
                TEx[self._te_rows[i]] += xv[i] * self._te[self._te_off[i]:self._te_off[i + 1]]
            Q = P + np.asarray(AS @ TEx) * rho
        else:
            Q = P.copy()
        pred = (self._b0S + np.tensordot(xv, self._D0S, axes=(0, 0))).reshape(-1) if k else self._b0S.reshape(-1)
        cbar = (cv - AS @ pred) * (rho / self.length_scale_)
        return active, Q, P, cbar

    def frame_system(self, A: Any, c: ArrayLike, x: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """One frame's dense ``(Ā, c̄)`` of eq. 4 over all unknowns ``u`` (for checks on small problems).

        Returns
        -------
        Abar : (m, 3K (k + 1)) float64
        cbar : (m,) float64
        """
        xv = self._check_x(x)
        AS, cv = self._local_rows(A, c)
        _, Q, P, cbar = self._frame_blocks(AS, cv, xv)
        return np.concatenate([Q] + [xi * P for xi in xv], axis=1), cbar

    def _block(self, i: int, j: int) -> NDArray[np.float64]:
        return self._M[(i, j)] if i <= j else self._M[(j, i)].T

    def _add(self, i: int, j: int, blk: NDArray[np.float64]) -> None:
        key = (i, j) if i <= j else (j, i)
        val = blk if i <= j else blk.T
        cur = self._M.get(key)
        if cur is None:
            self._M[key] = val.copy()
            self._nbr[i].add(j)
            self._nbr[j].add(i)
        else:
            cur += val

    def update(self, A: Any, c: ArrayLike, x: ArrayLike) -> AdaptiveModel:
        """Add one frame's constraints and refine (Algorithm 1).

        Parameters
        ----------
        A : (m, 3n) sparse or dense
            Constraint rows over ``[x0, y0, z0, x1, ...]`` in the model's frame
            (:func:`point_to_plane_rows`), touching only :attr:`vertex_ids_`.
        c : (m,) float
            Their targets: ``A (b0 + ΔB x) ≈ c``.
        x : (k,) float
            The frame's weights (from the tracking stage, kept fixed here).

        Returns
        -------
        self
        """
        xv = self._check_x(x)
        AS, cv = self._local_rows(A, c)
        with one_blas_thread():
            return self._update(AS, cv, xv)

    def update_planes(self, rows: ArrayLike, normals: ArrayLike, targets: ArrayLike, x: ArrayLike) -> AdaptiveModel:
        """:meth:`update` with point-to-plane rows ``nᵀ v = target`` at constraint vertices (the tracker's fast path).

        Parameters
        ----------
        rows : (m,) int
            Positions in :attr:`vertex_ids_` (not vertex ids).
        normals : (m, 3) float
            Model frame.
        targets : (m,) float
        x : (k,) float
        """
        xv = self._check_x(x)
        AS, cv = self._plane_rows(rows, normals, targets)
        with one_blas_thread():  # small dense blocks: threads only wait for busy cores
            return self._update(AS, cv, xv)

    def _plane_rows(self, rows: ArrayLike, normals: ArrayLike, targets: ArrayLike) -> tuple[
        sp.csr_matrix, NDArray[np.float64]
    ]:
        r = np.asarray(rows, np.int64).reshape(-1)
        p = self.vertex_ids_.size
        if r.size and (r.min() < 0 or r.max() >= p):
            raise ValueError(f"rows must index vertex_ids_ (0..{p - 1})")
        N = np.asarray(normals, np.float64)
        if N.shape != (r.size, 3):
            raise ValueError(f"normals must be ({r.size}, 3) to match rows, got {N.shape}")
        cv = np.asarray(targets, np.float64).reshape(-1)
        if cv.shape != (r.size,):
            raise ValueError(f"targets must be ({r.size},) to match rows, got {np.shape(targets)}")
        if not (np.isfinite(N).all() and np.isfinite(cv).all()):
            raise ValueError("normals and targets must be finite")
        cols = (3 * r[:, None] + np.arange(3)).reshape(-1)
        AS = sp.csr_matrix((N.reshape(-1), cols, np.arange(0, 3 * r.size + 1, 3)), shape=(r.size, 3 * p))
        return AS, cv

    def fit_neutral(self, A: Any, c: ArrayLike) -> AdaptiveModel:
        """The paper's initialisation (eq. 1): the identity ``z0`` alone from one frame of a neutral face.

        Solves ``min ||Ā0 z0 − c̄||² + β1 ||D_E z0||² + β3 ||z0||²`` with ``x = 0``
        (``Ā0 = A E / √m``), replacing ``z0``; the statistics are not touched (add the
        frame with :meth:`update` and ``x = 0`` when its correspondences are final).
        Alternate it with new correspondences (and the pose) for the Gauss–Newton of eq. 1.

        Parameters
        ----------
        A : (m, 3n) sparse or dense
        c : (m,) float
        """
        AS, cv = self._local_rows(A, c)
        with one_blas_thread():
            return self._fit_neutral(AS, cv)

    def fit_neutral_planes(self, rows: ArrayLike, normals: ArrayLike, targets: ArrayLike) -> AdaptiveModel:
        """:meth:`fit_neutral` with point-to-plane rows at constraint vertices (see :meth:`update_planes`)."""
        AS, cv = self._plane_rows(rows, normals, targets)
        with one_blas_thread():
            return self._fit_neutral(AS, cv)

    def _fit_neutral(self, AS: sp.csr_matrix, cv: NDArray[np.float64]) -> AdaptiveModel:
        xv = np.zeros(len(self._names))
        _, Q, _, cbar = self._frame_blocks(AS, cv, xv)
        H = Q.T @ Q
        H[np.diag_indices_from(H)] += self._reg[0]
        self._u[0] = _spd_solve(H, Q.T @ cbar)
        self._refresh()
        return self

    def _update(self, AS: sp.csr_matrix, cv: NDArray[np.float64], xv: NDArray[np.float64]) -> AdaptiveModel:
        active, Q, P, cbar = self._frame_blocks(AS, cv, xv)
        # decay, then add this frame (stored × g is the unnormalised sum)
        self._s = self.gamma * self._s + 1.0
        self._g *= self.gamma
        if self._g < 1e-150:
            for key in self._M:
                self._M[key] *= self._g
            self._y *= self._g
            self._g = 1.0
        inv_g = 1.0 / self._g
        sat = self.saturated_
        blocks = [0, *(int(i) + 1 for i in active)]
        wts = {0: 1.0, **{int(i) + 1: float(xv[i]) for i in active}}
        PtP = P.T @ P
        QtP = Q.T @ P
        for a_idx, a in enumerate(blocks):
            for b in blocks[a_idx:]:
                if sat[a] and sat[b]:
                    continue  # both fixed for good: never read again
                if a == 0 and b == 0:
                    blk = Q.T @ Q
                elif a == 0:
                    blk = wts[b] * QtP
                else:
                    blk = (wts[a] * wts[b]) * PtP
                self._add(a, b, blk * inv_g)
            self._y[a] += (Q.T @ cbar if a == 0 else wts[a] * (P.T @ cbar)) * inv_g
        # coverage
        self.coverage_[0] += max(1.0 - float(xv.sum()), 0.0)
        self.coverage_[1:] += xv
        self.n_frames_ += 1
        todo = [bk for bk in blocks if not sat[bk]]
        self._gauss_seidel(todo, self.sweeps)
        self.saturated_ |= self.coverage_ > self.coverage
        self._refresh()
        return self

    def _gauss_seidel(self, todo: Sequence[int], sweeps: int) -> None:
        if not todo or self._s == 0:
            return
        f = self._g / self._s  # stored → M^t
        for _ in range(sweeps):
            for bk in todo:
                if (bk, bk) not in self._M:
                    continue
                rhs = self._y[bk].copy()
                for j in self._nbr[bk]:
                    if j != bk:
                        rhs -= self._block(bk, j) @ self._u[j]
                Mbb = f * self._M[(bk, bk)]
                Mbb[np.diag_indices_from(Mbb)] += self._reg[bk]
                self._u[bk] = _spd_solve(Mbb, f * rhs)

    def refine(self, sweeps: int = 10) -> AdaptiveModel:
        """More Gauss–Seidel sweeps over every block with statistics that is not saturated."""
        if isinstance(sweeps, bool) or not isinstance(sweeps, int | np.integer) or sweeps < 1:
            raise ValueError(f"sweeps must be a positive integer, got {sweeps!r}")
        todo = [bk for bk in range(len(self._names) + 1) if not self.saturated_[bk] and (bk, bk) in self._M]
        with one_blas_thread():
            self._gauss_seidel(todo, int(sweeps))
        self._refresh()
        return self

    def statistics(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The aggregated ``(M^t, y^t)`` of Algorithm 1 as dense arrays (small problems; for checks).

        Returns
        -------
        M : (3K (k + 1), 3K (k + 1)) float64
        y : (3K (k + 1),) float64
        """
        nb = len(self._names) + 1
        K3 = 3 * self.n_basis
        f = self._g / self._s if self._s else 0.0
        M = np.zeros((nb * K3, nb * K3))
        for (i, j), blk in self._M.items():
            M[i * K3:(i + 1) * K3, j * K3:(j + 1) * K3] = f * blk
            M[j * K3:(j + 1) * K3, i * K3:(i + 1) * K3] = f * blk.T
        return M, f * self._y.reshape(-1)

    @property
    def regularization_(self) -> NDArray[np.float64]:
        """The diagonal ``D`` of eq. 6, (3K (k + 1),)."""
        return self._reg.reshape(-1).copy()


def _spd_solve(A: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``A⁻¹ b`` for a small SPD ``A`` by Cholesky (LAPACK potrf/potrs).

    ``scipy.linalg.solve(assume_a="pos")`` does the same factorisation but measured
    ~40× slower per 150×150 block on a loaded 2-core machine (scipy 1.17: extra checks,
    and a threaded BLAS whose threads wait for busy cores). These blocks are far too
    small to gain from threads: every public method that solves them (update,
    update_planes, fit_neutral, fit_neutral_planes, refine) holds BLAS to one thread
    with :func:`workbench._blas.one_blas_thread` once, around all its work.
    """
    return sla.cho_solve(sla.cho_factor(A, check_finite=False), b, check_finite=False)


def adaptive_model(adapt: Any, model: Any, vertex_ids: ArrayLike, progress: Callable[[float, str], Any] | None = None,
                   *, error: type[TrackError] = TrackError) -> AdaptiveModel | None:
    """The trackers' ``adapt`` argument → an :class:`AdaptiveModel` on ``vertex_ids`` (or None).

    ``True`` builds one with the defaults, a dict with those options (the tracker sets
    ``vertex_ids`` and ``progress``), ``False`` gives None and an :class:`AdaptiveModel`
    built on ``model`` is used as it is (updated in place). ``None`` is the caller's
    default and must be resolved by it. Anything else raises ``error`` naming ``adapt``.
    """
    say = None if progress is None else (lambda f, msg: progress(0.0, msg))  # frames start at 0
    if adapt is True:
        return AdaptiveModel(model, vertex_ids=vertex_ids, progress=say)
    if adapt is False:
        return None
    if isinstance(adapt, dict):
        if "vertex_ids" in adapt or "progress" in adapt:
            raise error("adapt: the tracker sets vertex_ids and progress itself (pass an AdaptiveModel "
                        "built on the vertices you want to choose them)")
        try:
            return AdaptiveModel(model, vertex_ids=vertex_ids, progress=say, **adapt)
        except (TypeError, ValueError) as exc:
            raise error(f"adapt: {exc}") from None
    if isinstance(adapt, AdaptiveModel):
        if adapt.model.n_vertices != model.n_vertices or adapt.shape_names != list(model.shape_names):
            raise error("adapt: the AdaptiveModel was built on another model (vertices or shapes differ)")
        return adapt
    raise error(f"adapt must be None, a bool, a dict of AdaptiveModel options or an AdaptiveModel, "
                f"got {type(adapt).__name__}")
