"""Performance capture: track markers, landmarks and point clouds onto the rig (Bouaziz et al. 2013)."""

from workbench.capture.solver import WeightSolver

__all__ = ["WeightSolver"]
