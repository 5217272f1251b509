"""Rig any face: carry a template's blendshapes onto another mesh (Sumner & Popovic 2004, as Li et al. 2010 §3).

:class:`RigTransfer` does it in two phases, so the expensive part runs once:

**Set-up** (``RigTransfer(source, target)``)

1. *Frames.* Both models go to metres with the subject's left, up and front
   along x, y, z (``metadata.units``, ``up_axis``, ``front_axis``), in units of
   the template's head size.
2. *Rigid alignment* (:mod:`.registration`): a similarity from landmark pairs
   ``(source_vertex, target_vertex)`` when given (>= 3), else from the eyeball
   centres when both models have eyes (:attr:`FaceModel.part_roles`), else by
   lining up the top of the head and the centroid of the head's upper half
   (scale from the units, or from the head's width when the units disagree
   with it by more than 1.5x); then trimmed ICP with scale.
3. *Non-rigid fit* of the template skin onto the target skin (ICP with a
   smooth displacement, stiff to soft, on CHOLMOD; far, normal-incompatible and
   border correspondences rejected, so a neck, a bust, holes and noise do not
   pull it). Landmarks are soft constraints throughout.
4. *Correspondence:* every target skin triangle (its centroid) and vertex gets
   the closest point of the fitted template (triangle + barycentric) when it is
   near and its normal agrees. Target parts (eyes, lashes, teeth, tongue) are
   matched to the template's parts by role; unmatched ones stay fixed (eyeballs,
   upper teeth), move rigidly with the nearest skin (lower teeth, tongue) or
   follow the skin under them (lashes, brows, hair, anything else).
5. *Factorisation:* the Poisson system ``(D^T A D + P) d = D^T A g`` on the
   target skin (``D`` the per-triangle gradient, ``A`` the triangle areas, ``P``
   a pin holding target vertices still where the template has no partner or
   never moves), factored once with CHOLMOD.

**Transfer** (:meth:`RigTransfer.run`)

Per shape, the template's deformation gradient of each triangle
``G = M' M^-1`` (Sumner & Popovic's frames with the scaled normal as third
column) is carried to the target triangles that map to it, conjugated by the
fit's local Jacobian ``J`` (``J G J^-1``: the shape seen through the warp from
template to target, so a wider face gets a wider smile and a tilted jaw opens
along its own axis), and the displacement ``d`` whose triangle gradients match
``(G - I)`` in the tangent planes is one back-substitution; all shapes go as one
multi-column solve. Names, slider ranges, mute and vertex masks (interpolated)
are carried over; the target keeps its own mesh, polygons, parts and units.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from os import PathLike
from typing import Any, Literal

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.core.shapes import UNIT_TO_METRES, BlendShape
from workbench.geometry.axes import AxesError, face_axes
from workbench.geometry.frames import triangle_frames
from workbench.geometry.masks import MissingPartError, skin_surface
from workbench.geometry.normals import face_normals, vertex_normals
from workbench.geometry.parts import RIGID_ROLES
from workbench.geometry.similarity import Similarity, fit_similarity
from workbench.geometry.sparse_cholesky import SparseSPDSolver
from workbench.geometry.surface import SurfaceQuery
from workbench.model import FaceModel, ModelMetadata
from workbench.rigging.registration import affine_icp, nonrigid_icp, rigid_icp
from workbench.rigging.report import RigTransferError, ShapeQuality, StretchMeter, TransferReport

__all__ = ["RigTransfer", "TransferResult", "transfer_rig", "transfer_rig_report"]

logger = logging.getLogger(__name__)

Progress = Callable[[float, str], None] | None
Conjugation = Literal["jacobian", "rotation", "none"]

#: correspondences farther than this (head units, ~4 mm on an adult head) from the fitted template are dropped
MAP_DISTANCE = 0.01
#: below this cosine between normals a correspondence is dropped
MAP_NORMAL_COS = 0.3


# --------------------------------------------------------------------------- inputs


@dataclass
class _Side:
    """One model in the working frame: skin, parts, roles."""

    model: FaceModel
    frame: Similarity  # model coordinates -> working frame
    skin_ids: NDArray[np.int64]  # model vertex ids of the skin
    skin_faces: NDArray[np.int64]  # local (into skin_ids)
    X: NDArray[np.float64]  # all vertices in the working frame
    roles: tuple[str, ...]

    @property
    def skin_X(self) -> NDArray[np.float64]:
        return self.X[self.skin_ids]


def _canonical(model: FaceModel) -> Similarity:
    """Model coordinates -> metres, subject's left / up / front as x / y / z."""
    try:
        axes = face_axes(model)
    except AxesError as e:
        raise RigTransferError(str(e)) from None
    return Similarity(UNIT_TO_METRES[model.metadata.units], axes, np.zeros(3))


def _skin(model: FaceModel, what: str) -> tuple[NDArray[np.int64], NDArray[np.int64], tuple[str, ...]]:
    """The skin surface (model ids, local triangles) and the part roles; raises when there is none."""
    if np.asarray(model.faces).size == 0:
        raise RigTransferError(f"{what} {model.metadata.name or 'model'}: the mesh has no triangles")
    try:
        ids, faces = skin_surface(model)
    except MissingPartError as e:
        raise RigTransferError(f"{what} {e}") from None
    return ids, faces, tuple(model.part_roles)


