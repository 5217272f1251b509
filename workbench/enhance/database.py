"""The high-resolution performance database of Bermano et al. 2014, §4 (what §5 matches against).

For detailed frames ``d`` (D, n, 3) of one mesh in full correspondence:

1. **Frequency separation** (§4.2, eq. 1): ``f(d)`` by one implicit
   curvature-flow step plus one uniform Laplacian step
   (:class:`~workbench.enhance.frequency.CurvatureFlowFilter`; sign, scale and
   units of ``λdt`` are pinned there), factored once on the neutral.
2. **High-frequency detail** ``d^h``: per-triangle deformation gradients from
   ``f(d)`` to ``d`` (Sumner–Popović), stored in each low-frequency triangle's
   own orthonormal frame ``R = [t1, t2, n]`` as ``H = Rᵀ T R`` — invariant to
   rigid motions of the frame, so the detail can be put onto another
   low-frequency mesh ``a`` as ``R_a H R_aᵀ`` (§5.4's composition with ``a^ℓ``).
   Stored as float32 (the paper's databases are ~1000 frames).
3. **Compressed shape space** ``D̃`` (§4.2): ``f(d)`` rigidly aligned to the
   low-frequency neutral ``f(d0)`` (Horn), its deformation gradients relative
   to ``f(d0)``, averaged (area-weighted) over seed-and-grow patches of
   ~``patch_size`` vertices (:mod:`workbench.enhance.patches`): 9 numbers per patch.
4. **Voluntary regions** (§4.3, §5.3): soft per-triangle weights ``ω_r`` (given,
   or one region covering everything); per patch their mean, and the region
   normal matrices ``D̃ᵀ diag(ω_r) D̃`` of eq. 3 precomputed.

What §5 needs is served by :meth:`PerformanceDatabase.lowpass`,
:meth:`~PerformanceDatabase.encode`, :meth:`~PerformanceDatabase.compose` and
:meth:`~PerformanceDatabase.reconstruct` (the Poisson solve, factored once on
``f(d0)``). The matching of eq. 2–3 (:meth:`~PerformanceDatabase.match`,
convex weights per region by :class:`~workbench.enhance.matching.SimplexLSQ`, factored once)
and the blending of eq. 4 (:meth:`~PerformanceDatabase.blend_detail`) are here
too; :meth:`~PerformanceDatabase.enhance` chains them per input frame
(:mod:`workbench.enhance.spatial`).

Hand-written because no library implements the paper's database; the
operators are libigl's, the factorizations CHOLMOD's (SuperLU as fallback).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.enhance.errors import DatabaseError
from workbench.enhance.frequency import CurvatureFlowFilter
from workbench.enhance.gradients import (
    PoissonReconstructor,
    deformation_gradients,
    frame_inverses,
    frame_matrices,
    local_frames,
    rigid_align,
)
from workbench.enhance.matching import SimplexLSQ
from workbench.enhance.patches import face_patches, grow_patches
from workbench.enhance.polar import from_polar, to_polar
from workbench.enhance.spatial import Correspondence, EnhanceResult, Progress, enhance_frames
from workbench.geometry.sparse_cholesky import Backend

__all__ = ["DatabaseError", "PerformanceDatabase"]

FORMAT = "workbench.enhance.database/2"
#: version 1 had no detail_blend (matrices, blended as matrices): read as "matrix"
_FORMATS_READ = ("workbench.enhance.database/1", FORMAT)


def _check_mesh(neutral: ArrayLike, faces: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    v = np.asarray(neutral, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3:
        raise DatabaseError(f"neutral must be (n, 3) with n >= 3, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise DatabaseError(f"neutral contains NaN/inf at vertex {int(np.flatnonzero(~np.isfinite(v).all(1))[0])}")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
        raise DatabaseError(f"faces must be (m, 3) triangles with m >= 1, got shape {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        raise DatabaseError(f"faces must be integer vertex indices, got dtype {f.dtype}")
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise DatabaseError(f"faces index vertices in [{f.min()}, {f.max()}] but neutral has {v.shape[0]} vertices")
    return np.ascontiguousarray(v), np.ascontiguousarray(f, dtype=np.int64)


def _check_frames(frames: ArrayLike, n: int) -> NDArray[np.floating[Any]]:
    """The frames as given when they are a float array (no (D, n, 3) float64 copy), else as float64."""
    x = np.asarray(frames)
    if not np.issubdtype(x.dtype, np.floating):
        x = np.asarray(x, dtype=np.float64)
    if x.ndim == 2 and x.shape == (n, 3):
        raise DatabaseError(f"frames must be a stack (D, {n}, 3); got one frame {x.shape} — pass frames[None]")
    if x.ndim != 3 or x.shape[2] != 3:
        raise DatabaseError(f"frames must be (D, n, 3), got shape {x.shape}")
    if x.shape[0] == 0:
        raise DatabaseError("frames is empty: the database needs at least one frame")
    if x.shape[1] != n:
        raise DatabaseError(
            f"frames have {x.shape[1]} vertices per frame but neutral has {n}: the frames must share the neutral's topology"
        )
    bad = ~np.isfinite(x).all(axis=(1, 2))
    if bad.any():
        raise DatabaseError(f"frames contains NaN/inf (frame {int(np.flatnonzero(bad)[0])} of {x.shape[0]})")
    return x


def _check_regions(regions: Any, n: int, faces: NDArray[np.int64]) -> tuple[list[str], NDArray[np.float32]]:
    """Region names and per-triangle weights (R, m) in [0, 1]."""
    m = faces.shape[0]
    if regions is None:
        return ["all"], np.ones((1, m), np.float32)
    if isinstance(regions, Mapping):
        names = [str(k) for k in regions]
        arrays = [np.asarray(regions[k], dtype=np.float64) for k in regions]
    else:
        arr = np.asarray(regions, dtype=np.float64)
        if arr.ndim != 2:
            raise DatabaseError(f"regions must be a mapping name -> weights or an (R, n|m) array, got shape {arr.shape}")
        names = [f"region_{i}" for i in range(arr.shape[0])]
        arrays = list(arr)
    if not arrays:
        raise DatabaseError("regions is empty: pass None for one region covering the whole mesh")
    out = np.zeros((len(arrays), m), np.float32)
    for i, (name, w) in enumerate(zip(names, arrays, strict=True)):
        if w.ndim != 1 or w.shape[0] not in (n, m):
            raise DatabaseError(
                f"regions[{name!r}] must hold one weight per vertex ({n}) or per triangle ({m}), got shape {w.shape}"
            )
        if not np.all(np.isfinite(w)) or w.min() < 0:
            raise DatabaseError(f"regions[{name!r}] must be finite weights >= 0")
        tw = w if w.shape[0] == m and m != n else w[faces].mean(axis=1)
        if tw.max() <= 0:
            raise DatabaseError(f"regions[{name!r}] is zero everywhere")
        out[i] = tw
    return names, out


DetailBlend = Literal["matrix", "polar"]
#: the per-triangle shape of ``detail_`` under each blend: what the blend reads
_DETAIL_SHAPE: dict[str, tuple[int, ...]] = {"matrix": (3, 3), "polar": (9,)}


def _check_detail_blend(value: str) -> DetailBlend:
    if value not in _DETAIL_SHAPE:
        raise DatabaseError(f"detail_blend must be 'matrix' or 'polar', got {value!r}")
    return value  # type: ignore[return-value]


class PerformanceDatabase:
    """Detailed frames encoded for performance enhancement (Bermano et al. 2014, §4).

    Build with :meth:`from_frames` (or :meth:`load`); the constructor takes the
    parameters only, scikit-learn style.

    Parameters
    ----------
    patch_size : int
        Target vertices per patch of the compressed shape space (paper: 100).
    lambda_dt : float
        Implicit curvature-flow step in mm² (paper: 125).
    metres_per_unit : float
        Size of a model unit (0.1 for the decimetre sample head).
    seed : int
        Seed of the patch sampling.
    backend : {"auto", "cholmod", "superlu"}
        Sparse factorization for the filter and the reconstruction.
    detail_blend : {"matrix", "polar"}, default "matrix"
        How eq. 4 blends the detail of several frames: linearly in the 3x3 matrices, or
        in their polar parts (rotation vector and stretch) as the paper does, which
        keeps a rotated fold from shrinking when it is blended with an unrotated one.
        ``"matrix"`` is the default because it is closer to the truth on every
        performance we can generate (their wrinkles add linearly in vertex space, so
        their gradients add linearly too): on the held-out frames of a warped,
        re-triangulated face (``tests/test_enhance_spatial.py``) the detail band's error
        is 0.33 of the input's (median) against 0.43 with ``"polar"``. With captured
        detail, try both (``benchmarks/bench_enhance.py`` validates both on the same frames).

    Attributes
    ----------
    neutral_ : (n, 3) float64
        The detailed neutral ``d0``.
    faces_ : (m, 3) int64
    neutral_low_ : (n, 3) float64
        ``f(d0)``, the reference of the shape space and of the reconstruction.
    detail_ : (D, m, 3, 3) or (D, m, 9) float32
        High-frequency detail ``d^h`` per frame and triangle, in the low-frequency triangle's frame:
        3x3 matrices with ``detail_blend="matrix"``, polar parts (rotation vector, stretch;
        :mod:`workbench.enhance.polar`) with ``"polar"`` — what the blend reads, so that neither
        path converts per frame. :meth:`detail_matrices` gives matrices either way;
        :meth:`set_detail_blend` converts.
    features_ : (D, P, 9) float64
        Compressed shape-space vectors ``D̃`` (row-major patch-mean deformation gradients).
    vertex_patch_ : (n,) int32, face_patch_ : (m,) int32
        Patch of each vertex / triangle.
    region_names_ : list of str
    region_weights_ : (R, m) float32
        Soft per-triangle weights ``ω_r``.
    region_patch_weights_ : (R, P) float64
        ``ω_r`` averaged per patch (the diagonal of eq. 3 on the compressed vectors).
    region_gram_ : (R, D, D) float64
        ``D̃ᵀ diag(ω_r) D̃`` (eq. 3's precomputed normal matrices).
    """

    neutral_: NDArray[np.float64]
    faces_: NDArray[np.int64]
    neutral_low_: NDArray[np.float64]
    detail_: NDArray[np.float32]
    features_: NDArray[np.float64]
    vertex_patch_: NDArray[np.int32]
    face_patch_: NDArray[np.int32]
    region_names_: list[str]
    region_weights_: NDArray[np.float32]
    region_patch_weights_: NDArray[np.float64]
    region_gram_: NDArray[np.float64]

    def __init__(
        self,
        patch_size: int = 100,
        *,
        lambda_dt: float = 125.0,
        metres_per_unit: float = 1e-3,
        seed: int = 0,
        backend: Backend = "auto",
        detail_blend: DetailBlend = "matrix",
    ) -> None:
        self.patch_size = patch_size
        self.lambda_dt = lambda_dt
        self.metres_per_unit = metres_per_unit
        self.seed = seed
        self.backend = backend
        self.detail_blend = detail_blend

    # ------------------------------------------------------------------ build
    @classmethod
    def from_frames(
        cls,
        neutral: ArrayLike,
        faces: ArrayLike,
        frames: ArrayLike,
        *,
        patch_size: int = 100,
        regions: Mapping[str, ArrayLike] | ArrayLike | None = None,
        progress: Progress | None = None,
        lambda_dt: float = 125.0,
        metres_per_unit: float = 1e-3,
        seed: int = 0,
        backend: Backend = "auto",
        detail_blend: DetailBlend = "matrix",
    ) -> PerformanceDatabase:
        """Encode detailed frames into a database.

        Parameters
        ----------
        neutral : (n, 3) float
            The detailed neutral frame ``d0``.
        faces : (m, 3) int
            Triangles shared by the neutral and every frame.
        frames : (D, n, 3) float
            Detailed frames in correspondence with ``neutral`` (head-stabilised or not:
            the shape-space features are computed after a rigid alignment).
        patch_size : int
            Target vertices per patch (paper: 100).
        regions : mapping name -> (n,) or (m,) weights, or (R, n|m) array, optional
            Voluntary regions with soft weights in [0, 1] (§4.3); default one region of ones.
        progress : callable(fraction, message), optional
        lambda_dt, metres_per_unit, seed, backend, detail_blend
            See the class parameters.

        Raises
        ------
        DatabaseError
            Mismatched topology or frame shapes, NaN/inf, an empty frame stack, bad regions
            or a bad ``patch_size`` (the message names the argument).
        """
        say = progress or (lambda f, msg: None)
        v, f = _check_mesh(neutral, faces)
        x = _check_frames(frames, v.shape[0])
        if isinstance(patch_size, bool) or int(patch_size) != patch_size or not 1 <= patch_size <= v.shape[0]:
            raise DatabaseError(f"patch_size must be an integer in [1, {v.shape[0]}], got {patch_size!r}")
        names, region_w = _check_regions(regions, v.shape[0], f)
        _check_detail_blend(detail_blend)
        self = cls(int(patch_size), lambda_dt=lambda_dt, metres_per_unit=metres_per_unit, seed=seed, backend=backend,
                   detail_blend=detail_blend)
        self.neutral_, self.faces_ = v, f
        self.region_names_, self.region_weights_ = names, region_w
        say(0.0, "factoring the curvature-flow operator")
        self._fit_operators()
        say(0.05, "growing patches")
        self.vertex_patch_ = grow_patches(v, f, self.patch_size, seed=seed)
        self.face_patch_ = face_patches(f, self.vertex_patch_)
        self._averager = None
        D, m = x.shape[0], f.shape[0]
        self.detail_ = np.empty((D, m, *_DETAIL_SHAPE[self.detail_blend]), np.float32)
        self.features_ = np.empty((D, self.n_patches_, 9), np.float64)
        chunk = 8
        for s in range(0, D, chunk):
            say(0.1 + 0.85 * s / D, f"encoding frames {s + 1}–{min(D, s + chunk)} of {D}")
            lows = self._filter.transform(x[s : s + chunk])
            for i, low in enumerate(lows):
                self.detail_[s + i] = self._detail(low, np.asarray(x[s + i], np.float64))
                self.features_[s + i] = self.encode(low)
        self._fit_regions()
        say(1.0, f"encoded {D} frames")
        return self

    def _fit_operators(self) -> None:
        self._filter = CurvatureFlowFilter(
            self.lambda_dt, metres_per_unit=self.metres_per_unit, backend=self.backend
        ).fit(self.neutral_, self.faces_)
        self.neutral_low_ = self._filter.transform(self.neutral_)
        self._low_inverse = frame_inverses(frame_matrices(self.neutral_low_, self.faces_))
        self._poisson = PoissonReconstructor(backend=self.backend).fit(self.neutral_low_, self.faces_)
        self._face_area = 0.5 * np.asarray(igl.doublearea(self.neutral_low_, self.faces_)).ravel()
        self._averager: sp.csr_matrix | None = None

    @property
    def n_patches_(self) -> int:
        return int(self.vertex_patch_.max()) + 1

    @property
    def n_frames_(self) -> int:
        return int(self.detail_.shape[0])

    def _patch_mean(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Area-weighted mean of per-triangle rows (m, k) per patch, (P, k)."""
        avg = self._averager
        if avg is None:
            w = self._face_area
            P, m = self.n_patches_, len(self.face_patch_)
            den = np.bincount(self.face_patch_, weights=w, minlength=P)
            S = sp.csr_matrix((w, (self.face_patch_, np.arange(m))), shape=(P, m))
            avg = self._averager = sp.csr_matrix(sp.diags(1.0 / np.where(den > 0, den, 1.0)) @ S)
        return np.asarray(avg @ values)

    def _fit_regions(self) -> None:
        w = self.region_weights_.astype(np.float64).T  # (m, R)
        self.region_patch_weights_ = self._patch_mean(w).T  # (R, P)
        Dt = self.features_.reshape(self.n_frames_, -1)  # (D, 9P)
        om = np.repeat(self.region_patch_weights_, 9, axis=1)  # (R, 9P)
        self.region_gram_ = np.einsum("ik,rk,jk->rij", Dt, om, Dt)
        self._matchers = [SimplexLSQ(g) for g in self.region_gram_]

    def _detail(self, low: NDArray[np.float64], detailed: NDArray[np.float64]) -> NDArray[np.float32]:
        T = deformation_gradients(low, self.faces_, detailed)
        R = local_frames(low, self.faces_)
        H = R.transpose(0, 2, 1) @ T @ R
        return (to_polar(H) if self.detail_blend == "polar" else H).astype(np.float32)

    def detail_matrices(self, index: int) -> NDArray[np.float64]:
        """Frame ``index``'s detail ``H`` as matrices (m, 3, 3)."""
        d = self.detail_[index]
        return from_polar(d) if self.detail_blend == "polar" else d.astype(np.float64)

    def set_detail_blend(self, detail_blend: DetailBlend) -> PerformanceDatabase:
        """Blend the detail as matrices or polar parts from now on (converts :attr:`detail_`; returns self)."""
        mode = _check_detail_blend(detail_blend)
        if mode != self.detail_blend:
            conv = to_polar if mode == "polar" else from_polar
            out = np.empty((*self.detail_.shape[:2], *_DETAIL_SHAPE[mode]), np.float32)
            for i in range(len(out)):
                out[i] = conv(self.detail_[i])
            self.detail_, self.detail_blend = out, mode
        return self

    # ------------------------------------------------------------------ what §5 uses
    def lowpass(self, X: ArrayLike) -> NDArray[np.float64]:
        """``f(X)``: the low-frequency version of a frame (n, 3) or stack (k, n, 3) (eq. 1 + umbrella)."""
        return self._filter.transform(X)

    def low_gradients(self, low: ArrayLike) -> NDArray[np.float64]:
        """Deformation gradients from ``f(d0)`` to a low-frequency frame, (m, 3, 3) (``a^ℓ``)."""
        return deformation_gradients(self.neutral_low_, self.faces_, low, rest_inverse=self._low_inverse)

    def encode(self, low: ArrayLike) -> NDArray[np.float64]:
        """Compressed shape-space vector of a low-frequency frame (n, 3), (P, 9).

        The frame is first rigidly aligned to ``f(d0)`` (Horn), as in §5.2.
        """
        y = np.asarray(low, np.float64)
        R, t = rigid_align(y, self.neutral_low_)
        T = self.low_gradients(y @ R.T + t)
        return self._patch_mean(T.reshape(-1, 9))

    def compose(self, detail: ArrayLike, low: ArrayLike) -> NDArray[np.float64]:
        """Target Jacobians from ``f(d0)`` (m, 3, 3): the detail ``H`` (m, 3, 3) put onto a low-frequency frame.

        ``J = (R H Rᵀ) T^ℓ`` with ``R`` the low frame's triangle frames and ``T^ℓ``
        its gradients from ``f(d0)`` (§5.4).
        """
        y = np.asarray(low, np.float64)
        R = local_frames(y, self.faces_)
        H = np.asarray(detail, np.float64)
        return (R @ H @ R.transpose(0, 2, 1)) @ self.low_gradients(y)

    def reconstruct(self, jacobians: ArrayLike, anchor: ArrayLike) -> NDArray[np.float64]:
        """Poisson reconstruction (§5.5) from Jacobians over ``f(d0)``; each piece placed at ``anchor``'s mean."""
        return self._poisson.solve(jacobians, anchor)

    def place_pieces(self, X: ArrayLike, low: ArrayLike) -> NDArray[np.float64]:
        """Per-vertex translation (n, 3) putting each piece of ``X`` where its low band matches ``low``.

        ``f`` keeps translations, so shifting a piece by the area-weighted mean of
        ``low − f(X)`` over it makes ``f(X)`` and ``low`` share their centroids.
        """
        return self._poisson.piece_shift(np.asarray(low, np.float64) - self.lowpass(X))

    def enhance(
        self, frames: ArrayLike, *, correspondence: Correspondence | None = None, progress: Progress | None = None
    ) -> NDArray[np.float64]:
        """Enhanced frames (T, n, 3) on the database's mesh (§5; :func:`workbench.enhance.spatial.enhance_frames`).

        Parameters
        ----------
        frames : (T, n_in, 3) or (n_in, 3) float
            Input frames: the database's own mesh, or another one through ``correspondence``.
        correspondence : Correspondence, optional
            :meth:`Correspondence.loop` (the database is a Loop subdivision of the input),
            :meth:`Correspondence.from_surface`, or the identity (default).
        progress : callable(fraction, message), optional

        Raises
        ------
        DatabaseError
            Frames of the wrong shape or vertex count, or NaN/inf.
        """
        return self.enhance_result(frames, correspondence=correspondence, progress=progress).frames

    def enhance_result(
        self, frames: ArrayLike, *, correspondence: Correspondence | None = None, progress: Progress | None = None
    ) -> EnhanceResult:
        """Like :meth:`enhance`, with the matched weights per frame and region and the time per stage."""
        return enhance_frames(self, frames, correspondence=correspondence, progress=progress)

    def frame(self, index: int, low: ArrayLike) -> NDArray[np.float64]:
        """Database frame ``index``'s detail put onto ``low`` (n, 3) and reconstructed, (n, 3)."""
        return self.reconstruct(self.compose(self.detail_matrices(index), low), low)

    # ------------------------------------------------------------------ §5 matching and blending
    def match(self, low: ArrayLike) -> NDArray[np.float64]:
        """Convex weights per region (R, D) of a low-frequency frame (n, 3) (§5.3, eq. 2–3).

        The frame is aligned to ``f(d0)`` and encoded (:meth:`encode`); per region the
        weighted projection onto the database's compressed shape space uses the
        precomputed normal matrices :attr:`region_gram_`.
        """
        a = self.encode(low).ravel()  # (9P,)
        Dt = self.features_.reshape(self.n_frames_, -1)  # (D, 9P)
        om = np.repeat(self.region_patch_weights_, 9, axis=1)  # (R, 9P)
        rhs = (om * a) @ Dt.T  # (R, D)
        return np.stack([self._matchers[r].solve(rhs[r]) for r in range(len(rhs))])

    def detail_coefficients(self, weights: ArrayLike) -> tuple[NDArray[np.float32], NDArray[np.int64]]:
        """Eq. 4's per-triangle weight of each active frame, (m, k) float32, and the active frames (k,)."""
        W = np.asarray(weights, np.float64)
        R, D = len(self.region_names_), self.n_frames_
        if W.shape != (R, D):
            raise ValueError(f"weights must be ({R}, {D}) (regions, frames), got {W.shape}")
        om = self.region_weights_.astype(np.float64)
        tot = om.sum(axis=0)
        om = np.where(tot > 0, om / np.where(tot > 0, tot, 1.0), 1.0 / R)  # (R, m)
        active = np.flatnonzero(W.max(axis=0) > 1e-6)
        return (om.T @ W[:, active]).astype(np.float32), active.astype(np.int64)

    def blend_compose(self, weights: ArrayLike, low: ArrayLike) -> NDArray[np.float64]:
        """:meth:`compose` of :meth:`blend_detail`, fused per triangle with numba when it is installed."""
        from workbench.enhance.kernels import NUMBA, blend_compose

        if not NUMBA:
            return self.compose(self.blend_detail(weights), low)
        C, active = self.detail_coefficients(weights)
        y = np.asarray(low, np.float64)
        return blend_compose(C, active, self.detail_, local_frames(y, self.faces_), self.low_gradients(y))

    def blend_detail(self, weights: ArrayLike) -> NDArray[np.float64]:
        """Detail ``b^h`` (m, 3, 3) blended from per-region weights (R, D) by eq. 4.

        With ``detail_blend="polar"`` the blend is linear in the polar parts (rotation
        vectors and stretches, the paper's shape space), then turned back into matrices;
        with ``"matrix"`` linear in the matrices. Triangles outside every region (all
        ``ω = 0``) take the regions' mean.
        """
        C, active = self.detail_coefficients(weights)
        out = np.zeros((C.shape[0], *self.detail_.shape[2:]), np.float32)
        for j, i in enumerate(active):  # k is small (the convex weights are sparse): one axpy per frame
            out += C[:, j].reshape(-1, *([1] * (self.detail_.ndim - 2))) * self.detail_[i]
        return from_polar(out) if self.detail_blend == "polar" else out.astype(np.float64)

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the database as ``.npz`` (no pickles), atomically (temp file + ``os.replace``)."""
        p = Path(path)
        arrays: dict[str, NDArray[Any]] = {
            "format": np.array(FORMAT),
            "patch_size": np.array(self.patch_size, np.int64),
            "lambda_dt": np.array(self.lambda_dt, np.float64),
            "detail_blend": np.array(self.detail_blend),
            "metres_per_unit": np.array(self.metres_per_unit, np.float64),
            "seed": np.array(self.seed, np.int64),
            "neutral": self.neutral_,
            "faces": self.faces_,
            "detail": self.detail_,
            "features": self.features_,
            "vertex_patch": self.vertex_patch_,
            "face_patch": self.face_patch_,
            "region_names": np.array(self.region_names_, dtype=str),
            "region_weights": self.region_weights_,
        }
        fd, tmp = tempfile.mkstemp(prefix=p.name + ".", suffix=".tmp", dir=p.parent or ".")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **arrays)  # type: ignore[arg-type]
            os.replace(tmp, p)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        return p

    @classmethod
    def load(cls, path: str | os.PathLike[str], *, backend: Backend = "auto") -> PerformanceDatabase:
        """Read a database written by :meth:`save` (operators are refactored, features read back exactly)."""
        try:
            with np.load(Path(path), allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise DatabaseError(f"path {str(path)!r} is not a readable database file: {exc}") from None
        if str(data.get("format", "")) not in _FORMATS_READ:
            raise DatabaseError(f"path {str(path)!r} is not a {FORMAT} file (format {data.get('format')!r})")
        self = cls(
            int(data["patch_size"]),
            lambda_dt=float(data["lambda_dt"]),
            detail_blend=_check_detail_blend(str(data.get("detail_blend", "matrix"))),
            metres_per_unit=float(data["metres_per_unit"]),
            seed=int(data["seed"]),
            backend=backend,
        )
        self.neutral_, self.faces_ = _check_mesh(data["neutral"], data["faces"])
        self.detail_ = data["detail"]
        self.features_ = data["features"]
        self.vertex_patch_ = data["vertex_patch"]
        self.face_patch_ = data["face_patch"]
        self.region_names_ = [str(s) for s in data["region_names"]]
        self.region_weights_ = data["region_weights"]
        n, m = len(self.neutral_), len(self.faces_)
        D = self.detail_.shape[0]
        if (
            self.detail_.shape[1:] != (m, *_DETAIL_SHAPE[self.detail_blend])
            or self.features_.shape[0] != D
            or self.vertex_patch_.shape != (n,)
            or self.face_patch_.shape != (m,)
            or self.features_.shape[1:] != (int(self.vertex_patch_.max()) + 1, 9)
            or self.region_weights_.shape != (len(self.region_names_), m)
        ):
            raise DatabaseError(f"path {str(path)!r}: the arrays do not fit together (a damaged or edited file)")
        self._fit_operators()
        self._fit_regions()
        return self
