"""Expression cloning: a performance of one face played on another (Noh & Neumann 2001).

A performance given as an animated mesh of ``source`` (a scan, another
character, a point cache from another tool) is carried onto ``target`` of any
topology, vertex order and units, as the SIGGRAPH 2006 course describes Noh &
Neumann's expression cloning:

1. **Dense correspondence.** The rigging step's set-up
   (:class:`~workbench.rigging.RigTransfer`: rigid alignment, non-rigid fit of
   the source skin onto the target with the point-to-plane tail
   ``fine_fit=True``, :func:`~workbench.rigging.registration.planar_refine`,
   so a grown jaw is followed, closest points) gives every target skin
   vertex a point (triangle, barycentric coordinates) on the *deformed source
   model* — the source fitted onto the target. The paper's RBF volume morph and
   cylindrical projection play this part there; the rigging fit is ours already
   and holds on open mouths and eye sockets, where a cylindrical projection
   picks the first of several hits. Target vertices whose normal disagrees with
   their closest point (the two sides of a lip contact line, §2.3) borrow their
   neighbours' points, ring by ring, so a lower-lip vertex never follows an
   upper-lip triangle.
2. **Direction and magnitude (§2.2.1-§2.2.2).** At each source vertex a
   matrix ``T`` turns a motion vector with the surface and scales it by the
   local proportions, measured between the source and the deformed source
   (:mod:`~workbench.rigging.clone_motion`): ``motion="frames"`` is the paper
   as printed (local frames of the normal and one edge, ``R = F1 F0ᵀ``; one-ring
   bounding-box ratios with outliers filtered, ``T = S R``);
   ``motion="affine"`` is the fit's local linear map of each one-ring
   (rotation, stretch and shear), smoothed; ``motion="field"``, the default,
   is the Jacobian of a smooth 3-D map fitted to the whole correspondence (a
   thin-plate spline), which also knows how the face stretches along its
   normal — what a one-ring cannot see — and is closer to the truth on the
   generated faces of the benchmark.
3. **Animation (eq. 17–18).** ``m' = T m`` at each source vertex, and each
   target vertex moves by the barycentric blend of its source triangle's
   ``m'``. Steps 2–3 are one sparse matrix (3 n_target × 3 n_source) built
   once: a frame costs one sparse product.

Eyes, teeth and tongue follow as in a rig transfer (matched parts carry the
source part's motion; others move rigidly with the skin around them), except
that with ``motion="field"`` a matched part's motion is mapped by the field's
Jacobian at each of its points — the field is a map of space, so it reaches
inside the mouth — rather than by one map averaged over the skin around the
part (foreign face 7.3 → 6.3 % of the motion, a 1.25× jaw 10.4 → 9.8 %).

Hand-written because no kept library implements expression cloning; the
correspondence, fit and parts are the rigging step's.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence
from os import PathLike

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from workbench.model import FaceModel
from workbench.rigging.clone_motion import (
    AFFINE_SMOOTHING,
    MotionModel,
    _adjacency,
    field_jacobian,
    field_step,
    fit_field,
    local_scales,
    motion_transforms,
)
from workbench.rigging.correspondence import MAP_DISTANCE, Correspondence
from workbench.rigging.sides import Side
from workbench.rigging.transfer import RigTransfer

__all__ = ["ExpressionCloner", "clone_animation", "local_scales"]

Progress = Callable[[float, str], None] | None

#: frames cloned per block (bounds the memory of the parts' step)
_BLOCK = 64


class ExpressionCloner:
    """Set up expression cloning from ``source`` onto ``target`` once; :meth:`clone` plays performances.

    Parameters
    ----------
    source : FaceModel
        The face the performances are animated meshes of (its neutral is ``source.vertices``).
    target : FaceModel or path
        Any face: other topology, vertex order, units and proportions.
    landmarks : sequence of (source_vertex, target_vertex), optional
        Corresponding vertex pairs (as :class:`~workbench.rigging.RigTransfer`).
    motion : {"field", "affine", "frames"}
        How a motion vector turns and scales (:mod:`~workbench.rigging.clone_motion`):
        the Jacobian of a smooth map fitted to the correspondence (default), the
        fit's smoothed local linear map per one-ring, or the paper's frames and
        one-ring box ratios as printed.
    smoothing : float
        The affine model's smoothing length over the source's bounding diagonal.
    progress : callable, optional
        ``progress(fraction, message)`` over the set-up.

    Attributes
    ----------
    transfer_ : RigTransfer
        The correspondence set-up (its report fields: ``alignment``, ``registration``, ``warnings``).
    operator_ : (3 n_skin_t, 3 n_skin_s) sparse
        Source skin motion (working frame) -> target skin motion (working frame), eq. 17–18.
    scales_ : (n_skin_s, 3) float
        The local scale factors (normal, tangent, tangent): the box ratios after the
        outlier filter (``"frames"``), the map's stretches (``"field"``, ``"affine"``).
    transforms_ : (n_skin_s, 3, 3) float
        ``T`` per source skin vertex (working frame), ``m' = T m`` (eq. 16).
    setup_seconds_ : float
    """

    def __init__(self, source: FaceModel, target: FaceModel | str | PathLike[str], *,
                 landmarks: Sequence[tuple[int, int]] | None = None, motion: MotionModel = "field",
                 smoothing: float = AFFINE_SMOOTHING, progress: Progress = None) -> None:
        t0 = time.perf_counter()
        say = progress or (lambda f, m: None)
        self.transfer_ = rt = RigTransfer(source, target, landmarks=landmarks, fine_fit=True,
                                          progress=lambda f, m: say(0.9 * f, m))
        self.source, self.target = rt.source, rt.target
        say(0.9, "motion-vector frames")
        F = np.asarray(rt.src.skin_faces, np.int64)
        # target skin vertex -> source triangle (barycentric), lip-side safe, far ones held still
        self._rows = self._barycentric_rows(rt.correspondence, rt.tgt, F, rt.src.skin_X.shape[0])
        self._set_motion(motion, smoothing)
        self._nearest: NDArray[np.int64] | None = None  # for the nearest-copy peer, on first use
        self.setup_seconds_ = time.perf_counter() - t0
        say(1.0, "set up")

    def with_motion(self, motion: MotionModel, smoothing: float = AFFINE_SMOOTHING) -> ExpressionCloner:
        """A cloner with another motion model on the same correspondence (no second fit)."""
        other = copy.copy(self)
        other._set_motion(motion, smoothing)
        return other

    def _set_motion(self, motion: MotionModel, smoothing: float) -> None:
        """``transforms_``, ``scales_`` and ``operator_`` of ``motion`` on this correspondence."""
        rt = self.transfer_
        self.motion = motion
        X0, X1 = rt.src.skin_X, rt.fit.positions
        field = fit_field(X0, X1, trusted=np.asarray(rt.fit.accepted, bool)) if motion == "field" else None
        self.transforms_, self.scales_ = motion_transforms(
            X0, X1, np.asarray(rt.src.skin_faces, np.int64), motion, smoothing, field=field)
        self.operator_ = self._operator(self._rows, self.transforms_)
        # matched parts (teeth, tongue, eyes) move by the field's map at each of their points, evaluated
        # once here (their points do not change from frame to frame)
        self._part_jacobians: dict[int, NDArray[np.float64]] | None = None
        if field is not None:
            h = field_step(X0)
            self._part_jacobians = {c: field_jacobian(field, P, h) for c, P in rt.parts_motion.matched_points().items()}

    @staticmethod
    def _operator(B: sp.csr_matrix, T: NDArray[np.float64]) -> sp.csr_matrix:
        """(3 n_t, 3 n_s): row block i = sum over source vertices j of B[i, j] * T_j."""
        B = B.tocoo()
        n_t, n_s = B.shape
        i, j, b = B.row, B.col, B.data
        r = (3 * i[:, None, None] + np.arange(3)[None, :, None]).repeat(3, 2)
        c = (3 * j[:, None, None] + np.arange(3)[None, None, :]).repeat(3, 1)
        v = b[:, None, None] * T[j]
        return sp.csr_matrix((v.ravel(), (r.ravel(), c.ravel())), shape=(3 * n_t, 3 * n_s))

    @staticmethod
    def _barycentric_rows(corr: Correspondence, tgt: Side, F: NDArray[np.int64], n_s: int) -> sp.csr_matrix:
        """(n_t, n_s): each target skin vertex's source point as barycentric weights (eq. 18)."""
        n_t = tgt.skin_ids.size
        rows = np.repeat(np.arange(n_t), 3)
        B = sp.csr_matrix((corr.v_bary.ravel(), (rows, F[corr.v_face].ravel())), shape=(n_t, n_s))
        ok = np.asarray(corr.v_ok, bool).copy()
        # far from the source (a neck, a bust): fade out over one more MAP_DISTANCE, then still
        weight = np.clip(2.0 - corr.v_dist / MAP_DISTANCE, 0.0, 1.0)
        todo = (~ok) & (weight > 0)  # near, but its normal disagrees: the other side of a lip line
        if todo.any():  # borrow the done neighbours' source points, ring by ring
            At = _adjacency(np.asarray(tgt.skin_faces, np.int64), n_t)
            for _ in range(8):
                from_done = (At @ sp.diags(ok.astype(np.float64))).tocsr()
                deg = np.asarray(from_done.sum(1)).ravel()
                take = todo & (deg > 0)
                if not take.any():
                    break
                borrowed = sp.diags(1.0 / np.maximum(deg, 1e-300)) @ from_done @ B
                B = (sp.diags((~take).astype(np.float64)) @ B + sp.diags(take.astype(np.float64)) @ borrowed).tocsr()
                ok |= take
                todo &= ~take
        return (sp.diags(np.where(ok, weight, 0.0)) @ B).tocsr()

    # ------------------------------------------------------------------ playing
    def clone(self, frames: ArrayLike, *, progress: Progress = None) -> NDArray[np.float64]:
        """(T, n_target, 3) target meshes playing ``frames`` ((T, n_source, 3) source meshes)."""
        return self._play(_check_frames(frames, self.source.n_vertices), progress=progress)

    def _play(self, P: NDArray[np.float64], *, say_from: float = 0.0, progress: Progress = None
              ) -> NDArray[np.float64]:
        """:meth:`clone` of checked frames; progress runs from ``say_from`` to 1."""
        src_model, tgt_model = self.source, self.target
        rt = self.transfer_
        src, tgt = rt.src, rt.tgt
        Tn = P.shape[0]
        out = np.empty((Tn, tgt_model.n_vertices, 3))
        base = np.asarray(src_model.vertices, np.float64)
        n_ts = tgt.skin_ids.size
        for a in range(0, Tn, _BLOCK):
            b = min(a + _BLOCK, Tn)
            motion = P[a:b] - base  # (k, N, 3) source units
            work = src.frame.linear(motion)  # working frame
            m = work[:, src.skin_ids].reshape(b - a, -1).T  # (3 n_s, k)
            w = np.zeros((b - a, tgt_model.n_vertices, 3))
            w[:, tgt.skin_ids] = np.asarray(self.operator_ @ m).T.reshape(b - a, n_ts, 3)
            rt.parts_motion.fill(motion, w, jacobians=self._part_jacobians)
            out[a:b] = tgt_model.vertices + tgt.frame.inverse_linear(w)
            if progress is not None:
                progress(say_from + (1.0 - say_from) * b / Tn, f"cloned {b} of {Tn} frames")
        return out

    def nearest_copy(self, frames: ArrayLike) -> NDArray[np.float64]:
        """Peer: (T, n_target, 3) where each target vertex copies the motion of the nearest source vertex.

        The naive baseline of the benchmark and the tutorial: the same rigid alignment and
        units as :meth:`clone`, no correspondence, no local frames.
        """
        from scipy.spatial import cKDTree

        P = _check_frames(frames, self.source.n_vertices)
        rt = self.transfer_
        if self._nearest is None:
            self._nearest = cKDTree(rt.src.X).query(rt.tgt.X)[1]
        motion = rt.src.frame.linear(P - self.source.vertices)
        return self.target.vertices + rt.tgt.frame.inverse_linear(motion[:, self._nearest])

    def deformation_transfer(self, frames: ArrayLike) -> NDArray[np.float64]:
        """Peer: (T, n_target, 3) by deformation transfer of each frame's motion (Sumner & Popović).

        One back-substitution of the rig transfer's prefactored Poisson system per frame
        (:meth:`~workbench.rigging.RigTransfer.transfer_motion`).
        """
        P = _check_frames(frames, self.source.n_vertices)
        rt = self.transfer_
        return self.target.vertices + rt.tgt.frame.inverse_linear(rt.transfer_motion(P - self.source.vertices))

    def marker_take(self, frames: ArrayLike, *, markers: int = 120, seed: int = 0
                    ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """The clone as a marker take on the target: ``(vertex_ids (m,), positions (T, m, 3))``.

        ``markers`` face vertices of the target spread out
        (:func:`~workbench.capture.synthetic.spread_face_vertices`); what the Capture tab tracks
        onto the target's rig (solve weights) or replays through its shell (drive handles).
        """
        from workbench.capture.synthetic import spread_face_vertices

        ids = spread_face_vertices(self.target, markers, seed=seed)
        meshes = self.clone(frames)
        return ids, meshes[:, ids]

    def clone_face(self, frames: ArrayLike, times: ArrayLike | None = None, *, fps: float = 30.0,
                   progress: Progress = None) -> FaceModel:
        """The target playing the cloned frames on its timeline (baked frames: every exporter writes it).

        ``times`` (T,) seconds default to ``arange(T) / fps``. The face keeps the target's mesh, parts and
        metadata; its neutral is the first cloned frame and shape ``frame_k`` holds frame k
        (:mod:`workbench.animation.baked_frames`).
        """
        from workbench.animation.baked_frames import baked_frames_model

        meshes = self.clone(frames, progress=progress)
        t = np.arange(len(meshes)) / float(fps) if times is None else np.asarray(times, np.float64).reshape(-1)
        if t.size != len(meshes):
            raise ValueError(f"clone_face: times has {t.size} entries for {len(meshes)} frames")
        return baked_frames_model(meshes, None, t, fps, like=self.target, what="Cloned performance")


def _check_frames(frames: ArrayLike, n: int) -> NDArray[np.float64]:
    P = np.asarray(frames, np.float64)
    if P.ndim == 2:
        P = P[None]
    if P.ndim != 3 or P.shape[1:] != (n, 3):
        raise ValueError(f"clone_animation: frames must have shape (T, {n}, 3) (the source's vertex count), "
                         f"got {P.shape}")
    if P.shape[0] == 0:
        raise ValueError("clone_animation: frames is empty (T = 0)")
    bad = ~np.isfinite(P).all(axis=(1, 2))
    if bad.any():
        raise ValueError(f"clone_animation: frames {np.flatnonzero(bad)[:5].tolist()} hold NaN or inf")
    return P


def clone_animation(frames: ArrayLike, source: FaceModel, target: FaceModel | str | PathLike[str], *,
                    landmarks: Sequence[tuple[int, int]] | None = None, motion: MotionModel = "field",
                    progress: Progress = None) -> NDArray[np.float64]:
    """Play a performance of ``source`` on ``target`` (expression cloning, Noh & Neumann 2001).

    Parameters
    ----------
    frames : (T, n_source, 3) float
        The performance: source meshes (the source's neutral is ``source.vertices``).
    source : FaceModel
    target : FaceModel or path
        Any topology, vertex order and units.
    landmarks : sequence of (source_vertex, target_vertex), optional
    motion : {"field", "affine", "frames"}
        The motion model (:class:`ExpressionCloner`).
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    (T, n_target, 3) float
        Target meshes in the target's units.
    """
    say = progress or (lambda f, m: None)
    P = _check_frames(frames, source.n_vertices)  # fail before the set-up
    cloner = ExpressionCloner(source, target, landmarks=landmarks, motion=motion,
                              progress=lambda f, m: say(0.5 * f, m))
    return cloner._play(P, say_from=0.5, progress=say)
