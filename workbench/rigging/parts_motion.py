"""How the target's parts move in a transferred shape (the rows the skin's Poisson solve leaves out).

A part matched to a template part (an eyeball, the teeth, the tongue, lashes)
takes the template part's motion, seen through the fit's Jacobian around it; a
part without a partner follows the target's own transferred skin under it
(lashes, brows, hair) or moves rigidly with it (lower teeth, tongue); fixed
parts (eyeballs, upper teeth without a partner) stay still.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.geometry.surface import SurfaceQuery
from workbench.rigging.correspondence import Correspondence, PartPlan
from workbench.rigging.sides import Side

__all__ = ["PartsMotion"]


@dataclass(frozen=True)
class _MatchedPart:
    """What carrying a template part's motion to a target part needs that no shape changes."""

    s_ids: NDArray[np.intp]  # the template part's vertices
    Lp: NDArray[np.float64]  # (3, 3) the fit's Jacobian averaged over the skin around it
    Xmap: NDArray[np.float64]  # (q, 3) the target part's points in the template part's frame
    at_ids: NDArray[np.intp]  # (q, 3) template vertices blended at each point's closest point ((q, 1) nearest)
    at_w: NDArray[np.float64]  # (q, 3) their barycentric weights ((q, 1) ones)
    offset: NDArray[np.float64]  # (q, 3) from that closest point to the point
    affine: NDArray[np.float64]  # (4, p) least squares of an affine motion over the template part


class PartsMotion:
    """Fills the target parts' rows of transferred shapes.

    Parameters
    ----------
    src, tgt : Side
        The template and the target in the working frame.
    corr : Correspondence
        Its fit's Jacobians and the template triangle areas weigh the local Jacobian.
    plan : list of (int, str, int)
        What each target part does (:func:`.correspondence.match_parts`).
    """

    def __init__(self, src: Side, tgt: Side, corr: Correspondence, plan: PartPlan) -> None:
        self.src, self.tgt, self.corr, self.plan = src, tgt, corr, plan
        self._tri_tree: cKDTree | None = None
        self._parts: dict[int, _MatchedPart] = {}  # per matched target part, built on first use

    def local_jacobian(self, P: NDArray[np.float64], k: int = 8) -> NDArray[np.float64]:
        """(3, 3): the fit's Jacobian averaged (by area) over the template skin triangles nearest to the points ``P``."""
        src = self.src
        if self._tri_tree is None:
            self._tri_tree = cKDTree(src.skin_X[src.skin_faces].mean(1))
        _, nn = self._tri_tree.query(P, k=min(k, src.skin_faces.shape[0]))
        near = np.unique(nn)
        w = self.corr.src_area[near]
        L = (self.corr.J_fit[near] * w[:, None, None]).sum(0) / max(float(w.sum()), 1e-300)
        return L if abs(np.linalg.det(L)) > 1e-9 else np.eye(3)

    def matched_points(self) -> dict[int, NDArray[np.float64]]:
        """Per matched target part (component id), its points placed in the template part's frame, (p, 3)."""
        return {c: self._matched_part(c, sc).Xmap for c, how, sc in self.plan if how == "matched"}

    def fill(self, deltas: NDArray[np.float64], out: NDArray[np.float64], *,
             jacobians: Mapping[int, NDArray[np.float64]] | None = None) -> None:
        """Fill the target parts' rows of ``out`` (k, n, 3), working frame, from template ``deltas`` (k, N, 3).

        The skin rows of ``out`` must hold the transferred skin already (parts follow it).
        ``jacobians``, optional: per matched part (component id), (p, 3, 3) maps of its motion
        at each of its :meth:`matched_points`, in place of the one averaged over the skin
        around the part (expression cloning's smooth field).
        """
        tgt = self.tgt
        skin_tree: cKDTree | None = None
        for c, how, sc in self.plan:
            ids = np.flatnonzero(tgt.model.component_labels == c)
            if how == "fixed":
                continue
            if how == "matched":
                out[:, ids] = self._matched(deltas, self._matched_part(c, sc),
                                            None if jacobians is None else jacobians.get(c))
                continue
            # no partner: follow the target's own (already transferred) skin
            if skin_tree is None:
                skin_tree = cKDTree(tgt.skin_X)
            if how == "follow":
                _, nn = skin_tree.query(tgt.X[ids])
                out[:, ids] = out[:, tgt.skin_ids[nn]]
            else:
                out[:, ids] = self._rigid_with_skin(out, tgt.X[ids], skin_tree)

    def _matched_part(self, c: int, sc: int) -> _MatchedPart:
        """Target part ``c`` placed on template part ``sc`` (kept: cloning fills every block of frames).

        The part's linear map: the fit's Jacobian averaged over the template skin around it; its
        place: the parts' centroids. Each placed point reads the template part's motion at the
        closest point of its surface.
        """
        part = self._parts.get(c)
        if part is not None:
            return part
        src = self.src
        Y = self.tgt.X[self.tgt.model.component_labels == c]
        s_ids = np.flatnonzero(src.model.component_labels == sc)
        Xs = src.X[s_ids]
        Lp = self.local_jacobian(Xs)
        Xmap = (Y - Y.mean(0)) @ np.linalg.inv(Lp).T + Xs.mean(0)
        sF = np.asarray(src.model.faces, np.int64)
        lab = src.model.component_labels
        pf = sF[(lab[sF] == sc).all(1)]
        if pf.size:
            _, f, C, b = SurfaceQuery(src.X, pf).closest(Xmap)
            at_ids, at_w = pf[f], b
        else:
            _, nn = cKDTree(Xs).query(Xmap)
            C, at_ids, at_w = Xs[nn], s_ids[nn][:, None], np.ones((len(nn), 1))
        affine = np.linalg.pinv(np.c_[Xs - Xs.mean(0), np.ones(len(Xs))])
        part = self._parts[c] = _MatchedPart(s_ids, Lp, Xmap, at_ids, at_w, Xmap - C, affine)
        return part

    def _matched(self, deltas: NDArray[np.float64], part: _MatchedPart,
                 jacobian: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """(k, q, 3): the motion of the template part carried to the target part's points (see :meth:`fill`)."""
        src = self.src
        lin = src.frame.scale * src.frame.R
        dpart = deltas[:, part.s_ids] @ lin.T  # (k, p, 3) working frame
        # the template part's motion at the closest point of its surface, plus its affine motion
        # (least squares over the part) across the offset from there: exact on the template's own
        # part, first-order right for a part of another shape moving rigidly
        coef = part.affine @ dpart.transpose(1, 0, 2).reshape(len(part.s_ids), -1)
        lin_k = coef[:3].reshape(3, -1, 3)  # [j, shape, comp]: d_comp = sum_j x_j lin_k[j]
        at = np.einsum("qj,kqjc->kqc", part.at_w, deltas[:, part.at_ids] @ lin.T)
        at = at + np.einsum("qj,jkc->kqc", part.offset, lin_k)
        if jacobian is not None:
            return np.asarray(np.einsum("qij,kqj->kqi", jacobian, at))
        return np.asarray(at @ part.Lp.T)

    def _rigid_with_skin(self, out: NDArray[np.float64], Y: NDArray[np.float64], skin_tree: cKDTree
                         ) -> NDArray[np.float64]:
        """(k, p, 3): a linearised rigid motion fitted to the nearest transferred skin, at the points ``Y``."""
        tgt = self.tgt
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
        return np.asarray(np.cross(wv[:, None, :], ry[None]) + tv[:, None, :])
