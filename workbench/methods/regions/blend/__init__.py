"""Per-region blend weights, smooth blending over overlaps, and region sculpting (Joshi et al. 2003, §2–§4).

Paper: "Learning Controls for Blend Shape Based Realistic Facial Animation"
(``shared/papers/siggraph2006-course-performance-driven-facial-animation.md``).
§2: "linear blending in each of these regions will reconstruct much more detail";
§4 "Creating Keyframes": the user drags points, a minimisation over the region's
blending weights makes them follow; "Motion Damping" scales the mouse motion.

The region blend and its equations are in
:mod:`~workbench.methods.regions.blend.evaluate` (the weights it blends in
:mod:`~workbench.methods.regions.blend.weights`, its pipeline layer in
:mod:`~workbench.methods.regions.blend.layer`); region sculpting and motion
damping in :mod:`~workbench.methods.regions.blend.sculpt`, with the bounded
least-squares solver in :mod:`~workbench.methods.regions.blend.lsq`.

Hand-written because this blend (per-region weights, overlap weights, a bounded
solve restricted to the touched regions) is specific to the paper; the numerics
are numpy/scipy.
"""

from __future__ import annotations

from workbench.methods.regions.blend.evaluate import (
    region_blend_displacement,
    region_blend_positions,
)
from workbench.methods.regions.blend.layer import RegionLayer
from workbench.methods.regions.blend.lsq import bounded_lsq as bounded_lsq
from workbench.methods.regions.blend.sculpt import damp_drag, drag_damping, solve_region_drag
from workbench.methods.regions.blend.sculpt import drag_system as drag_system
from workbench.methods.regions.blend.weights import RegionState, RegionWeights

__all__ = [
    "RegionLayer",
    "RegionState",
    "RegionWeights",
    "damp_drag",
    "drag_damping",
    "region_blend_displacement",
    "region_blend_positions",
    "solve_region_drag",
]
