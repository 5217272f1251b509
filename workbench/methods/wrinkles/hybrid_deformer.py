"""Large-scale shell plus pose-space details, per frame (Bickel et al. 2008, Fig. 2, §6.1).

The large-scale motion of a face comes from a linear shell driven by ``H``
handle vertices (:mod:`workbench.methods.handles.shell`); what it misses is
added from a fitted :class:`~workbench.methods.wrinkles.pose_space.PoseSpace`
of details in local frames (:mod:`workbench.methods.wrinkles.features`):

* :class:`DetailEvaluator` evaluates a fitted pose space on a deforming mesh
  frame by frame (normals, local frames, details) without allocating; it uses
  the numba kernels of :mod:`workbench.methods.wrinkles.kernels` when
  available, else numpy.
* :class:`HybridDeformer` ties the shell, the feature graph, the WPSD edge
  weights and the fit together: examples in, deformed positions out.
* :func:`compare_methods` measures global/local blend shapes, PSD and WPSD
  against ground truth as the basis grows (§6.1, Fig. 4/5).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.geometry.normals import vertex_normals
from workbench.methods.handles.shell import ShellDeformer
from workbench.methods.wrinkles import kernels as _kernels
from workbench.methods.wrinkles.features import (
    FeatureGraph,
    FloatArray,
    _positions,
    edge_weights,
    extract_details,
    local_frames,
    tangent_neighbours,
    to_world,
)
from workbench.methods.wrinkles.pose_space import FitMode, PoseSpace, fit_pose_space, greedy_fit

__all__ = [
    "COMPARISON_METHODS",
    "DetailEvaluator",
    "DetailSet",
    "HybridDeformer",
    "compare_methods",
]


class DetailEvaluator:
    """Per-frame evaluation of a fitted pose space on a deforming mesh: frames + details.

    Holds float32, contiguous copies of everything a frame needs and reuses its
    buffers, so a frame allocates nothing. Uses the numba kernels of
    :mod:`workbench.methods.wrinkles.kernels` when available (``backend="auto"``), else numpy.

    Parameters
    ----------
    pose_space : PoseSpace
        Values must be details in local frames.
    faces : (m, 3) int
    neighbours : (n,) int
        Tangent neighbours (:func:`tangent_neighbours`).
    backend : {"auto", "numba", "numpy"}
    """

    def __init__(self, pose_space: PoseSpace, faces: ArrayLike, neighbours: ArrayLike, backend: str = "auto") -> None:
        if backend not in ("auto", "numba", "numpy"):
            raise ValueError(f"DetailEvaluator: backend must be auto, numba or numpy, got {backend!r}")
        if backend == "numba" and not _kernels.AVAILABLE:
            raise RuntimeError("DetailEvaluator: backend='numba' but numba is not installed")
        self.backend = "numba" if backend != "numpy" and _kernels.AVAILABLE else "numpy"
        self.pose_space = pose_space
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)
        n = pose_space.n_vertices
        self.neighbours = np.ascontiguousarray(neighbours, dtype=np.int32)
        if self.neighbours.shape != (n,):
            raise ValueError(f"DetailEvaluator: neighbours must be ({n},), got {self.neighbours.shape}")
        self.FS = np.ascontiguousarray(pose_space.basis_features, np.float32)
        self.W = np.ascontiguousarray(pose_space.weights, np.float32)
        if pose_space.alpha is not None:
            # edge ids fit in int16 (F is a few hundred): less memory traffic per frame
            idx_type = np.int16 if self.FS.shape[1] < np.iinfo(np.int16).max else np.int32
            self.a_idx = np.ascontiguousarray(pose_space.alpha.index, idx_type)
            self.a_val = np.ascontiguousarray(pose_space.alpha.value, np.float32)
        self.vf_ptr, self.vf_idx = _kernels.vertex_face_csr(self.faces, n)
        self._fbuf = np.empty((self.faces.shape[0], 3), np.float32)
        self._normals = np.zeros((n, 3), np.float32)
        self._all_rows = np.arange(n, dtype=np.int32)
        self._all_faces = np.arange(self.faces.shape[0], dtype=np.int32)
        # vertices with details (non-zero RBF weights; the rest of the head has none)
        # and the faces around them: a frame only touches these
        Wv = np.abs(self.W).max(axis=(1, 2)) if pose_space.alpha is not None else np.abs(self.W).max(axis=(0, 2))
        self.rows = np.flatnonzero(Wv > 0).astype(np.int32)
        touched = np.zeros(n, bool)
        touched[self.rows] = True
        self.face_rows = np.flatnonzero(touched[self.faces].any(axis=1)).astype(np.int32)
        if pose_space.alpha is not None:
            self._W8 = _kernels.pad_poses(self.W)  # WPSD weights in groups of 8 poses
            self._D = np.empty((self.FS.shape[1], self._W8.shape[1]), np.float32)

    def normals(self, X: NDArray[np.float32]) -> NDArray[np.float32]:
        """Unit area-weighted normals of X (n, 3) float32 (an internal buffer; copy to keep)."""
        if self.backend == "numba":
            _kernels.vertex_normals(
                X, self.faces, self.vf_ptr, self.vf_idx, self._all_faces, self._all_rows, self._fbuf, self._normals
            )
        else:
            self._normals[:] = vertex_normals(X, self.faces)
        return self._normals

    def apply(
        self,
        X: ArrayLike,
        features: ArrayLike,
        strength: float = 1.0,
        *,
        add_base: bool = True,
        out: NDArray[np.float32] | None = None,
    ) -> NDArray[np.float32]:
        """``X + strength · R_v d_v(f)`` (or only the detail displacement with ``add_base=False``).

        Parameters
        ----------
        X : (n, 3) float
            Large-scale positions (frames are taken from this surface).
        features : (F,) float
            Strain of the current pose.
        """
        X32 = np.ascontiguousarray(X, np.float32)
        f = np.ascontiguousarray(features, np.float32).reshape(-1)
        if out is None:
            out = np.empty_like(X32)
        ps = self.pose_space
        if self.backend == "numba":
            if ps.alpha is not None:
                # normals and details only where there are details; elsewhere out = X (or 0)
                N = self._normals
                _kernels.vertex_normals(
                    X32, self.faces, self.vf_ptr, self.vf_idx, self.face_rows, self.rows, self._fbuf, N
                )
                if out is not X32:
                    if add_base:
                        np.copyto(out, X32)
                    else:
                        out.fill(0.0)
                D = _kernels.wpsd_pose_table(self.FS, f, self._D)
                _kernels.wpsd_apply(
                    X32, N, self.neighbours, self.rows, self.a_idx, self.a_val, D, self._W8,
                    np.float32(strength), add_base, out,
                )
            else:
                N = self.normals(X32)
                phi = np.ascontiguousarray(ps.distances(f), np.float32)
                _kernels.psd_apply(X32, N, self.neighbours, phi, self.W, np.float32(strength), add_base, out)
            return out
        fr = local_frames(X32, self.faces, self.neighbours)
        d = to_world(fr, ps.evaluate(f)) * strength
        out[:] = X32 + d if add_base else d
        return out


@dataclass
class DetailSet:
    """Training data for a pose space: features and local details of T poses."""

    features: FloatArray  # (T, F)
    details: NDArray[np.float32]  # (T, n, 3) local frames
    large_scale: NDArray[np.float32] | None = None  # (T, n, 3) if kept


class HybridDeformer:
    """Large-scale shell + fine-scale pose-space details in one call (Bickel et al. 2008, Fig. 2).

    Parameters
    ----------
    shell : ShellDeformer
        Built on the rest mesh with the handle vertices.
    graph : FeatureGraph, optional
        Default: :meth:`FeatureGraph.from_handles` on the rest handle positions.
    weighted : bool
        WPSD (True) or global PSD (False).
    beta : float, optional
        WPSD decay (see :func:`edge_weights`).
    neighbours : int
        Nearest handles per handle for the automatic feature graph.
    active : (n,) bool, optional
        Vertices that carry details (others get exactly zero). Default: skin
        vertices (when the shell knows component names) within ``reach`` mean
        feature-edge lengths of the graph (``L_{v,i} − l_i`` of the nearest
        edge) — the face, not the back of the head, the tongue or the eyes,
        whose "details" would only be the shell's large-scale mismatch.
    reach : float
        See ``active``.
    """

    def __init__(
        self,
        shell: ShellDeformer,
        graph: FeatureGraph | None = None,
        *,
        weighted: bool = True,
        beta: float | None = None,
        neighbours: int = 4,
        active: ArrayLike | None = None,
        reach: float = 4.0,
    ) -> None:
        self.shell = shell
        self.rest = shell.vertices
        self.faces = shell.faces
        self.handles = shell.handles
        rest_h = self.rest[self.handles]
        self.graph = graph if graph is not None else FeatureGraph.from_handles(rest_h, neighbours)
        n = self.rest.shape[0]
        ew = edge_weights(self.rest, rest_h, self.graph, beta=beta)
        self.alpha = ew if weighted else None
        self.neighbours = tangent_neighbours(self.faces, n)
        if active is not None:
            self.active = np.asarray(active, bool).reshape(n)
        else:
            self.active = ew.nearest_excess <= reach * float(np.mean(self.graph.rest_lengths))
            names = list(shell.component_names or [])
            if "skin" in names and shell.component_labels is not None:
                self.active &= np.asarray(shell.component_labels).reshape(n) == names.index("skin")
        self.pose_space: PoseSpace | None = None

    def large_scale(self, handle_positions: ArrayLike) -> NDArray[np.float32]:
        """Shell deformation for (H, 3) handle positions, (n, 3) float32."""
        return self.shell.deform(handle_positions)

    def details_of(self, examples: ArrayLike) -> DetailSet:
        """Features and local details of detailed example meshes (T, n, 3) (paper mode)."""
        X = _positions(examples, "examples")
        if X.ndim == 2:
            X = X[None]
        T, n = X.shape[:2]
        feats = np.empty((T, len(self.graph)))
        det = np.empty((T, n, 3), np.float32)
        ls = np.empty((T, n, 3), np.float32)
        for t in range(T):
            p = X[t, self.handles]
            ls[t] = self.large_scale(p)
            feats[t] = self.graph.strain(p)
            det[t] = extract_details(X[t], ls[t], local_frames(ls[t], self.faces, self.neighbours))
        det[:, ~self.active] = 0.0
        return DetailSet(feats, det, ls)

    def fit(
        self,
        examples: ArrayLike | DetailSet,
        *,
        mode: FitMode = "interp",
        max_basis: int | None = None,
        tolerance: float = 0.0,
    ) -> PoseSpace:
        """Fit the pose space to detailed example meshes (T, n, 3) or a :class:`DetailSet`.

        ``interp`` with no ``max_basis`` uses every example; otherwise the basis is
        chosen greedily.
        """
        ds = examples if isinstance(examples, DetailSet) else self.details_of(examples)
        if mode == "interp" and max_basis is None and tolerance == 0.0:
            self.pose_space = fit_pose_space(ds.features, ds.details, alpha=self.alpha, mode="interp")
        else:
            self.pose_space, _ = greedy_fit(
                ds.features, ds.details, alpha=self.alpha, mode=mode, max_basis=max_basis, tolerance=tolerance
            )
        return self.pose_space

    def evaluator(self, backend: str = "auto") -> DetailEvaluator:
        """A per-frame :class:`DetailEvaluator` of the fitted pose space (cached per backend)."""
        if self.pose_space is None:
            raise RuntimeError("HybridDeformer: fit() first")
        cache = self.__dict__.setdefault("_evaluators", {})
        key = (id(self.pose_space), backend)
        if key not in cache:
            cache.clear()
            cache[key] = DetailEvaluator(self.pose_space, self.faces, self.neighbours, backend)
        return cache[key]

    def frame(
        self, handle_positions: ArrayLike, strength: float = 1.0, *, backend: str = "auto",
        out: NDArray[np.float32] | None = None,
    ) -> NDArray[np.float32]:
        """Fast path of :meth:`deform`: ``B·u_H`` + normals + frames + (W)PSD, (n, 3) float32.

        With numba every step is a fused two-thread kernel (no BLAS in the loop).
        """
        p = np.asarray(handle_positions, dtype=np.float64).reshape(-1, 3)
        if p.shape[0] != self.handles.size:
            raise ValueError(f"frame: expected {self.handles.size} handle positions, got {p.shape[0]}")
        if not hasattr(self, "_rest32"):
            self._rest32 = np.ascontiguousarray(self.rest, np.float32)
            self._uniq, self._col = np.unique(self.handles, return_inverse=True)
            self._count = np.bincount(self._col, minlength=self._uniq.size).astype(np.float64)[:, None]
            self._X = np.empty_like(self._rest32)
        d = p - self.rest[self.handles]
        uH = np.zeros((self._uniq.size, 3))
        np.add.at(uH, self._col, d)
        uH = np.ascontiguousarray(uH / self._count, np.float32)
        ev = self.evaluator(backend) if self.pose_space is not None else None
        use_numba = (ev.backend if ev is not None else ("numba" if _kernels.AVAILABLE and backend != "numpy" else "numpy")) == "numba"
        if use_numba:
            _kernels.bmul_add(self.shell.basis_, uH, self._rest32, self._X)
        else:
            np.add(self._rest32, self.shell.basis_ @ uH, out=self._X)
        if ev is None or strength == 0.0:
            if out is None:
                return self._X.copy()
            np.copyto(out, self._X)
            return out
        return ev.apply(self._X, self.graph.strain(p), strength, out=out)

    def deform(self, handle_positions: ArrayLike, strength: float = 1.0) -> NDArray[np.float32]:
        """Large-scale + fine-scale positions for (H, 3) handle positions, (n, 3) float32 (numpy reference)."""
        p = np.asarray(handle_positions, dtype=np.float64).reshape(-1, 3)
        X = self.large_scale(p)
        if self.pose_space is None or strength == 0.0:
            return X
        d = self.pose_space.evaluate(self.graph.strain(p))
        fr = local_frames(X, self.faces, self.neighbours)
        return (X + strength * to_world(fr, d)).astype(np.float32)


# --------------------------------------------------------------------------- comparison (§6.1, Fig. 4/5)

#: method name -> (values are details in local frames?, weighted metric?)
COMPARISON_METHODS: dict[str, tuple[bool, bool]] = {
    "global blend shapes": (False, False),
    "local blend shapes": (False, True),
    "PSD": (True, False),
    "WPSD": (True, True),
}


def compare_methods(
    hybrid: HybridDeformer,
    train: ArrayLike,
    test: ArrayLike | None = None,
    *,
    max_basis: int = 10,
    modes: Sequence[FitMode] = ("interp", "lsq"),
    methods: Sequence[str] | None = None,
) -> list[dict[str, float | int | str]]:
    """L2 error vs basis size for blend shapes, PSD and WPSD (Bickel et al. 2008, §6.1, Fig. 4).

    * **global blend shapes**: RBF (φ(r) = r) interpolation of the *full*
      displacements ``example − rest`` with the global feature distance; no shell.
    * **local blend shapes**: the same with the per-vertex weighted distance (eq. 3).
    * **PSD** / **WPSD**: shell ``B·u_H`` + details in local frames (§5.2 / §5.3).

    Each method is fitted with greedy basis selection from the rest pose, with
    exact interpolation of the chosen poses (``"interp"``) and with least squares
    over the whole training sequence (``"lsq"``).

    Parameters
    ----------
    hybrid : HybridDeformer
        Gives the shell, the feature graph, the edge weights and the face
        region (``hybrid.active``) over which errors are measured.
    train : (T, n, 3) float
        Detailed training frames (ground truth).
    test : (T', n, 3) float, optional
        Held-out frames, evaluated with each fit.
    max_basis : int
        Largest basis (rest pose included).

    Returns
    -------
    list of dict
        One row per (method, mode, basis size): ``method``, ``mode``, ``basis``,
        ``train_rms`` and ``test_rms`` (RMS per-vertex position error over the
        face region, model units), ``test_handle_max`` (largest error at a
        handle vertex on the test frames).
    """
    rest = hybrid.rest
    alpha = hybrid.alpha or edge_weights(rest, rest[hybrid.handles], hybrid.graph)
    mask = hybrid.active
    handle_mask = np.zeros(rest.shape[0], bool)
    handle_mask[hybrid.handles] = True
    sets = {"train": hybrid.details_of(train)}
    full = {"train": (np.asarray(train, np.float64) - rest[None]).astype(np.float32)}
    if test is not None:
        sets["test"] = hybrid.details_of(test)
        full["test"] = (np.asarray(test, np.float64) - rest[None]).astype(np.float32)
        # world error of details at handle vertices: the shell is exact there
        gt_test = np.asarray(test, np.float32)
    rows: list[dict[str, float | int | str]] = []
    for name in methods or list(COMPARISON_METHODS):
        is_detail, weighted = COMPARISON_METHODS[name]
        values = sets["train"].details if is_detail else full["train"]
        for mode in modes:

            def record(P: int, err: float, ps: PoseSpace, name: str = name, mode: str = mode, is_detail: bool = is_detail) -> None:
                row: dict[str, float | int | str] = {"method": name, "mode": mode, "basis": P, "train_rms": err}
                if test is not None:
                    ds = sets["test"]
                    pred = ps.evaluate_many(ds.features)
                    if is_detail:
                        err_v = pred - ds.details
                        assert ds.large_scale is not None
                        hmax = np.abs(ds.large_scale[:, handle_mask] - gt_test[:, handle_mask]).max()
                        hmax = max(hmax, float(np.abs(pred[:, handle_mask]).max()))
                    else:
                        err_v = pred - full["test"]
                        hmax = float(np.linalg.norm(err_v[:, handle_mask], axis=2).max())
                    row["test_rms"] = float(np.sqrt(np.mean(np.sum(err_v[:, mask] ** 2, axis=2))))
                    row["test_handle_max"] = float(hmax)
                rows.append(row)

            greedy_fit(
                sets["train"].features,
                values,
                alpha=alpha if weighted else None,
                mode=mode,
                max_basis=max_basis,
                vertex_mask=mask,
                callback=record,
            )
    return rows
