"""Track a sequence of point clouds onto the rig: ICP pose + point-to-plane weights (Bouaziz et al. 2013, §3.1).

Depth sensors and scanners give, per frame, points on the face without
correspondences. :func:`track_clouds` (called by
:func:`workbench.capture.track` when ``vertex_ids`` is None) tracks them online,
frame by frame, as the paper does:

1. **Sampling** (once per take, :func:`sample_vertices`): the front-facing skin
   around the moving part of the face (:func:`~workbench.capture.synthetic.face_vertices`),
   without the mesh border and its first ring, spread by farthest-point
   sampling into ``samples`` vertices that the shapes move and ``rigid_samples``
   vertices that they barely move (at most ``0.5 %`` of the head size under any
   one shape: forehead, temples, nose bridge — the paper's "front head and nose
   region").
2. **Rigid pose** by point-to-plane ICP of the stable vertices (posed with the
   current expression) against a k-d tree of the cloud (``scipy.spatial.cKDTree``):
   linearised rotation and translation (a 6 × 6 solve) with Huber weights,
   warm-started from the previous frame.
3. **Weights** from point-to-plane constraints: each sampled vertex of the
   posed mesh takes its nearest cloud point; pairs farther than a threshold
   (``max_distance``, then ``2.5 ×`` the median distance, floored at
   ``min_distance``), whose normals disagree (the cloud's local PCA normal vs
   the mesh normal, more than ``max_normal_angle`` apart, either orientation),
   or whose residual is a Tukey outlier are rejected. The rows
   ``nᵀ(b0 + ΔB w) = nᵀ c`` (model frame; ``n`` the mesh normal, which follows
   the expression to first order) go to
   :class:`~workbench.capture.solver.WeightSolver` with the L1 and temporal
   terms, warm-started.
4. Steps 2–3 alternate ``iterations`` times (3), each with new correspondences.
5. **Adaptation** (on by default for clouds): an
   :class:`~workbench.capture.adapt.AdaptiveModel` (identity, expression
   transfer, correctives, §2–3.2) is the rig the frames are tracked on.
   ``result.info["adapted"]`` is that model: ``.to_model()`` is the adapted rig.
   As in the paper (§3, "Initialization"), the take is assumed to start with a
   neutral face: on the first usable frame the identity and the pose are fitted
   alone (eq. 1 by Gauss–Newton: ``init_iterations`` rounds of ICP,
   correspondences and :meth:`~workbench.capture.adapt.AdaptiveModel.fit_neutral_planes`)
   before the weights; ``neutral_start=False`` skips it. With ``refine=True`` each
   frame's final constraints then update the model as well (§3.2, the neutral and
   every active shape's correctives) and the next frame tracks the refined rig.
   That refinement is off by default: on realistic takes (about 30 shapes active
   at once, a non-zero rest) the correctives and the weights trade off — the
   paper counts on a sparse solution ("blendshape compensation", §3.1) — and the
   weights come out 25–35 % worse than with the identity alone
   (``benchmarks/bench_capture_clouds_realistic.py``).

The fit term is normalised per accepted constraint and by the head size
squared, and the λ's are relative to the average shape's squared norm along
the normals over the samples (fixed for the take), as for markers
(:mod:`workbench.capture.track`): the same ``l1`` and ``temporal`` mean the
same for both kinds of input.

A frame whose cloud is empty or has fewer than ``min_points`` points, or that
keeps fewer than ``min_correspondences`` pairs (all outliers), holds the previous
frame's weights and pose and is flagged (:data:`~workbench.capture.result.FLAG_HELD`),
and the rig does not adapt on it; frames before the first solvable one take
its values. ``errors`` is the RMS point-to-plane distance of the accepted pairs
(model units).

Shapes: clouds are ``(p_t, 3)`` float per frame (NaN rows are dropped), in the
model's units; weights ``(T, k)`` in ``model.shape_names`` order.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from workbench.capture.adapt import AdaptiveModel, adaptive_model
from workbench.capture.cloud_icp import CloudNormals, cloud_pairs, rigid_icp, unit
from workbench.capture.cloud_inputs import check_clouds, check_units
from workbench.capture.cloud_samples import STABLE_MOTION, sample_vertices
from workbench.capture.result import FLAG_HELD, CloudTrackError, TrackResult
from workbench.capture.rig import ExpressionSpace
from workbench.capture.solver import WeightSolver
from workbench.geometry.normals import vertex_normals

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["CLOUD_IDENTITY_OPTIONS", "CLOUD_L1", "CLOUD_L1_REFINE", "CLOUD_TEMPORAL", "STABLE_MOTION", "CloudTrackError",
           "sample_vertices", "track_clouds"]

# the ICP's pieces under the names benchmarks/bench_capture.py calls them by
_rigid_icp = rigid_icp
_CloudNormals = CloudNormals

#: default sparsity for point clouds (relative, as for markers), with the identity fitted at the start
#: and then held (``refine=False``). Chosen on realistic takes (dense co-articulated weights with a
#: non-zero rest, :func:`workbench.testing.realistic_weights`; seeds other than the benchmark's): a
#: stronger L1 shrinks the many weights that are active at once (0.005 → 0.02 costs ~30 % RMSE)
CLOUD_L1 = 0.005
#: default sparsity with the online refinement of §3.2 (``refine=True``): twice the markers' default.
#: On a face that is not the template weaker L1 lets shapes switch on to explain the identity (the
#: paper's "blendshape compensation"), which the refinement then learns into their correctives
CLOUD_L1_REFINE = 0.02
#: the adaptive model's options for the identity fitted at the start (``refine=False``; a dict given as
#: ``adapt`` overrides them). A richer smooth basis than the refinement's (200 Laplacian eigenvectors
#: per coordinate instead of 50) and a weaker bending prior (β1 = 0.1): an actor who is another person
#: (a MakeHuman identity + a warp, mean offset 6.5 mm, up to 34 mm) is fitted within 1.0 mm instead of
#: 1.9 (median point-to-plane), and the weight RMSE falls from 0.42 to 0.18 (5k head, realistic take).
#: The set-up is then mostly the 200 eigenvectors: 17 s at 20k on a busy 2-core machine, against 15 s
#: for the refinement's 50 with their transfer rows (which this mode builds only if a frame needs them)
CLOUD_IDENTITY_OPTIONS: dict[str, Any] = {"n_basis": 200, "betas": (0.1, 0.1, 0.001)}
#: default temporal smoothness for point clouds (relative). Lower than the markers' default: a
#: point-to-plane row sees one direction of a vertex's motion, so the prior weighs more per frame and lags
CLOUD_TEMPORAL = 0.05

Progress = Callable[[float, str], Any]


# ------------------------------------------------------------------ geometry
def _faces_around(F: NDArray[np.int64], ids: NDArray[np.intp], n: int) -> NDArray[np.int64]:
    """The triangles touching the vertices ``ids``: enough for those vertices' full normals."""
    on = np.zeros(n, bool)
    on[ids] = True
    return F[on[F].any(1)]


