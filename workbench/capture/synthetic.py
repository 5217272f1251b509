"""Generated ground truth for tracking: known weight curves and head motion → markers, landmarks, point clouds.

Nothing here is measured: :func:`synthetic_performance` *makes* a performance
whose answer is known, so tests and benchmarks can score a tracker
(Bouaziz et al. 2013, §3.1) by weight RMSE and pose error rather than by eye.

* **Weights** ``(T, k)``: sparse smooth curves, like a real performance — a few
  shapes active at a time (``active`` on average), each activation a
  raised-cosine bump (exactly 0 outside its support, smooth inside) of
  0.3–1.5 s and amplitude 0.3–1.0, clipped to the slider range. Muted shapes
  stay 0; derived (corrective) shapes play their drivers' product, as
  ``model.evaluate`` does (:class:`~workbench.capture.rig.ExpressionSpace`).
* **Head motion** ``(T, 4, 4)``: smooth yaw/pitch/roll (up to ``15° · head_motion``)
  about the head's centre and a smooth drift (up to ``0.05 · head_motion`` head
  sizes); ``p -> R p + t`` as the timeline's head pose.
* **Meshes** ``(T, n, 3)``: ``neutral + Σ w δ`` posed — the blend stage of
  ``model.evaluate`` (a model without layer edits evaluates to the same).
* **Markers** ``(T, m, 3)`` at ``marker_ids`` and **landmarks** ``(T, l, 3)`` at a
  disjoint vertex set ``landmark_ids``: the meshes there, plus Gaussian noise,
  with occlusions as NaN runs (each observation hidden with probability
  ``occlusion``, in runs of a few frames).
* **Point clouds** (when ``points > 0``): per frame, ``points`` area-weighted random
  samples of the front-facing skin triangles of the posed mesh, plus noise, and a
  share ``outliers`` of points scattered in the head's bounding box; the triangle
  and barycentric coordinates of each sample are kept (``-1`` for outliers).

The curves reuse the idea of :func:`workbench.methods.regions.marker_fit._smooth_curves`
(smooth bumps per shape) but with compact support, so that most weights are
exactly zero at any time, which is what an L1 prior assumes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.rig import ExpressionSpace
from workbench.geometry.axes import axis_vector
from workbench.geometry.masks import skin_or_all_mask
from workbench.geometry.normals import face_normals, vertex_normals

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["SyntheticPerformance", "face_vertices", "synthetic_performance"]


@dataclass(frozen=True, eq=False)
class SyntheticPerformance:
    """A generated take and its truth (see the module docstring). Lengths in model units.

    Attributes
    ----------
    fps : float
    shape_names : tuple of str
    weights : (T, k) float
        True played weights in ``shape_names`` order.
    poses : (T, 4, 4) float
        True head pose ``p -> R p + t``.
    meshes : (T, n, 3) float32
        True posed meshes (no noise).
    marker_ids : (m,) int
    markers : (T, m, 3) float
        Noisy marker positions, NaN where occluded.
    landmark_ids : (l,) int
        Disjoint from ``marker_ids``.
    landmarks : (T, l, 3) float
    clouds : list of (p, 3) float
        One point cloud per frame (empty list when ``points == 0``).
    cloud_triangles : list of (p,) int
        Skin triangle of each sample (``-1`` for an outlier).
    cloud_barycentric : (list of (p, 3) float)
        Barycentric coordinates of each sample in its triangle.
    noise : float
    head_size : float
    """

    fps: float
    shape_names: tuple[str, ...]
    weights: NDArray[np.float64]
    poses: NDArray[np.float64]
    meshes: NDArray[np.float32]
    marker_ids: NDArray[np.intp]
    markers: NDArray[np.float64]
    landmark_ids: NDArray[np.intp]
    landmarks: NDArray[np.float64]
    clouds: list[NDArray[np.float64]]
    cloud_triangles: list[NDArray[np.intp]]
    cloud_barycentric: list[NDArray[np.float64]]
    noise: float
    head_size: float

    @property
    def n_frames(self) -> int:
        return int(self.weights.shape[0])


# ------------------------------------------------------------------ geometry helpers
def face_vertices(model: FaceState) -> NDArray[np.intp]:
    """Front-facing skin vertices around the moving part of the face (where markers are glued).

    The bounding box of the vertices some shape moves by ≥ 5 % of the largest
    move, grown by 10 % (so forehead, temples and nose bridge, which barely
    move, are in), intersected with the skin vertices whose neutral normal is
    within 70° of ``metadata.front_axis``.
    """
    V = np.asarray(model.vertices, np.float64)
    F = np.asarray(model.faces, np.int64)
    skin = skin_or_all_mask(model)
    space = ExpressionSpace.from_model(model)
    mot = space.motion()
    front = axis_vector(model.metadata.front_axis)
    moving = skin & (mot >= 0.05 * max(float(mot[skin].max(initial=0.0)), 1e-300))
    if not moving.any():
        moving = skin
    lo, hi = V[moving].min(0), V[moving].max(0)
    pad = 0.1 * (hi - lo)
    inside = ((V >= lo - pad) & (V <= hi + pad)).all(1)
    N = vertex_normals(V, F) if F.size else np.tile(front, (V.shape[0], 1))
    facing = N @ front > np.cos(np.radians(70.0))
    ids = np.flatnonzero(skin & inside & facing)
    return ids if ids.size else np.flatnonzero(skin)


def spread_face_vertices(model: FaceState, count: int, *, seed: int = 0) -> NDArray[np.intp]:
    """``count`` face vertices spread out by farthest-point sampling (where a marker set would be glued).

    From :func:`face_vertices`; sorted ids. Deterministic given ``seed``.
    """
    cand = face_vertices(model)
    if int(count) < 3:
        raise ValueError(f"count must be at least 3 markers, got {count!r}")
    return _farthest(np.asarray(model.vertices, np.float64), cand, int(count), np.random.default_rng(seed))


def _farthest(V: NDArray[np.float64], cand: NDArray[np.intp], m: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """``m`` spread-out vertices of ``cand`` by farthest-point sampling from a random start."""
    m = min(int(m), cand.size)
    chosen = [int(rng.integers(cand.size))]
    d = np.linalg.norm(V[cand] - V[cand[chosen[0]]], axis=1)
    for _ in range(m - 1):
        i = int(np.argmax(d))
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(V[cand] - V[cand[i]], axis=1))
    return np.sort(cand[np.array(chosen, np.intp)])


def _ids(value: int | ArrayLike, what: str, model: FaceState, cand: NDArray[np.intp], rng: np.random.Generator
         ) -> NDArray[np.intp]:
    if np.ndim(value) == 0:
        m = int(value)  # type: ignore[arg-type]
        if m < 0:
            raise ValueError(f"{what} must be a count ≥ 0 or vertex ids, got {value!r}")
        if m > cand.size:
            raise ValueError(f"{what}: asked for {m} points, the face has {cand.size} candidate vertices")
        return _farthest(np.asarray(model.vertices, np.float64), cand, m, rng) if m else np.zeros(0, np.intp)
    ids = np.asarray(value)
    if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"{what} must be a count or a 1-D array of vertex ids, got {ids.dtype} {ids.shape}")
    if ids.size and (ids.min() < 0 or ids.max() >= model.n_vertices):
        raise ValueError(f"{what}: vertex ids must be in 0..{model.n_vertices - 1}")
    return ids.astype(np.intp)


# ------------------------------------------------------------------ curves
def _bump_curves(rng: np.random.Generator, T: int, fps: float, eligible: NDArray[np.intp], k: int,
                 active: float) -> NDArray[np.float64]:
    """(T, k) sums of raised-cosine bumps on the eligible shapes, ``active`` bumps alive on average."""
    out = np.zeros((T, k))
    if T == 0 or eligible.size == 0 or active <= 0:
        return out
    t = np.arange(T, dtype=np.float64)
    mean_width = 0.9 * fps  # frames: widths are uniform in 0.3–1.5 s
    n_bumps = rng.poisson(active * (T + mean_width) / mean_width)
    for _ in range(int(n_bumps)):
        j = int(eligible[rng.integers(eligible.size)])
        width = rng.uniform(0.3, 1.5) * fps
        centre = rng.uniform(-0.5 * width, T - 1 + 0.5 * width)
        amp = rng.uniform(0.3, 1.0)
        u = (t - centre) / (0.5 * width)
        inside = np.abs(u) < 1.0
        out[inside, j] += amp * 0.5 * (1.0 + np.cos(np.pi * u[inside]))
    return out


def _smooth_noise(rng: np.random.Generator, T: int, fps: float, period: float) -> NDArray[np.float64]:
    """(T,) smooth curve in about [-1, 1]: a few sinusoids with periods around ``period`` seconds."""
    t = np.arange(T) / fps
    out = np.zeros(T)
    for _ in range(3):
        p = period * rng.uniform(0.5, 1.5)
        out += np.sin(2 * np.pi * t / p + rng.uniform(0, 2 * np.pi)) / 3.0
    return out


def _rotation(yaw: float, pitch: float, roll: float, up: NDArray[np.float64], front: NDArray[np.float64]
              ) -> NDArray[np.float64]:
    from scipy.spatial.transform import Rotation

    side = np.cross(up, front)
    return np.asarray(
        (Rotation.from_rotvec(yaw * up) * Rotation.from_rotvec(pitch * side) * Rotation.from_rotvec(roll * front)
         ).as_matrix(), np.float64)


def _occlude(rng: np.random.Generator, X: NDArray[np.float64], share: float, fps: float) -> None:
    """NaN runs (about 0.2 s long) hiding each observation with probability ``share``, in place."""
    if share <= 0 or X.size == 0:
        return
    T, m = X.shape[:2]
    run = max(1, round(0.2 * fps))
    starts = rng.random((T, m)) < share / run
    hidden = np.zeros((T, m), bool)
    for s in range(run):
        hidden[s:] |= starts[: T - s] if s else starts
    X[hidden] = np.nan


# ------------------------------------------------------------------ the generator
def synthetic_performance(
    model: FaceState,
    T: int,
    *,
    fps: float = 30.0,
    seed: int = 0,
    markers: int | ArrayLike = 100,
    landmarks: int | ArrayLike = 68,
    noise: float = 0.0,
    occlusion: float = 0.0,
    head_motion: float = 1.0,
    active: float = 3.0,
    shapes: ArrayLike | None = None,
    points: int = 0,
    outliers: float = 0.0,
    weights: ArrayLike | None = None,
) -> SyntheticPerformance:
    """A take with known answer (see the module docstring): a pure function of its arguments.

    Parameters
    ----------
    model : FaceModel
        Needs blendshapes.
    T : int
        Frames (≥ 1).
    fps : float
        Frame rate (> 0); curve widths and occlusion runs are in seconds.
    seed : int
    markers, landmarks : int or (m,) int
        A count (spread over :func:`face_vertices` by farthest-point sampling; the
        landmarks avoid the markers' vertices) or explicit vertex ids.
    noise : float
        Gaussian noise per coordinate, model units (markers, landmarks and clouds).
    occlusion : float
        In [0, 1): probability that a marker or landmark observation is NaN.
    head_motion : float
        ≥ 0: scales the rigid motion (0 = the head stays at the model's pose).
    active : float
        Shapes active at a time, on average.
    shapes : (s,) int or str, optional
        The shapes that may be animated (indices or names; default every plain shape).
    points : int
        Point-cloud samples per frame (0: no clouds).
    outliers : float
        In [0, 1): share of each cloud replaced by points scattered in the head's box.
    weights : (T, k) float, optional
        Play these weights (``shape_names`` order) instead of generated bumps: the plain
        shapes' columns are used, muted shapes are 0 and derived shapes follow their drivers
        (e.g. a realistic take from :func:`workbench.testing.realistic_take`). ``active``
        and ``shapes`` are then unused; the random stream of the rest is unchanged.

    Returns
    -------
    SyntheticPerformance
    """
    if isinstance(T, bool) or not isinstance(T, int | np.integer) or T < 1:
        raise ValueError(f"T must be an int ≥ 1, got {T!r}")
    for name, value, lo, hi in (("fps", fps, 0.0, np.inf), ("noise", noise, 0.0, np.inf),
                                ("occlusion", occlusion, 0.0, 1.0), ("head_motion", head_motion, 0.0, np.inf),
                                ("active", active, 0.0, np.inf), ("outliers", outliers, 0.0, 1.0)):
        v = float(value)
        if not (np.isfinite(v) and lo <= v and (v < hi or hi == np.inf)) or (name == "fps" and v <= 0):
            raise ValueError(f"{name} must be a finite number in [{lo:g}, {hi:g}), got {value!r}")
    if int(points) < 0:
        raise ValueError(f"points must be ≥ 0, got {points!r}")
    if not model.shapes:
        raise ValueError("model: it has no blendshapes to animate")
    rng = np.random.default_rng(seed)
    T = int(T)
    fps = float(fps)
    space = ExpressionSpace.from_model(model)
    k = space.k
    names = space.shape_names
    if shapes is None:
        eligible = space.plain
    else:
        sel = []
        for s in np.atleast_1d(np.asarray(shapes, object)):
            if isinstance(s, str) and s not in names:
                raise ValueError(f"shapes: the model has no shape {s!r}")
            j = names.index(s) if isinstance(s, str) else int(s)
            if not 0 <= j < k:
                raise ValueError(f"shapes: index {j} is not a shape (0..{k - 1})")
            sel.append(j)
        bad = [s for s in sel if s not in set(space.plain.tolist())]
        if bad:
            raise ValueError(f"shapes: {[names[b] for b in bad]} are muted or derived (not animatable)")
        eligible = np.array(sel, np.intp)

    # weights
    raw = _bump_curves(rng, T, fps, eligible, k, float(active))
    if weights is not None:
        given = np.asarray(weights, np.float64)
        if given.shape != (T, k):
            raise ValueError(f"weights must be (T, k) = ({T}, {k}) in shape_names order, got {given.shape}")
        if not np.isfinite(given).all():
            raise ValueError("weights must be finite")
        raw = given
    W = space.full_weights(raw[:, space.plain])

    # head motion
    V0 = space.neutral
    up, front = axis_vector(model.metadata.up_axis), axis_vector(model.metadata.front_axis)
    centre = 0.5 * (V0.min(0) + V0.max(0))
    size = space.size
    hm = float(head_motion)
    poses = np.tile(np.eye(4), (T, 1, 1))
    if hm > 0:
        amp = np.radians(15.0) * hm
        yaw = amp * _smooth_noise(rng, T, fps, 4.0)
        pitch = 0.6 * amp * _smooth_noise(rng, T, fps, 3.0)
        roll = 0.4 * amp * _smooth_noise(rng, T, fps, 5.0)
        drift = 0.05 * hm * size * np.stack([_smooth_noise(rng, T, fps, 6.0) for _ in range(3)], axis=1)
        for f in range(T):
            R = _rotation(yaw[f], pitch[f], roll[f], up, front)
            poses[f, :3, :3] = R
            poses[f, :3, 3] = centre - R @ centre + drift[f]

    # meshes: the blend, then the pose
    D = np.asarray(space.deltas, np.float64).reshape(k, -1)
    local = (V0.reshape(1, -1) + W @ D).reshape(T, -1, 3)
    meshes = np.einsum("tij,tnj->tni", poses[:, :3, :3], local) + poses[:, None, :3, 3]

    # markers and landmarks
    cand = face_vertices(model)
    marker_ids = _ids(markers, "markers", model, cand, rng)
    rest = np.setdiff1d(cand, marker_ids)
    landmark_ids = _ids(landmarks, "landmarks", model, rest if rest.size else cand, rng)
    nz = float(noise)

    def observe(ids: NDArray[np.intp]) -> NDArray[np.float64]:
        X = meshes[:, ids].copy()
        if nz > 0:
            X += rng.normal(0.0, nz, X.shape)
        _occlude(rng, X, float(occlusion), fps)
        return X

    marker_pos = observe(marker_ids)
    landmark_pos = observe(landmark_ids)

    # point clouds
    clouds: list[NDArray[np.float64]] = []
    tris: list[NDArray[np.intp]] = []
    barys: list[NDArray[np.float64]] = []
    if int(points) > 0:
        F = np.asarray(model.faces, np.int64)
        skin = skin_or_all_mask(model)
        fn = face_normals(V0, F, unit=False)
        area = 0.5 * np.linalg.norm(fn, axis=1)
        facing = (fn @ front) > 0.2 * 2.0 * area
        ok = skin[F].all(1) & facing
        face_ids = np.flatnonzero(ok)
        if face_ids.size == 0:
            raise ValueError("model: no front-facing skin triangles to sample a point cloud from")
        p = area[face_ids] / area[face_ids].sum()
        n_out = round(float(outliers) * int(points))
        n_in = int(points) - n_out
        for f in range(T):
            tri = face_ids[rng.choice(face_ids.size, n_in, p=p)]
            r1, r2 = rng.random(n_in), rng.random(n_in)
            s = np.sqrt(r1)
            b = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
            M = meshes[f].astype(np.float64)
            X = np.einsum("pc,pcd->pd", b, M[F[tri]])
            if nz > 0:
                X += rng.normal(0.0, nz, X.shape)
            lo, hi = M.min(0), M.max(0)
            out = lo + rng.random((n_out, 3)) * (hi - lo)
            clouds.append(np.concatenate([X, out]))
            tris.append(np.concatenate([tri, np.full(n_out, -1, np.intp)]))
            barys.append(np.concatenate([b, np.zeros((n_out, 3))]))

    return SyntheticPerformance(
        fps, names, W, poses, meshes.astype(np.float32), marker_ids, marker_pos, landmark_ids, landmark_pos,
        clouds, tris, barys, nz, size,
    )
