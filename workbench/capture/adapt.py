"""The dynamic expression model: the rig adapted to the actor while tracking (Bouaziz et al. 2013, §2, §3.2).

A template rig ``B* = [b0*, b1*, ..., bk*]`` (the model's neutral and its
shapes) is adapted online to the face that is being tracked, as in the
paper's *adaptive DEM*:

* **Identity** — the neutral ``b0 = m + P y + ℓ E z0``: the paper's identity
  PCA ``m + P y`` when one is given (``identity=``, :mod:`workbench.capture.identity`:
  for the sample head, built from MakeHuman's modelling targets; ``m`` is the
  template's neutral ``b0*``), solved at the initialisation (:meth:`fit_neutral`,
  eq. 1, prior ``β1 ||D_P y||²``) and then kept; plus a smooth offset in a
  low-dimensional spectral basis ``E`` (the first ``n_basis`` eigenvectors of
  the skin's cotangent Laplacian, ``-L e = λ M e`` with the mass matrix ``M``,
  per coordinate). Without a PCA (a user's own rig has no population of
  scans), **E doubles as the identity basis**: ``z0`` plays both the paper's
  ``y`` and ``z0``, and it is regularised with ``β1`` (the PCA term's weight)
  on the bending ``||D_E z0||²`` plus ``β3 ||z0||²``.
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
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from workbench.blas import one_blas_thread
from workbench.capture.block_statistics import BlockStatistics, spd_solve
from workbench.capture.constraints import (
    check_vertex_ids,
    constraint_rows,
    default_constraint_vertices,
    plane_rows,
    point_to_plane_rows,
)
from workbench.capture.expression_transfer import ExpressionTransfer, TransferRows, sub_faces
from workbench.capture.identity import IdentityModel
from workbench.capture.result import TrackError
from workbench.capture.spectral import laplacian_basis
from workbench.geometry.masks import skin_or_all_mask
from workbench.model import BlendShape, FaceModel

__all__ = ["AdaptiveModel", "ExpressionTransfer", "adaptive_model", "laplacian_basis", "point_to_plane_rows"]

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
    identity : IdentityModel, optional
        The paper's identity PCA ``m + P y`` (:mod:`workbench.capture.identity`, on
        this model's vertices, ``m`` its neutral). :meth:`fit_neutral` then solves
        ``y`` with ``z0`` (eq. 1, ``β1 ||D_P y||²``); without it ``E`` doubles as the
        identity basis.
    lazy_rows : bool, default False
        Build the refinement's transfer rows (a sparse solve per shape with ``3K``
        right-hand sides) only when a frame first needs them (:meth:`update` with weights). Until then :meth:`deltas_at`
        transfers the current neutral exactly. For a rig whose identity is fitted at
        the start and then held (``track_clouds`` without ``refine``).

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
    identity_coefficients_ : (l,) float64
        ``y`` (model units; zeros without ``identity`` or before :meth:`fit_neutral`).
    coverage_ : (k + 1,) float64
        ``σ`` of the neutral (``Σ max(x̄, 0)``) and of every shape.
    saturated_ : (k + 1,) bool
    n_frames_ : int
    transfer_ : ExpressionTransfer
    setup_seconds_ : float
    """

    _cur_DS: NDArray[np.float64] | None

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
        identity: IdentityModel | None = None,
        lazy_rows: bool = False,
    ) -> None:
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
        self.identity: IdentityModel | None = None
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
        Fs = sub_faces(F, skin, n)
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
        self._V0 = V

        # the constraint vertices
        if vertex_ids is None:
            S = default_constraint_vertices(D, skin, ell, self.max_vertices)
        else:
            S = check_vertex_ids(vertex_ids, n)
        self.vertex_ids_ = S
        self._E_S = E[S]  # (p, K)
        self._E3 = np.kron(self._E_S, np.eye(3))  # (3p, 3K)
        local = np.full(n, -1, np.int64)
        local[skin] = np.arange(skin.size)
        # the transfer rows serve the per-frame refinement only: built on its first use (an identity
        # fitted at the start and then held needs only exact transfers of the neutral, see deltas_at)
        self._rows_inputs: tuple[Any, ...] | None = (E_skin, local[S], lambda f, msg: say(0.1 + 0.9 * f, msg))
        self._rows_built: TransferRows | None = None
        if not lazy_rows:
            self._build_rows()
        self._template_b0S = V[S].copy()
        self._template_D0S = D[:, S].copy()
        self._P_S: NDArray[np.float64] | None = None

        # the regularisation diagonal
        dE = lam / lam[-1] if lam[-1] > 0 else np.zeros_like(lam)
        bend = np.repeat(dE**2, 3)
        self._reg = np.stack([b[0] * bend + b[2]] + [b[1] * bend + b[2]] * k) if k else \
            (b[0] * bend + b[2])[None]
        self.use_identity(identity)  # checks it, then reset()
        self.setup_seconds_ = time.perf_counter() - t0
        say(1.0, f"adaptive model ready ({self.setup_seconds_:.1f} s)")

    # ------------------------------------------------------------------ state
    def _build_rows(self) -> TransferRows:
        if self._rows_built is None:
            assert self._rows_inputs is not None
            E_skin, rows, say = self._rows_inputs
            self._rows_built = TransferRows(self.transfer_, E_skin, rows, say, self._names)
            self._rows_inputs = None
        return self._rows_built

    @property
    def _rows(self) -> TransferRows:
        return self._build_rows()

    def reset(self) -> AdaptiveModel:
        """Forget every frame: back to the template (``u = 0``), no statistics."""
        k = len(self._names)
        K3 = 3 * self.n_basis
        self._u = np.zeros((k + 1, K3))
        self._set_identity(np.zeros(0 if self.identity is None else self.identity.n_components))
        self._stats = BlockStatistics(k + 1, K3, self.gamma, self._reg)
        self.coverage_ = np.zeros(k + 1)
        self.saturated_ = np.zeros(k + 1, bool)
        self.n_frames_ = 0
        self._refresh()
        return self

    def use_identity(self, identity: IdentityModel | None) -> AdaptiveModel:
        """Use another identity PCA (or none) from now on; back to the template (:meth:`reset`).

        Cheaper than a new model: the Laplacian basis and the transfer rows are kept.
        """
        if identity is not None:
            if not isinstance(identity, IdentityModel):
                raise TypeError(f"identity must be an IdentityModel, got {type(identity).__name__}")
            if identity.mean.shape != (self.model.n_vertices, 3):
                raise ValueError(f"identity: its mean has {identity.mean.shape[0]} vertices, the model "
                                 f"{self.model.n_vertices}")
        self.identity = identity
        S = self.vertex_ids_
        self._P_S = None if identity is None else identity.basis[:, S].reshape(identity.n_components, -1).T
        return self.reset()

    def _set_identity(self, y: NDArray[np.float64]) -> None:
        """The template at the constraint vertices moved to the identity ``m + P y`` (transfer is linear in b0)."""
        self.identity_coefficients_ = np.asarray(y, np.float64).copy()
        self._id_offset = np.zeros_like(self._V0)
        self._b0S = self._template_b0S.copy()
        self._D0S = self._template_D0S.copy()
        if self.identity is None or not np.any(y):
            return
        off = np.tensordot(self.identity_coefficients_, self.identity.basis, axes=(0, 0))
        self._id_offset = off
        S = self.vertex_ids_
        self._b0S = self._b0S + off[S]
        b0 = self._V0 + off
        for i in range(len(self._names)):  # T_i* b0 − b0 (one sparse solve per shape)
            self._D0S[i] = self.transfer_.delta(i, b0)[S]

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
        if k and self._rows_built is None:
            self._cur_DS = None  # no rows yet (no refinement): exact transfers of the neutral, on demand
        elif k:
            K = self.n_basis
            corr = (self._E_S @ U[1:].transpose(1, 0, 2).reshape(K, 3 * k)).reshape(p, k, 3).transpose(1, 0, 2)
            self._cur_DS = self._D0S + ell * (self._rows.of_neutral(self._u[0]) + corr)
        else:
            self._cur_DS = np.zeros((0, p, 3))

    def neutral_at(self) -> NDArray[np.float64]:
        """The current neutral at :attr:`vertex_ids_`, (p, 3)."""
        return self._cur_b0S.copy()

    def deltas_at(self) -> NDArray[np.float64]:
        """The current deltas ``b_i − b0`` at :attr:`vertex_ids_`, (k, p, 3)."""
        if self._cur_DS is None:
            # the exact transfer of the current neutral (no refinement yet, so no correctives); the
            # refinement's rows give the same to first order, as the transfer is linear in b0
            self._cur_DS = self.shapes_[:, self.vertex_ids_]
        return self._cur_DS.copy()

    @property
    def neutral_(self) -> NDArray[np.float64]:
        """The adapted neutral ``b0* + P y + ℓ E z0``, (n, 3)."""
        U0 = self._u[0].reshape(self.n_basis, 3)
        return self._V0 + self._id_offset + self.length_scale_ * (self.basis_ @ U0)

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
            Q = P + np.asarray(AS @ self._rows.weighted(xv, active)) * rho
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
        AS, cv = constraint_rows(A, c, self.vertex_ids_, self.model.n_vertices)
        _, Q, P, cbar = self._frame_blocks(AS, cv, xv)
        return np.concatenate([Q] + [xi * P for xi in xv], axis=1), cbar

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
        AS, cv = constraint_rows(A, c, self.vertex_ids_, self.model.n_vertices)
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
        AS, cv = plane_rows(rows, normals, targets, self.vertex_ids_.size)
        with one_blas_thread():  # small dense blocks: threads only wait for busy cores
            return self._update(AS, cv, xv)

    def fit_neutral(self, A: Any, c: ArrayLike) -> AdaptiveModel:
        """The paper's initialisation (eq. 1): the identity (``y`` and ``z0``) from one frame of a neutral face.

        Solves ``min ||Ā0 z0 − c̄||² + β1 ||D_E z0||² + β3 ||z0||²`` with ``x = 0``
        (``Ā0 = A E / √m``), replacing ``z0``; with an identity PCA, ``y`` joins it
        (columns ``A P / (√m ℓ)``, prior ``β1 ||D_P y||²``) and replaces the previous ``y``
        (``y`` is not refined online: the neutral frame constrains it, the
        correctives ``z0`` carry on); the statistics are not touched (add the
        frame with :meth:`update` and ``x = 0`` when its correspondences are final).
        Alternate it with new correspondences (and the pose) for the Gauss–Newton of eq. 1.

        Parameters
        ----------
        A : (m, 3n) sparse or dense
        c : (m,) float
        """
        AS, cv = constraint_rows(A, c, self.vertex_ids_, self.model.n_vertices)
        with one_blas_thread():
            return self._fit_neutral(AS, cv)

    def fit_neutral_planes(self, rows: ArrayLike, normals: ArrayLike, targets: ArrayLike) -> AdaptiveModel:
        """:meth:`fit_neutral` with point-to-plane rows at constraint vertices (see :meth:`update_planes`)."""
        AS, cv = plane_rows(rows, normals, targets, self.vertex_ids_.size)
        with one_blas_thread():
            return self._fit_neutral(AS, cv)

    def _fit_neutral(self, AS: sp.csr_matrix, cv: NDArray[np.float64]) -> AdaptiveModel:
        xv = np.zeros(len(self._names))
        if self.identity is not None:
            self._set_identity(np.zeros(self.identity.n_components))  # y and z0 are solved together, from m
        _, Q, _, cbar = self._frame_blocks(AS, cv, xv)
        reg = self._reg[0]
        if self._P_S is not None and self._P_S.shape[1]:
            # [y, z0] jointly, y in model units: its columns and prior scaled like the rows (÷ √m ℓ);
            # β1 of the PCA prior in mm² as the paper's (IdentityModel.prior_weight)
            ident = self.identity
            assert ident is not None
            scale = 1.0 / (math.sqrt(max(AS.shape[0], 1)) * self.length_scale_)
            Q = np.concatenate([np.asarray(AS @ self._P_S) * scale, Q], axis=1)
            reg = np.concatenate([ident.prior_weight(self.betas[0]) * scale**2 / ident.std**2, reg])
        H = Q.T @ Q
        H[np.diag_indices_from(H)] += reg
        sol = spd_solve(H, Q.T @ cbar)
        l_ = sol.size - self._u.shape[1]
        self._u[0] = sol[l_:]
        if l_:
            self._set_identity(sol[:l_])
        self._refresh()
        return self

    def _update(self, AS: sp.csr_matrix, cv: NDArray[np.float64], xv: NDArray[np.float64]) -> AdaptiveModel:
        active, Q, P, cbar = self._frame_blocks(AS, cv, xv)
        blocks = [0, *(int(i) + 1 for i in active)]
        weights = {0: 1.0, **{int(i) + 1: float(xv[i]) for i in active}}
        sat = self.saturated_
        self._stats.add_frame(blocks, weights, Q, P, cbar, sat)
        # coverage
        self.coverage_[0] += max(1.0 - float(xv.sum()), 0.0)
        self.coverage_[1:] += xv
        self.n_frames_ += 1
        self._stats.gauss_seidel(self._u, [bk for bk in blocks if not sat[bk]], self.sweeps)
        self.saturated_ |= self.coverage_ > self.coverage
        self._refresh()
        return self

    def refine(self, sweeps: int = 10) -> AdaptiveModel:
        """More Gauss–Seidel sweeps over every block with statistics that is not saturated."""
        if isinstance(sweeps, bool) or not isinstance(sweeps, int | np.integer) or sweeps < 1:
            raise ValueError(f"sweeps must be a positive integer, got {sweeps!r}")
        todo = [bk for bk in range(len(self._names) + 1) if not self.saturated_[bk] and self._stats.has(bk)]
        with one_blas_thread():
            self._stats.gauss_seidel(self._u, todo, int(sweeps))
        self._refresh()
        return self

    def statistics(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The aggregated ``(M^t, y^t)`` of Algorithm 1 as dense arrays (small problems; for checks).

        Returns
        -------
        M : (3K (k + 1), 3K (k + 1)) float64
        y : (3K (k + 1),) float64
        """
        return self._stats.dense()

    @property
    def regularization_(self) -> NDArray[np.float64]:
        """The diagonal ``D`` of eq. 6, (3K (k + 1),)."""
        return self._reg.reshape(-1).copy()


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
