"""Step 5 of a rig transfer: the Poisson system that carries template deformation gradients onto the target.

Per shape, the template's deformation gradient of each triangle ``G = M' M⁻¹``
(Sumner & Popović's frames, :func:`workbench.geometry.frames.triangle_frames`)
is carried to the target triangles that map to it, conjugated by the fit's
local Jacobian ``J`` (``J G J⁻¹``), and the displacement ``d`` whose triangle
gradients match ``(G − I)`` in the tangent planes solves
``(Dᵀ A D + P) d = Dᵀ A g`` (``D`` the per-triangle gradient, ``A`` the
triangle areas, ``P`` a pin holding target vertices still where the template
has no partner or never moves). :class:`PoissonTransfer` factors the matrix
once (CHOLMOD) and keeps the sparse, linear map from template deltas to the
right-hand side, so all shapes go as one multi-column solve.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from workbench.geometry.normals import face_normals
from workbench.geometry.sparse_cholesky import SparseSPDSolver
from workbench.rigging.correspondence import MAP_DISTANCE, Correspondence, safe_inverse
from workbench.rigging.sides import Side

__all__ = ["PoissonTransfer"]


def _cross_matrix(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """(p, 3, 3): ``[v]_x w = v x w``."""
    out = np.zeros((v.shape[0], 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -v[:, 2], v[:, 1]
    out[:, 1, 0], out[:, 1, 2] = v[:, 2], -v[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -v[:, 1], v[:, 0]
    return out


def _hat_gradients(Y: NDArray[np.float64], Fg: NDArray[np.int64]) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
]:
    """Per triangle: hat-function gradients ``g[t, a]`` (m, 3, 3), areas (m,) and unit normals (m, 3)."""
    cr = face_normals(Y, Fg, unit=False)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    nrm = cr / (2.0 * area[:, None])
    P = Y[Fg]
    g = np.stack([np.cross(nrm, P[:, 2] - P[:, 1]), np.cross(nrm, P[:, 0] - P[:, 2]),
                  np.cross(nrm, P[:, 1] - P[:, 0])], axis=1) / (2.0 * area[:, None, None])
    return g, area, nrm


class PoissonTransfer:
    """The target skin's Poisson system, factored once, and its right-hand sides for template deltas.

    Parameters
    ----------
    src, tgt : Side
        The template and the target in the working frame.
    t_good : (m_t,) bool
        The target's usable skin triangles.
    corr : Correspondence
        Target skin -> fitted template (:func:`.correspondence.correspond`).

    Attributes
    ----------
    matrix : (n_t, n_t) sparse CSC
        ``Dᵀ A D + P`` (kept for peers and checks).
    system : SparseSPDSolver
        Its factorisation.
    pin_share : float
        Share of the target skin vertices pinned (partly or fully).
    """

    def __init__(self, src: Side, tgt: Side, t_good: NDArray[np.bool_], corr: Correspondence) -> None:
        Y = tgt.skin_X
        n = Y.shape[0]
        Fg = tgt.skin_faces[t_good]
        g, area, nrm = _hat_gradients(Y, Fg)
        # cotangent matrix sum_t A_t g_a . g_b
        blocks = area[:, None, None] * np.einsum("tal,tbl->tab", g, g)
        rows = np.repeat(Fg, 3, axis=1).ravel()
        cols = np.tile(Fg, (1, 3)).ravel()
        Lc = sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(n, n))
        # still vertices: far from the fitted template (neck, bust), or on template triangles no shape moves
        source = src.model
        moving_src = np.ones(source.n_vertices, bool)  # no shapes (a performance's source): all may move
        if source.shapes:
            disp = np.stack([sh.delta for sh in source.shapes])
            big = float(np.abs(disp).max())
            moving_src = np.any(np.abs(disp) > 1e-7 * big, axis=(0, 2)) if big > 0 else np.zeros_like(moving_src)
        still_face = ~np.any(moving_src[src.skin_ids[src.skin_faces]], axis=1)
        pin = np.clip((corr.v_dist - MAP_DISTANCE) / MAP_DISTANCE, 0.0, 1.0)
        pin[corr.v_ok & still_face[corr.v_face]] = 1.0
        diag = np.asarray(Lc.diagonal()).ravel()
        scale = float(diag[diag > 0].mean()) if (diag > 0).any() else 1.0
        w = 100.0 * np.where(diag > 0, diag, scale) * pin + 1e-8 * scale
        self.pin_share = float((pin > 0).mean())
        self.matrix = sp.csc_matrix(Lc + sp.diags(w))
        self.system = SparseSPDSolver(self.matrix)
        self._rhs_map = _rhs_operator(src, corr, Fg, g, area, nrm, n)

    def right_hand_sides(self, deltas: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n_target_skin, 3 k) right-hand sides of :attr:`matrix` for (k, N, 3) template deltas (columns: component, shape)."""
        k = deltas.shape[0]
        rhs = self._rhs_map @ np.asarray(deltas, np.float64).transpose(1, 2, 0).reshape(-1, k)  # (3 n, k)
        return np.asarray(rhs).reshape(-1, 3 * k)

    def solve(self, deltas: NDArray[np.float64]) -> NDArray[np.float64]:
        """(k, n_target_skin, 3) target skin displacements (working frame) of (k, N, 3) template deltas (model units)."""
        k = deltas.shape[0]
        rhs = self.right_hand_sides(deltas)
        sol = self.system.solve(rhs)  # columns (component, shape)
        return np.asarray(sol).reshape(rhs.shape[0], 3, k).transpose(2, 0, 1)