def _check_surface(X: NDArray[np.float64], F: NDArray[np.int64], what: str) -> tuple[NDArray[np.bool_], list[str]]:
    """Degenerate and non-manifold checks: (usable face mask, warnings); raises when nothing usable is left."""
    warnings: list[str] = []
    if F.shape[0] < 4:
        raise RigTransferError(f"{what}: the skin has {F.shape[0]} triangles; a face needs a surface")
    area = 0.5 * np.linalg.norm(face_normals(X, F, unit=False), axis=1)
    scale = float(np.median(area)) if area.size else 0.0
    if not np.isfinite(scale) or scale <= 0:
        raise RigTransferError(f"{what}: the skin's triangles are degenerate (zero area)")
    good = area > 1e-8 * scale
    bad = int((~good).sum())
    if bad > 0.05 * F.shape[0]:
        raise RigTransferError(
            f"{what}: {bad} of {F.shape[0]} skin triangles are degenerate (zero area); clean the mesh first"
        )
    if bad:
        warnings.append(f"{what}: {bad} degenerate (zero-area) skin triangles left out of the solve")
    n = X.shape[0]
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    nm = int((counts > 2).sum())
    if nm > 0.01 * counts.size:
        raise RigTransferError(
            f"{what}: {nm} non-manifold edges (shared by more than two triangles) in the skin; "
            "the mesh is not a surface — split or clean it first"
        )
    if nm:
        warnings.append(f"{what}: {nm} non-manifold skin edges (shared by more than two triangles)")
    return good, warnings


def _part_centre(side: _Side, comp: int) -> NDArray[np.float64]:
    ids = np.flatnonzero(side.model.component_labels == comp)
    return side.X[ids].mean(0)


def _eye_centres(side: _Side) -> NDArray[np.float64] | None:
    """(2, 3) left and right eyeball centres (working frame), or None."""
    roles = side.roles
    if "eyeball_left" in roles and "eyeball_right" in roles:
        return np.stack([_part_centre(side, roles.index("eyeball_left")), _part_centre(side, roles.index("eyeball_right"))])
    return None


# --------------------------------------------------------------------------- the transfer


@dataclass
class TransferResult:
    """The rigged target and how the transfer went."""

    model: FaceModel
    report: TransferReport


@dataclass(frozen=True)
class SkinCorrespondence:
    """Target skin vertex -> template triangle, read-only views of a :class:`RigTransfer`.

    Attributes
    ----------
    matched : (n_t,) bool
        The vertex found a template triangle.
    face : (n_t,) int
        Template triangle of each target vertex (meaningful where ``matched``).
    bary : (n_t, 3) float
        Barycentric coordinates in that triangle.
    jacobians : (m_s, 3, 3) float
        Per template triangle, the fit's linear map from template rest to fitted frame.
    """

    matched: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    jacobians: np.ndarray