@dataclass
class _CloudSetup:
    """Per take: samples, their neutral / deltas / normals, the solver."""

    space: ExpressionSpace
    ids: NDArray[np.intp]
    stable: NDArray[np.bool_]
    N0: NDArray[np.float64]  # (s, 3) neutral normals at the samples
    dN: NDArray[np.float64]  # (k, s, 3) change of the (unnormalised) normal per shape
    ref: float
    solver: WeightSolver


def _setup(model: FaceState, ids: NDArray[np.intp], stable: NDArray[np.bool_], l1: float, temporal: float
           ) -> _CloudSetup:
    space = ExpressionSpace.from_model(model)
    V = space.neutral
    F = np.asarray(model.faces, np.int64)
    Fs = _faces_around(F, ids, V.shape[0])
    D = np.asarray(space.deltas, np.float64)

    def area_normals(X: NDArray[np.float64]) -> NDArray[np.float64]:
        # unnormalised: the first-order model below is linear in the cross products
        return vertex_normals(X, Fs, unit=False)[ids]

    n0 = area_normals(V)
    scale = np.maximum(np.linalg.norm(n0, axis=1, keepdims=True), 1e-300)
    # the normal of the blend to first order: n(x) ≈ n0 + Σ x_i (n(b0 + δ_i) − n0), per vertex relative to |n0|
    dN = np.stack([(area_normals(V + D[i]) - n0) / scale for i in range(space.k)]) if space.k else \
        np.zeros((0, ids.size, 3))
    N0 = n0 / scale
    # the λ scale: the average plain shape's squared norm along the normals per sample, in head sizes²
    Dp = D[np.ix_(space.plain, ids)]  # (kp, s, 3)
    proj = np.einsum("ksd,sd->ks", Dp, unit(N0))
    ref = float((proj**2).sum()) / max(space.plain.size, 1) / max(ids.size, 1) / space.size**2
    ref = ref if ref > 0 else 1.0
    solver = WeightSolver(space.lo, space.hi, l1=l1 * ref, temporal=temporal * ref, relative=False,
                          tol=1e-6 * math.sqrt(ref))
    return _CloudSetup(space, ids, stable, N0, dN, ref, solver)


