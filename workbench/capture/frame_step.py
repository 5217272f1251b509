"""One frame of the marker tracker: rigid pose and weights, alternated (Bouaziz et al. 2013, §3.1).

:class:`FrameStepper` holds what carries from frame to frame — the last weights
(the warm start and the temporal prior's two past frames), the last pose and the
adapting rig — so the offline tracker (:func:`~workbench.capture.track.track_markers`,
a loop over the take) and the live one (:class:`~workbench.capture.live.LiveTracker`,
a frame as it arrives) run the same step. Hand-written glue over the robust pose
(:mod:`.pose`) and the weight solver (:mod:`.solver`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.capture.pose import PoseError, fit_rigid_robust, pose_matrix
from workbench.capture.result import FLAG_POSE_ALL

if TYPE_CHECKING:
    from workbench.capture.adapt import AdaptiveModel
    from workbench.capture.track import MarkerSetup

#: the reweighted pose stops when it moves the markers by less than this share of their extent
POSE_TOL = 1e-6


class FrameStepper:
    """Track frame after frame on a marker set-up (see the module docstring).

    Parameters
    ----------
    setup : MarkerSetup
        The take's fixed part (rig at the markers, Gram blocks, solver, rigid markers).
    iterations : int
        Pose / weight alternations per frame.
    adaptive : AdaptiveModel, optional
        Refined by every solved frame's markers; the set-up adopts it.
    rows : (m,) int, optional
        The markers' rows in ``adaptive.vertex_ids_``.
    fit_scale : bool
        Fit the head pose as a similarity: a uniform scale with the rotation and translation,
        on the rigid markers at the frame's expression (Umeyama's scale). For landmarks from a
        camera whose distance to the actor changes — FaceMesh's coordinates scale with the face's
        size in the image, so an actor leaning 15 % closer would otherwise read as every shape
        that widens the face (``bench_live.py`` table 9). The scale is removed before the
        weights' fit; the pose returned stays rigid and :attr:`scale` holds the scale. Off for
        markers in metric units (a motion-capture take: the actor's size does not change).

    Attributes
    ----------
    scale : float
        The last solved frame's scale (1 until one is fitted; > 1: the face is larger than the
        rig's frame, e.g. the actor closer to the camera than at the neutral).
    """

    def __init__(self, setup: MarkerSetup, iterations: int, adaptive: AdaptiveModel | None = None,
                 rows: NDArray[np.intp] | None = None, *, fit_scale: bool = False) -> None:
        self.setup = setup
        self.fit_scale = bool(fit_scale)
        self.scale = 1.0
        self.iterations = int(iterations)
        self.adaptive = adaptive
        self.rows = rows
        kp = setup.space.plain.size
        self.w = np.zeros(kp)
        self.wf = setup.space.full_weights(self.w)
        self.w_prev: NDArray[np.float64] | None = None
        self.w_prev2: NDArray[np.float64] | None = None
        self.M = np.eye(4)
        self.sweeps = 0

    def hold(self, w: NDArray[np.float64]) -> None:
        """A frame that was not solved, holding weights ``w``: it still counts in the temporal prior."""
        self.w_prev2, self.w_prev = self.w_prev, np.array(w, np.float64)

    def step(self, Yf: NDArray[np.float64], vis: NDArray[np.bool_], *, adapt: bool = True
             ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, str]:
        """Solve one frame: ``(plain weights, pose (4, 4), RMS error, flag)`` for markers ``Yf`` (m, 3) seen at ``vis``.

        ``adapt=False``: this frame does not refine the adapting rig (the live tracker adapts on
        every few frames only, to keep up with the camera).
        """
        setup, space, solver = self.setup, self.setup.space, self.setup.solver
        m, kp = vis.size, space.plain.size
        flag = ""
        Yv = Yf[vis]
        Dv = setup.Dh[vis].reshape(-1, kp)  # weighted rows (MarkerSetup.marker_weights)
        nv = int(vis.sum())
        sw = setup.fit_weight(vis)
        sel = None if nv == m else vis
        G0 = setup.gram(sel)
        G = G0 * (setup.norm / sw)
        rig = vis & setup.is_rigid
        w, wf, M, s = self.w, self.wf, self.M, self.scale
        for _it in range(self.iterations):
            X = setup.marker_positions(w, wf)
            pose = None
            if rig.sum() >= 3:
                try:
                    pose = fit_rigid_robust(X[rig], Yf[rig], scale=self.fit_scale, max_iter=10, tol=POSE_TOL)
                except PoseError:
                    pose = None
            if pose is None:
                flag = FLAG_POSE_ALL
                try:
                    pose = fit_rigid_robust(X[vis], Yv, scale=self.fit_scale, max_iter=10, tol=POSE_TOL)
                except PoseError:
                    pose = None
            if pose is not None:
                M, s = pose_matrix(pose.rotation, pose.translation), pose.scale
            R, t = M[:3, :3], M[:3, 3]
            local = (Yv - t) @ R / s  # Rᵀ (y − t) / s, row-wise
            c = local - setup.X0[vis]
            if space.derived:
                c = c - setup.derived_offset(wf, vis)
            d = setup.depth_in_rig(R)  # the camera's axis under this pose: the fit is across it
            if d is not None:
                G = (G0 - setup.depth_gram(sel, d)) * (setup.norm / sw)
                c = setup.across(c, d)
            h = Dv.T @ c.reshape(-1) * (setup.norm / sw)
            w = solver.solve_gram(G, h, self.w_prev, self.w_prev2, w0=w)
            self.sweeps += solver.n_iter_
            if space.derived:
                wf = space.full_weights(w)
        wf = space.full_weights(w)
        X = setup.marker_positions(w, wf)
        r = s * X[vis] @ M[:3, :3].T + M[:3, 3] - Yv
        error = float(np.sqrt((r * r).sum(1).mean()))
        self.w, self.wf, self.M, self.scale = w, wf, M, s
        self.w_prev2, self.w_prev = self.w_prev, w.copy()
        am = self.adaptive
        if adapt and am is not None and self.rows is not None:  # the frame refines the rig for the next frames
            local = (Yv - M[:3, 3]) @ M[:3, :3] / s - setup.rest_offsets[vis]
            # the markers weigh in the rig's refinement as in the weights' fit (unweighted, the
            # correctives would learn what the weighting leaves out)
            am.update_planes(*setup.marker_planes(self.rows, vis, local), wf)
            setup.adopt(am, self.rows)
        return w, M, error, flag
