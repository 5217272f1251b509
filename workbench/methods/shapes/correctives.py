"""Corrective (combination) shapes: a shape whose weight is the product of its drivers' weights.

Blender's corrective shape keys (a driver multiplying two shape-key values)
and Maya's combination shapes fix what two expressions get wrong together:
``jawOpen`` with ``mouthSmileLeft`` stretches the lip corner, so a corrective
``jawOpen_mouthSmileLeft`` adds the fix at weight ``w_jawOpen · w_mouthSmileLeft``
— nothing when either is at rest, all of it when both are at 1.

Where they live
---------------
The corrective's delta is an ordinary shape of the model's shape stack
(sculpted, masked, muted, saved and exported like any other); what makes it a
corrective is a rule ``name -> (driver, ...)`` in the ``correctives`` slot of
the shape-tools family (a :class:`Correctives` value, immutable, undoable).
The family registers the rules with the core as
:class:`workbench.core.families.WeightProducts`, and the core applies them in
one place, :func:`workbench.core.families.derive_weights`, when a state view is
made: so the blend of ``evaluate()``, ``evaluate_at(t)`` (the corrective
follows its drivers' *keyed* weights), every layer that reads weights, the
viewport and ``model.weights`` all see ``clamp(∏ w_d)`` for the corrective,
whatever weight was set or keyed for it. Exporters get the same weights from
:meth:`workbench.export.encoding.MeshEncoding.weights` (the same function over
all frames at once).

A rule is checked when set (its shapes exist, at least two different drivers,
none of them a corrective itself, no shape driving itself). Removing or renaming a
driver through the core's shape edits leaves the rule dangling: a missing
driver counts as weight 0 (the corrective plays nothing) and the rule comes
back to life with an undo; files store only rules whose shapes all exist.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from workbench.core.shapes import ModelError

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["Correctives", "check_correctives", "corrective_rules", "normalize_drivers"]


@dataclass(frozen=True, eq=False)
class Correctives(Mapping[str, tuple[str, ...]]):
    """Corrective shape name -> its drivers (immutable; an edit makes a new value)."""

    rules: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "rules", MappingProxyType({str(k): tuple(str(d) for d in v) for k, v in self.rules.items()})
        )

    def __getitem__(self, name: str) -> tuple[str, ...]:
        return self.rules[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.rules)

    def __len__(self) -> int:
        return len(self.rules)

    def __repr__(self) -> str:
        return "Correctives({" + ", ".join(f"{k!r}: {' × '.join(v)}" for k, v in self.rules.items()) + "})"

    def with_rule(self, name: str, drivers: Iterable[str]) -> Correctives:
        return Correctives({**self.rules, name: tuple(drivers)})

    def without(self, name: str) -> Correctives:
        return Correctives({k: v for k, v in self.rules.items() if k != name})

    def driven_by(self, shape: str) -> list[str]:
        """Correctives that ``shape`` drives."""
        return [k for k, v in self.rules.items() if shape in v]


def normalize_drivers(name: str, drivers: Any, what: str = "drivers") -> tuple[str, ...]:
    """``drivers`` as a tuple of names; raises :class:`ModelError` naming the argument."""
    if isinstance(drivers, str) or not isinstance(drivers, Iterable):
        raise ModelError(f"{what} of {name!r} must be a list of two or more shape names, got {drivers!r}")
    out = tuple(drivers)
    if not all(isinstance(d, str) for d in out):
        raise ModelError(f"{what} of {name!r} must be shape names (strings), got {list(out)!r}")
    if len(out) < 2:
        raise ModelError(f"{what} of {name!r} must name two or more shapes (the weight is their product), got {list(out)}")
    if len(set(out)) != len(out):
        raise ModelError(f"{what} of {name!r} must name different shapes, got {list(out)}")
    if name in out:
        raise ModelError(f"{what} of {name!r}: a corrective cannot drive itself")
    return out


def check_rules(rules: Mapping[str, tuple[str, ...]], shape_names: Iterable[str]) -> None:
    """Raise :class:`ModelError` unless every rule is well formed over ``shape_names``."""
    names = set(shape_names)
    for name, drivers in rules.items():
        if name not in names:
            raise ModelError(f"corrective {name!r}: no blendshape of that name")
        normalize_drivers(name, drivers)
        missing = [d for d in drivers if d not in names]
        if missing:
            raise ModelError(f"drivers of {name!r}: no blendshape named {missing[0]!r}")
        nested = [d for d in drivers if d in rules]
        if nested:
            raise ModelError(f"drivers of {name!r}: {nested[0]!r} is a corrective itself (drive it by its drivers)")


def check_correctives(model: FaceState, value: Any) -> Correctives:
    """Slot check: a :class:`Correctives` (or mapping) whose rules fit the model's shapes."""
    if isinstance(value, Mapping) and not isinstance(value, Correctives):
        value = Correctives(dict(value))
    if not isinstance(value, Correctives):
        raise ModelError(f"correctives: expected a Correctives mapping, got {type(value).__name__}")
    check_rules(value, model.shape_names)
    return value


def corrective_rules(slots: Mapping[str, Any]) -> Mapping[str, tuple[str, ...]]:
    """The weight-product rules the core applies (:class:`workbench.core.families.WeightProducts`)."""
    value = slots["correctives"]
    return value.rules if isinstance(value, Correctives) else {}