def _rhs_operator(
    src: Side, corr: Correspondence, Fg: NDArray[np.int64], g: NDArray[np.float64], area: NDArray[np.float64],
    nrm: NDArray[np.float64], n: int,
) -> sp.csr_matrix:
    """(3 n_target_skin, 3 N_template) sparse: template deltas (model units) -> ``D^T A g`` of the target.

    Linear in the deltas: the frame ``M = [e1, e2, n / sqrt|n|]`` of each
    template triangle is differentiated at rest (exact for the in-plane
    columns; the normal column to first order), so a blend of transferred
    shapes is the transfer of the blend.
    """
    sF = src.skin_faces
    tri = corr.tri_src
    X = src.skin_X[sF[tri]]  # (m, 3, 3) template corners of each target triangle's partner
    e1, e2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    c = np.cross(e1, e2)
    a = np.linalg.norm(c, axis=1)
    a = np.where(a > 0, a, 1.0)
    ch = c / a[:, None]
    proj = np.eye(3)[None] - 0.5 * ch[:, :, None] * ch[:, None, :]
    N1 = -(proj @ _cross_matrix(e2)) / np.sqrt(a)[:, None, None]
    N2 = (proj @ _cross_matrix(e1)) / np.sqrt(a)[:, None, None]
    Minv = corr.src_frames_inv[tri]  # rows r1, r2, r3
    J = corr.J[tri]
    Jinv = safe_inverse(J)
    Pt = np.eye(3)[None] - nrm[:, :, None] * nrm[:, None, :]
    B = Jinv @ Pt
    q = np.einsum("tkl,tak->tal", B, Minv)  # q[t, a] = B^T r_a
    JN1, JN2 = J @ N1, J @ N2
    T1 = J[:, :, None, :] * q[:, 0, None, :, None] + JN1[:, :, None, :] * q[:, 2, None, :, None]  # [t, i, l, j]
    T2 = J[:, :, None, :] * q[:, 1, None, :, None] + JN2[:, :, None, :] * q[:, 2, None, :, None]
    lin = src.frame.scale * src.frame.R  # model delta -> working frame
    T1 = T1 @ lin
    T2 = T2 @ lin
    C = np.stack([-(T1 + T2), T1, T2], axis=1)  # (m, corner c, i, l, j)
    E = area[:, None, None, None, None] * np.einsum("tal,tcilj->taicj", g, C)  # (m, a, i, c, j)
    scorn = src.skin_ids[sF[tri]]  # (m, 3) template model vertex ids
    rows = (3 * Fg[:, :, None, None, None] + np.arange(3)[None, None, :, None, None])
    cols = (3 * scorn[:, None, None, :, None] + np.arange(3)[None, None, None, None, :])
    rows, cols = np.broadcast_arrays(rows, cols)
    keep = np.repeat(corr.tri_near, 81)
    R = sp.csr_matrix((E.ravel()[keep], (rows.ravel()[keep], cols.ravel()[keep])),
                      shape=(3 * n, 3 * src.model.n_vertices))
    R.sum_duplicates()
    return R
