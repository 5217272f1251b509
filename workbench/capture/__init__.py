"""Performance capture: track markers, landmarks and point clouds onto the rig (Bouaziz et al. 2013).

The method family of issue 17, after "Online Modeling for Realtime Facial
Animation" (Bouaziz, Wang, Pauly, SIGGRAPH 2013): per frame, a rigid head pose
and blendshape weights with an L1 sparsity prior and a second-difference
temporal prior (§3.1), optionally adapting the rig to the actor (§2, §3.2).

* :func:`replay` / :class:`ReplayResult` — markers drive the shell's handles and the
  wrinkles (Bickel et al. 2008, Fig. 6; :mod:`.replay`), ``model.capture.apply_replay``;
* :func:`track` — the entry point: ``(T, m, 3)`` markers / landmarks with
  ``vertex_ids`` (:mod:`.track`), or point clouds (:mod:`.clouds`);
* :class:`TrackResult` — weights, poses, errors, flags; ``to_timeline``
  (:mod:`.result`); ``model.capture.apply(result)`` keys it as one undo step
  (:mod:`.facet`, registered by :mod:`.family`);
* :class:`WeightSolver` — the per-frame bounded L1 + temporal QP by warm-started
  shooting (:mod:`.solver`); :mod:`.pose` — robust rigid pose;
* :func:`synthetic_performance` — generated ground truth (:mod:`.synthetic`);
* :func:`track_clouds` / :class:`AdaptiveModel` — point clouds and the dynamic
  expression model (:mod:`.clouds`, :mod:`.adapt`); :class:`IdentityModel` /
  :func:`sample_identity_model` — the identity PCA (:mod:`.identity`);
* :class:`LiveTracker` — camera frames as they arrive (the ``video`` extra's FaceMesh,
  the marker tracker's step, the rig adapting online; :mod:`.live`);
* :mod:`.inputs` — C3D, marker CSV, NPY/NPZ, PLY/NPZ clouds, depth PNGs;
* :func:`track_video` and friends — video through MediaPipe FaceMesh (the
  ``video`` extra; :mod:`.video`, imported on first use).

Why the solver is hand-written: no kept library solves a bounded L1 +
temporal QP warm-started per frame at this rate (``scipy.optimize.lsq_linear``
has no L1 term nor warm start; OSQP through ``qpsolvers`` sets up per frame and
is slower; ``benchmarks/bench_capture.py`` measures both).
"""

from typing import Any

from workbench.capture.adapt import AdaptiveModel
from workbench.capture.clouds import CloudTrackError, track_clouds
from workbench.capture.identity import IdentityModel, sample_identity_model
from workbench.capture.landmark_registration import LANDMARK_L1
from workbench.capture.live import LiveFrame, LiveTracker
from workbench.capture.replay import ReplayResult, replay
from workbench.capture.result import TrackError, TrackResult
from workbench.capture.solver import WeightSolver
from workbench.capture.synthetic import SyntheticPerformance, synthetic_performance
from workbench.capture.track import track

__all__ = [
    "LANDMARK_L1",
    "AdaptiveModel",
    "CloudTrackError",
    "IdentityModel",
    "LandmarkSequence",
    "LiveFrame",
    "LiveTracker",
    "ReplayResult",
    "SyntheticPerformance",
    "TrackError",
    "TrackResult",
    "VideoExtraMissing",
    "WeightSolver",
    "landmark_vertex_map",
    "register_landmarks",
    "replay",
    "sample_identity_model",
    "synthetic_performance",
    "track",
    "track_clouds",
    "track_video",
    "video_landmarks",
]

#: from :mod:`.video`, imported on first use (it loads OpenCV and MediaPipe only when called)
_VIDEO = {"LandmarkSequence", "VideoExtraMissing", "landmark_vertex_map", "register_landmarks", "track_video",
          "video_landmarks"}


def __getattr__(name: str) -> Any:
    if name in _VIDEO:
        from workbench.capture import video

        return getattr(video, name)
    raise AttributeError(f"module 'workbench.capture' has no attribute {name!r}")
