"""numba kernels for the per-frame pose-space pipeline (optional; numpy fallbacks elsewhere).

Why numba: a frame of pose-space wrinkles at 100k vertices is ``u = B·u_H``
(89 columns), vertex normals, local frames and WPSD (16 edges × 6–7 poses per
vertex). In numpy these are ~10 separate passes with temporaries and a
single-threaded sparse gather, ≈ 20 ms at 100k (``benchmarks/bench_wrinkles.py``,
``shared/notes/performance-anchors.md``); the frame budget is 6 ms. Fused,
two-thread loops over vertices reach it. BLAS is deliberately *not* used in
the frame loop: spinning OpenBLAS threads next to numba threads on 2 cores was
3–13× slower, so ``B·u_H`` is a numba kernel too.

Every kernel writes into a caller-provided output (no allocation per frame)
and uses float32 storage with float32 arithmetic, like a GPU implementation.
numba's threads follow ``numba.set_num_threads`` (default: all cores).
``AVAILABLE`` is False when numba is not installed; callers then use numpy.
"""

from __future__ import annotations

import numpy as np

from workbench._numba import NUMBA, njit, prange

#: numba is installed (else the kernels run as plain Python; see workbench._numba)
AVAILABLE = NUMBA

_BLOCK = 1024


@njit(parallel=True, fastmath=True, cache=True)
def bmul_add(B, uH, rest, out):
    """``out = rest + B @ uH``; B (n, H) float32 in Fortran order, uH (H, 3), rest/out (n, 3).

    Blocks of rows (their accumulators stay in L1), one pass over each column
    of the Fortran-ordered basis per block. The column is taken as a 1-D
    contiguous slice so the inner loop vectorizes (indexing ``B[i, j]``
    directly did not: 1.5x slower at 80k).
    """
    n, H = B.shape
    nblocks = (n + _BLOCK - 1) // _BLOCK
    for bi in prange(nblocks):
        s = bi * _BLOCK
        e = min(n, s + _BLOCK)
        m = e - s
        acc = np.zeros((3, _BLOCK), np.float32)
        a0 = acc[0]
        a1 = acc[1]
        a2 = acc[2]
        for j in range(H):
            u0, u1, u2 = uH[j, 0], uH[j, 1], uH[j, 2]
            if u0 == 0.0 and u1 == 0.0 and u2 == 0.0:
                continue
            col = B[s:e, j]
            for i in range(m):
                b = col[i]
                a0[i] += b * u0
                a1[i] += b * u1
                a2[i] += b * u2
        for i in range(m):
            out[s + i, 0] = rest[s + i, 0] + a0[i]
            out[s + i, 1] = rest[s + i, 1] + a1[i]
            out[s + i, 2] = rest[s + i, 2] + a2[i]


@njit(parallel=True, fastmath=True, cache=True)
def vertex_normals(X, faces, vf_ptr, vf_idx, face_rows, rows, fbuf, out):
    """Area-weighted unit vertex normals of X for the vertices ``rows`` into ``out`` (n, 3).

    The per-frame twin of :func:`workbench.geometry.normals.vertex_normals` (same
    convention, float32; ``tests/test_geometry_normals.py`` holds them equal),
    kept for speed: it fuses the cross products and the gather over a
    vertex -> face CSR (``vf_ptr``, ``vf_idx``) into two threaded passes with no
    allocation, and visits only the vertices that carry details, where the numpy
    function makes ~10 passes over the whole mesh (the 6 ms frame budget above).

    ``face_rows``: the faces incident to ``rows`` (their cross products go to the
    scratch ``fbuf`` (m, 3)); rows of ``out`` not in ``rows`` are left as they are.
    Wrinkles need normals only where there are details, often half of the head.
    """
    for i in prange(face_rows.shape[0]):
        f = face_rows[i]
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        e1x, e1y, e1z = X[b, 0] - X[a, 0], X[b, 1] - X[a, 1], X[b, 2] - X[a, 2]
        e2x, e2y, e2z = X[c, 0] - X[a, 0], X[c, 1] - X[a, 1], X[c, 2] - X[a, 2]
        fbuf[f, 0] = e1y * e2z - e1z * e2y
        fbuf[f, 1] = e1z * e2x - e1x * e2z
        fbuf[f, 2] = e1x * e2y - e1y * e2x
    for i in prange(rows.shape[0]):
        v = rows[i]
        sx = np.float32(0.0)
        sy = np.float32(0.0)
        sz = np.float32(0.0)
        for k in range(vf_ptr[v], vf_ptr[v + 1]):
            f = vf_idx[k]
            sx += fbuf[f, 0]
            sy += fbuf[f, 1]
            sz += fbuf[f, 2]
        ln = np.sqrt(sx * sx + sy * sy + sz * sz)
        if ln > 0:
            out[v, 0] = sx / ln
            out[v, 1] = sy / ln
            out[v, 2] = sz / ln
        else:
            out[v, 0] = 0.0
            out[v, 1] = 0.0
            out[v, 2] = 0.0


@njit(inline="always", fastmath=True)
def _frame_apply(X, N, nb, v, d0, d1, d2):
    """World vector of local (d0, d1, d2) in the frame [t, b, n] of vertex v."""
    nx, ny, nz = N[v, 0], N[v, 1], N[v, 2]
    w = nb[v]
    tx, ty, tz = X[w, 0] - X[v, 0], X[w, 1] - X[v, 1], X[w, 2] - X[v, 2]
    dot = tx * nx + ty * ny + tz * nz
    tx -= dot * nx
    ty -= dot * ny
    tz -= dot * nz
    ln = np.sqrt(tx * tx + ty * ty + tz * tz)
    if ln < 1e-12:  # same fallback as pose_space.local_frames
        if abs(nx) < 0.9:
            tx, ty, tz = 1.0 - nx * nx, -nx * ny, -nx * nz
        else:
            tx, ty, tz = -ny * nx, 1.0 - ny * ny, -ny * nz
        ln = np.sqrt(tx * tx + ty * ty + tz * tz)
    tx /= ln
    ty /= ln
    tz /= ln
    bx, by, bz = ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx
    return (
        tx * d0 + bx * d1 + nx * d2,
        ty * d0 + by * d1 + ny * d2,
        tz * d0 + bz * d1 + nz * d2,
    )