class RigTransfer:
    """Set up a transfer from ``source`` (a rig) to ``target`` (a mesh); :meth:`run` does it.

    Parameters
    ----------
    source : FaceModel
        The template rig (its blendshapes are transferred).
    target : FaceModel or path
        The face to rig (a path is read with :func:`workbench.load`). Its own
        shapes, if any, are kept unless a template shape has the same name.
    landmarks : sequence of (source_vertex, target_vertex), optional
        Corresponding vertex pairs; with three or more they fix the rigid
        alignment, and all of them pull the fit.
    progress : callable, optional
        ``progress(fraction, message)`` over set-up and transfer.
    conjugation : {"jacobian", "rotation", "none"}
        How template gradients are seen on the target: through the fit's local
        Jacobian (default), its rotation only, or as they are (plain
        deformation transfer).

    Raises
    ------
    RigTransferError
        The inputs cannot be transferred (no shapes, no skin, degenerate or
        non-manifold surface, a target that does not look like a face); the
        message names what is wrong. Nothing is built.
    """

    def __init__(
        self,
        source: FaceModel,
        target: FaceModel | str | PathLike[str],
        *,
        landmarks: Sequence[tuple[int, int]] | None = None,
        progress: Progress = None,
        conjugation: Conjugation = "jacobian",
    ) -> None:
        t0 = time.perf_counter()
        self._progress = progress
        if not isinstance(source, FaceModel):
            raise TypeError(f"transfer_rig: source must be a FaceModel, got {type(source).__name__}")
        if not isinstance(target, FaceModel):
            if isinstance(target, str | PathLike):
                from workbench.io import load

                target = load(target)
            else:
                raise TypeError(f"transfer_rig: target must be a FaceModel or a path, got {type(target).__name__}")
        if not source.shapes:
            raise RigTransferError(f"source {source.metadata.name or 'model'}: has no blendshapes to transfer")
        if conjugation not in ("jacobian", "rotation", "none"):
            raise ValueError(f"conjugation must be 'jacobian', 'rotation' or 'none', got {conjugation!r}")
        self.source = source
        self.target = target
        self.conjugation = conjugation
        self.warnings: list[str] = []
        self._say(0.0, "checking the meshes")
        self._landmarks = self._check_landmarks(landmarks)

        # 1. frames: template head size = 1
        s_ids, s_F, s_roles = _skin(source, "source")
        t_ids, t_F, t_roles = _skin(target, "target")
        cs, ct = _canonical(source), _canonical(target)
        S0 = cs(source.vertices[s_ids])
        centre = S0.mean(0)
        head = float(np.linalg.norm(S0.max(0) - S0.min(0)))
        to_work = Similarity(1.0 / head, np.eye(3), -centre / head)
        src_frame = cs.then(to_work)
        self.head_metres = head
        self.src = _Side(source, src_frame, s_ids, s_F, src_frame(source.vertices), s_roles)
        tgt_frame0 = ct.then(to_work)
        tgt0 = _Side(target, tgt_frame0, t_ids, t_F, tgt_frame0(target.vertices), t_roles)
        _, w = _check_surface(self.src.skin_X, s_F, "source")
        self.warnings += w
        self._t_good, w = _check_surface(tgt0.skin_X, t_F, "target")
        self.warnings += w

        # 2. rigid alignment (of the target onto the template)
        self._say(0.02, "rigid alignment")
        self.tgt, self.alignment = self._align(tgt0)

        # 3. non-rigid fit of the template skin onto the target skin
        self._say(0.08, "non-rigid fit")
        self._t_query = SurfaceQuery(self.tgt.skin_X, t_F[self._t_good])
        lms = None
        if self._landmarks:
            sl = np.array([a for a, _ in self._landmarks], np.int64)
            tl = np.array([b for _, b in self._landmarks], np.int64)
            s_local = np.full(source.n_vertices, -1, np.int64)
            s_local[s_ids] = np.arange(s_ids.size)
            keep = s_local[sl] >= 0
            if keep.any():
                lms = (s_local[sl[keep]], self.tgt.X[tl[keep]])
        A, b = affine_icp(self.src.skin_X, s_F, self._t_query)
        fit = nonrigid_icp(
            self.src.skin_X @ A.T + b, s_F, self._t_query, landmarks=lms,
            progress=None if progress is None else (lambda f, m: self._say(0.08 + 0.72 * f, m)),
        )
        self.fit = fit
        self.registration = self._judge_fit(fit)

        # 4. correspondence, parts, 5. the factorisation
        self._say(0.82, "correspondence")
        self._correspond()
        self._say(0.88, "parts")
        self._match_parts()
        self._say(0.9, "factoring the Poisson system")
        self._factor()
        self._src_quality = self._source_quality()
        self.setup_seconds = time.perf_counter() - t0
        self._say(0.95, "set up")

    # ------------------------------------------------------------------ helpers
    def _say(self, f: float, msg: str) -> None:
        if self._progress is not None:
            self._progress(float(min(max(f, 0.0), 1.0)), msg)

    def _check_landmarks(self, landmarks: Sequence[tuple[int, int]] | None) -> list[tuple[int, int]]:
        if landmarks is None:
            return []
        out = []
        for i, pair in enumerate(landmarks):
            try:
                a, b = (int(x) for x in pair)
            except (TypeError, ValueError):
                raise RigTransferError(f"landmarks[{i}]: expected a (source_vertex, target_vertex) pair, got {pair!r}") from None
            if not 0 <= a < self.source.n_vertices:
                raise RigTransferError(f"landmarks[{i}]: source vertex {a} is outside 0..{self.source.n_vertices - 1}")
            if not 0 <= b < self.target.n_vertices:
                raise RigTransferError(f"landmarks[{i}]: target vertex {b} is outside 0..{self.target.n_vertices - 1}")
            out.append((a, b))
        return out

    # ------------------------------------------------------------------ 2. rigid
    def _align(self, tgt0: _Side) -> tuple[_Side, dict[str, Any]]:
        """Move the target into the template's frame; returns the moved side and what was done."""
        S = self.src.skin_X
        T = tgt0.skin_X
        info: dict[str, Any] = {}
        # an initial similarity template -> target
        if len(self._landmarks) >= 3:
            a = np.array([p[0] for p in self._landmarks])
            b = np.array([p[1] for p in self._landmarks])
            init = fit_similarity(self.src.X[a], tgt0.X[b])
            info["method"] = "landmarks"
        else:
            es, et = _eye_centres(self.src), _eye_centres(tgt0)
            if es is not None and et is not None and np.linalg.norm(es[0] - es[1]) > 0 and np.linalg.norm(et[0] - et[1]) > 0:
                init = self._two_point(es, et)
                info["method"] = "eyes"
            else:
                init = self._head_top(S, T)
                info["method"] = "head top"
        query = SurfaceQuery(T, tgt0.skin_faces[self._t_good])
        lms = None
        if self._landmarks:
            a = np.array([p[0] for p in self._landmarks])
            b = np.array([p[1] for p in self._landmarks])
            s_local = np.full(self.source.n_vertices, -1, np.int64)
            s_local[self.src.skin_ids] = np.arange(self.src.skin_ids.size)
            keep = s_local[a] >= 0
            if keep.any():
                lms = (s_local[a[keep]], tgt0.X[b[keep]])
        sim, share, med = rigid_icp(S, self.src.skin_faces, query, init, landmarks=lms, landmark_weight=0.5)
        inv = Similarity(1.0 / sim.scale, sim.R.T, -(sim.t @ sim.R) / sim.scale)  # target -> template frame
        frame = tgt0.frame.then(inv)
        moved = _Side(tgt0.model, frame, tgt0.skin_ids, tgt0.skin_faces, frame(tgt0.model.vertices), tgt0.roles)
        # scale in target units per template unit
        units = self.source.metadata.metres_per_unit / self.target.metadata.metres_per_unit
        ang = float(np.degrees(np.arccos(np.clip((np.trace(sim.R) - 1) / 2, -1, 1))))
        info.update(scale=float(sim.scale * units), rotation_deg=ang, accepted=share,
                    median_distance=float(med * self.head_metres / self.target.metadata.metres_per_unit))
        if not 0.5 <= sim.scale <= 2.0:
            self.warnings.append(
                f"target: the head is {sim.scale:.2f}x the template's size in metres; check the target's units "
                f"({self.target.metadata.units!r})"
            )
        return moved, info

    @staticmethod
    def _two_point(es: NDArray[np.float64], et: NDArray[np.float64]) -> Similarity:
        """Similarity taking the template's eye centres to the target's, keeping up as up."""

        def frame(e: NDArray[np.float64]) -> NDArray[np.float64]:
            x = e[0] - e[1]
            x /= np.linalg.norm(x)
            up = np.array([0.0, 1.0, 0.0])
            y = up - (up @ x) * x
            y /= np.linalg.norm(y)
            return np.stack([x, y, np.cross(x, y)], 1)

        R = frame(et) @ frame(es).T
        s = float(np.linalg.norm(et[0] - et[1]) / np.linalg.norm(es[0] - es[1]))
        t = et.mean(0) - s * (es.mean(0) @ R.T)
        return Similarity(s, R, t)

    def _head_top(self, S: NDArray[np.float64], T: NDArray[np.float64]) -> Similarity:
        """Line up the top of the head and the centroid of the head's upper half (scale from the units)."""
        height = float(S[:, 1].max() - S[:, 1].min())
        s = 1.0
        for _ in range(3):
            bs = S[S[:, 1] > S[:, 1].max() - 0.5 * height]
            bt = T[T[:, 1] > T[:, 1].max() - 0.5 * height * s]
            ws = float(np.sqrt(((bs[:, [0, 2]] - bs[:, [0, 2]].mean(0)) ** 2).sum(1).mean()))
            wt = float(np.sqrt(((bt[:, [0, 2]] - bt[:, [0, 2]].mean(0)) ** 2).sum(1).mean()))
            geo = wt / ws if ws > 0 else 1.0
            if 1 / 1.5 <= geo <= 1.5:
                break
            s = geo
        if s != 1.0:
            self.warnings.append(
                f"target: its units ({self.target.metadata.units!r}) make the head {geo:.2f}x the template's width; "
                "scaled by the head's size instead"
            )
        bs = S[S[:, 1] > S[:, 1].max() - 0.5 * height]
        bt = T[T[:, 1] > T[:, 1].max() - 0.5 * height * s]
        cs_, ct_ = bs.mean(0), bt.mean(0)
        t = np.array([ct_[0] - s * cs_[0], T[:, 1].max() - s * S[:, 1].max(), ct_[2] - s * cs_[2]])
        return Similarity(s, np.eye(3), t)

    # ------------------------------------------------------------------ 3. fit quality
    def _judge_fit(self, fit: Any) -> dict[str, Any]:
        """Registration quality on the template's face (the skin its shapes move); raises if it is no face."""
        S0 = self.src.skin_X
        F = self.src.skin_faces
        stretch, flipped = StretchMeter(S0, F).measure(fit.positions - S0)
        area = 0.5 * np.linalg.norm(face_normals(S0, F, unit=False), axis=1)
        disp = np.stack([sh.delta[self.src.skin_ids] for sh in self.source.shapes])
        big = float(np.abs(disp).max())
        face_v = (np.linalg.norm(disp, axis=2) > 0.02 * big).any(0) if big > 0 else np.ones(S0.shape[0], bool)
        face_t = face_v[F].any(1)
        bad = (stretch > 2.0) | flipped
        distortion = float(area[bad & face_t].sum() / max(area[face_t].sum(), 1e-300))
        coverage = float(fit.accepted[face_v].mean())
        to_t = self.head_metres / self.target.metadata.metres_per_unit
        d = fit.distance[face_v & fit.accepted] if (face_v & fit.accepted).any() else fit.distance[face_v]
        med = float(np.median(d))
        p95 = float(np.percentile(d, 95))
        info = dict(coverage=coverage, head_coverage=float(fit.accepted.mean()), median_residual=med * to_t,
                    p95_residual=p95 * to_t, distortion=distortion, iterations=fit.iterations)
        problems = []
        if coverage < 0.8:
            problems.append(f"only {coverage:.0%} of the template's face found target surface near it")
        if distortion > 0.05:
            problems.append(f"fitting the template onto it stretched or folded {distortion:.0%} of the template's face")
        if med > 0.01:
            problems.append(f"the fitted template stays {med * self.head_metres * 1000:.1f} mm (median) off its surface")
        if problems:
            raise RigTransferError(
                f"target {self.target.metadata.name or ''}: does not look like a face the template can be fitted to: "
                + "; ".join(problems)
                + ". Check its up/front axes and units, or give landmark pairs."
            )
        if distortion > 0.01:
            self.warnings.append(f"fit: {distortion:.1%} of the template's face stretched beyond 2x or folded")
        if coverage < 0.95:
            self.warnings.append(f"fit: {1 - coverage:.0%} of the template's face found no target surface (holes?)")
        return info

    # ------------------------------------------------------------------ 4. correspondence
    def _correspond(self) -> None:
        src_F = self.src.skin_faces
        fitted = self.fit.positions
        q = SurfaceQuery(fitted, src_F)
        Y = self.tgt.skin_X
        tF = self.tgt.skin_faces
        good = self._t_good
        Fg = tF[good]
        # triangles: centroid -> template triangle (face normals must agree)
        cen = Y[Fg].mean(1)
        d, face, _, _ = q.closest(cen)
        fallback = face.copy()
        tn = face_normals(Y, Fg)
        ok = (d < MAP_DISTANCE) & ((tn * q.face_normals[face]).sum(1) > MAP_NORMAL_COS)
        # near but on the wrong side of a fold (a mouth corner, a lid): borrow a neighbour's template
        # triangle, ring by ring; what is still left takes its closest one
        near = d < MAP_DISTANCE  # far (neck, bust): no template partner, held still (gradient 0)
        face = np.where(ok, face, -1)
        todo = near & ~ok
        if todo.any():
            TT, _ = igl.triangle_triangle_adjacency(Fg)
            for _ in range(6):
                nb = np.where(TT[todo] >= 0, face[np.maximum(TT[todo], 0)], -1)  # (t, 3)
                pick = nb.max(1)
                idx = np.flatnonzero(todo)
                face[idx] = pick
                todo[idx[pick >= 0]] = False
                if not todo.any():
                    break
            face[todo] = fallback[todo]
        self._tri_src = np.maximum(face, 0)  # (m_good,) template triangle of each usable target triangle
        self._tri_ok = near
        # vertices: closest template point (masks, pins, parts following)
        dv, fv, _, bv = q.closest(Y)
        vn = vertex_normals(Y, tF)
        okv = (dv < MAP_DISTANCE) & ((vn * q.normals_at(fv, bv)).sum(1) > MAP_NORMAL_COS)
        self._v_face, self._v_bary, self._v_ok, self._v_dist = fv, bv, okv, dv
        # the fit's Jacobian per template triangle (template rest -> fitted)
        S0 = self.src.skin_X
        M0 = triangle_frames(S0, src_F)
        M1 = triangle_frames(fitted, src_F)
        self._src_frames_inv = _safe_inv(M0)
        J = M1 @ self._src_frames_inv
        self._J_fit = J
        self._src_area = 0.5 * np.linalg.norm(face_normals(S0, src_F, unit=False), axis=1)
        self._tri_tree: cKDTree | None = None
        if self.conjugation == "rotation":
            U, _, Vt = np.linalg.svd(J)
            D = np.ones((J.shape[0], 3))
            D[:, 2] = np.sign(np.linalg.det(U @ Vt))
            J = (U * D[:, None, :]) @ Vt
        elif self.conjugation == "none":
            J = np.broadcast_to(np.eye(3), J.shape).copy()
        self._J = J

    # ------------------------------------------------------------------ parts
    def _match_parts(self) -> None:
        """Decide what each target part does: matched to a template part by role, else a policy."""
        src, tgt = self.src, self.tgt
        self.parts: dict[str, str] = {}
        self._part_plan: list[tuple[int, str, int]] = []  # (target comp, how, source comp)
        s_roles = src.roles

        def family(r: str) -> str:
            return "eyeball" if r.startswith("eyeball") else "teeth" if r.startswith("teeth") else r

        for c, (name, role) in enumerate(zip(tgt.model.component_names, tgt.roles, strict=True)):
            if not (tgt.model.component_labels == c).any():
                continue
            if role == "skin":
                self.parts[name] = "skin"
                continue
            cands = [i for i, r in enumerate(s_roles) if r == role and r != "other"]
            if not cands and role not in ("eyeball_left", "eyeball_right", "teeth_upper", "teeth_lower", "other"):
                cands = [i for i, r in enumerate(s_roles) if family(r) == family(role)]
            cands = [i for i in cands if (src.model.component_labels == i).any()]
            if cands:
                ct = _part_centre(tgt, c)
                best = min(cands, key=lambda i: float(np.linalg.norm(_part_centre(src, i) - ct)))
                # a partner must be near: within a tenth of the head
                if float(np.linalg.norm(_part_centre(src, best) - ct)) < 0.1:
                    self._part_plan.append((c, "matched", best))
                    self.parts[name] = f"matched {src.model.component_names[best]}"
                    continue
            if role in ("eyeball_left", "eyeball_right", "eyeball", "teeth_upper"):
                self._part_plan.append((c, "fixed", -1))
                self.parts[name] = "fixed"
            elif role in RIGID_ROLES:
                self._part_plan.append((c, "rigid", -1))
                self.parts[name] = "rigid with the skin"
            else:
                self._part_plan.append((c, "follow", -1))
                self.parts[name] = "follows the skin"

    # ------------------------------------------------------------------ 5. factor
    def _factor(self) -> None:
        """The Poisson matrix (factored once) and the sparse map from template deltas to its right-hand side."""
        Y = self.tgt.skin_X
        n = Y.shape[0]
        Fg = self.tgt.skin_faces[self._t_good]
        # hat-function gradients g[t, a] and areas of the target triangles
        cr = face_normals(Y, Fg, unit=False)
        area = 0.5 * np.linalg.norm(cr, axis=1)
        nrm = cr / (2.0 * area[:, None])
        P = Y[Fg]
        g = np.stack([np.cross(nrm, P[:, 2] - P[:, 1]), np.cross(nrm, P[:, 0] - P[:, 2]),
                      np.cross(nrm, P[:, 1] - P[:, 0])], axis=1) / (2.0 * area[:, None, None])  # (m, 3, 3)
        # cotangent matrix sum_t A_t g_a . g_b
        blocks = area[:, None, None] * np.einsum("tal,tbl->tab", g, g)
        rows = np.repeat(Fg, 3, axis=1).ravel()
        cols = np.tile(Fg, (1, 3)).ravel()
        Lc = sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(n, n))
        # still vertices: far from the fitted template (neck, bust), or on template triangles no shape moves
        disp = np.stack([sh.delta for sh in self.source.shapes])
        big = float(np.abs(disp).max())
        moving_src = np.zeros(self.source.n_vertices, bool)
        if big > 0:
            moving_src = np.any(np.abs(disp) > 1e-7 * big, axis=(0, 2))
        still_face = ~np.any(moving_src[self.src.skin_ids[self.src.skin_faces]], axis=1)
        pin = np.clip((self._v_dist - MAP_DISTANCE) / MAP_DISTANCE, 0.0, 1.0)
        pin[self._v_ok & still_face[self._v_face]] = 1.0
        diag = np.asarray(Lc.diagonal()).ravel()
        scale = float(diag[diag > 0].mean()) if (diag > 0).any() else 1.0
        w = 100.0 * np.where(diag > 0, diag, scale) * pin + 1e-8 * scale
        self._pin_share = float((pin > 0).mean())
        self.matrix = sp.csc_matrix(Lc + sp.diags(w))  # the Poisson system (kept for peers and checks)
        self._system = SparseSPDSolver(self.matrix)
        self._rhs_map = self._rhs_operator(Fg, g, area, nrm, n)

    def _rhs_operator(
        self, Fg: NDArray[np.int64], g: NDArray[np.float64], area: NDArray[np.float64],
        nrm: NDArray[np.float64], n: int,
    ) -> sp.csr_matrix:
        """(3 n_target_skin, 3 N_template) sparse: template deltas (model units) -> ``D^T A g`` of the target.

        Linear in the deltas: the frame ``M = [e1, e2, n / sqrt|n|]`` of each
        template triangle is differentiated at rest (exact for the in-plane
        columns; the normal column to first order), so a blend of transferred
        shapes is the transfer of the blend.
        """
        sF = self.src.skin_faces
        tri = self._tri_src
        X = self.src.skin_X[sF[tri]]  # (m, 3, 3) template corners of each target triangle's partner
        e1, e2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
        c = np.cross(e1, e2)
        a = np.linalg.norm(c, axis=1)
        a = np.where(a > 0, a, 1.0)
        ch = c / a[:, None]
        proj = np.eye(3)[None] - 0.5 * ch[:, :, None] * ch[:, None, :]
        N1 = -(proj @ _cross_matrix(e2)) / np.sqrt(a)[:, None, None]
        N2 = (proj @ _cross_matrix(e1)) / np.sqrt(a)[:, None, None]
        Minv = self._src_frames_inv[tri]  # rows r1, r2, r3
        J = self._J[tri]
        Jinv = _safe_inv(J)
        Pt = np.eye(3)[None] - nrm[:, :, None] * nrm[:, None, :]
        B = Jinv @ Pt
        q = np.einsum("tkl,tak->tal", B, Minv)  # q[t, a] = B^T r_a
        JN1, JN2 = J @ N1, J @ N2
        T1 = J[:, :, None, :] * q[:, 0, None, :, None] + JN1[:, :, None, :] * q[:, 2, None, :, None]  # [t, i, l, j]
        T2 = J[:, :, None, :] * q[:, 1, None, :, None] + JN2[:, :, None, :] * q[:, 2, None, :, None]
        lin = self.src.frame.scale * self.src.frame.R  # model delta -> working frame
        T1 = T1 @ lin
        T2 = T2 @ lin
        C = np.stack([-(T1 + T2), T1, T2], axis=1)  # (m, corner c, i, l, j)
        E = area[:, None, None, None, None] * np.einsum("tal,tcilj->taicj", g, C)  # (m, a, i, c, j)
        scorn = self.src.skin_ids[sF[tri]]  # (m, 3) template model vertex ids
        rows = (3 * Fg[:, :, None, None, None] + np.arange(3)[None, None, :, None, None])
        cols = (3 * scorn[:, None, None, :, None] + np.arange(3)[None, None, None, None, :])
        rows, cols = np.broadcast_arrays(rows, cols)
        keep = np.repeat(self._tri_ok, 81)
        R = sp.csr_matrix((E.ravel()[keep], (rows.ravel()[keep], cols.ravel()[keep])),
                          shape=(3 * n, 3 * self.source.n_vertices))
        R.sum_duplicates()
        return R

    def right_hand_sides(self, deltas: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n_target_skin, 3 k) right-hand sides of :attr:`matrix` for (k, N, 3) template deltas (columns: component, shape)."""
        k = deltas.shape[0]
        rhs = self._rhs_map @ np.asarray(deltas, np.float64).transpose(1, 2, 0).reshape(-1, k)  # (3 n, k)
        return np.asarray(rhs).reshape(-1, 3 * k)

    @property
    def skin_correspondence(self) -> SkinCorrespondence:
        """Where each target skin vertex sits on the fitted template (for detail transfer)."""
        return SkinCorrespondence(self._v_ok, self._v_face, self._v_bary, self._J_fit)

    def run(self, *, progress: Progress = None) -> TransferResult:
        """Transfer every template shape; returns the rigged target and the report.

        ``progress`` replaces the set-up's progress callback from here on.
        """
        if progress is not None:
            self._progress = progress
        t0 = time.perf_counter()
        self._say(0.95, "transferring shapes")
        shapes = list(self.source.shapes)
        k = len(shapes)
        deltas = np.stack([s.delta for s in shapes]).astype(np.float64)  # (k, N, 3) template units
        rhs = self.right_hand_sides(deltas)
        n = rhs.shape[0]
        sol = self._system.solve(rhs)  # columns (component, shape)
        work = sol.reshape(n, 3, k).transpose(2, 0, 1)  # (k, n_skin, 3) working frame
        out = np.zeros((k, self.target.n_vertices, 3))
        out[:, self.tgt.skin_ids] = work
        self._parts_motion(deltas, out)
        # working frame -> target units and axes
        back = out @ self.tgt.frame.R / self.tgt.frame.scale
        masks = self._masks(shapes)
        new_shapes = [
            BlendShape(s.name, back[i], s.slider_min, s.slider_max, s.mute, masks[i]) for i, s in enumerate(shapes)
        ]
        names = {s.name for s in shapes}
        kept = [s for s in self.target.shapes if s.name not in names]
        if len(kept) < len(self.target.shapes):
            self.warnings.append(
                f"target: its own shapes {sorted(names & set(self.target.shape_names))} were replaced by the template's"
            )
        quality = self._quality(shapes, work)
        transfer_s = time.perf_counter() - t0
        report = TransferReport(
            source=self.source.metadata.name or "source",
            target=self.target.metadata.name or "target",
            shapes=tuple(quality),
            alignment=self.alignment,
            registration=self.registration,
            correspondence={"mapped": float(self._v_ok.mean()), "pinned": self._pin_share,
                            "conjugation": self.conjugation},
            parts=dict(self.parts),
            landmarks=tuple(self._landmarks),
            warnings=tuple(self.warnings),
            timings={"setup": self.setup_seconds, "transfer": transfer_s},
        )
        meta: ModelMetadata = self.target.metadata.with_provenance(report.to_json())
        t = self.target
        model = FaceModel(t.vertices, t.faces, [*new_shapes, *kept], polygons=t.polygons,
                          component_labels=t.component_labels, component_names=t.component_names, metadata=meta)
        for wmsg in self.warnings:
            logger.warning("transfer_rig: %s", wmsg)
        self._say(1.0, "done")
        return TransferResult(model, report)

    # ------------------------------------------------------------------ pieces of run
    def _parts_motion(self, deltas: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        """Fill the target parts' rows of ``out`` (k, n, 3), working frame."""
        src, tgt = self.src, self.tgt
        lin = src.frame.scale * src.frame.R
        skin_tree: cKDTree | None = None
        full: NDArray[np.float64] | None = None  # all template deltas in the working frame, when a part needs them
        for c, how, sc in self._part_plan:
            ids = np.flatnonzero(tgt.model.component_labels == c)
            Y = tgt.X[ids]
            if how == "fixed":
                continue
            if how == "matched":
                s_ids = np.flatnonzero(src.model.component_labels == sc)
                Xs = src.X[s_ids]
                # the part's linear map: the fit's Jacobian averaged over the template skin around it;
                # its place: the parts' centroids
                Lp = self._local_jacobian(Xs)
                cs_, ct_ = Xs.mean(0), Y.mean(0)
                Xmap = (Y - ct_) @ np.linalg.inv(Lp).T + cs_  # target part points in the template part's frame
                dpart = deltas[:, s_ids] @ lin.T  # (k, p, 3) working frame
                # the template part's motion at the closest point of its surface, plus its affine motion
                # (least squares over the part) across the offset from there: exact on the template's own
                # part, first-order right for a part of another shape moving rigidly
                A = np.c_[Xs - Xs.mean(0), np.ones(len(Xs))]
                coef = np.linalg.pinv(A) @ dpart.transpose(1, 0, 2).reshape(len(Xs), -1)
                lin_k = coef[:3].reshape(3, -1, 3)  # [j, shape, comp]: d_comp = sum_j x_j lin_k[j]
                sF = np.asarray(src.model.faces, np.int64)
                lab = src.model.component_labels
                pf = sF[(lab[sF] == sc).all(1)]
                if pf.size:
                    q = SurfaceQuery(src.X, pf)
                    _, f, C, b = q.closest(Xmap)
                    if full is None:
                        full = deltas @ lin.T
                    at = np.einsum("qj,kqjc->kqc", b, full[:, pf[f]])
                else:
                    _, nn = cKDTree(Xs).query(Xmap)
                    C = Xs[nn]
                    at = dpart[:, nn]
                at = at + np.einsum("qj,jkc->kqc", Xmap - C, lin_k)
                out[:, ids] = at @ Lp.T
                continue
            # no partner: follow the target's own (already transferred) skin
            if skin_tree is None:
                skin_tree = cKDTree(tgt.skin_X)
            local = np.full(tgt.model.n_vertices, -1, np.int64)
            local[tgt.skin_ids] = np.arange(tgt.skin_ids.size)
            if how == "follow":
                _, nn = skin_tree.query(Y)
                out[:, ids] = out[:, tgt.skin_ids[nn]]
            else:  # rigid: a linearised rigid motion fitted to the nearest skin
                _, nn = skin_tree.query(Y, k=min(8, tgt.skin_ids.size))
                near = np.unique(nn)
                P = tgt.skin_X[near]
                c0 = P.mean(0)
                # d(p) = w x (p - c0) + t: rows [ -[p-c0]_x | I ]
                r = P - c0
                rows = np.zeros((len(P), 3, 6))
                rows[:, 0, 1], rows[:, 0, 2] = r[:, 2], -r[:, 1]
                rows[:, 1, 0], rows[:, 1, 2] = -r[:, 2], r[:, 0]
                rows[:, 2, 0], rows[:, 2, 1] = r[:, 1], -r[:, 0]
                rows[:, :, 3:] = np.eye(3)
                A = rows.reshape(-1, 6)
                b = out[:, tgt.skin_ids[near]].transpose(1, 2, 0).reshape(-1, out.shape[0])
                motion = np.linalg.pinv(A) @ b  # (6, k): rotation vector and translation per shape
                ry = Y - c0
                wv, tv = motion[:3].T, motion[3:].T  # (k, 3)
                out[:, ids] = np.cross(wv[:, None, :], ry[None]) + tv[:, None, :]

    def _local_jacobian(self, P: NDArray[np.float64], k: int = 8) -> NDArray[np.float64]:
        """The fit's Jacobian averaged (by area) over the template skin triangles nearest to the points ``P``."""
        if self._tri_tree is None:
            self._tri_tree = cKDTree(self.src.skin_X[self.src.skin_faces].mean(1))
        _, nn = self._tri_tree.query(P, k=min(k, self.src.skin_faces.shape[0]))
        near = np.unique(nn)
        w = self._src_area[near]
        L = (self._J_fit[near] * w[:, None, None]).sum(0) / max(float(w.sum()), 1e-300)
        return L if abs(np.linalg.det(L)) > 1e-9 else np.eye(3)

    def _masks(self, shapes: list[BlendShape]) -> list[NDArray[np.float32] | None]:
        """Vertex masks interpolated at each target vertex's template point (nearest for parts)."""
        if all(s.vertex_mask is None for s in shapes):
            return [None] * len(shapes)
        sF = self.src.skin_ids[self.src.skin_faces]
        tree = cKDTree(self.src.X)
        _, nn_all = tree.query(self.tgt.X)
        out: list[NDArray[np.float32] | None] = []
        for s in shapes:
            if s.vertex_mask is None:
                out.append(None)
                continue
            m = s.vertex_mask.astype(np.float64)
            t = m[nn_all]
            t[self.tgt.skin_ids] = (m[sF[self._v_face]] * self._v_bary).sum(1)
            out.append(np.clip(t, 0.0, 1.0).astype(np.float32))
        return out

    def _source_quality(self) -> list[tuple[float, int, int]]:
        """(max stretch, flipped, new self-intersecting triangles) of every template shape on the template skin.

        Once, at set-up. Self-intersections (:mod:`.intersections`) are counted
        only with numba (0 without it; :meth:`_quality` logs that): the numpy
        path takes ~0.5 s per shape on a 20k-vertex face.
        """
        from workbench.rigging.intersections import NUMBA, SelfIntersections

        meter = StretchMeter(self.src.skin_X, self.src.skin_faces)
        crossing = SelfIntersections(self.src.skin_X, self.src.skin_faces) if NUMBA else None
        lin = self.src.frame.scale * self.src.frame.R
        out = []
        for s in self.source.shapes:
            d = s.delta[self.src.skin_ids].astype(np.float64) @ lin.T
            mx, _, fl, _ = meter.shape_quality(d)
            out.append((mx, fl, 0 if crossing is None else crossing.count_new(d)))
        return out

    def _quality(self, shapes: list[BlendShape], work: NDArray[np.float64]) -> list[ShapeQuality]:
        """Stretch, flips and new self-intersections of every transferred shape on the target skin, beside the template's."""
        from workbench.rigging.intersections import NUMBA, SelfIntersections

        faces = self.tgt.skin_faces[self._t_good]
        meter = StretchMeter(self.tgt.skin_X, faces)
        crossing: SelfIntersections | None = getattr(self, "_t_crossing", None)
        if crossing is None and NUMBA:
            crossing = self._t_crossing = SelfIntersections(self.tgt.skin_X, faces)  # the rest pose, once
        elif crossing is None:
            msg = "self-intersections not checked: numba is not installed (pip install 'face-workbench[fast]')"
            if msg not in self.warnings:
                self.warnings.append(msg)  # in the report, so a 0 in its table is not read as "none"
        out = []
        for i, s in enumerate(shapes):
            mx, med, fl, moved = meter.shape_quality(work[i])
            smx, sfl, sx = self._src_quality[i]
            out.append(ShapeQuality(name=s.name, max_stretch=mx, median_stretch=med, flipped=fl,
                                    source_max_stretch=smx, source_flipped=sfl, moved=moved,
                                    intersecting=0 if crossing is None else crossing.count_new(work[i]),
                                    source_intersecting=sx, triangles=int(faces.shape[0]),
                                    source_triangles=int(self.src.skin_faces.shape[0])))
        return out


