"""Registers pose-space wrinkles: the ``wrinkles`` slot, ``model.wrinkles``, the layer and its file part."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.families import Family, SlotSpec, register_family
from workbench.core.manifest import Checker, Spec, json_path
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.wrinkles.facet import WrinklesFacet, check_state
from workbench.methods.wrinkles.layer import WrinkleLayer, WrinkleState

if TYPE_CHECKING:
    from workbench.core.state import FaceState

logger = logging.getLogger(__name__)

def fit_sample_wrinkles(
    model: FaceState,
    poses: Mapping[str, Mapping[str, float]] | None = None,
    sculptor: object | None = None,
) -> WrinklesFacet:
    """Procedural example poses (:mod:`.examples`) fitted onto ``model``; returns ``model.wrinkles``.

    Works on any rig: the poses' ARKit weights are mapped onto the rig's own
    shapes (other spellings, split halves, merged pairs); poses the rig cannot
    express are left out and logged (:func:`~.examples.example_poses_for`
    gives the same report). Sets the default handles first if the model has
    none (one undo step each).

    Raises
    ------
    ValueError
        Not even two example poses can be built on this rig.
    """
    from workbench.methods.wrinkles.examples import WrinkleSculptor, example_poses_for

    facet: WrinklesFacet = model.wrinkles  # type: ignore[attr-defined]
    handles = model.handles  # type: ignore[attr-defined]
    on_rig, skipped = example_poses_for(model.shape_names, poses)
    for pose, why in skipped.items():
        logger.warning("wrinkle example %r: %s", pose, why)
    if len(on_rig) < 2:
        raise ValueError(
            f"fit wrinkles: only {len(on_rig)} of the example poses can be built on this rig "
            f"({'; '.join(f'{k}: {v}' for k, v in skipped.items())})"
        )
    if len(handles) == 0:
        handles.set(default_face_handles(model), label="Default handles")
    s = sculptor if isinstance(sculptor, WrinkleSculptor) else WrinkleSculptor(model)
    facet.fit({k: (w, s.detailed(w)) for k, w in on_rig.items()})
    return facet


class WrinklesFilePart:
    """``wrinkles: null | {...}`` and the ``wrinkles_*`` arrays: the fit's inputs, refitted on load.

    Stored: the feature graph, the fitted handle vertices, the training features
    and (possibly edited) training details, the basis and fitting options, and
    how the wrinkles are shown. Loading recomputes the WPSD edge weights and
    the RBF weights from them with the same basis (deterministic), so the
    file holds what the user made, not a solver's by-products.
    """

    keys: tuple[str, ...] = ("wrinkles",)

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]:
        st: WrinkleState = model.slot("wrinkles")
        ps = st.pose_space
        if ps is None or st.graph is None or st.handles is None:
            return {"wrinkles": None}, {}
        entry = {
            "examples": [{"name": n, "weights": dict(w)} for n, w in zip(st.example_names, st.example_weights, strict=True)],
            "strength": st.strength,
            "enabled": st.enabled,
            "weighted": st.weighted,
            "mode": ps.mode,
            "rcond": ps.rcond,
            "beta": None if ps.alpha is None else float(ps.alpha.beta),
            "basis": [int(b) for b in ps.basis if b >= 0],
            "errors": [float(e) for e in ps.errors],
        }
        if st.free_nodes:
            entry["free_nodes"] = True
        arrays = {
            "wrinkles_edges": st.graph.edges.astype("<i4"),
            "wrinkles_rest_lengths": st.graph.rest_lengths.astype("<f8"),
            "wrinkles_handles": st.handles.astype("<i4"),
            "wrinkles_train_features": np.asarray(ps.train_features, "<f8"),
            "wrinkles_train_values": np.asarray(ps.train_values, "<f4"),
        }
        return {"wrinkles": entry}, arrays

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        value = c.key(manifest, "", "wrinkles", None)
        if value is None:
            return {"wrinkles": None}
        f = "wrinkles"
        w = c.obj(value, f)
        examples = []
        for i, ej in enumerate(c.lst(c.key(w, f, "examples"), f"{f}.examples")):
            ef = f"{f}.examples[{i}]"
            ej = c.obj(ej, ef)
            weights = {k: c.number(x, json_path(f"{ef}.weights", k))
                       for k, x in c.obj(c.key(ej, ef, "weights"), f"{ef}.weights").items()}
            examples.append({"name": c.string(c.key(ej, ef, "name"), f"{ef}.name", nonempty=True),
                             "weights": weights})
        mode = c.string(c.key(w, f, "mode"), f"{f}.mode")
        if mode not in ("interp", "lsq"):
            c.expect(f"{f}.mode", "'interp' or 'lsq'", mode)
        beta = c.key(w, f, "beta", None)
        T = len(examples)
        basis = [c.integer(b, f"{f}.basis[{i}]", hi=max(T - 1, 0)) for i, b in enumerate(c.lst(c.key(w, f, "basis"), f"{f}.basis"))]
        return {"wrinkles": {
            "examples": examples,
            "strength": c.number(c.key(w, f, "strength"), f"{f}.strength"),
            "enabled": c.boolean(c.key(w, f, "enabled"), f"{f}.enabled"),
            "weighted": c.boolean(c.key(w, f, "weighted"), f"{f}.weighted"),
            "mode": mode,
            "rcond": c.number(c.key(w, f, "rcond"), f"{f}.rcond"),
            "beta": None if beta is None else c.number(beta, f"{f}.beta"),
            "basis": basis,
            "errors": [c.number(e, f"{f}.errors[{i}]") for i, e in enumerate(c.lst(c.key(w, f, "errors", []), f"{f}.errors"))],
            "free_nodes": c.boolean(c.key(w, f, "free_nodes", False), f"{f}.free_nodes"),
        }}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]:
        w = m["wrinkles"]
        if w is None:
            return {}, set()
        n = m["mesh"]["n_vertices"]
        T = len(w["examples"])
        specs: dict[str, Spec] = {
            "wrinkles_edges": ("<i4", ("F", 2), "(feature edges, 2)"),
            "wrinkles_rest_lengths": ("<f8", ("F",), "(feature edges,) like wrinkles_edges"),
            "wrinkles_handles": ("<i4", ("h",), "(fitted handles,)"),
            "wrinkles_train_features": ("<f8", (T, "F"), "(len(wrinkles.examples), feature edges)"),
            "wrinkles_train_values": ("<f4", (T, n, 3), "(len(wrinkles.examples), mesh.n_vertices, 3)"),
        }
        return specs, set(specs)

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        if m["wrinkles"] is None:
            return
        a = dict(arrays)
        c.in_range(a, "wrinkles_handles", 0, m["mesh"]["n_vertices"] - 1, "vertex ids")
        c.in_range(a, "wrinkles_edges", 0, int(a["wrinkles_handles"].shape[0]) - 1, "indices into wrinkles_handles")
        if a["wrinkles_rest_lengths"].size and a["wrinkles_rest_lengths"].min() <= 0:
            c.fail("arrays.wrinkles_rest_lengths", "rest lengths must be > 0")

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        w = m["wrinkles"]
        if w is None:
            return {}
        from workbench.methods.wrinkles.features import FeatureGraph, edge_weights
        from workbench.methods.wrinkles.pose_space import fit_pose_space

        h = np.asarray(arrays["wrinkles_handles"], np.int32)
        g = FeatureGraph(arrays["wrinkles_edges"], arrays["wrinkles_rest_lengths"])
        V = np.asarray(model.vertices, np.float64)
        alpha = edge_weights(V, V[h], g, beta=w["beta"]) if w["weighted"] else None
        ps = fit_pose_space(arrays["wrinkles_train_features"], arrays["wrinkles_train_values"], alpha=alpha,
                            basis=w["basis"], mode=w["mode"], rcond=w["rcond"])
        ps = dataclasses.replace(ps, errors=tuple(w["errors"]))
        state = WrinkleState(g, h, ps, tuple(e["name"] for e in w["examples"]),
                             tuple(e["weights"] for e in w["examples"]), w["strength"], w["enabled"], w["weighted"],
                             bool(w.get("free_nodes", False)))
        return {"wrinkles": state}


FAMILY = register_family(
    Family(
        name="wrinkles",
        slots=(SlotSpec("wrinkles", lambda m: WrinkleState(), deforms=True, check=check_state),),
        facet=WrinklesFacet,
        layer=WrinkleLayer,
        order=40,
        file_part=WrinklesFilePart(),
    )
)
