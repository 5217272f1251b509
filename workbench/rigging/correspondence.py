"""Step 4 of a rig transfer: where the target's skin and parts sit on the fitted template.

* :func:`correspond` — every usable target skin triangle (its centroid) and
  vertex gets the closest point of the fitted template (triangle and
  barycentric coordinates) when it is near and its normal agrees; a triangle on
  the wrong side of a fold borrows a neighbour's partner. With it come the
  fit's Jacobian per template triangle (template rest -> fitted) and the
  conjugation the transfer sees template gradients through.
* :func:`match_parts` — each target part (eyes, lashes, teeth, tongue) is
  matched to the template part of the same role, else it stays fixed, moves
  rigidly with the skin or follows the skin under it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import igl
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.core.shapes import BlendShape
from workbench.geometry.frames import triangle_frames
from workbench.geometry.normals import face_normals, triangle_areas, vertex_normals
from workbench.geometry.parts import RIGID_ROLES
from workbench.geometry.surface import SurfaceQuery
from workbench.rigging.sides import Side, part_centre

__all__ = ["MAP_DISTANCE", "MAP_NORMAL_COS", "Correspondence", "SkinCorrespondence", "correspond", "match_parts",
           "safe_inverse"]

Conjugation = Literal["jacobian", "rotation", "none"]
#: (target component, how: "matched" / "fixed" / "rigid" / "follow", template component or -1)
PartPlan = list[tuple[int, str, int]]

#: correspondences farther than this (head units, ~4 mm on an adult head) from the fitted template are dropped
MAP_DISTANCE = 0.01
#: below this cosine between normals a correspondence is dropped
MAP_NORMAL_COS = 0.3


@dataclass(frozen=True)
class SkinCorrespondence:
    """Target skin vertex -> template triangle, read-only views of a :class:`~workbench.rigging.RigTransfer`.

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


@dataclass
class Correspondence:
    """Target skin -> fitted template (working frame), as :func:`correspond` finds it.

    Attributes
    ----------
    tri_src : (m_good,) int
        Template triangle of each usable target skin triangle.
    tri_near : (m_good,) bool
        The triangle is near the fitted template (far ones, a neck or a bust, are held still).
    v_face, v_bary, v_ok, v_dist : (n_t,) int, (n_t, 3) float, (n_t,) bool, (n_t,) float
        Each target skin vertex's closest template triangle, barycentric
        coordinates, whether it is a match (near, normals agreeing) and its distance.
    src_frames_inv : (m_s, 3, 3) float
        Inverse Sumner & Popović frames of the template's rest triangles (zero where singular).
    J_fit : (m_s, 3, 3) float
        The fit's Jacobian per template triangle (template rest -> fitted).
    J : (m_s, 3, 3) float
        What template gradients are seen through: ``J_fit``, its rotation, or the identity.
    src_area : (m_s,) float
        Areas of the template's rest skin triangles.
    """

    tri_src: NDArray[np.int64]
    tri_near: NDArray[np.bool_]
    v_face: NDArray[np.int64]
    v_bary: NDArray[np.float64]
    v_ok: NDArray[np.bool_]
    v_dist: NDArray[np.float64]
    src_frames_inv: NDArray[np.float64]
    J_fit: NDArray[np.float64]
    J: NDArray[np.float64]
    src_area: NDArray[np.float64]

    def skin(self) -> SkinCorrespondence:
        """The vertex part, for detail transfer."""
        return SkinCorrespondence(self.v_ok, self.v_face, self.v_bary, self.J_fit)

    def masks(self, shapes: Sequence[BlendShape], src: Side, tgt: Side) -> list[NDArray[np.float32] | None]:
        """Vertex masks interpolated at each target vertex's template point (nearest template vertex for parts)."""
        if all(s.vertex_mask is None for s in shapes):
            return [None] * len(shapes)
        sF = src.skin_ids[src.skin_faces]
        _, nn_all = cKDTree(src.X).query(tgt.X)
        out: list[NDArray[np.float32] | None] = []
        for s in shapes:
            if s.vertex_mask is None:
                out.append(None)
                continue
            m = s.vertex_mask.astype(np.float64)
            t = m[nn_all]
            t[tgt.skin_ids] = (m[sF[self.v_face]] * self.v_bary).sum(1)
            out.append(np.clip(t, 0.0, 1.0).astype(np.float32))
        return out


