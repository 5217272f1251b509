"""Registers the shape tools: the ``correctives`` slot, ``model.shape_tools``, the weight rules, the file part.

The corrective rules reach the evaluation through the core's one registration
point for derived weights (:class:`workbench.core.families.WeightProducts`):
no layer, no hook in the state module (see :mod:`.correctives`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from workbench.core.families import Family, SlotSpec, WeightProducts, register_family
from workbench.core.manifest import Checker, Spec
from workbench.methods.shapes.correctives import (
    Correctives,
    check_correctives,
    corrective_rules,
    normalize_drivers,
)
from workbench.methods.shapes.facet import ShapeToolsFacet

if TYPE_CHECKING:
    from workbench.core.state import FaceState


class CorrectivesFilePart:
    """``correctives: [{"name": "jawOpen_mouthSmileLeft", "drivers": ["jawOpen", "mouthSmileLeft"]}]``; no arrays.

    The corrective's delta is an ordinary saved shape. Files without the key
    (every file written before this release) have no correctives. Only rules
    whose shapes all exist are written (a driver removed by a plain
    ``remove_shape`` leaves its rule dangling in the live model).
    """

    keys: tuple[str, ...] = ("correctives",)

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]:
        names = set(model.shape_names)
        rules = [
            {"name": k, "drivers": list(v)}
            for k, v in model.slot("correctives").items()
            if k in names and all(d in names for d in v)
        ]
        return {"correctives": rules}, {}

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        shapes = {s["name"] for s in m["shapes"]}
        out: dict[str, tuple[str, ...]] = {}
        entries = c.lst(c.key(manifest, "", "correctives", []), "correctives")
        for i, ej in enumerate(entries):
            f = f"correctives[{i}]"
            ej = c.obj(ej, f)
            name = c.string(c.key(ej, f, "name"), f"{f}.name", nonempty=True)
            drivers = c.strings(c.key(ej, f, "drivers"), f"{f}.drivers", unique=True)
            if name not in shapes:
                c.fail(f"{f}.name", f"{name!r} is not a saved shape")
            if name in out:
                c.fail(f"{f}.name", f"duplicate corrective {name!r}")
            for j, d in enumerate(drivers):
                if d not in shapes:
                    c.fail(f"{f}.drivers[{j}]", f"{d!r} is not a saved shape")
            try:
                normalize_drivers(name, drivers)
            except ValueError as exc:
                c.fail(f"{f}.drivers", str(exc))
            out[name] = tuple(str(d) for d in drivers)
        for i, rule in enumerate(out.values()):
            nested = [d for d in rule if d in out]
            if nested:
                c.fail(f"correctives[{i}].drivers", f"{nested[0]!r} is a corrective itself")
        return {"correctives": out}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]:
        return {}, set()

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        return None

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        rules = m["correctives"]
        return {"correctives": Correctives(rules)} if rules else {}


FAMILY = register_family(
    Family(
        name="shape_tools",
        slots=(SlotSpec("correctives", lambda m: Correctives(), deforms=True, check=check_correctives),),
        facet=ShapeToolsFacet,
        order=5,
        tab="widgets.tabs.shapes",
        file_part=CorrectivesFilePart(),
        weight_products=WeightProducts(reads=("correctives",), rules=corrective_rules),
    )
)