#: WPSD evaluates the pose distances in groups of this many poses (see wpsd_apply)
POSE_GROUP = 8


def wpsd_pose_table(FS: np.ndarray, f: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out[i, j] = (f_i − FS[j, i])²``, (F, P8) float32, zero in the padding columns.

    The only per-frame work that depends on the pose: F·P numbers (a few kB),
    computed once so the per-vertex loop only weights and sums table rows.
    """
    P = FS.shape[0]
    np.subtract(f[:, None], FS.T, out=out[:, :P])
    np.square(out[:, :P], out=out[:, :P])
    out[:, P:] = 0.0
    return out


def pad_poses(W: np.ndarray) -> np.ndarray:
    """(n, P, 3) RBF weights -> (n, P8, 3) float32, P8 the next multiple of :data:`POSE_GROUP`."""
    n, P, _ = W.shape
    P8 = -(-P // POSE_GROUP) * POSE_GROUP
    out = np.zeros((n, P8, 3), np.float32)
    out[:, :P] = W
    return out


@njit(parallel=True, fastmath=True, cache=True)
def wpsd_apply(X, N, nb, rows, a_idx, a_val, D, W, strength, add_base, out):
    """WPSD (eq. 3, 5) + local frames: ``out = [X +] strength · R_v Σ_j W[v, j] ‖f − FS_j‖_v``.

    Only the vertices ``rows`` (those with non-zero RBF weights) are written;
    the caller fills the others (``X`` or zero: their detail is zero).

    X, N (n, 3) float32: large-scale positions and their unit normals; nb (n,)
    tangent neighbours; a_idx/a_val (n, K) edge weights (strongest first, zero
    padded); D (F, P8) the table of :func:`wpsd_pose_table`; W (n, P8, 3) RBF
    weights padded by :func:`pad_poses`.

    Eight poses at a time in eight scalar accumulators: the sums over a
    vertex's edges are then eight independent chains (twice as fast as one
    accumulator array per vertex, which serializes on store-to-load latency).
    """
    K = a_idx.shape[1]
    P8 = D.shape[1]
    for row in prange(rows.shape[0]):
        v = rows[row]
        d0 = np.float32(0.0)
        d1 = np.float32(0.0)
        d2 = np.float32(0.0)
        for j0 in range(0, P8, 8):
            r0 = r1 = r2 = r3 = r4 = r5 = r6 = r7 = np.float32(0.0)
            for k in range(K):
                a = a_val[v, k]
                if a == 0.0:
                    break  # weights are sorted strongest first, zeros only pad the row
                i = a_idx[v, k]
                r0 += a * D[i, j0]
                r1 += a * D[i, j0 + 1]
                r2 += a * D[i, j0 + 2]
                r3 += a * D[i, j0 + 3]
                r4 += a * D[i, j0 + 4]
                r5 += a * D[i, j0 + 5]
                r6 += a * D[i, j0 + 6]
                r7 += a * D[i, j0 + 7]
            rs = (np.sqrt(r0), np.sqrt(r1), np.sqrt(r2), np.sqrt(r3),
                  np.sqrt(r4), np.sqrt(r5), np.sqrt(r6), np.sqrt(r7))  # fmt: skip
            for q in range(8):
                r = rs[q]
                d0 += W[v, j0 + q, 0] * r
                d1 += W[v, j0 + q, 1] * r
                d2 += W[v, j0 + q, 2] * r
        wx, wy, wz = _frame_apply(X, N, nb, v, d0 * strength, d1 * strength, d2 * strength)
        if add_base:
            out[v, 0] = X[v, 0] + wx
            out[v, 1] = X[v, 1] + wy
            out[v, 2] = X[v, 2] + wz
        else:
            out[v, 0] = wx
            out[v, 1] = wy
            out[v, 2] = wz


@njit(parallel=True, fastmath=True, cache=True)
def psd_apply(X, N, nb, phi, W, strength, add_base, out):
    """Global PSD (eq. 2) + local frames: ``out = [X +] strength · R_v Σ_j φ_j W[j, v]``; W (P, n, 3)."""
    P, n = W.shape[0], W.shape[1]
    for v in prange(n):
        d0 = np.float32(0.0)
        d1 = np.float32(0.0)
        d2 = np.float32(0.0)
        for j in range(P):
            d0 += W[j, v, 0] * phi[j]
            d1 += W[j, v, 1] * phi[j]
            d2 += W[j, v, 2] * phi[j]
        wx, wy, wz = _frame_apply(X, N, nb, v, d0 * strength, d1 * strength, d2 * strength)
        if add_base:
            out[v, 0] = X[v, 0] + wx
            out[v, 1] = X[v, 1] + wy
            out[v, 2] = X[v, 2] + wz
        else:
            out[v, 0] = wx
            out[v, 1] = wy
            out[v, 2] = wz


def vertex_face_csr(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex -> incident faces as CSR (ptr (n+1,) int64, idx (3m,) int32)."""
    Fa = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    corner = Fa.ravel()
    order = np.argsort(corner, kind="stable")
    idx = (order // 3).astype(np.int32)
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(corner, minlength=n), out=ptr[1:])
    return ptr, idx
