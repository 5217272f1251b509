"""FaceMesh landmarks registered onto a rig: the landmark -> vertex map (the second step of :mod:`workbench.capture.video`).

On a frame of the actor at rest: a robust similarity from anchor landmarks to
the rig's named landmarks (:data:`ANCHORS`), trimmed similarity ICP of the face
mesh landmarks onto the skin surface, then each landmark's nearest front-facing
skin vertex (the iris landmarks: the eyeballs' vertices), with the inner lips
parted: on a closed mouth an upper-lip landmark and its lower-lip partner sit at
one point, and each is put on its own lip by the rig's jawOpen
(:data:`INNER_LIP_PAIRS`; on the sample head 8 of the 9 pairs shared one vertex
and the jaw read at half its truth). :attr:`LandmarkRegistration.view_axis` is
the camera's axis in the model's frame (where :meth:`~LandmarkRegistration.to_model`
puts the landmarks; each frame's head pose carries it onto the rig), along which the
trackers do not fit the weights (FaceMesh's depth is a guess), and :func:`landmark_weights` what each
landmark counts for across it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.facemesh import (
    N_LANDMARKS,
    N_MESH,
    LandmarkSequence,
    VideoError,
    landmark_points,
)
from workbench.capture.pose import PoseError, fit_rigid, fit_rigid_robust
from workbench.geometry.masks import eyeball_mask, skin_or_all_mask

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["ANCHORS", "FEATURE_LANDMARKS", "INNER_LIP_PAIRS", "LANDMARK_L1", "OTHER_LANDMARK_WEIGHT", "LandmarkRegistration", "landmark_vertex_map",
           "landmark_weights", "register_landmarks"]

#: FaceMesh landmark of each rig landmark (:func:`workbench.rigging.template_landmarks` names;
#: ``*_left`` is the subject's left, on the image's right). Checked on the sample head: each
#: FaceMesh point lies within 4 px (480 px render) of the rig landmark's vertex.
ANCHORS: Mapping[str, int] = {
    "nose_tip": 4,  # the most frontal nose point (FaceMesh 1 is the tip's underside)
    "chin": 199,  # the front of the chin (152 is its underside)
    "mouth_corner_left": 291,
    "mouth_corner_right": 61,
    "eyelid_left": 386,  # upper lid, middle
    "eyelid_right": 159,
    "brow_inner_left": 336,
    "brow_inner_right": 107,
    "upper_lip": 0,
    "lower_lip": 16,
}
#: FaceMesh's inner lip contours as (upper, lower) pairs from one corner to the other (MediaPipe's
#: lipsUpperInner and lipsLowerInner without their shared corners 78 and 308). On a closed mouth the
#: two landmarks of a pair sit at one point, where the rig's upper and lower lips meet.
INNER_LIP_PAIRS: tuple[tuple[int, int], ...] = (
    (191, 95), (80, 88), (81, 178), (82, 87), (13, 14), (312, 317), (311, 402), (310, 318), (415, 324),
)
#: a landmark's vertex moving less than this share of the head size under any shape is "still"
_STILL = 0.01

#: FaceMesh landmarks on what the detector sees in the image — the lips, the eye openings and
#: lids, the brows, the nose (MediaPipe's FACEMESH_LIPS, _LEFT/RIGHT_EYE, _LEFT/RIGHT_EYEBROW
#: and _NOSE contours; ``tests/test_live.py`` checks them against mediapipe's): 116 of the 478.
#: The others (cheeks, forehead, jaw line, irises) are placed by the face model around them and
#: follow an expression only part of the way.
FEATURE_LANDMARKS: tuple[int, ...] = (
    # lips
    0, 13, 14, 17, 37, 39, 40, 61, 78, 80, 81, 82, 84, 87, 88, 91, 95, 146, 178, 181, 185, 191, 267, 269,
    270, 291, 308, 310, 311, 312, 314, 317, 318, 321, 324, 375, 402, 405, 409, 415,
    # eyes
    7, 33, 133, 144, 145, 153, 154, 155, 157, 158, 159, 160, 161, 163, 173, 246, 249, 263, 362, 373, 374, 380,
    381, 382, 384, 385, 386, 387, 388, 390, 398, 466,
    # brows
    46, 52, 53, 55, 63, 65, 66, 70, 105, 107, 276, 282, 283, 285, 293, 295, 296, 300, 334, 336,
    # nose
    1, 2, 4, 5, 6, 19, 45, 48, 64, 94, 97, 98, 115, 168, 195, 197, 220, 275, 278, 294, 326, 327, 344, 440,
)
#: the weight of the other landmarks in the fit of the weights (the feature landmarks weigh 1).
#: Chosen on rendered takes (``benchmarks/bench_live.py``) with the inner lips each on their own
#: lip and the weights fitted in the image plane (:attr:`LandmarkRegistration.view_axis`): the jaw
#: outline and the chin follow an opening jaw half-way (13 of 28 px at the chin) while the lips
#: follow it (45 of 48), so at 0.1 the jaw was read as mouthLowerDown. On the issue's whole take
#: 0.1 / 0.03 / 0 give 0.110 / 0.096 / 0.096 RMSE on the sample head and 0.136 / 0.121 / 0.123 on a
#: foreign face (jawOpen 0.70 / 0.80 / 0.83 and 0.90 / 1.02 / 1.07 of the truth), dense takes
#: 0.170 / 0.173 / 0.177 and 0.190 / 0.192 / 0.193. (Before those two fixes 0.1 was best: equal
#: weights 0.165, 0.1 0.146, 0 0.176.)
OTHER_LANDMARK_WEIGHT = 0.03

#: the sparsity for FaceMesh landmarks, live (:class:`~workbench.capture.LiveTracker`) and offline
#: (:func:`~workbench.capture.track_video`) (relative, as :data:`~workbench.capture.track.DEFAULT_L1` =
#: 0.01 for markers). FaceMesh misreads an expression as a mix — the parting lips also as
#: ``mouthFrown*`` and ``mouthLowerDown*``, a smile also as ``mouthShrugLower`` and ``mouthDimple*``, a
#: turned head as ``browDownLeft`` — and at the markers' 0.01 those false readings cost more than the
#: true ones give: on the issue's whole rendered take the RMSE over the face shapes was 0.146 (sample
#: head) and 0.165 (a foreign face), against 0.112 for all-zero weights. Chosen on the rendered takes
#: of ``benchmarks/bench_live.py`` (tables 4–6, both faces) as the largest that costs nothing on dense
#: co-articulated takes, with or without the guided calibration: at 0.03 the whole take is 0.114 /
#: 0.132 (still not below all-zero weights: the true readings are short), dense takes within ±0.01 of
#: 0.01's, calibrated 0.087 / 0.081 (0.091 / 0.091); table 7's held-out takes agree (ten other
#: expressions 0.115 / 0.131, 0.129 / 0.152 at 0.01 — but all-zero weights give 0.095 there: squints,
#: puffs, funnels and presses are barely read at all). Stronger sparsity goes on trading weak true
#: readings for false ones: at 0.05 the uncalibrated takes gain another 0.01, the calibrated dense ones
#: lose as much, and ``mouthRollLower`` falls to 0.19 of its truth (0.47 at 0.01); at 0.1 the inner
#: brow reads 0.16 of its truth (0.74 at 0.01). (Those numbers are from before the inner lips were
#: parted and the depth left the fit; since then 0.03 against 0.01: the whole take 0.096 / 0.121
#: against 0.130 / 0.179, the dense takes 0.173 / 0.149 against 0.185 / 0.154, the held-out ones
#: 0.119 / 0.134 and 0.183 / 0.217 against 0.138 / 0.156 and 0.187 / 0.221.)
LANDMARK_L1 = 0.03


def landmark_weights(other: float = OTHER_LANDMARK_WEIGHT) -> NDArray[np.float64]:
    """(478,) each FaceMesh landmark's weight in the fit of the weights: 1 on :data:`FEATURE_LANDMARKS`, else ``other``.

    For ``track(..., marker_weights=)`` with a :class:`LandmarkRegistration`'s ``vertex_ids``
    (``track_video`` and the live tracker pass it).
    """
    if not (math.isfinite(other) and 0.0 <= other <= 1.0):
        raise VideoError(f"other: a landmark weight in [0, 1], got {other!r}")
    w = np.full(N_LANDMARKS, float(other))
    w[list(FEATURE_LANDMARKS)] = 1.0
    return w

@dataclass(frozen=True, eq=False)
class LandmarkRegistration:
    """The FaceMesh landmarks registered onto a rig; see :func:`register_landmarks`.

    Attributes
    ----------
    vertex_ids : (478,) int
        The rig vertex of each landmark (for ``track(..., vertex_ids=...)``).
    matrix : (4, 4) float
        The similarity from :meth:`LandmarkSequence.points` (pixels) to the model's
        frame and units: ``q = M @ [p, 1]``.
    scale : float
        Model units per pixel (at the face).
    image_size : (int, int)
        ``(width, height)`` the points were made with.
    surface_distance : (478,) float
        Each registered rest landmark's distance to the skin surface (model units).
    vertex_distance : (478,) float
        Each registered rest landmark's distance to its vertex (model units).
    inliers : (478,) bool
        The landmarks the final ICP step kept (iris landmarks are never used: False).
    still : (478,) bool
        Landmarks whose vertex no single shape moves by more than 1 % of the head size
        (the ones :meth:`to_model` measures a frame's scale on).
    rest : (478, 3) float
        The rest frame's landmarks in the model's frame.
    anchors : dict of str to int
        The rig landmarks and FaceMesh indices the start used.
    rms : float
        Root-mean-square surface distance of the inliers (model units).
    """

    vertex_ids: NDArray[np.intp]
    matrix: NDArray[np.float64]
    scale: float
    image_size: tuple[int, int]
    surface_distance: NDArray[np.float64]
    vertex_distance: NDArray[np.float64]
    inliers: NDArray[np.bool_]
    still: NDArray[np.bool_]
    rest: NDArray[np.float64]
    anchors: Mapping[str, int]
    rms: float

    def apply(self, points: ArrayLike) -> NDArray[np.float64]:
        """``(..., 3)`` pixel-frame points (:meth:`LandmarkSequence.points`) → the model's frame."""
        P = np.asarray(points, np.float64)
        return P @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    @property
    def view_axis(self) -> NDArray[np.float64]:
        """(3,) the camera's axis (toward the camera) in the model's frame: where FaceMesh's depth points.

        It is fixed in the coordinates :meth:`to_model` gives; the head turns under it (the
        trackers carry it onto the rig by each frame's head pose).

        FaceMesh's depth is its face model's guess, not a measurement: on the sample head's
        rendered jaw opening (jawOpen 0.9) its lower-lip landmarks come 2 mm toward the camera where
        the lip goes 14 mm back, and its chin goes 4 mm back where the chin goes 23 (in the image
        plane the lip's landmarks follow: 22 mm down of 24). ``track_markers(..., depth_axis=view_axis)``
        fits the weights across it.
        """
        a = self.matrix[:3, :3] @ np.array([0.0, 0.0, 1.0])
        return np.asarray(a / np.linalg.norm(a), np.float64)

    def to_model(self, landmarks: LandmarkSequence | ArrayLike, *, rescale: bool = False) -> NDArray[np.float64]:
        """Landmarks of every frame in the model's frame and units, for :func:`workbench.capture.track`.

        Parameters
        ----------
        landmarks : LandmarkSequence or (T, 478, 3) float
            MediaPipe's normalized landmarks (NaN rows where no face was found), from
            frames of :attr:`image_size`.
        rescale : bool
            Remove each frame's scale relative to the rest frame (a similarity fitted on
            the :attr:`still` landmarks, robustly), about their centre, for takes where
            the head moves toward or away from the camera. Off by default: MediaPipe's
            own scale wobbles by ±2 % with the expression (a blink shrinks the face), and
            on the test take removing it lowers jawOpen's correlation from 0.99 to 0.97.
            The trackers fit the scale in the head pose instead, at each frame's expression
            (``track(..., fit_scale=True)``, the default of ``track_video`` and
            :class:`~workbench.capture.LiveTracker`): use one or the other, not both.

        Returns
        -------
        (T, 478, 3) float
            NaN where no face was found.
        """
        if isinstance(landmarks, LandmarkSequence):
            if landmarks.image_size != self.image_size:
                raise VideoError(
                    f"{landmarks.source}: frames are {landmarks.image_size[0]}×{landmarks.image_size[1]} px but "
                    f"the registration was made on {self.image_size[0]}×{self.image_size[1]} px"
                )
            L = landmarks.landmarks
        else:
            L = np.asarray(landmarks, np.float64)
            if L.ndim == 2:
                L = L[None]
        if L.ndim != 3 or L.shape[1:] != (N_LANDMARKS, 3):
            raise VideoError(f"landmarks must be (frames, {N_LANDMARKS}, 3), got shape {L.shape}")
        Y = self.apply(landmark_points(L, self.image_size))
        if not rescale:
            return Y
        s = self.still
        for t in range(Y.shape[0]):
            if not np.isfinite(Y[t]).all():
                Y[t] = np.nan
                continue
            try:
                pose = fit_rigid_robust(self.rest[s], Y[t, s], scale=True, max_iter=10)
            except PoseError:
                continue
            c = Y[t, s].mean(0)
            Y[t] = c + (Y[t] - c) / pose.scale
        return Y


def _rest_landmarks(landmarks: Any, frame: int, image_size: tuple[int, int] | None
                    ) -> tuple[NDArray[np.float64], tuple[int, int], str]:
    if isinstance(landmarks, LandmarkSequence):
        if not -landmarks.n_frames <= int(frame) < landmarks.n_frames:
            raise VideoError(f"{landmarks.source}: frame {frame} is not in the sequence (0..{landmarks.n_frames - 1})")
        return landmarks.landmarks[int(frame)], image_size or landmarks.image_size, f"{landmarks.source} frame {frame}"
    L = np.asarray(landmarks, np.float64)
    where = "landmarks"
    if L.ndim == 3:
        if not -L.shape[0] <= int(frame) < L.shape[0]:
            raise VideoError(f"landmarks: frame {frame} is not in the sequence (0..{L.shape[0] - 1})")
        L = L[int(frame)]
        where = f"landmarks frame {frame}"
    if L.shape != (N_LANDMARKS, 3):
        raise VideoError(f"{where}: expected ({N_LANDMARKS}, 3) FaceMesh landmarks, got shape {L.shape}")
    return L, image_size or (1, 1), where


def _part_the_lips(ids: NDArray[np.intp], X: NDArray[np.float64], VW: NDArray[np.float64], idx: NDArray[np.intp],
                   W: NDArray[np.float64], jaw: NDArray[np.float64], k: int = 12) -> None:
    """Move an inner-lip landmark that sits on the wrong lip onto the right one (``ids`` in place).

    On a closed mouth FaceMesh's upper and lower inner-lip landmarks coincide, and so do the
    rig's two lips: the nearest vertex is a coin flip, and an upper-lip landmark on a lower-lip
    vertex reads the parting lips as a misfit. On the sample head 8 of the 18 fell on the wrong
    lip and jawOpen was read at about half of its truth. The rig's ``jaw`` (each vertex's motion
    under jawOpen) tells the lips apart: for a pair (:data:`INNER_LIP_PAIRS`) whose upper landmark
    moves with the jaw at least as much as its lower one, the ``k`` vertices nearest the pair are
    split at the middle of their jaw motion, and each landmark takes its nearest vertex on its
    side. A pair with no such jump around it (no seam there) is left as it was.

    ``VW`` : (n, 3) the vertices in the nearest-vertex metric; ``idx`` the candidate vertices;
    ``X`` : (478, 3) the registered landmarks; ``W`` the metric (``X @ W`` compares with ``VW``).
    """
    from scipy.spatial import cKDTree

    if idx.size < 2:
        return
    tree = cKDTree(VW[idx])
    for up, lo in INNER_LIP_PAIRS:
        if jaw[ids[up]] < jaw[ids[lo]]:
            continue
        _, j = tree.query(0.5 * (X[up] + X[lo]) @ W, k=min(k, idx.size))
        cand = idx[np.atleast_1d(j)]
        m = jaw[cand]
        mid = 0.5 * (m.min() + m.max())
        upper, lower = cand[m < mid], cand[m > mid]
        if upper.size == 0 or lower.size == 0:
            continue
        new_up = upper[np.argmin(np.linalg.norm(VW[upper] - X[up] @ W, axis=1))]
        new_lo = lower[np.argmin(np.linalg.norm(VW[lower] - X[lo] @ W, axis=1))]
        ids[up], ids[lo] = new_up, new_lo


def register_landmarks(
    model: FaceState,
    landmarks: LandmarkSequence | ArrayLike,
    *,
    frame: int = 0,
    image_size: tuple[int, int] | None = None,
    anchors: Mapping[str, int] | None = None,
    iterations: int = 50,
    depth_weight: float = 0.5,
) -> LandmarkRegistration:
    """Register FaceMesh landmarks of the actor at rest onto a rig; the landmark → vertex map.

    Parameters
    ----------
    model : FaceModel
        A rig with ARKit-named shapes and ``metadata.up_axis`` / ``front_axis``
        (what :func:`workbench.rigging.template_landmarks` needs).
    landmarks : LandmarkSequence, (T, 478, 3) or (478, 3) float
        MediaPipe's normalized landmarks; ``frame`` picks the rest frame.
    frame : int
        The frame of the actor at rest (neutral face), ideally facing the camera.
    image_size : (int, int), optional
        ``(width, height)`` of the frames; a :class:`LandmarkSequence` knows it; for
        an array it defaults to (1, 1), right for square frames only.
    anchors : mapping of str to int, optional
        Rig landmark name → FaceMesh index for the start (default :data:`ANCHORS`);
        at least 4 that the rig has.
    iterations : int
        Most ICP iterations.
    depth_weight : float
        In (0, 1]: how much the distance along the camera's axis counts when picking
        each landmark's vertex (MediaPipe's depth is approximate).

    Returns
    -------
    LandmarkRegistration

    Raises
    ------
    VideoError
        No face in the rest frame, a rig lacking the anchors, bad arguments.
    """
    from scipy.spatial import cKDTree

    from workbench.capture.rig import ExpressionSpace
    from workbench.geometry.normals import vertex_normals
    from workbench.geometry.surface import SurfaceQuery
    from workbench.rigging.landmarks import template_landmarks

    if not (0.0 < float(depth_weight) <= 1.0):
        raise VideoError(f"depth_weight must be in (0, 1], got {depth_weight!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) or iterations < 1:
        raise VideoError(f"iterations must be an int ≥ 1, got {iterations!r}")
    L, size, where = _rest_landmarks(landmarks, frame, image_size)
    if not np.isfinite(L).all():
        raise VideoError(f"{where}: no face was found there; register on a frame with a face (see .found)")
    P = landmark_points(L, size)

    V = np.asarray(model.vertices, np.float64)
    F = np.asarray(model.faces, np.int64)
    skin = skin_or_all_mask(model)
    tl = template_landmarks(model)  # type: ignore[arg-type]  # a FaceState is the FaceModel it needs
    use = {k: int(v) for k, v in (ANCHORS if anchors is None else anchors).items() if k in tl}
    if len(use) < 4:
        raise VideoError(
            f"model: the registration needs at least 4 of the rig landmarks {sorted(ANCHORS if anchors is None else anchors)} "
            f"(workbench.rigging.template_landmarks found {sorted(tl)})"
        )
    bad = [i for i in use.values() if not 0 <= i < N_MESH]
    if bad:
        raise VideoError(f"anchors: FaceMesh indices must be in 0..{N_MESH - 1}, got {bad}")
    names = list(use)
    start = fit_rigid_robust(P[[use[k] for k in names]], V[[tl[k] for k in names]], scale=True, loss="huber")
    M = start.matrix

    # trimmed similarity ICP of the face-mesh landmarks onto the skin surface
    Fs = F[skin[F].all(1)]
    if Fs.shape[0] == 0:
        Fs = F
    query = SurfaceQuery(V, Fs)
    Pm = P[:N_MESH]
    ok = np.ones(N_MESH, bool)
    dist = np.zeros(N_MESH)
    for _ in range(int(iterations)):
        X = Pm @ M[:3, :3].T + M[:3, 3]
        dist, _face, C, _bary = query.closest(X)
        ok = dist <= 3.0 * float(np.median(dist))
        if int(ok.sum()) < 10:
            break
        new = fit_rigid(Pm[ok], C[ok], scale=True)
        change = float(np.abs(Pm @ new[:3, :3].T + new[:3, 3] - X).max())
        M = new
        if change < 1e-7 * float(np.ptp(V, axis=0).max()):
            break
    scale = float(np.cbrt(np.linalg.det(M[:3, :3])))
    R = M[:3, :3] / scale
    X = P @ M[:3, :3].T + M[:3, 3]
    sdist, *_ = query.closest(X)

    # each landmark's vertex: nearest front-facing one, the camera axis counted at depth_weight
    view = R @ np.array([0.0, 0.0, 1.0])  # toward the camera, in the model's frame
    N = vertex_normals(V, F)
    facing = (N @ view) > 0.0
    basis = np.linalg.svd(np.eye(3) - np.outer(view, view))[0][:, :2]  # the image plane's axes
    W = np.c_[basis, float(depth_weight) * view]

    def nearest(points: NDArray[np.float64], mask: NDArray[np.bool_]) -> NDArray[np.intp]:
        idx = np.flatnonzero(mask)
        _, j = cKDTree(V[idx] @ W).query(points @ W)
        return np.asarray(idx[j], np.intp)

    ids = np.empty(N_LANDMARKS, np.intp)
    skin_f = skin & facing if (skin & facing).any() else skin
    ids[:N_MESH] = nearest(X[:N_MESH], skin_f)
    eyes = eyeball_mask(model)
    eyes_f = eyes & facing if (eyes & facing).any() else eyes
    ids[N_MESH:] = nearest(X[N_MESH:], eyes_f if eyes_f.any() else skin_f)

    space = ExpressionSpace.from_model(model)
    if "jawOpen" in space.shape_names:
        jaw = np.linalg.norm(np.asarray(space.deltas[space.shape_names.index("jawOpen")], np.float64), axis=1)
        _part_the_lips(ids, X, V @ W, np.flatnonzero(skin_f), W, jaw)
    still = space.motion(ids) / space.size <= _STILL
    still[N_MESH:] = False
    if int(still.sum()) < 4:
        still = np.ones(N_LANDMARKS, bool)
        still[N_MESH:] = False
    inliers = np.zeros(N_LANDMARKS, bool)
    inliers[:N_MESH] = ok
    rms = float(np.sqrt(np.mean(dist[ok] ** 2))) if ok.any() else float("nan")
    return LandmarkRegistration(
        vertex_ids=ids,
        matrix=M,
        scale=scale,
        image_size=(int(size[0]), int(size[1])),
        surface_distance=np.asarray(sdist, np.float64),
        vertex_distance=np.linalg.norm(X - V[ids], axis=1),
        inliers=inliers,
        still=np.asarray(still, bool),
        rest=X,
        anchors=dict(use),
        rms=rms,
    )


def landmark_vertex_map(
    model: FaceState,
    landmarks_frame: LandmarkSequence | ArrayLike,
    **options: Any,
) -> NDArray[np.intp]:
    """``(478,)`` rig vertex ids of the FaceMesh landmarks, by registration on a rest frame.

    ``register_landmarks(model, landmarks_frame, **options).vertex_ids``: see
    :func:`register_landmarks` (options ``frame``, ``image_size``, ``anchors``,
    ``iterations``, ``depth_weight``). The landmarks must be brought into the model's
    frame and units before tracking: :meth:`LandmarkRegistration.to_model`.
    """
    return register_landmarks(model, landmarks_frame, **options).vertex_ids
