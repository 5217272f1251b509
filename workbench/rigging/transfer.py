"""Rig any face: carry a template's blendshapes onto another mesh (Sumner & Popovic 2004, as Li et al. 2010 §3).

:class:`RigTransfer` does it in two phases, so the expensive part runs once.
It strings the stages together; each stage is a module of its own:
:mod:`.sides` (step 1), :mod:`.fitting` (2, 3), :mod:`.correspondence` (4),
:mod:`.deformation` (5 and the solve), :mod:`.parts_motion` and :mod:`.quality`.

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

import numpy as np
from numpy.typing import NDArray

from workbench.core.shapes import BlendShape
from workbench.geometry.similarity import Similarity
from workbench.geometry.surface import SurfaceQuery
from workbench.model import FaceModel, ModelMetadata
from workbench.rigging.correspondence import (
    Conjugation,
    Correspondence,
    SkinCorrespondence,
    correspond,
    match_parts,
)
from workbench.rigging.deformation import PoissonTransfer
from workbench.rigging.fitting import align_rigidly, fit_template, judge_fit
from workbench.rigging.parts_motion import PartsMotion
from workbench.rigging.quality import TransferQuality
from workbench.rigging.report import RigTransferError, TransferReport
from workbench.rigging.sides import Side, canonical_frame, check_landmarks, check_surface, skin_of

__all__ = ["RigTransfer", "SkinCorrespondence", "TransferResult", "transfer_rig", "transfer_rig_report"]

logger = logging.getLogger(__name__)

Progress = Callable[[float, str], None] | None


@dataclass
class TransferResult:
    """The rigged target and how the transfer went."""

    model: FaceModel
    report: TransferReport


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
    fine_fit : bool
        After the non-rigid fit, a point-to-plane tail that lets the template slide
        along the target (:func:`~workbench.rigging.registration.planar_refine`):
        a denser, truer correspondence where proportions differ locally (a grown
        jaw), for expression cloning; about 3 s more set-up. Off by default: rig
        transfer's tests and numbers are measured without it.

    Attributes
    ----------
    src, tgt : Side
        The template and the target in the working frame (template head size 1).
    alignment, registration : dict
        What the rigid alignment did and how the non-rigid fit went (the report's).
    fit : NonRigidResult
        The template skin fitted onto the target (``fit.positions``, working frame).
    parts : dict of str to str
        What each target component does.
    matrix : sparse CSC
        The target skin's Poisson matrix.
    warnings : list of str

    Raises
    ------
    RigTransferError
        The inputs cannot be transferred (no skin, degenerate or non-manifold
        surface, a target that does not look like a face; :meth:`run`: a source
        without shapes); the message names what is wrong. Nothing is built. The
        set-up alone (correspondence, fit) serves expression cloning
        (:class:`~workbench.rigging.clone.ExpressionCloner`), which needs no shapes.
    """

    def __init__(
        self,
        source: FaceModel,
        target: FaceModel | str | PathLike[str],
        *,
        landmarks: Sequence[tuple[int, int]] | None = None,
        progress: Progress = None,
        conjugation: Conjugation = "jacobian",
        fine_fit: bool = False,
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
        if conjugation not in ("jacobian", "rotation", "none"):
            raise ValueError(f"conjugation must be 'jacobian', 'rotation' or 'none', got {conjugation!r}")
        self.source = source
        self.target = target
        self.conjugation = conjugation
        self.warnings: list[str] = []
        self._say(0.0, "checking the meshes")
        self._landmarks = check_landmarks(landmarks, source, target)

        # 1. frames: template head size = 1
        tgt0 = self._sides()

        # 2. rigid alignment (of the target onto the template)
        self._say(0.02, "rigid alignment")
        self.tgt, self.alignment = align_rigidly(self.src, tgt0, self._landmarks, self._t_good, self.head_metres,
                                                 self.warnings)

        # 3. non-rigid fit of the template skin onto the target skin
        self._say(0.08, "non-rigid fit")
        self._t_query = SurfaceQuery(self.tgt.skin_X, self.tgt.skin_faces[self._t_good])
        self.fit = fit_template(
            self.src, self.tgt, self._t_query, self._landmarks,
            progress=None if progress is None else (lambda f, m: self._say(0.08 + 0.72 * f, m)), fine=fine_fit,
        )
        self.registration = judge_fit(self.fit, self.src, self.tgt, self.head_metres, self.warnings, self._t_query)

        # 4. correspondence, parts, 5. the factorisation
        self._say(0.82, "correspondence")
        self._corr = correspond(self.src, self.tgt, self._t_good, self.fit.positions, conjugation)
        self._say(0.88, "parts")
        self.parts, plan = match_parts(self.src, self.tgt)
        self._parts = PartsMotion(self.src, self.tgt, self._corr, plan)
        self._say(0.9, "factoring the Poisson system")
        self._poisson = PoissonTransfer(self.src, self.tgt, self._t_good, self._corr)
        self.matrix = self._poisson.matrix  # the Poisson system (kept for peers and checks)
        self._system = self._poisson.system
        self._quality = TransferQuality(self.src, self.tgt, self._t_good)
        self.setup_seconds = time.perf_counter() - t0
        self._say(0.95, "set up")

    def _say(self, f: float, msg: str) -> None:
        if self._progress is not None:
            self._progress(float(min(max(f, 0.0), 1.0)), msg)

    def _sides(self) -> Side:
        """Step 1: both models in the working frame (template head size 1) with their skins checked.

        Sets :attr:`src`, :attr:`head_metres` and the target's usable triangles; returns the
        target in its own canonical frame (the rigid alignment moves it onto the template).
        """
        source, target = self.source, self.target
        s_ids, s_F, s_roles = skin_of(source, "source")
        t_ids, t_F, t_roles = skin_of(target, "target")
        cs, ct = canonical_frame(source), canonical_frame(target)
        S0 = cs(source.vertices[s_ids])
        centre = S0.mean(0)
        head = float(np.linalg.norm(S0.max(0) - S0.min(0)))
        to_work = Similarity(1.0 / head, np.eye(3), -centre / head)
        src_frame = cs.then(to_work)
        self.head_metres = head
        self.src = Side(source, src_frame, s_ids, s_F, src_frame(source.vertices), s_roles)
        tgt_frame0 = ct.then(to_work)
        tgt0 = Side(target, tgt_frame0, t_ids, t_F, tgt_frame0(target.vertices), t_roles)
        _, w = check_surface(self.src.skin_X, s_F, "source")
        self.warnings += w
        self._t_good, w = check_surface(tgt0.skin_X, t_F, "target")
        self.warnings += w
        return tgt0

    def right_hand_sides(self, deltas: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n_target_skin, 3 k) right-hand sides of :attr:`matrix` for (k, N, 3) template deltas (columns: component, shape)."""
        return self._poisson.right_hand_sides(deltas)

    @property
    def correspondence(self) -> Correspondence:
        """The dense correspondence: each target skin vertex on a template triangle (barycentric)."""
        return self._corr

    @property
    def parts_motion(self) -> PartsMotion:
        """Moves the target's non-skin parts (eyes, teeth…) with the template motion it is given."""
        return self._parts

    @property
    def poisson(self) -> PoissonTransfer:
        """The prefactored Poisson system of deformation transfer (template deltas -> target skin)."""
        return self._poisson

    def transfer_motion(self, motion: NDArray[np.float64]) -> NDArray[np.float64]:
        """(k, n_target, 3) target motion (working frame) for (k, N, 3) template motion, by deformation transfer.

        One Poisson back-substitution per column (Sumner & Popović); the parts follow
        through :attr:`parts_motion`. :meth:`run` uses it for the shapes.
        """
        motion = np.asarray(motion, np.float64)
        out = np.zeros((motion.shape[0], self.target.n_vertices, 3))
        out[:, self.tgt.skin_ids] = self._poisson.solve(motion)  # (k, n_skin, 3) working frame
        self._parts.fill(motion, out)
        return out

    @property
    def skin_correspondence(self) -> SkinCorrespondence:
        """Where each target skin vertex sits on the fitted template (for detail transfer)."""
        return self._corr.skin()

    def run(self, *, progress: Progress = None) -> TransferResult:
        """Transfer every template shape; returns the rigged target and the report.

        ``progress`` replaces the set-up's progress callback from here on.
        """
        if not self.source.shapes:
            raise RigTransferError(f"source {self.source.metadata.name or 'model'}: has no blendshapes to transfer")
        if progress is not None:
            self._progress = progress
        t0 = time.perf_counter()
        self._say(0.95, "transferring shapes")
        shapes = list(self.source.shapes)
        deltas = np.stack([s.delta for s in shapes]).astype(np.float64)  # (k, N, 3) template units
        out = self.transfer_motion(deltas)
        # working frame -> target units and axes
        back = out @ self.tgt.frame.R / self.tgt.frame.scale
        masks = self._corr.masks(shapes, self.src, self.tgt)
        new_shapes = [
            BlendShape(s.name, back[i], s.slider_min, s.slider_max, s.mute, masks[i]) for i, s in enumerate(shapes)
        ]
        names = {s.name for s in shapes}
        kept = [s for s in self.target.shapes if s.name not in names]
        if len(kept) < len(self.target.shapes):
            self.warnings.append(
                f"target: its own shapes {sorted(names & set(self.target.shape_names))} were replaced by the template's"
            )
        quality = self._quality.shapes(shapes, out[:, self.tgt.skin_ids], self.warnings)
        transfer_s = time.perf_counter() - t0
        report = TransferReport(
            source=self.source.metadata.name or "source",
            target=self.target.metadata.name or "target",
            shapes=tuple(quality),
            alignment=self.alignment,
            registration=self.registration,
            correspondence={"mapped": float(self._corr.v_ok.mean()), "pinned": self._poisson.pin_share,
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
    if isinstance(source, FaceModel) and not source.shapes:  # before the set-up's work
        raise RigTransferError(f"source {source.metadata.name or 'model'}: has no blendshapes to transfer")
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