def safe_inverse(M: NDArray[np.float64]) -> NDArray[np.float64]:
    """Batched 3x3 inverse, (p, 3, 3); singular matrices give zeros."""
    det = np.linalg.det(M)
    ok = np.abs(det) > 1e-300
    out = np.zeros_like(M)
    if ok.any():
        out[ok] = np.linalg.inv(M[ok])
    return out


def _triangle_partners(q: SurfaceQuery, Y: NDArray[np.float64], Fg: NDArray[np.int64]
                       ) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Template triangle of each target triangle (by its centroid; normals must agree), and which are near."""
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
    return np.maximum(face, 0), near


def correspond(
    src: Side, tgt: Side, t_good: NDArray[np.bool_], fitted: NDArray[np.float64], conjugation: Conjugation
) -> Correspondence:
    """Map the target skin onto the fitted template skin.

    Parameters
    ----------
    src, tgt : Side
        The template and the target, both in the working frame.
    t_good : (m_t,) bool
        The target's usable skin triangles.
    fitted : (n_s, 3) float
        The template skin fitted onto the target (:func:`.fitting.fit_template`).
    conjugation : {"jacobian", "rotation", "none"}
        What template gradients are seen through.
    """
    src_F = src.skin_faces
    q = SurfaceQuery(fitted, src_F)
    Y = tgt.skin_X
    tri_src, near = _triangle_partners(q, Y, tgt.skin_faces[t_good])
    # vertices: closest template point (masks, pins, parts following)
    dv, fv, _, bv = q.closest(Y)
    vn = vertex_normals(Y, tgt.skin_faces)
    okv = (dv < MAP_DISTANCE) & ((vn * q.normals_at(fv, bv)).sum(1) > MAP_NORMAL_COS)
    # the fit's Jacobian per template triangle (template rest -> fitted)
    S0 = src.skin_X
    frames_inv = safe_inverse(triangle_frames(S0, src_F))
    J_fit = triangle_frames(fitted, src_F) @ frames_inv
    J = J_fit
    if conjugation == "rotation":
        U, _, Vt = np.linalg.svd(J)
        D = np.ones((J.shape[0], 3))
        D[:, 2] = np.sign(np.linalg.det(U @ Vt))
        J = (U * D[:, None, :]) @ Vt
    elif conjugation == "none":
        J = np.broadcast_to(np.eye(3), J.shape).copy()
    return Correspondence(tri_src, near, fv, bv, okv, dv, frames_inv, J_fit, J, triangle_areas(S0, src_F))


def match_parts(src: Side, tgt: Side) -> tuple[dict[str, str], PartPlan]:
    """What each target part does: matched to a template part by role, else a policy.

    Returns
    -------
    dict
        Component name -> what happens to it, for the report (``"skin"``,
        ``"matched eye_left"``, ``"fixed"``, ``"rigid with the skin"``, ``"follows the skin"``).
    list of (int, str, int)
        Per non-skin target component: ``(component, how, template component)``
        with ``how`` one of ``"matched"``, ``"fixed"``, ``"rigid"``, ``"follow"`` (template -1 unless matched).
    """
    parts: dict[str, str] = {}
    plan: PartPlan = []
    s_roles = src.roles

    def family(r: str) -> str:
        return "eyeball" if r.startswith("eyeball") else "teeth" if r.startswith("teeth") else r

    for c, (name, role) in enumerate(zip(tgt.model.component_names, tgt.roles, strict=True)):
        if not (tgt.model.component_labels == c).any():
            continue
        if role == "skin":
            parts[name] = "skin"
            continue
        cands = [i for i, r in enumerate(s_roles) if r == role and r != "other"]
        if not cands and role not in ("eyeball_left", "eyeball_right", "teeth_upper", "teeth_lower", "other"):
            cands = [i for i, r in enumerate(s_roles) if family(r) == family(role)]
        cands = [i for i in cands if (src.model.component_labels == i).any()]
        if cands:
            ct = part_centre(tgt, c)
            best = min(cands, key=lambda i: float(np.linalg.norm(part_centre(src, i) - ct)))
            # a partner must be near: within a tenth of the head
            if float(np.linalg.norm(part_centre(src, best) - ct)) < 0.1:
                plan.append((c, "matched", best))
                parts[name] = f"matched {src.model.component_names[best]}"
                continue
        if role in ("eyeball_left", "eyeball_right", "eyeball", "teeth_upper"):
            plan.append((c, "fixed", -1))
            parts[name] = "fixed"
        elif role in RIGID_ROLES:
            plan.append((c, "rigid", -1))
            parts[name] = "rigid with the skin"
        else:
            plan.append((c, "follow", -1))
            parts[name] = "follows the skin"
    return parts, plan
