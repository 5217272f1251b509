"""Steps 2 and 3 of a rig transfer: the target lined up with the template, then the template skin fitted onto it.

* :func:`align_rigidly` — a similarity from three or more landmark pairs, else
  from the eyeball centres, else from the top of the head and the centroid of
  its upper half; then trimmed ICP with scale (:func:`.registration.rigid_icp`).
  It returns the target seen in the template's working frame.
* :func:`fit_template` — an affine ICP then the non-rigid ICP of the template
  skin onto the target skin (:func:`.registration.nonrigid_icp`), landmarks
  pulling throughout.
* :func:`judge_fit` — how well that fit went on the template's face, raising
  when the target does not look like a face the template can be fitted to.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.geometry.normals import triangle_areas
from workbench.geometry.similarity import Similarity, fit_similarity
from workbench.geometry.surface import SurfaceQuery, boundary_vertices
from workbench.rigging.registration import (
    NonRigidResult,
    affine_icp,
    nonrigid_icp,
    planar_refine,
    rigid_icp,
)
from workbench.rigging.report import RigTransferError, StretchMeter
from workbench.rigging.sides import Side, eye_centres

__all__ = ["align_rigidly", "fit_template", "judge_fit", "landmark_pull"]

Landmarks = Sequence[tuple[int, int]]


def landmark_pull(
    landmarks: Landmarks, src: Side, tgt: Side
) -> tuple[NDArray[np.int64], NDArray[np.float64]] | None:
    """The landmark pairs whose template vertex is skin: (template skin positions, target points), or None."""
    if not landmarks:
        return None
    a = np.array([p[0] for p in landmarks], np.int64)
    b = np.array([p[1] for p in landmarks], np.int64)
    local = src.skin_local(a)
    keep = local >= 0
    return (local[keep], tgt.X[b[keep]]) if keep.any() else None


def align_rigidly(
    src: Side, tgt0: Side, landmarks: Landmarks, t_good: NDArray[np.bool_], head_metres: float, warnings: list[str]
) -> tuple[Side, dict[str, Any]]:
    """Move the target into the template's working frame.

    Parameters
    ----------
    src, tgt0 : Side
        The template, and the target in its own canonical frame.
    landmarks : sequence of (source_vertex, target_vertex)
    t_good : (m_t,) bool
        The target's usable skin triangles.
    head_metres : float
        The template head's size (the working frame's unit) in metres.
    warnings : list of str
        Appended to when the target's units look wrong.

    Returns
    -------
    Side
        The target in the template's working frame.
    dict
        What was done: ``method``, ``scale`` (target units per template unit),
        ``rotation_deg``, ``accepted``, ``median_distance`` (target units).
    """
    S = src.skin_X
    T = tgt0.skin_X
    info: dict[str, Any] = {}
    # an initial similarity template -> target
    if len(landmarks) >= 3:
        a = np.array([p[0] for p in landmarks])
        b = np.array([p[1] for p in landmarks])
        init = fit_similarity(src.X[a], tgt0.X[b])
        info["method"] = "landmarks"
    else:
        es, et = eye_centres(src), eye_centres(tgt0)
        if es is not None and et is not None and np.linalg.norm(es[0] - es[1]) > 0 and np.linalg.norm(et[0] - et[1]) > 0:
            init = _two_point(es, et)
            info["method"] = "eyes"
        else:
            init = _head_top(S, T, tgt0.model.metadata.units, warnings)
            info["method"] = "head top"
    query = SurfaceQuery(T, tgt0.skin_faces[t_good])
    lms = landmark_pull(landmarks, src, tgt0)
    sim, share, med = rigid_icp(S, src.skin_faces, query, init, landmarks=lms, landmark_weight=0.5)
    inv = Similarity(1.0 / sim.scale, sim.R.T, -(sim.t @ sim.R) / sim.scale)  # target -> template frame
    moved = tgt0.moved(tgt0.frame.then(inv))
    # scale in target units per template unit
    t_meta = tgt0.model.metadata
    units = src.model.metadata.metres_per_unit / t_meta.metres_per_unit
    ang = float(np.degrees(np.arccos(np.clip((np.trace(sim.R) - 1) / 2, -1, 1))))
    info.update(scale=float(sim.scale * units), rotation_deg=ang, accepted=share,
                median_distance=float(med * head_metres / t_meta.metres_per_unit))
    if not 0.5 <= sim.scale <= 2.0:
        warnings.append(
            f"target: the head is {sim.scale:.2f}x the template's size in metres; check the target's units "
            f"({t_meta.units!r})"
        )
    return moved, info


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


def _head_top(S: NDArray[np.float64], T: NDArray[np.float64], units: str, warnings: list[str]) -> Similarity:
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
        warnings.append(
            f"target: its units ({units!r}) make the head {geo:.2f}x the template's width; "
            "scaled by the head's size instead"
        )
    bs = S[S[:, 1] > S[:, 1].max() - 0.5 * height]
    bt = T[T[:, 1] > T[:, 1].max() - 0.5 * height * s]
    cs_, ct_ = bs.mean(0), bt.mean(0)
    t = np.array([ct_[0] - s * cs_[0], T[:, 1].max() - s * S[:, 1].max(), ct_[2] - s * cs_[2]])
    return Similarity(s, np.eye(3), t)


def fit_template(
    src: Side, tgt: Side, query: SurfaceQuery, landmarks: Landmarks,
    progress: Callable[[float, str], None] | None = None, fine: bool = False,
) -> NonRigidResult:
    """The template skin fitted onto the target skin (``query``): affine ICP, then non-rigid ICP with the landmarks.

    ``fine``: then a soft point-to-plane tail (:func:`.registration.planar_refine`), for a dense
    correspondence that follows local changes of proportion (expression cloning).
    """
    A, b = affine_icp(src.skin_X, src.skin_faces, query)
    X0 = src.skin_X @ A.T + b
    lms = landmark_pull(landmarks, src, tgt)
    fit = nonrigid_icp(X0, src.skin_faces, query, landmarks=lms, progress=progress)
    if not fine:
        return fit
    tail = planar_refine(fit.positions, X0, src.skin_faces, query, landmarks=lms)
    return NonRigidResult(tail.positions, tail.accepted, tail.distance, fit.iterations + tail.iterations,
                          fit.factorizations + tail.factorizations)


def _near_target_border(P: NDArray[np.float64], tgt: Side, query: SurfaceQuery) -> NDArray[np.bool_]:
    """Points whose way to the target surface ends at (or within 3 mean edges of) one of its open borders.

    A template point over a hole of the target (inside an open mouth bag, over a
    cut-out eye socket) reaches the target at or next to the hole's rim.
    """
    T, F = tgt.skin_X, tgt.skin_faces
    rim = boundary_vertices(F, T.shape[0])
    dist, face, _, bary = query.closest(P)
    out = query.on_boundary(face, bary)
    if rim.any():
        edge = float(np.mean(np.linalg.norm(T[F[:, 0]] - T[F[:, 1]], axis=1)))
        d_rim = cKDTree(T[rim]).query(P)[0]
        out |= d_rim <= dist + 3.0 * edge
    return np.asarray(out)


def judge_fit(
    fit: NonRigidResult, src: Side, tgt: Side, head_metres: float, warnings: list[str], query: SurfaceQuery
) -> dict[str, Any]:
    """Registration quality on the template's face (the skin its shapes move); raises if the target is no face.

    Template face that lies over a hole or border of the target (its closest
    target point is on the target's boundary: an open mouth bag, eye sockets
    cut out of the skin, a face cut off at the hairline) has no surface to find
    by design, so it is reported (``over_holes``) rather than counted against
    the coverage, up to half of the face.

    Parameters
    ----------
    query : SurfaceQuery
        The target skin the template was fitted onto (working frame).

    Returns
    -------
    dict
        ``coverage`` (share of the template's face, less what lies over the
        target's holes, that found target surface), ``over_holes`` (share of
        the face over holes or borders), ``head_coverage`` (share of the whole
        template skin), ``median_residual`` and ``p95_residual`` (target
        units), ``distortion`` (area share stretched beyond 2x or folded),
        ``iterations``.

    Raises
    ------
    RigTransferError
        Under 80 % coverage, half the face or more over holes, over 5 %
        distortion or a median residual over 1 % of the head: the target does
        not look like a face.
    """
    S0 = src.skin_X
    F = src.skin_faces
    stretch, flipped = StretchMeter(S0, F).measure(fit.positions - S0)
    area = triangle_areas(S0, F)
    # the face: where the template's shapes move (a template without shapes, a performance's
    # source for expression cloning: all of its skin)
    face_v = np.ones(S0.shape[0], bool)
    if src.model.shapes:
        disp = np.stack([sh.delta[src.skin_ids] for sh in src.model.shapes])
        big = float(np.abs(disp).max())
        if big > 0:
            face_v = (np.linalg.norm(disp, axis=2) > 0.02 * big).any(0)
    face_t = face_v[F].any(1)
    bad = (stretch > 2.0) | flipped
    distortion = float(area[bad & face_t].sum() / max(area[face_t].sum(), 1e-300))
    over_hole = ~fit.accepted & _near_target_border(fit.positions, tgt, query)
    judged = face_v & ~over_hole
    over_holes = float(over_hole[face_v].mean())
    coverage = float(fit.accepted[judged].mean()) if judged.any() else 0.0
    to_t = head_metres / tgt.model.metadata.metres_per_unit
    d = fit.distance[face_v & fit.accepted] if (face_v & fit.accepted).any() else fit.distance[face_v]
    med = float(np.median(d))
    p95 = float(np.percentile(d, 95))
    info = dict(coverage=coverage, over_holes=over_holes, head_coverage=float(fit.accepted.mean()),
                median_residual=med * to_t,
                p95_residual=p95 * to_t, distortion=distortion, iterations=fit.iterations)
    problems = []
    if coverage < 0.8:
        problems.append(f"only {coverage:.0%} of the template's face found target surface near it")
    if over_holes >= 0.5:
        problems.append(f"{over_holes:.0%} of the template's face lies over holes or borders of it")
    if distortion > 0.05:
        problems.append(f"fitting the template onto it stretched or folded {distortion:.0%} of the template's face")
    if med > 0.01:
        problems.append(f"the fitted template stays {med * head_metres * 1000:.1f} mm (median) off its surface")
    if problems:
        raise RigTransferError(
            f"target {tgt.model.metadata.name or ''}: does not look like a face the template can be fitted to: "
            + "; ".join(problems)
            + ". Check its up/front axes and units, or give landmark pairs."
        )
    if distortion > 0.01:
        warnings.append(f"fit: {distortion:.1%} of the template's face stretched beyond 2x or folded")
    if coverage < 0.95:
        warnings.append(f"fit: {1 - coverage:.0%} of the template's face found no target surface (holes?)")
    if over_holes > 0.05:
        log_holes = f"fit: {over_holes:.0%} of the template's face lies over holes or open borders of the target"
        warnings.append(log_holes + " (an open mouth, eye sockets): there it follows the nearest border")
    return info
