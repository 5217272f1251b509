"""One frame of a point cloud against the posed samples: PCA normals, point-to-plane ICP, correspondences.

Steps 2 and 3 of :mod:`workbench.capture.clouds`: the rigid pose by
point-to-plane ICP (a linearised rotation and translation, Huber weights) and
the pairs the weights are fitted to (nearest cloud point, rejected when far,
when the normals disagree or as a Tukey outlier).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

__all__ = ["CloudNormals", "cloud_pairs", "rigid_icp", "unit"]

#: neighbours of a cloud point for its PCA normal
_NORMAL_K = 8


def unit(N: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rows scaled to unit length (zero rows stay zero), (..., 3)."""
    ln = np.linalg.norm(N, axis=-1, keepdims=True)
    return N / np.where(ln > 0, ln, 1.0)


class CloudNormals:
    """PCA normals of one cloud, computed for the points that are asked for (cached)."""

    def __init__(self, P: NDArray[np.float64], tree: cKDTree) -> None:
        self.P = P
        self.tree = tree
        self.N = np.full((P.shape[0], 3), np.nan)

    def __call__(self, j: NDArray[np.intp]) -> NDArray[np.float64]:
        todo = np.unique(j[np.isnan(self.N[j, 0])])
        if todo.size:
            k = min(_NORMAL_K, self.P.shape[0])
            _, nb = self.tree.query(self.P[todo], k=k)
            nb = np.asarray(nb).reshape(todo.size, k)
            Q = self.P[nb] - self.P[nb].mean(1, keepdims=True)
            C = np.einsum("pki,pkj->pij", Q, Q)
            _, vec = np.linalg.eigh(C)
            self.N[todo] = vec[:, :, 0]
        return self.N[j]


def rigid_icp(X: NDArray[np.float64], N: NDArray[np.float64], tree: cKDTree, cloud: NDArray[np.float64],
               normals: CloudNormals, M: NDArray[np.float64], thr: float, cos_min: float, steps: int,
               min_pairs: int) -> tuple[NDArray[np.float64], int]:
    """Point-to-plane ICP of model points ``X`` (normals ``N``) to the cloud from pose ``M``: (pose, pairs)."""
    R, t = M[:3, :3].copy(), M[:3, 3].copy()
    used = 0
    for _ in range(steps):
        Q = X @ R.T + t
        Nw = N @ R.T
        d, j = tree.query(Q, distance_upper_bound=thr)
        ok = np.isfinite(d)
        if ok.sum() < min_pairs:
            break
        jj = j[ok]
        cos = np.abs((normals(jj) * Nw[ok]).sum(1))
        keep = cos >= cos_min
        if keep.sum() < min_pairs:
            break
        Qk, Nk, Ck = Q[ok][keep], Nw[ok][keep], cloud[jj[keep]]
        r = (Nk * (Qk - Ck)).sum(1)
        sig = max(1.4826 * float(np.median(np.abs(r))), 1e-12 * thr)
        w = np.minimum(1.0, 1.345 * sig / np.maximum(np.abs(r), 1e-300))  # Huber
        qc = Qk.mean(0)
        J = np.concatenate([np.cross(Qk - qc, Nk), Nk], axis=1)  # d r / d (ω, τ)
        H = (J * w[:, None]).T @ J
        g = (J * w[:, None]).T @ r
        H[np.diag_indices(6)] += 1e-12 * max(float(np.trace(H)), 1e-300)
        try:
            step = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        dR = Rotation.from_rotvec(step[:3]).as_matrix()
        R = dR @ R
        t = dR @ (t - qc) + qc + step[3:]
        used = int(keep.sum())
        if np.linalg.norm(step[:3]) * thr + np.linalg.norm(step[3:]) < 1e-4 * thr:
            break
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R, t
    return out, used


def cloud_pairs(X: NDArray[np.float64], N: NDArray[np.float64], M: NDArray[np.float64], tree: cKDTree,
           cloud: NDArray[np.float64], normals: CloudNormals, thr: float, cos_min: float, min_pairs: int,
           size: float) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None:
    """One correspondence pass: each sample's nearest cloud point, with the rejections of the module docstring.

    Returns
    -------
    (ok, C, rw, dist) or None
        Accepted sample indices ``(m,)``, their targets in the model frame ``(m, 3)``, Tukey
        weights ``(m,)`` and distances ``(m,)``; None when fewer than ``min_pairs`` remain.
    """
    R, t = M[:3, :3], M[:3, 3]
    Q = X @ R.T + t
    d, j = tree.query(Q, distance_upper_bound=thr)
    ok = np.flatnonzero(np.isfinite(d))
    if ok.size < min_pairs:
        return None
    cos = np.abs((normals(j[ok]) * (N[ok] @ R.T)).sum(1))
    ok = ok[cos >= cos_min]
    if ok.size < min_pairs:
        return None
    C = (cloud[j[ok]] - t) @ R  # model frame
    r = (N[ok] * (X[ok] - C)).sum(1)
    sig = max(1.4826 * float(np.median(np.abs(r))), 1e-9 * size)
    good = np.abs(r) <= 4.685 * sig  # Tukey's rejection point
    if int(good.sum()) < min_pairs:
        return None
    u = np.abs(r[good]) / (4.685 * sig)
    return ok[good], C[good], (1.0 - u * u) ** 2, d[ok][good]
