"""Marker fitting with blend regions plus an RBF residual (Joshi et al. 2003, §3).

Per frame, the marker positions are projected onto the blend-shape space by
bounded least squares, globally and then per region, and the mesh is moved by
the radial-basis interpolation of the residual at the markers so the markers
are met. The method is explained in :mod:`~workbench.methods.regions.marker_fit.fit`
(:func:`fit_markers`); the residual's kernels in
:mod:`~workbench.methods.regions.marker_fit.rbf` (:class:`RBFResidual`); the result
in :mod:`~workbench.methods.regions.marker_fit.result` (:class:`MarkerFit`); a
synthetic performance to test it on in
:mod:`~workbench.methods.regions.marker_fit.synthetic` and the comparison with a
global fit in :mod:`~workbench.methods.regions.marker_fit.fidelity`.
"""

from __future__ import annotations

from workbench.methods.regions.marker_fit.fidelity import fidelity_table, format_fidelity_table
from workbench.methods.regions.marker_fit.fit import fit_markers
from workbench.methods.regions.marker_fit.rbf import KERNELS as KERNELS
from workbench.methods.regions.marker_fit.rbf import RBFResidual
from workbench.methods.regions.marker_fit.result import MarkerFit
from workbench.methods.regions.marker_fit.synthetic import (
    SyntheticPerformance,
    generate_synthetic_marker_performance,
)

__all__ = [
    "MarkerFit",
    "RBFResidual",
    "SyntheticPerformance",
    "fidelity_table",
    "fit_markers",
    "format_fidelity_table",
    "generate_synthetic_marker_performance",
]