class _SampleRig:
    """The rig at the samples as the frames see it: the template's, or the adapted one's after each update."""

    def __init__(self, setup: _CloudSetup, am: AdaptiveModel | None) -> None:
        space = setup.space
        self.plain = space.plain
        self.k = space.k
        self.s = setup.ids.size
        self.N0 = setup.N0
        self.dN_flat = setup.dN.reshape(space.k, -1)
        if am is not None:
            self.refresh(am)
        else:
            self._set(space.neutral[setup.ids].copy(), np.asarray(space.deltas[:, setup.ids], np.float64))

    def _set(self, X0: NDArray[np.float64], D: NDArray[np.float64]) -> None:
        self.X0, self.D = X0, D
        self.D_flat = D.reshape(self.k, -1)  # (k, 3s) for blending
        self.DpT = np.ascontiguousarray(D[self.plain].transpose(1, 2, 0))  # (s, 3, kp) for the constraint rows

    def refresh(self, am: AdaptiveModel, shapes: bool = True) -> None:
        """Take the adapted rig's neutral and (unless ``shapes`` is False) deltas at the samples."""
        self._set(am.neutral_at(), am.deltas_at() if shapes else self.D)

    def blend(self, wf: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Sample positions and unit normals (model frame) for full weights ``wf``."""
        X = self.X0 + (wf @ self.D_flat).reshape(self.s, 3)
        N = unit(self.N0 + (wf @ self.dN_flat).reshape(self.s, 3))
        return X, N


# ------------------------------------------------------------------ the tracker
def _count(value: Any, what: str, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < lo:
        raise CloudTrackError(f"{what} must be an int ≥ {lo}, got {value!r}")
    return int(value)


def _number(value: Any, what: str, lo: float, hi: float = math.inf) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CloudTrackError(f"{what} must be a number, got {value!r}") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise CloudTrackError(f"{what} must be a number in [{lo:g}, {hi:g}], got {value!r}")
    return v


def track_clouds(
    model: FaceState,
    clouds: Any,
    *,
    fps: float = 30.0,
    l1: float | None = None,
    temporal: float | None = None,
    adapt: Any = True,
    refine: bool = False,
    progress: Progress | None = None,
    iterations: int = 3,
    rigid_steps: int = 4,
    samples: int = 1200,
    rigid_samples: int = 400,
    max_distance: float | None = None,
    min_distance: float | None = None,
    max_normal_angle: float = 60.0,
    min_points: int = 50,
    min_correspondences: int = 30,
    initial_pose: ArrayLike | None = None,
    neutral_start: bool = True,
    init_iterations: int = 10,
    solver: Any = None,
) -> TrackResult:
    """Track a sequence of point clouds (see the module docstring): pose + weights per frame, adapting the rig.

    Parameters
    ----------
    model : FaceModel
        The rig.
    clouds : sequence of (p_t, 3) float, or (T, p, 3) float
        One cloud per frame, model units; empty clouds are allowed (held frames).
    fps : float
    l1, temporal : float, optional
        Relative λ's (default :data:`CLOUD_L1`, or :data:`CLOUD_L1_REFINE` with
        ``refine``; :data:`CLOUD_TEMPORAL`).
    adapt : bool, dict, AdaptiveModel or None
        Adapt the rig to the actor (None or True: an :class:`AdaptiveModel` on the
        tracker's samples, with :data:`CLOUD_IDENTITY_OPTIONS` — or, with ``refine``,
        its own defaults; a dict: its options, over those; an AdaptiveModel: that
        one — its ``vertex_ids_`` become the samples; its identity is fitted on the
        neutral start and, with ``refine``, it is updated in place; False: off).
    refine : bool
        With ``adapt``: after the start's identity fit, keep refining the model on
        every frame (§3.2: the neutral and each shape's correctives, aggregated over
        the frames). Off by default: on realistic takes, where some 30 shapes are
        active at once, the correctives and the weights trade off (the paper's
        "blendshape compensation") and the weights come out worse — measured in
        ``benchmarks/bench_capture_clouds_realistic.py`` (the module docstring). On
        sparse takes (a few shapes at a time) it lowers the fit error further.
    progress : callable, optional
        ``progress(fraction, message)``.
    iterations : int
        Pose / correspondence / weight alternations per frame (≥ 1).
    rigid_steps : int
        ICP steps per pose update (≥ 1).
    samples, rigid_samples : int
        Vertices fitted (:func:`sample_vertices`).
    max_distance : float, optional
        Pairs farther apart are rejected (model units; default 3 % of the head size).
    min_distance : float, optional
        Floor of the adaptive threshold (default 0.5 % of the head size).
    max_normal_angle : float
        Degrees; pairs whose normals disagree more are rejected.
    min_points, min_correspondences : int
        Below these a frame is held (flagged).
    initial_pose : (4, 4) float, optional
        Pose before the first frame (default identity: the cloud near the model).
    neutral_start : bool
        With adaptation: the take starts with a neutral face, as the paper requires
        (§3, "Initialization"): on the first usable frame the identity and the pose
        are fitted alone (eq. 1, ``init_iterations`` Gauss–Newton steps with new
        correspondences each) before the weights. False: the identity is only
        learnt from the aggregated frames.
    init_iterations : int
        Steps of that initialisation (≥ 1).
    solver : optional
        The per-frame weight solver: anything with WeightSolver's
        ``solve_gram(G, h, w_prev, w_prev2, w0=...)`` on the normalised normal equations
        (``G, h`` per accepted pair and head size², as the module docstring says). Default:
        :class:`~workbench.capture.solver.WeightSolver` on the sliders' box with the λ's
        (benchmarks put a per-frame ``scipy.optimize.lsq_linear`` here).

    Returns
    -------
    TrackResult
        ``kind == "clouds"``; ``info["adapted"]`` is the :class:`AdaptiveModel` (or None).

    Raises
    ------
    CloudTrackError
        Input that cannot be tracked, naming the argument.
    """
    t_start = time.perf_counter()
    fps_ = _number(fps, "fps", 0.0)
    if fps_ <= 0:
        raise CloudTrackError(f"fps must be a positive number, got {fps!r}")
    if not isinstance(refine, bool | np.bool_):
        raise CloudTrackError(f"refine must be True or False, got {refine!r}")
    l1_ = (CLOUD_L1_REFINE if refine else CLOUD_L1) if l1 is None else _number(l1, "l1", 0.0)
    temporal_ = CLOUD_TEMPORAL if temporal is None else _number(temporal, "temporal", 0.0)
    iters = _count(iterations, "iterations", 1)
    rsteps = _count(rigid_steps, "rigid_steps", 1)
    min_pts = _count(min_points, "min_points", 6)
    min_corr = _count(min_correspondences, "min_correspondences", 6)
    init_iters = _count(init_iterations, "init_iterations", 1)
    cos_min = math.cos(math.radians(_number(max_normal_angle, "max_normal_angle", 0.0, 90.0)))
    if not model.shapes:
        raise CloudTrackError("model: it has no blendshapes to track")
    if solver is not None and not callable(getattr(solver, "solve_gram", None)):
        raise CloudTrackError(f"solver must have a solve_gram method like WeightSolver's, got {type(solver).__name__}")
    P_all = check_clouds(clouds)
    T = len(P_all)
    M = np.eye(4)
    if initial_pose is not None:
        M = np.asarray(initial_pose, np.float64)
        if M.shape != (4, 4) or not np.isfinite(M).all():
            raise CloudTrackError(f"initial_pose must be a finite (4, 4) matrix, got shape {M.shape}")

    if isinstance(adapt, AdaptiveModel):
        ids = adapt.vertex_ids_.astype(np.intp)
        space0 = ExpressionSpace.from_model(model)
        mot = space0.motion(ids) / space0.size
        stable = mot <= STABLE_MOTION
        if stable.sum() < 6:
            stable = np.zeros(ids.size, bool)
            stable[np.argsort(mot)[: max(6, ids.size // 4)]] = True
    else:
        ids, stable = sample_vertices(model, samples, rigid_samples)
    setup = _setup(model, ids, stable, l1_, temporal_)
    space = setup.space
    size = space.size
    thr_max = 0.03 * size if max_distance is None else _number(max_distance, "max_distance", 0.0)
    thr_min = 0.005 * size if min_distance is None else _number(min_distance, "min_distance", 0.0)
    if thr_max <= 0:
        raise CloudTrackError(f"max_distance must be > 0, got {max_distance!r}")
    thr_min = min(thr_min, thr_max)
    check_units(P_all, space.neutral[ids], model)
    adapt_ = True if adapt is None else adapt
    if not refine and (adapt_ is True or isinstance(adapt_, dict)):
        adapt_ = {**CLOUD_IDENTITY_OPTIONS, "lazy_rows": True, **({} if adapt_ is True else adapt_)}
    am = adaptive_model(adapt_, model, ids, progress, error=CloudTrackError)
    if am is not None and not (refine or neutral_start or isinstance(adapt, AdaptiveModel)):
        # (a given AdaptiveModel with neither is tracked on as it is: e.g. the rest of an adapted take)
        raise CloudTrackError("adapt: with neutral_start=False and refine=False a new adaptive rig would never "
                              "adapt (pass refine=True to learn it from the frames, or adapt=False)")
    t_setup = time.perf_counter() - t_start

    plain = space.plain
    derived = sorted(space.derived)
    kp = plain.size
    norm = 1.0 / size**2
    rig = _SampleRig(setup, am)

    W = np.zeros((T, kp))
    poses = np.tile(np.eye(4), (T, 1, 1))
    errors = np.full(T, np.nan)
    flags = [""] * T
    pairs = np.zeros(T, np.int64)
    w = np.zeros(kp)
    wf = space.full_weights(w)
    w_prev: NDArray[np.float64] | None = None
    w_prev2: NDArray[np.float64] | None = None
    solver = setup.solver if solver is None else solver
    every = max(1, T // 100)
    first = -1
    t_adapt = 0.0
    for f in range(T):
        if progress is not None and f % every == 0:
            progress(f / T, f"tracking cloud {f + 1} of {T}")
        P = P_all[f]
        solved = False
        if P.shape[0] >= min_pts:
            tree = cKDTree(P)
            cn = CloudNormals(P, tree)
            Mf = M.copy()
            thr = thr_max if first >= 0 else 3.0 * thr_max  # the first frame may start farther away
            found = False
            if am is not None and neutral_start and first < 0:
                # the paper's initialisation (eq. 1): a neutral face; identity and pose by Gauss–Newton
                for _it in range(init_iters):
                    X, N = rig.blend(wf)
                    Mf, _ = rigid_icp(X, N, tree, P, cn, Mf, thr, cos_min, 4 * rsteps, 6)
                    pr = cloud_pairs(X, N, Mf, tree, P, cn, thr, cos_min, min_corr, size)
                    if pr is None:
                        break
                    ok, C, rw, dist = pr
                    sw = np.sqrt(rw)
                    am.fit_neutral_planes(ok, N[ok] * sw[:, None], (N[ok] * C).sum(1) * sw)
                    rig.refresh(am, shapes=False)  # the first frame is blended at zero weights
                    thr = min(thr_max, max(2.5 * float(np.median(dist)), thr_min))
                    found = True
                if found:
                    rig.refresh(am)
            acc: tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None = None
            for it in range(iters):
                X, N = rig.blend(wf)
                # rigid pose: the stable samples (all of them while the first frame's pose is unknown)
                unknown = first < 0 and it == 0 and not found
                sel = np.ones(ids.size, bool) if unknown else setup.stable
                Mf, _ = rigid_icp(X[sel], N[sel], tree, P, cn, Mf, thr, cos_min, 4 * rsteps if unknown else rsteps, 6)
                pr = cloud_pairs(X, N, Mf, tree, P, cn, thr, cos_min, min_corr, size)
                if pr is None:
                    break
                ok, C, rw, dist = pr
                Nn = N[ok] * np.sqrt(rw)[:, None]
                A = (Nn[:, :, None] * rig.DpT[ok]).sum(1)
                base = rig.X0[ok]
                if derived:
                    base = base + np.tensordot(wf[derived], rig.D[derived][:, ok], axes=(0, 0))
                c = (Nn * (C - base)).sum(1)
                m = ok.size
                G = (A.T @ A) * (norm / m)
                h = (A.T @ c) * (norm / m)
                w = solver.solve_gram(G, h, w_prev, w_prev2, w0=w)
                wf = space.full_weights(w)
                acc = pr
                # the next pass looks closer
                thr = min(thr_max, max(2.5 * float(np.median(dist)), thr_min))
            if acc is not None:
                solved = True
                ok, C, rw, _ = acc
                X, N = rig.blend(wf)
                res = (N[ok] * (X[ok] - C)).sum(1)
                errors[f] = float(np.sqrt(np.mean(res**2)))
                pairs[f] = ok.size
                M = Mf
                if am is not None and refine:
                    ta = time.perf_counter()
                    sw = np.sqrt(rw)
                    am.update_planes(ok, N[ok] * sw[:, None], (N[ok] * C).sum(1) * sw, wf)
                    rig.refresh(am)
                    t_adapt += time.perf_counter() - ta
        if not solved:
            flags[f] = FLAG_HELD
            if first >= 0:
                W[f], poses[f] = W[f - 1], poses[f - 1]
                w_prev2, w_prev = w_prev, W[f].copy()
            continue
        if first < 0:
            first = f
        W[f], poses[f] = w, M
        w_prev2, w_prev = w_prev, w.copy()
    if first < 0:
        raise CloudTrackError(
            f"clouds: no frame could be tracked (each needs at least min_points={min_pts} points and "
            f"min_correspondences={min_corr} pairs near the face; the largest cloud has "
            f"{max(p.shape[0] for p in P_all)} points)")
    W[:first], poses[:first] = W[first], poses[first]
    if progress is not None:
        progress(1.0, f"tracked {T} clouds")
    names = space.shape_names
    derived_names = space.unsolved_names
    total = time.perf_counter() - t_start
    return TrackResult(
        space.full_weights(W), poses, errors, tuple(flags), fps_, names, derived_names, size, "clouds",
        {"l1": l1_, "temporal": temporal_, "refine": bool(refine), "iterations": iters, "rigid_steps": rsteps,
         "vertex_ids": ids.copy(), "stable": stable.copy(), "pairs": pairs, "lambda_scale": setup.ref,
         "max_distance": thr_max, "min_distance": thr_min, "adapted": am,
         "seconds": {"setup": t_setup, "frames": total - t_setup, "adaptation": t_adapt}},
    )
