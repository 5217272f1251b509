"""Registers painterly blending: ``model.expressions`` and ``model.paint``, the paint layer, file parts."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.families import Family, SlotSpec, register_family
from workbench.core.manifest import Checker, Spec, json_path
from workbench.core.shapes import ModelError
from workbench.methods.paint.expressions import Expression, expressions_to_json
from workbench.methods.paint.facet import ExpressionsFacet, PaintFacet, check_mix
from workbench.methods.paint.layer import PaintLayer
from workbench.methods.paint.painting import PaintMix

if TYPE_CHECKING:
    from workbench.core.state import FaceState


def _check_library(model: FaceState, value: Any) -> Mapping[str, Expression]:
    for name, e in value.items():
        if not isinstance(e, Expression) or e.name != name:
            raise ModelError(f"expressions: {name!r} must map to an Expression of that name")
        if e.displacement.shape != (model.n_vertices, 3):
            raise ModelError(f"expression {name!r}: displacement must be ({model.n_vertices}, 3)")
    return value


class ExpressionsFilePart:
    """``expressions: [{"name", "weights", "n_handles"}]`` and the ``expression_*`` arrays."""

    keys: tuple[str, ...] = ("expressions",)

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]:
        lib = model.slot("expressions")
        exprs = list(lib.values())
        n = model.n_vertices
        arrays = {
            "expression_displacements": (
                np.stack([e.displacement for e in exprs]).astype("<f4") if exprs else np.zeros((0, n, 3), "<f4")
            ),
            "expression_handle_vertices": np.concatenate(
                [np.zeros(0, "<i4")] + [e.handle_vertices.astype("<i4") for e in exprs]
            ),
            "expression_handle_offsets": np.concatenate(
                [np.zeros((0, 3), "<f4")] + [e.handle_offsets.astype("<f4") for e in exprs]
            ),
        }
        return {"expressions": expressions_to_json(lib)}, arrays

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        out = []
        seen: set[str] = set()
        for i, ej in enumerate(c.lst(c.key(manifest, "", "expressions", []), "expressions")):
            f = f"expressions[{i}]"
            ej = c.obj(ej, f)
            name = c.string(c.key(ej, f, "name"), f"{f}.name", nonempty=True)
            if name in seen:
                c.fail(f"{f}.name", f"duplicate expression name {name!r}")
            seen.add(name)
            weights = {k: c.number(w, json_path(f"{f}.weights", k))
                       for k, w in c.obj(c.key(ej, f, "weights"), f"{f}.weights").items()}
            out.append({"name": name, "weights": weights,
                        "n_handles": c.integer(c.key(ej, f, "n_handles"), f"{f}.n_handles")})
        return {"expressions": out}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]:
        n = m["mesh"]["n_vertices"]
        E = len(m["expressions"])
        H = sum(e["n_handles"] for e in m["expressions"])
        specs: dict[str, Spec] = {
            "expression_displacements": ("<f4", (E, n, 3), "(len(expressions), mesh.n_vertices, 3)"),
            "expression_handle_vertices": ("<i4", (H,), "(sum of expressions[].n_handles,)"),
            "expression_handle_offsets": ("<f4", (H, 3), "(sum of expressions[].n_handles, 3)"),
        }
        required = {"expression_displacements"} if E else set()
        if H:
            required |= {"expression_handle_vertices", "expression_handle_offsets"}
        return specs, required

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        c.in_range(dict(arrays), "expression_handle_vertices", 0, m["mesh"]["n_vertices"] - 1, "vertex ids")

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        if not m["expressions"]:
            return {}
        n = model.n_vertices
        disp = arrays.get("expression_displacements", np.zeros((0, n, 3), "<f4"))
        hv = arrays.get("expression_handle_vertices", np.zeros(0, "<i4"))
        ho = arrays.get("expression_handle_offsets", np.zeros((0, 3), "<f4"))
        library, start = {}, 0
        for i, ej in enumerate(m["expressions"]):
            stop = start + ej["n_handles"]
            library[ej["name"]] = Expression(ej["name"], disp[i], ej["weights"], hv[start:stop], ho[start:stop])
            start = stop
        return {"expressions": MappingProxyType(library)}


class PaintFilePart:
    """``paint: ["smile", ...]`` and ``paint_maps`` (P, n) <f4 in that order."""

    keys: tuple[str, ...] = ("paint",)

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]:
        mix = model.slot("paint_layers")
        n = model.n_vertices
        maps = np.stack([mix[k] for k in mix]).astype("<f4") if len(mix) else np.zeros((0, n), "<f4")
        return {"paint": list(mix)}, {"paint_maps": maps}

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        paint = c.strings(c.key(manifest, "", "paint", []), "paint", unique=True)
        known = {e["name"] for e in m["expressions"]} | {s["name"] for s in m["shapes"]}
        for i, p in enumerate(paint):
            if p not in known:
                c.fail(f"paint[{i}]", f"paints {p!r}, which is neither a saved expression nor a shape")
        return {"paint": paint}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]:
        P = len(m["paint"])
        spec: Spec = ("<f4", (P, m["mesh"]["n_vertices"]), "(len(paint), mesh.n_vertices)")
        return {"paint_maps": spec}, {"paint_maps"} if P else set()

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        pm = arrays.get("paint_maps")
        if pm is not None and pm.size:
            if pm.min() < 0.0 or pm.max() > 1.0:
                c.fail("arrays.paint_maps", "values must be in [0, 1]")
            if pm.sum(axis=0, dtype=np.float64).max() > 1.0 + 1e-3:
                c.fail("arrays.paint_maps", "painted weights must sum to <= 1 at every vertex")

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        if not m["paint"]:
            return {}
        pm = arrays["paint_maps"]
        maps = {p: pm[i].copy() for i, p in enumerate(m["paint"])}
        for w in maps.values():
            w.setflags(write=False)
        return {"paint_layers": PaintMix(maps)}


EXPRESSIONS = register_family(
    Family(
        name="expressions",
        slots=(SlotSpec("expressions", lambda m: MappingProxyType({}), deforms=True, check=_check_library),),
        facet=ExpressionsFacet,
        order=29,
        file_part=ExpressionsFilePart(),
    )
)

PAINT = register_family(
    Family(
        name="paint",
        slots=(SlotSpec("paint_layers", lambda m: PaintMix(), deforms=True, changing=True, check=check_mix),),
        facet=PaintFacet,
        layer=PaintLayer,
        order=30,
        tab="widgets.tabs.paint",
        viewport="widgets.panels.paint_tool",
        recipe_slots=lambda slots: {"paint_layers": PaintMix()},  # a recipe paints nothing
        file_part=PaintFilePart(),
    )
)
