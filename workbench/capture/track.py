"""Online tracking of a take: rigid head pose + blendshape weights per frame (Bouaziz et al. 2013, §3.1).

:func:`track` is the entry point for every input: ``(T, m, 3)`` markers or
landmarks with ``vertex_ids`` (handled here), or a sequence of point clouds
without correspondences (handed to :func:`workbench.capture.clouds.track_clouds`).

Markers and landmarks, frame by frame, online (each frame sees only the past):

1. **Rigid pose** from the markers the shapes barely move (forehead, temples,
   nose bridge — the paper's "front head and nose region"), chosen from the
   shapes' displacement at the markers (at most 1 % of the head size; all markers
   when fewer than four are that still), by robust weighted Kabsch
   (:func:`~workbench.capture.pose.fit_rigid_robust`, Tukey) against the current
   expression at those markers.
2. **Weights** by :class:`~workbench.capture.solver.WeightSolver`: the
   observations brought into the model frame (``Rᵀ(y − t)``) minus the neutral
   give ``c``, the plain shapes' deltas at the visible markers give ``A``;
   ``min ||Aw − c||² + l1·Σw + temporal·||w − 2w₋₁ + w₋₂||²`` on the sliders'
   box, warm-started from the previous frame.
3. Steps 1–2 alternate ``iterations`` times (2 by default).

The fit term is normalised per visible marker and by the head size squared, and
the λ's are relative to the average shape's squared norm over all markers
(``trace(AᵀA)/k`` with every marker visible, in those units), fixed for the take:
so the λ's are unit-free, and a frame that loses markers keeps the balance of
data and priors per marker. ``l1`` shrinks an average shape's weight by
``l1/2``; ``temporal = 1`` trusts the constant-velocity prediction as much as
one frame of data (see :mod:`.solver`). By default both are chosen per take
from held-out markers (:mod:`.lambdas`): a dense real take wants little or no
L1, a sparse generated one more.

Occluded markers (NaN) drop their rows. A frame with fewer than ``min_markers``
visible markers is not solved: it holds the previous frame's weights and pose
and is flagged (:data:`~workbench.capture.result.FLAG_HELD`); frames before the
first solvable one take its values. Derived (corrective) shapes are not
unknowns: their current product is part of the prediction, and they follow
their drivers (:class:`~workbench.capture.rig.ExpressionSpace`).

With ``adapt`` (off by default for markers) the rig is adapted to the actor as the
take goes (the dynamic expression model, §4, :mod:`.adapt`): each solved frame's
markers in the model frame update the adapted neutral and shapes at the markers, and
the next frames are tracked on them; ``info["adapted"]`` holds the model.

Nothing here changes the model: the result is applied to the timeline by
``model.capture.apply(result)`` (one undo step).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.blas import one_blas_thread
from workbench.capture.adapt import AdaptiveModel, adaptive_model
from workbench.capture.frame_step import FrameStepper
from workbench.capture.pose import PoseError, fit_rigid_robust
from workbench.capture.result import FLAG_HELD, TrackError, TrackResult
from workbench.capture.rig import ExpressionSpace
from workbench.capture.solver import WeightSolver

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["AUTO", "DEFAULT_L1", "DEFAULT_TEMPORAL", "TrackError", "prepare_markers", "track", "track_markers"]

#: ``l1="auto"`` / ``temporal="auto"`` (the default): chosen per take by held-out markers (:mod:`.lambdas`)
AUTO = "auto"
#: the fixed sparsity of earlier versions (relative, see the module docstring); the Capture tab's slider start
DEFAULT_L1 = 0.01
#: the fixed temporal smoothness of earlier versions (relative); the Capture tab's slider start
DEFAULT_TEMPORAL = 0.25
#: markers moving less than this share of the head size under any one shape count as rigid
RIGID_MOTION = 0.01
#: the markers must spread within this factor of the model's vertices, else they are in other units
UNITS_FACTOR = 4.0

Progress = Callable[[float, str], Any]


# ------------------------------------------------------------------ input checks
def _vertex_ids(vertex_ids: Any, m: int, n: int) -> NDArray[np.intp]:
    ids = np.asarray(vertex_ids)
    if ids.ndim != 1:
        raise TrackError(f"vertex_ids must be a 1-D array of {m} vertex ids (one per marker), got shape {ids.shape}")
    if ids.size != m:
        raise TrackError(f"vertex_ids has {ids.size} ids but frames have {m} markers per frame")
    if ids.size and not np.issubdtype(ids.dtype, np.integer):
        if not (np.issubdtype(ids.dtype, np.floating) and np.all(np.isfinite(ids)) and np.all(ids == np.round(ids))):
            raise TrackError(f"vertex_ids must be integers, got dtype {ids.dtype}")
    ids = ids.astype(np.intp)
    bad = np.flatnonzero((ids < 0) | (ids >= n))
    if bad.size:
        raise TrackError(
            f"vertex_ids[{int(bad[0])}] = {int(ids[bad[0]])} is not a vertex of the model (0..{n - 1}); "
            f"{bad.size} of {m} ids are out of range"
        )
    return ids


def _frames(frames: Any) -> NDArray[np.float64]:
    try:
        Y = np.asarray(frames, np.float64)
    except (TypeError, ValueError) as exc:
        raise TrackError(f"frames must be a (T, m, 3) array of marker positions: {exc}") from None
    if Y.ndim != 3 or Y.shape[2] != 3:
        raise TrackError(f"frames must be (T, m, 3) marker positions (NaN = occluded), got shape {Y.shape}")
    if Y.shape[0] < 1 or Y.shape[1] < 1:
        raise TrackError(f"frames must hold at least one frame and one marker, got shape {Y.shape}")
    inf = np.isinf(Y)
    if inf.any():
        f, i, _ = (int(v) for v in np.argwhere(inf)[0])
        raise TrackError(f"frames[{f}, {i}] is infinite (use NaN for an occluded marker)")
    return Y


def _positive(value: Any, what: str) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise TrackError(f"{what} must be a positive number, got {value!r}")
    return v


def _lam(value: Any, what: str) -> float | None:
    """A λ as given (a float ≥ 0), or None for ``"auto"`` / None (chosen from the take)."""
    if value is None or (isinstance(value, str) and value == AUTO):
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not (math.isfinite(v) and v >= 0):
        raise TrackError(f"{what} must be a number ≥ 0 or 'auto' (chosen from the take), got {value!r}")
    return v


def check_marker_units(Y: NDArray[np.float64], X0: NDArray[np.float64], model: FaceState) -> float:
    """Median ratio of the markers' spread to the model's at the same vertices; raises when it is far from 1."""
    ratios = []
    step = max(1, Y.shape[0] // 50)
    for f in range(0, Y.shape[0], step):
        vis = np.isfinite(Y[f]).all(1)
        if vis.sum() < 3:
            continue
        a = Y[f, vis]
        b = X0[vis]
        sa = float(np.sqrt(((a - a.mean(0)) ** 2).sum(1).mean()))
        sb = float(np.sqrt(((b - b.mean(0)) ** 2).sum(1).mean()))
        if sb > 0:
            ratios.append(sa / sb)
    if not ratios:
        return 1.0
    r = float(np.median(ratios))
    if r == 0 or not (1.0 / UNITS_FACTOR <= r <= UNITS_FACTOR):
        units = getattr(getattr(model, "metadata", None), "units", "") or "model units"
        raise TrackError(
            f"frames: the markers spread {r:.3g}× as far as the model's vertices at vertex_ids "
            f"(the model is in {units}); they look like another unit or the wrong vertex_ids — "
            f"scale the frames by about {1.0 / r:.3g}" if r > 0 else
            "frames: all visible markers coincide; they cannot be tracked"
        )
    return r


# ------------------------------------------------------------------ the marker tracker
class MarkerSetup:
    """Everything per take that does not change per frame."""

    def __init__(self, model: FaceState, ids: NDArray[np.intp], l1: float, temporal: float,
                 rigid: ArrayLike | None, marker_weights: NDArray[np.float64] | None = None,
                 depth_axis: ArrayLike | None = None) -> None:
        space = ExpressionSpace.from_model(model)
        self.space = space
        self.ids = ids
        self.X0, self.D = space.marker_basis(ids)  # (m, 3), (m, 3, kp)
        m, kp = ids.size, space.plain.size
        #: (m,) each marker's weight in the fit (``Σ_m s_m ||x_m − y_m||²``; ones by default): the
        #: Gram blocks ``Gm`` and the right-hand side rows ``Dh`` carry it, ``fit_weight`` sums it
        self.marker_weights = np.ones(m) if marker_weights is None else np.asarray(marker_weights, np.float64)
        #: (3,) the unit axis, in the frames' coordinates, the weights are not fitted along (None: all three
        #: coordinates fit them); :meth:`depth_in_rig` carries it onto the rig for a frame's pose
        self.depth_axis = check_depth_axis(depth_axis)
        self._weigh()
        s2 = space.size**2
        self.norm = 1.0 / s2
        # the λ scale: an average shape's squared norm per (weighted) marker, in head sizes², fixed for the take;
        # the trace of the Gram (all three coordinates, Σ_m s_m ||D_m||²), so an l1 means the same with a depth axis
        ref = float(np.trace(self.G_all)) / max(kp, 1) / max(self.fit_weight(), 1e-300) * self.norm
        self.ref = ref if ref > 0 else 1.0
        self.solver = WeightSolver(space.lo, space.hi, l1=l1 * self.ref, temporal=temporal * self.ref,
                                   relative=False, tol=1e-6 * math.sqrt(self.ref))
        # rigid markers
        if rigid is None:
            motion = space.motion(ids) / space.size
            self.motion = motion
            still = np.flatnonzero(motion <= RIGID_MOTION)
            self.rigid = still if still.size >= 4 and _spread_ok(self.X0[still]) else np.arange(m)
        else:
            r = np.asarray(rigid)
            if r.dtype == bool:
                if r.shape != (m,):
                    raise TrackError(f"rigid must be ({m},) bool or marker indices, got shape {r.shape}")
                r = np.flatnonzero(r)
            r = r.astype(np.intp).reshape(-1)
            if r.size and (r.min() < 0 or r.max() >= m):
                raise TrackError(f"rigid: marker indices must be in 0..{m - 1}")
            if r.size < 3:
                raise TrackError(f"rigid: need at least 3 markers for the head pose, got {r.size}")
            self.rigid = np.unique(r)
        self.is_rigid = np.zeros(m, bool)
        self.is_rigid[self.rigid] = True
        self.D_derived: NDArray[np.float64] | None = None  # (k, m, 3) every shape's adapted deltas, once adapted
        #: (m, 3) where each marker sits off its vertex on the actor at rest beyond what the adapted
        #: identity explains (the rest calibration's residual): kept through every adoption
        self.rest_offsets = np.zeros((m, 3))

    def adopt(self, am: AdaptiveModel, rows: NDArray[np.intp]) -> None:
        """Track the adapted rig from now on: its neutral and deltas at the markers (``rows`` in ``am.vertex_ids_``)."""
        D_all = am.deltas_at()[:, rows]  # (k, m, 3)
        self.X0 = am.neutral_at()[rows] + self.rest_offsets
        self.D = np.ascontiguousarray(np.moveaxis(D_all[self.space.plain], 0, -1))
        self._weigh()
        self.D_derived = D_all

    def _weigh(self) -> None:
        """The weighted Gram blocks ``Gm`` (m, kp, kp), their sum ``G_all`` and the weighted rows ``Dh`` (m, 3, kp)."""
        self.Dh = self.D * self.marker_weights[:, None, None]  # h = Σ_m Dh_mᵀ c_m
        self.Gm = np.einsum("mck,mcl->mkl", self.Dh, self.D)  # per-marker Gram blocks s_m D_mᵀ D_m
        self.G_all = self.Gm.sum(0)
        #: (3, 3, kp, kp) ``Σ_m s_m D_m[a]ᵀ D_m[b]`` over all markers, by coordinate pair, with a depth
        #: axis: the Gram's part along any direction ``d`` is ``Σ_ab d_a d_b`` of them (:meth:`depth_gram`)
        self.G_axes: NDArray[np.float64] | None = None
        if self.depth_axis is not None:
            self.G_axes = np.stack([np.stack([self.Dh[:, a].T @ self.D[:, b] for b in range(3)]) for a in range(3)])

    def depth_in_rig(self, R: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """(3,) the depth axis in the rig's frame for a frame whose head rotation is ``R`` (None without one).

        The axis is the camera's, fixed in the frames' coordinates; the head turns under it, so
        what the fit leaves out turns with the pose: ``Rᵀ a``.
        """
        return None if self.depth_axis is None else R.T @ self.depth_axis

    def gram(self, sel: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """(kp, kp) ``Σ_m s_m D_mᵀ D_m`` over the markers ``sel`` (None: all)."""
        return self.G_all.copy() if sel is None else self.Gm[sel].sum(0)

    def depth_gram(self, sel: NDArray[np.bool_] | None, d: NDArray[np.float64]) -> NDArray[np.float64]:
        """(kp, kp) ``Σ_m s_m D_mᵀ d dᵀ D_m`` over the markers ``sel`` (None: all): the Gram's part along ``d``.

        ``gram(sel) − depth_gram(sel, d)`` is ``Σ_m s_m D_mᵀ P D_m`` with ``P = I − d dᵀ``; with
        ``P`` symmetric and idempotent, it and the targets projected by :meth:`across`
        (``h = Σ_m s_m D_mᵀ P c_m``) fit each marker's offset across ``d`` only.
        """
        kp = self.D.shape[2]
        if sel is None and self.G_axes is not None:  # every marker: 9 blocks summed, not m rows
            return np.asarray((np.outer(d, d).reshape(9) @ self.G_axes.reshape(9, kp * kp)).reshape(kp, kp))
        D = self.D if sel is None else self.D[sel]
        E = D[:, 0] * d[0] + D[:, 1] * d[1] + D[:, 2] * d[2]  # (m_sel, kp): each row along d
        s = self.marker_weights if sel is None else self.marker_weights[sel]
        return np.asarray((E * s[:, None]).T @ E)

    @staticmethod
    def across(c: NDArray[np.float64], d: NDArray[np.float64] | None) -> NDArray[np.float64]:
        """(n, 3) offsets ``c`` with their component along ``d`` removed (``c`` itself when ``d`` is None)."""
        return c if d is None else c - np.outer(c @ d, d)

    def marker_planes(self, rows: NDArray[np.intp], vis: NDArray[np.bool_], targets: NDArray[np.float64]
                      ) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
        """The ``vis`` markers at ``targets`` ((n_vis, 3), model frame) as the adaptive model's plane rows.

        Three axis-aligned planes per marker, each scaled by the square root of the marker's
        weight, so the rig adapts to the markers as the weights are fitted to them. Returns
        ``(rows, normals, targets)`` for :meth:`AdaptiveModel.update_planes` / ``fit_neutral_planes``
        (``rows`` are each marker's row in the model's ``vertex_ids_``).
        """
        sq = np.repeat(np.sqrt(self.marker_weights[vis]), 3)
        n = int(np.count_nonzero(vis))
        return np.repeat(rows[vis], 3), np.tile(np.eye(3), (n, 1)) * sq[:, None], targets.reshape(-1) * sq

    def fit_weight(self, vis: NDArray[np.bool_] | None = None) -> float:
        """The markers' total weight (the visible ones): what the fit term is averaged over."""
        s = self.marker_weights
        return float(s.sum() if vis is None else s[vis].sum())

    def derived_offset(self, wf: NDArray[np.float64], vis: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """``(m, 3)`` (or at the ``vis`` markers): what the derived shapes add for the full weights ``wf``."""
        if self.D_derived is None:
            return self.space.derived_offset(wf, self.ids if vis is None else self.ids[vis])
        D = self.D_derived if vis is None else self.D_derived[:, vis]
        X = np.zeros((D.shape[1], 3))
        for i in self.space.derived:
            if wf[i] != 0.0:
                X += wf[i] * D[i]
        return X

    def marker_positions(self, w: NDArray[np.float64], wf: NDArray[np.float64]) -> NDArray[np.float64]:
        """(m, 3) model-space marker positions for plain weights ``w`` (full weights ``wf``)."""
        X = self.X0 + self.D @ w
        if self.space.derived:
            X += self.derived_offset(wf)
        return X


def check_depth_axis(depth_axis: ArrayLike | None) -> NDArray[np.float64] | None:
    """``depth_axis`` as a (3,) unit vector (None stays None), or :class:`TrackError` saying what was expected."""
    if depth_axis is None:
        return None
    try:
        a = np.asarray(depth_axis, np.float64)
    except (TypeError, ValueError):
        raise TrackError(f"depth_axis must be a (3,) direction, got {depth_axis!r}") from None
    n = float(np.linalg.norm(a)) if a.shape == (3,) and np.isfinite(a).all() else 0.0
    if n == 0.0:
        raise TrackError(f"depth_axis must be a finite, non-zero (3,) direction, got {depth_axis!r}")
    return a / n


def check_marker_weights(marker_weights: ArrayLike | None, m: int) -> NDArray[np.float64] | None:
    """``marker_weights`` as (m,) float (None stays None), or :class:`TrackError` saying what was expected."""
    if marker_weights is None:
        return None
    s = np.asarray(marker_weights, np.float64)
    if s.shape != (m,):
        raise TrackError(f"marker_weights must have one weight per marker ({m},), got shape {s.shape}")
    if not np.isfinite(s).all() or (s < 0).any() or not (s > 0).any():
        raise TrackError("marker_weights must be finite, ≥ 0 and not all 0")
    return s


def _spread_ok(P: NDArray[np.float64]) -> bool:
    if P.shape[0] < 3:
        return False
    ev = np.linalg.eigvalsh(np.cov(P.T) if P.shape[0] > 1 else np.zeros((3, 3)))
    return bool(ev[2] > 0 and ev[1] > 1e-6 * ev[2])


def _rest(setup: MarkerSetup, Y: NDArray[np.float64], neutral: Any) -> NDArray[np.float64]:
    """The actor's ``(m, 3)`` rest markers (NaN: not seen) from ``neutral``, a frame index or positions."""
    m = setup.ids.size
    if isinstance(neutral, int | np.integer) and not isinstance(neutral, bool):
        if not -Y.shape[0] <= int(neutral) < Y.shape[0]:
            raise TrackError(f"neutral: frame {int(neutral)} is not in the take (0..{Y.shape[0] - 1})")
        rest = Y[int(neutral)]
    else:
        rest = np.asarray(neutral, np.float64)
        if rest.shape != (m, 3):
            raise TrackError(f"neutral must be a frame index or ({m}, 3) rest positions, got shape {rest.shape}")
        if np.isinf(rest).any():
            raise TrackError("neutral: rest positions must be finite (NaN for a marker not seen)")
    return rest


def _calibrate(setup: MarkerSetup, Y: NDArray[np.float64], neutral: Any) -> NDArray[np.float64]:
    """``(m, 3)`` model-frame offsets of the actor's rest markers from the rig's neutral at ``vertex_ids``."""
    rest = _rest(setup, Y, neutral)
    vis: NDArray[np.bool_] = np.asarray(np.isfinite(rest).all(1))
    rig = vis & setup.is_rigid
    try:
        pose = fit_rigid_robust(setup.X0[rig] if rig.sum() >= 3 else setup.X0[vis],
                                rest[rig] if rig.sum() >= 3 else rest[vis])
    except PoseError as exc:
        raise TrackError(f"neutral: the rest markers give no head pose ({exc})") from None
    local = (rest - pose.translation) @ pose.rotation
    return np.where(vis[:, None], local - setup.X0, 0.0)


def start_from_neutral(setup: MarkerSetup, Y: NDArray[np.float64], neutral: Any, am: AdaptiveModel | None,
                       rows: NDArray[np.intp]) -> NDArray[np.float64]:
    """Calibrate on the actor at rest; returns the ``(m, 3)`` rest offsets (see :func:`track_markers`).

    With adaptation the identity is first fitted to the rest markers (the paper's eq. 1),
    alternated with the pose, and adopted. What is left (all of it without adaptation) is
    added to the set-up's neutral as per-marker offsets (``setup.rest_offsets``), kept through
    every later adoption and out of the rig's updates. Dropping that residual with adaptation
    (as before) let the correctives chase a constant landmark-to-vertex offset: on FaceMesh
    landmarks the weight error doubled.
    """
    if am is not None:
        rest = _rest(setup, Y, neutral)  # the paper's neutral start: the identity from the rest markers
        seen: NDArray[np.bool_] = np.asarray(np.isfinite(rest).all(1))
        for _it in range(3):
            offsets = _calibrate(setup, Y, neutral)
            am.fit_neutral_planes(*setup.marker_planes(rows, seen, setup.X0[seen] + offsets[seen]))
            setup.adopt(am, rows)
    # what the identity cannot explain (a marker or landmark that sits off its vertex) stays a
    # per-marker offset; the rig adapts to the motion beyond it
    offsets = _calibrate(setup, Y, neutral)
    setup.rest_offsets = offsets
    setup.X0 = setup.X0 + offsets
    return offsets


def adaptive_for_markers(adapt: Any, model: FaceState, ids: NDArray[np.intp], progress: Progress | None) -> tuple[
    AdaptiveModel | None, NDArray[np.intp]
]:
    """The AdaptiveModel for ``adapt`` (None: off) and each marker's row in its ``vertex_ids_``."""
    if adapt is None or adapt is False:
        return None, ids
    am = adaptive_model(adapt, model, np.unique(ids), progress)
    if am is None:
        return None, ids
    col = np.full(model.n_vertices, -1, np.intp)
    col[am.vertex_ids_] = np.arange(am.vertex_ids_.size)
    rows = col[ids]
    if (rows < 0).any():
        raise TrackError(f"adapt: the AdaptiveModel's vertex_ids_ miss {int((rows < 0).sum())} of the marker "
                         f"vertices (build it with vertex_ids holding every marker vertex)")
    return am, rows


def prepare_markers(model: FaceState, frames: ArrayLike, vertex_ids: ArrayLike) -> tuple[
    NDArray[np.float64], NDArray[np.intp]
]:
    """Checked ``(T, m, 3)`` float frames and ``(m,)`` vertex ids (raises :class:`TrackError` naming the argument)."""
    Y = _frames(frames)
    ids = _vertex_ids(vertex_ids, Y.shape[1], model.n_vertices)
    return Y, ids


def track_markers(
    model: FaceState,
    frames: ArrayLike,
    vertex_ids: ArrayLike,
    *,
    fps: float = 30.0,
    l1: float | str | None = AUTO,
    temporal: float | str | None = AUTO,
    iterations: int = 2,
    min_markers: int = 4,
    rigid: ArrayLike | None = None,
    neutral: int | ArrayLike | None = None,
    adapt: Any = None,
    marker_weights: ArrayLike | None = None,
    depth_axis: ArrayLike | None = None,
    fit_scale: bool = False,
    progress: Progress | None = None,
) -> TrackResult:
    """Track ``(T, m, 3)`` markers or landmarks glued to ``vertex_ids`` (see the module docstring).

    Parameters are those of :func:`track`, plus ``iterations`` (pose/weight alternations
    per frame, ≥ 1), ``min_markers`` (fewer visible markers hold the frame, ≥ 3),
    ``rigid`` (marker indices or an (m,) mask for the head pose; default: chosen from
    the shapes' displacement) and ``neutral``: the actor at rest, as a frame index of
    ``frames`` or ``(m, 3)`` positions (a calibration take), NaN for markers not seen.
    With it, each marker's offset between the actor's rest face and the rig's neutral
    (after rigid alignment) is added to the rig's neutral at that marker, so an actor
    who is not the rig is not explained by expressions; the expressions themselves stay
    the rig's. Default None: markers sit on the rig's neutral (the rig is the actor).

    ``adapt`` (default None: off) adapts the rig to the actor while tracking (the dynamic
    expression model, Bouaziz 2013 §4): True, a dict of
    :class:`~workbench.capture.adapt.AdaptiveModel` options, or an AdaptiveModel built on
    the model whose ``vertex_ids_`` hold every marker vertex (updated in place). Each
    solved frame's visible markers, brought into the model frame, constrain the adapted
    neutral and shapes at the markers (three axis-aligned planes per marker, the frame's
    weights); the next frames are tracked on the adapted rig. With ``neutral``, the
    identity is fitted to the rest markers first (the paper's eq. 1, alternated with the
    pose) instead of the per-marker offsets. ``info["adapted"]`` is the AdaptiveModel
    (None without adaptation); ``.to_model()`` is the adapted rig.

    ``marker_weights`` (m,) ≥ 0 (default all 1): each marker's weight in the fit of the
    weights (not of the head pose), e.g. :func:`~workbench.capture.landmark_registration.landmark_weights`
    for FaceMesh landmarks, whose points on smooth skin lag the motion. The λ's keep their
    meaning: the fit term is averaged over the markers' total weight.

    ``depth_axis`` (3,), in the frames' coordinates (default None): a direction along which the
    markers' positions are a guess — a monocular detector's depth, the camera's axis, e.g.
    :attr:`~workbench.capture.landmark_registration.LandmarkRegistration.view_axis` for FaceMesh
    landmarks. The weights are then fitted on each marker's offset across it only (the head
    pose, the rest offsets and the adaptation still use all three coordinates). The axis stays
    with the camera: each frame's head rotation ``R`` carries it onto the rig (``Rᵀ a``), so a
    turned head's depth stays out of the fit (held in the rig's frame, a head turned by θ let
    ``sin θ`` of it back in: 21 % at 12°).

    ``fit_scale`` (default False): the head pose is a similarity, its uniform scale fitted each
    frame on the rigid markers and removed before the weights' fit — for landmarks from a camera
    the actor moves toward or away from (:class:`~workbench.capture.frame_step.FrameStepper`);
    ``info["scales"]`` (T,) holds it (None when off). Markers in metric units need it off.

    ``l1`` / ``temporal`` ``"auto"`` (the default; None is the same): chosen from the take by
    held-out markers (:func:`~workbench.capture.lambdas.choose_lambdas`); ``info["l1"]`` and
    ``info["temporal"]`` are the values used, ``info["lambda_choice"]`` what was tried (None
    when both were given).
    """
    fps_ = _positive(fps, "fps")
    l1_given = _lam(l1, "l1")
    temporal_given = _lam(temporal, "temporal")
    l1_ = DEFAULT_L1 if l1_given is None else l1_given
    temporal_ = DEFAULT_TEMPORAL if temporal_given is None else temporal_given
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) or iterations < 1:
        raise TrackError(f"iterations must be an int ≥ 1, got {iterations!r}")
    if isinstance(min_markers, bool) or not isinstance(min_markers, int | np.integer) or min_markers < 3:
        raise TrackError(f"min_markers must be an int ≥ 3, got {min_markers!r}")
    if not model.shapes:
        raise TrackError("model: it has no blendshapes to track")
    Y, ids = prepare_markers(model, frames, vertex_ids)
    T, m = Y.shape[:2]
    setup = MarkerSetup(model, ids, l1_, temporal_, rigid, check_marker_weights(marker_weights, m), depth_axis)
    space = setup.space
    check_marker_units(Y, setup.X0, model)
    am, rows = adaptive_for_markers(adapt, model, ids, progress)
    offsets = None if neutral is None else start_from_neutral(setup, Y, neutral, am, rows)
    visible: NDArray[np.bool_] = np.asarray(np.isfinite(Y).all(2))
    good: NDArray[np.bool_] = np.asarray(visible.sum(1) >= int(min_markers))
    if not good.any():
        raise TrackError(
            f"frames: no frame has at least min_markers={int(min_markers)} visible markers "
            f"(at most {int(visible.sum(1).max())} of {m})"
        )

    # per frame small dense blocks (kp × kp): BLAS threads only wait for busy cores (workbench.blas)
    with one_blas_thread():
        choice = None
        if l1_given is None or temporal_given is None:
            from workbench.capture.lambdas import choose_lambdas

            if progress is not None:
                progress(0.0, "choosing λ₁, λ₂ from held-out markers")
            mpu = float(getattr(getattr(model, "metadata", None), "metres_per_unit", 1.0) or 1.0)
            choice = choose_lambdas(setup, Y, visible, good, metres_per_unit=mpu, fix_l1=l1_given,
                                    fix_temporal=temporal_given, iterations=int(iterations))
            l1_, temporal_ = choice.l1, choice.temporal
            setup.solver.l1 = l1_ * setup.ref
            setup.solver.temporal = temporal_ * setup.ref

        kp = space.plain.size
        W = np.zeros((T, kp))
        poses = np.tile(np.eye(4), (T, 1, 1))
        errors = np.full(T, np.nan)
        flags = [""] * T
        stepper = FrameStepper(setup, int(iterations), am, rows, fit_scale=bool(fit_scale))
        scales = np.ones(T)
        every = max(1, T // 100)
        first = int(np.argmax(good))
        for f in range(T):
            if progress is not None and f % every == 0:
                progress(f / T, f"tracking frame {f + 1} of {T}")
            if not good[f]:
                flags[f] = FLAG_HELD
                if f > first:  # hold the previous frame
                    W[f], poses[f], scales[f] = W[f - 1], poses[f - 1], scales[f - 1]
                    stepper.hold(W[f])
                continue
            W[f], poses[f], errors[f], flags[f] = stepper.step(Y[f], visible[f])
            scales[f] = stepper.scale
    sweeps = stepper.sweeps
    # frames before the first solvable one take its values
    W[:first], poses[:first], scales[:first] = W[first], poses[first], scales[first]
    if progress is not None:
        progress(1.0, f"tracked {T} frames")
    derived = space.unsolved_names
    return TrackResult(
        space.full_weights(W), poses, errors, tuple(flags), fps_, space.shape_names, derived, space.size,
        "markers",
        {"l1": l1_, "temporal": temporal_, "iterations": int(iterations), "min_markers": int(min_markers),
         "rigid_markers": setup.rigid.copy(), "vertex_ids": ids.copy(), "lambda_scale": setup.ref,
         "marker_weights": setup.marker_weights.copy(),
         "depth_axis": setup.depth_axis, "scales": scales if fit_scale else None,
         "neutral_offsets": offsets, "adapted": am,
         "solver_sweeps": sweeps, "lambda_auto": (l1_given is None, temporal_given is None),
         "lambda_choice": None if choice is None else choice.as_info()},
    )


def track(
    model: FaceState,
    frames: Any,
    *,
    vertex_ids: ArrayLike | None = None,
    fps: float = 30.0,
    l1: float | str | None = AUTO,
    temporal: float | str | None = AUTO,
    adapt: Any = None,
    progress: Progress | None = None,
    **options: Any,
) -> TrackResult:
    """Track a take onto the model's blendshapes: rigid head pose + weights per frame (Bouaziz 2013 §3.1).

    Parameters
    ----------
    model : FaceModel
        The rig (its shapes, slider ranges, masks, mutes and correctives as they are now).
    frames : (T, m, 3) float, or sequence of (p_t, 3) float
        Markers / landmarks (NaN = occluded) in correspondence with ``vertex_ids``; or,
        without ``vertex_ids``, one point cloud per frame (no correspondences).
    vertex_ids : (m,) int, optional
        The model vertex of each marker. Given: the marker tracker (this module).
        None: the point-cloud tracker, :func:`workbench.capture.clouds.track_clouds`.
    fps : float
        Frame rate of the take.
    l1 : float or "auto"
        Sparsity ``λ`` (relative, unit-free). ``"auto"`` (the default; None is the same): for
        markers, chosen from the take by held-out markers (:mod:`.lambdas`; the choice is in
        ``info["lambda_choice"]``); for point clouds, the clouds tracker's default.
    temporal : float or "auto"
        Temporal smoothness ``λ`` (relative); ``"auto"`` as for ``l1``.
    adapt : bool, dict, AdaptiveModel or None
        Rig adaptation (the dynamic expression model, §4). Off by default for markers
        (None or False; see :func:`track_markers`), on for point clouds
        (:func:`~workbench.capture.clouds.track_clouds`).
    progress : callable, optional
        ``progress(fraction, message)``, called as frames are tracked.
    **options
        Passed on: for markers ``iterations``, ``min_markers``, ``rigid``, ``neutral``,
        ``marker_weights``, ``depth_axis``, ``fit_scale`` (:func:`track_markers`); for clouds, whatever ``track_clouds`` takes.

    Returns
    -------
    TrackResult

    Raises
    ------
    TrackError
        Input that cannot be tracked, naming the argument (nothing is changed on the model).
    """
    if vertex_ids is None:
        from workbench.capture.clouds import track_clouds

        return track_clouds(model, frames, fps=fps, l1=None if isinstance(l1, str) else l1,
                            temporal=None if isinstance(temporal, str) else temporal, adapt=adapt, progress=progress, **options)
    return track_markers(model, frames, vertex_ids, fps=fps, l1=l1, temporal=temporal, adapt=adapt,
                         progress=progress, **options)