def _cross_matrix(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """(p, 3, 3): ``[v]_x w = v x w``."""
    out = np.zeros((v.shape[0], 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -v[:, 2], v[:, 1]
    out[:, 1, 0], out[:, 1, 2] = v[:, 2], -v[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -v[:, 1], v[:, 0]
    return out


def _safe_inv(M: NDArray[np.float64]) -> NDArray[np.float64]:
    """Batched 3x3 inverse; singular matrices give zeros."""
    det = np.linalg.det(M)
    ok = np.abs(det) > 1e-300
    out = np.zeros_like(M)
    if ok.any():
        out[ok] = np.linalg.inv(M[ok])
    return out


# --------------------------------------------------------------------------- API


def transfer_rig_report(
    source: FaceModel,
    target: FaceModel | str | PathLike[str],
    *,
    landmarks: Sequence[tuple[int, int]] | None = None,
    progress: Progress = None,
    conjugation: Conjugation = "jacobian",
) -> TransferResult:
    """:func:`transfer_rig` that also returns the :class:`~workbench.rigging.report.TransferReport`.

    Returns
    -------
    TransferResult
        ``.model`` (the rigged target) and ``.report``.
    """
    return RigTransfer(source, target, landmarks=landmarks, progress=progress, conjugation=conjugation).run()


def transfer_rig(
    source: FaceModel,
    target: FaceModel | str | PathLike[str],
    *,
    landmarks: Sequence[tuple[int, int]] | None = None,
    progress: Progress = None,
) -> FaceModel:
    """Give ``target`` the blendshapes of ``source`` by deformation transfer (see :mod:`workbench.rigging.transfer`).

    Parameters
    ----------
    source : FaceModel
        The template rig, e.g. ``workbench.load_sample("head")``.
    target : FaceModel or path
        The face to rig, in any units, axes and topology; eyes, teeth and
        tongue may be separate parts, a neck or bust and holes are fine.
    landmarks : sequence of (source_vertex, target_vertex), optional
        Corresponding vertices (three or more fix the alignment).
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    FaceModel
        The target's mesh, polygons, parts and units with the template's shapes
        (names, slider ranges, mute, masks). Its ``metadata.provenance`` ends
        with the transfer report (``TransferReport.from_model(rig)``).

    Raises
    ------
    RigTransferError
        The message names the problem (no shapes, no skin, a degenerate or
        non-manifold target, a target that does not look like a face).
    """
    return transfer_rig_report(source, target, landmarks=landmarks, progress=progress).model
