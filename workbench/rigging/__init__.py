"""Rig any face: give a mesh the template's blendshapes, then refine them from examples (issue 16).

* :func:`transfer_rig` — correspondence (rigid + non-rigid fit of the template
  skin onto the target) and deformation transfer of every shape onto the
  target's own topology (:mod:`workbench.rigging.transfer`);
  :func:`transfer_rig_report` also returns the per-shape quality report
  (:class:`TransferReport`), and :class:`RigTransfer` splits the one-off set-up
  from the transfer.
* :func:`refine_rig` / :class:`RefineResult` — example-based refinement (Li et
  al. 2010 §3, :mod:`workbench.rigging.refine`), imported on first use.
* :func:`clone_animation` / :class:`ExpressionCloner` — a performance (an
  animated mesh) of one face played on another of any topology, vertex order
  and units (expression cloning, Noh & Neumann 2001; :mod:`workbench.rigging.clone`).
* :func:`transfer_details` / :func:`transfer_pose_space` — wrinkle details onto
  the target (Bickel et al. 2008 §5.4): carried example poses refitted on the rig,
  or the fitted pose space itself as printed (:mod:`workbench.rigging.pose_space_transfer`).
* :class:`RigSession` — the Rig tab's state: landmarks, examples and the three
  stages, each one undo step of the session's own history.

Rigging is a library, not a method family (:mod:`workbench.core.families`),
on purpose: a family adds state, a layer and edits to *one* face, while
rigging reads two faces (template and target) and *makes* a third, the rigged
target, whose shapes every family then works on. Its stages are undoable in
the :class:`RigSession` that holds them (never modified: the template and the
target; the result is a new model), so nothing of it belongs in a model's
slots, file part or pipeline, and the rigged model carries no trace of how it
was made beyond its metadata.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from workbench.rigging.clone import ExpressionCloner, clone_animation
from workbench.rigging.details import DetailMap, transfer_details
from workbench.rigging.landmarks import SuggestedLandmark, suggest_landmarks, template_landmarks
from workbench.rigging.pose_space_transfer import transfer_pose_space
from workbench.rigging.report import RigTransferError, ShapeQuality, TransferReport
from workbench.rigging.session import RigExample, RigSession, RigState
from workbench.rigging.transfer import (
    RigTransfer,
    TransferResult,
    transfer_rig,
    transfer_rig_report,
)

if TYPE_CHECKING:
    from workbench.rigging.refine import RefineResult, refine_rig

__all__ = [
    "DetailMap",
    "ExpressionCloner",
    "RefineResult",
    "RigExample",
    "RigSession",
    "RigState",
    "RigTransfer",
    "RigTransferError",
    "ShapeQuality",
    "SuggestedLandmark",
    "TransferReport",
    "TransferResult",
    "clone_animation",
    "refine_rig",
    "suggest_landmarks",
    "template_landmarks",
    "transfer_details",
    "transfer_pose_space",
    "transfer_rig",
    "transfer_rig_report",
]

_LAZY = {"refine_rig", "RefineResult"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        from workbench.rigging import refine

        return getattr(refine, name)
    raise AttributeError(f"module 'workbench.rigging' has no attribute {name!r}")
