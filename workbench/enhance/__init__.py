"""Performance enhancement (Bermano et al. 2014): data-driven retiming of key pairs (§6).

* :class:`PerformanceDatabase` — the detail database (§4): frequency separation
  by one implicit curvature-flow step, high-frequency detail as per-triangle
  gradients, the compressed shape space of patch-mean gradients, voluntary
  region weights, the eq. 2–3 convex matching and eq. 4 blending
  (:mod:`.database`); the voluntary regions found from motion (:mod:`.motion_regions`);
* :meth:`PerformanceDatabase.enhance` / :func:`enhance_frames` — spatial
  enhancement (§5) of input frames through a :class:`Correspondence` (:mod:`.spatial`);
* :func:`retime` / :class:`RetimeResult` — sequence projection (eq. 5–6) and
  temporally driven interpolation (§6.2) (:mod:`.retime`); point caches matched in
  a rig's weights, :class:`RigBasis` (:mod:`.rig_space`);
* ``model.enhance.retime(t0, t1, takes)`` — *Retime from performance* on the
  timeline, one undo step (:mod:`.facet`, registered by :mod:`.family`).
"""

from workbench.enhance.database import DatabaseError, PerformanceDatabase
from workbench.enhance.matching import simplex_lsq
from workbench.enhance.motion_regions import (
           MotionRegions,
           motion_regions,
           voluntary_cores_from_motion,
)
from workbench.enhance.retime import RetimeResult, retime
from workbench.enhance.rig_space import RigBasis
from workbench.enhance.spatial import Correspondence, EnhanceResult, enhance_frames
from workbench.enhance.voluntary import voluntary_region_weights

__all__ = ["Correspondence", "DatabaseError", "EnhanceResult", "MotionRegions", "PerformanceDatabase", "RetimeResult",
           "RigBasis", "enhance_frames", "motion_regions", "retime", "simplex_lsq", "voluntary_cores_from_motion",
           "voluntary_region_weights"]
