"""How well a marker fit recovers a synthetic performance: region-wise vs global, as a table."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.methods.regions.hierarchy import Regions
from workbench.methods.regions.marker_fit.fit import fit_markers
from workbench.methods.regions.marker_fit.result import _blend_with_global
from workbench.methods.regions.marker_fit.synthetic import SyntheticPerformance
from workbench.methods.regions.segmentation import component_roles

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel


def fidelity_table(
    model: FaceModel,
    regions: Regions,
    performance: SyntheticPerformance,
    *,
    levels: list[int] | None = None,
    regularization: float = 1e-2,
    rbf: str = "exponential",
) -> list[dict[str, Any]]:
    """Region-wise vs global fitting error and weight recovery on a synthetic performance.

    Errors are RMS over frames, area-weighted over the moving skin (vertices some
    shape moves), in model units; weight error is the RMS difference of the
    *per-vertex effective weights* (``sum_r W_r(v) w_r + W_bg(v) g``) from the
    truth's, over the same vertices and all shapes.

    Parameters
    ----------
    model : FaceModel
    regions : Regions
    performance : SyntheticPerformance
    levels : list of int, optional
        Region levels to compare (default all).
    regularization : float
    rbf : str

    Returns
    -------
    list of dict
        One row per method (``"global"``, ``"regions L<l>"``) with keys
        ``method, level, n_regions, marker_rms, marker_rms_rbf, vertex_rms,
        vertex_rms_rbf, weight_rms``.
    """
    lvls = list(range(regions.n_levels)) if levels is None else [regions.check_level(x) for x in levels]
    from workbench.geometry.operators import mass_matrix

    roles = component_roles(model)
    D = model.effective_deltas
    maxd = np.sqrt(np.einsum("knc,knc->kn", D, D, dtype=np.float64)).max(axis=0) if len(D) else np.zeros(model.n_vertices)
    eval_v = np.flatnonzero((roles == 0) & (maxd > 1e-3 * maxd.max(initial=0.0)))
    area = np.asarray(mass_matrix(model.vertices, model.faces).diagonal())[eval_v]
    area = area / area.sum()
    T = performance.n_frames
    truth_pos = [performance.positions(model, t)[eval_v] for t in range(T)]
    truth_w = [performance.vertex_weights(t)[eval_v] for t in range(T)]
    rows: list[dict[str, Any]] = []
    runs: list[tuple[str, int, bool]] = [("global", lvls[0], False)] + [(f"regions L{lv}", lv, True) for lv in lvls]
    for name, lv, use in runs:
        fit = fit_markers(
            model, regions, performance.markers, performance.marker_positions, lv,
            regularization=regularization, rbf=rbf, use_regions=use,
        )
        Wv = regions.weight_matrix(lv)[eval_v]
        bgv = regions.background[lv][eval_v].astype(np.float64)
        ev, evr, ew, emr = 0.0, 0.0, 0.0, 0.0
        for t in range(T):
            X = _blend_with_global(model, regions, fit.weights_at(t), fit.global_weights[t], eval_v)
            Xr = X + fit.residual_displacement(model, t)[eval_v]
            ev += float(area @ np.sum((X - truth_pos[t]) ** 2, axis=1))
            evr += float(area @ np.sum((Xr - truth_pos[t]) ** 2, axis=1))
            weff = np.asarray(Wv @ fit.region_weights[t].astype(np.float64)) + bgv[:, None] * fit.global_weights[t][None, :]
            ew += float(area @ np.mean((weff - truth_w[t]) ** 2, axis=1))
            # marker error after the RBF (should be ~0)
            Xm = _blend_with_global(model, regions, fit.weights_at(t), fit.global_weights[t], performance.markers)
            Xm = Xm + fit.residual_displacement(model, t)[performance.markers]
            emr += float(np.mean(np.sum((Xm - performance.marker_positions[t]) ** 2, axis=1)))
        rows.append(
            {
                "method": name,
                "level": lv if use else None,
                "n_regions": regions.n_regions(lv) if use else 0,
                "marker_rms": float(np.sqrt(np.mean(fit.marker_error_region**2))),
                "marker_rms_rbf": float(np.sqrt(emr / T)),
                "vertex_rms": float(np.sqrt(ev / T)),
                "vertex_rms_rbf": float(np.sqrt(evr / T)),
                "weight_rms": float(np.sqrt(ew / T)),
            }
        )
    return rows


def format_fidelity_table(rows: list[dict[str, Any]], units: str = "dm") -> str:
    """A markdown table of :func:`fidelity_table` rows."""
    head = (
        f"| method | regions | marker RMS ({units}) | after RBF | vertex RMS ({units}) | vertex RMS + RBF | weight RMS |\n"
        "|---|---|---|---|---|---|---|\n"
    )
    body = "".join(
        f"| {r['method']} | {r['n_regions']} | {r['marker_rms']:.2e} | {r['marker_rms_rbf']:.1e} | "
        f"{r['vertex_rms']:.2e} | {r['vertex_rms_rbf']:.2e} | {r['weight_rms']:.3f} |\n"
        for r in rows
    )
    return head + body
