"""Registers the blend regions: ``model.regions``, the region layer, animation and file part."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.families import Family, SlotSpec, TrackSpec, register_family
from workbench.core.manifest import Checker, Spec
from workbench.methods.regions.blend import RegionLayer, RegionState, RegionWeights
from workbench.methods.regions.facet import RegionsFacet, check_state
from workbench.methods.regions.hierarchy import Regions
from workbench.methods.regions.tracks import (
    REGIONS_PREFIX,
    check_region_tracks,
    region_track_shape,
    region_track_title,
    sampled_region_weights,
)

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState


_REGION_LEVEL_FIELDS = ("labels", "weight_rows", "weight_cols", "weight_vals", "background")


def _region_arrays(model: FaceState) -> dict[str, np.ndarray]:
    st = model.slot("regions")
    if st is None:
        return {}
    r = st.regions
    out: dict[str, np.ndarray] = {"regions_deformation": r.deformation.astype("<f4")}
    for f in _REGION_LEVEL_FIELDS:
        for lv, a in enumerate(getattr(r, f)):
            out[f"regions_{f}_{lv}"] = a.astype("<f4" if a.dtype.kind == "f" else "<i4")
    for lv, a in enumerate(r.parents):
        out[f"regions_parents_{lv}"] = a.astype("<i4")
    if st.weights is not None:
        out["regions_weight_values"] = st.weights.values.astype("<f4")
    return out


def _regions_json(model: FaceState) -> dict[str, Any] | None:
    st = model.slot("regions")
    if st is None:
        return None
    r = st.regions
    w = st.weights
    return {
        "level": st.level,
        "n_levels": r.n_levels,
        "threshold": r.threshold,
        "threshold_value": r.threshold_value,
        "overlap_rings": r.overlap_rings,
        "names": [list(x) for x in r.names],
        "kinds": [list(x) for x in r.kinds],
        "drivers": [[list(d) for d in x] for x in r.drivers],
        "weights": None
        if w is None
        else {"level": w.level, "region_names": list(w.region_names), "shape_names": list(w.shape_names)},
    }


def _check_regions(c: Checker, value: Any) -> dict[str, Any] | None:
    if value is None:
        return None
    f = "regions"
    r = c.obj(value, f)
    L = c.integer(c.key(r, f, "n_levels"), "regions.n_levels", lo=1, hi=1000)
    per_level = f" (one per level, regions.n_levels = {L})"
    names = [
        c.strings(x, f"regions.names[{lv}]", unique=True)
        for lv, x in enumerate(c.lst(c.key(r, f, "names"), "regions.names", L, per_level))
    ]
    kinds = [
        c.strings(x, f"regions.kinds[{lv}]", len(names[lv]), f" (one per name in regions.names[{lv}])")
        for lv, x in enumerate(c.lst(c.key(r, f, "kinds"), "regions.kinds", L, per_level))
    ]
    drivers = []
    for lv, x in enumerate(c.lst(c.key(r, f, "drivers"), "regions.drivers", L, per_level)):
        lf = f"regions.drivers[{lv}]"
        regs = c.lst(x, lf, len(names[lv]), f" (one per name in regions.names[{lv}])")
        drivers.append([c.strings(d, f"{lf}[{j}]") for j, d in enumerate(regs)])
    weights = None
    weights_json = c.key(r, f, "weights", None)
    if weights_json is not None:
        wf = "regions.weights"
        wj = c.obj(weights_json, wf)
        wl = c.integer(c.key(wj, wf, "level"), f"{wf}.level", hi=L - 1)
        weights = {
            "level": wl,
            "region_names": c.strings(
                c.key(wj, wf, "region_names"), f"{wf}.region_names", len(names[wl]),
                f" (one per region of level {wl})",
            ),
            "shape_names": c.strings(c.key(wj, wf, "shape_names"), f"{wf}.shape_names"),
        }
    return {
        "level": c.integer(c.key(r, f, "level"), "regions.level", hi=L - 1),
        "n_levels": L,
        "threshold": c.number(c.key(r, f, "threshold"), "regions.threshold"),
        "threshold_value": c.number(c.key(r, f, "threshold_value"), "regions.threshold_value"),
        "overlap_rings": c.integer(c.key(r, f, "overlap_rings"), "regions.overlap_rings"),
        "names": names,
        "kinds": kinds,
        "drivers": drivers,
        "weights": weights,
    }


class RegionsFilePart:
    """``regions: null | {...}`` in the manifest and the ``regions_*`` arrays (see :mod:`workbench.fileformat`)."""

    keys: tuple[str, ...] = ("regions",)

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]:
        return {"regions": _regions_json(model)}, _region_arrays(model)

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        return {"regions": _check_regions(c, c.key(dict(manifest), "", "regions", None))}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]:
        rj = m["regions"]
        specs: dict[str, Spec] = {}
        if rj is None:
            return specs, set()
        n = m["mesh"]["n_vertices"]
        L = rj["n_levels"]
        specs["regions_deformation"] = ("<f4", (n,), "(mesh.n_vertices,)")
        for lv in range(L):
            R = len(rj["names"][lv])
            nnz = f"nnz{lv}"
            specs[f"regions_labels_{lv}"] = ("<i4", (n,), "(mesh.n_vertices,)")
            specs[f"regions_background_{lv}"] = ("<f4", (n,), "(mesh.n_vertices,)")
            for fld, dt in (("rows", "<i4"), ("cols", "<i4"), ("vals", "<f4")):
                specs[f"regions_weight_{fld}_{lv}"] = (dt, (nnz,), f"(nnz,) like regions_weight_rows_{lv}")
            if lv < L - 1:
                specs[f"regions_parents_{lv}"] = ("<i4", (R,), f"(len(regions.names[{lv}]),)")
        wj = rj["weights"]
        if wj is not None:
            specs["regions_weight_values"] = (
                "<f4",
                (len(wj["region_names"]), len(wj["shape_names"])),
                "(len(regions.weights.region_names), len(regions.weights.shape_names))",
            )
        return specs, set(specs)

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        rj = m["regions"]
        if rj is None:
            return
        a = dict(arrays)
        n = m["mesh"]["n_vertices"]
        L = rj["n_levels"]
        for lv in range(L):
            R = len(rj["names"][lv])
            c.in_range(a, f"regions_labels_{lv}", -1, R - 1, f"labels (-1 or regions of level {lv})")
            c.in_range(a, f"regions_weight_rows_{lv}", 0, n - 1, "vertex ids")
            c.in_range(a, f"regions_weight_cols_{lv}", 0, R - 1, f"regions of level {lv}")
            if lv < L - 1:
                c.in_range(a, f"regions_parents_{lv}", 0, len(rj["names"][lv + 1]) - 1, f"regions of level {lv + 1}")

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        rj = m["regions"]
        if rj is None:
            return {}
        L = rj["n_levels"]
        regions = Regions(
            **{f: tuple(arrays[f"regions_{f}_{lv}"] for lv in range(L)) for f in _REGION_LEVEL_FIELDS},
            names=tuple(tuple(x) for x in rj["names"]),
            parents=tuple(arrays[f"regions_parents_{lv}"] for lv in range(L - 1)),
            kinds=tuple(tuple(x) for x in rj["kinds"]),
            drivers=tuple(tuple(tuple(d) for d in x) for x in rj["drivers"]),
            deformation=arrays["regions_deformation"],
            threshold=rj["threshold"],
            threshold_value=rj["threshold_value"],
            overlap_rings=rj["overlap_rings"],
        )
        wj = rj["weights"]
        weights = None
        if wj is not None:
            weights = RegionWeights(wj["level"], tuple(wj["shape_names"]), tuple(wj["region_names"]),
                                    arrays["regions_weight_values"])
        return {"regions": RegionState(regions, rj["level"], weights)}


def animate(view: StateView, sample: Any) -> dict[str, Any]:
    """The regions slot with the region weights of ``sample`` ({} when no region tracks apply).

    Keyed regions take their keyed weights; every other region of the keyed
    level follows the (already sampled) global weights, so it adds no
    correction. Tracks naming regions or levels the model no longer has, or
    holding a stale number of shapes, are skipped (``check_model`` reports them).
    """
    st = view.slot("regions")
    L, keyed = sampled_region_weights(sample.others)
    if L is None or not isinstance(st, RegionState) or L >= st.regions.n_levels:
        return {}
    names = st.regions.names[L]
    k = len(view.shapes)
    g = np.array([view.weights[s.name] for s in view.shapes], np.float32)
    values = np.tile(g, (len(names), 1))
    index = {nm: i for i, nm in enumerate(names)}
    for region, v in keyed.items():
        if region in index and v.shape == (k,):
            values[index[region]] = v
    rw = RegionWeights(L, tuple(view.shape_names), names, values)
    return {"regions": RegionState(st.regions, st.level, rw)}


def recipe_slots(slots: Mapping[str, Any]) -> dict[str, Any]:
    """A recipe records no region weights: the regions without them."""
    st = slots.get("regions")
    if isinstance(st, RegionState) and st.weights is not None:
        return {"regions": RegionState(st.regions, st.level, None)}
    return {}


FAMILY = register_family(
    Family(
        name="regions",
        slots=(SlotSpec("regions", lambda m: None, deforms=True, check=check_state),),
        facet=RegionsFacet,
        layer=RegionLayer,
        order=10,
        tab="widgets.tabs.regions",
        file_part=RegionsFilePart(),
        animate=animate,
        tracks={REGIONS_PREFIX: TrackSpec(region_track_shape, title=region_track_title)},
        check_tracks=check_region_tracks,
        recipe_slots=recipe_slots,
    )
)
