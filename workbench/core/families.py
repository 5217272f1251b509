"""The registry of method families: what a method adds to every face model.

A method family (handles, wrinkles, regions, paint, the timeline, and later
rigging, capture, enhancement) lives in its own folder and registers one
:class:`Family` here when its package is imported:

* ``slots`` — the versioned values it keeps in the model's state (each with an
  undoable ``set_slot``, a psygnal event of the same name, and a version
  number the evaluation cache is keyed on);
* ``facet`` — the object hung off the model under the family's name
  (``model.handles``, ``model.regions``…): its undoable edits;
* ``layer`` — its layer in the one evaluation pipeline (:mod:`.pipeline`),
  with ``order`` placing it among the others;
* ``file_part`` — its part of the saved ``.fwb`` file (:class:`FilePart`);
* ``animate`` — how a timeline sample sets its slots (see
  :meth:`FaceState.evaluate_at`).

The state module never imports a family; families import the state (for
types only). Adding a family is a new folder plus one ``register_family``
call, never an edit of :mod:`workbench.core.state`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from workbench.core.manifest import Checker, Spec
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState


@dataclass(frozen=True)
class SlotSpec:
    """One versioned value of the state.

    Parameters
    ----------
    name : str
        Slot name; also the name of its psygnal event (``model.events.<name>``).
    default : callable
        ``default(model) -> value`` at construction.
    deforms : bool
        Whether a change can move the evaluated mesh.
    changing : bool
        Whether it has a ``<name>_changing`` event (edited during interactions).
    check : callable, optional
        ``check(model, value) -> value``: validates (raises ``ModelError`` naming
        what was expected) and normalises a new value before it is installed.
    """

    name: str
    default: Callable[[FaceState], Any]
    deforms: bool = True
    changing: bool = False
    check: Callable[[FaceState, Any], Any] | None = None


class FilePart(Protocol):
    """A family's part of the ``.fwb`` file (the container is :mod:`workbench.fileformat`).

    The part owns some top-level manifest ``keys`` and some arrays. Loading runs
    in phases so that nothing is built before everything is checked: ``check``
    (its JSON, with a :class:`~workbench.core.manifest.Checker`; ``m`` has the
    container's fields and the earlier parts' entries already checked), ``specs``
    (dtype and shape of its arrays, and which must be present), ``check_values``
    (value ranges of its arrays), then ``load`` (slot values to install; raise
    ``ValueError`` for anything still wrong).
    """

    keys: tuple[str, ...]

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]: ...

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]: ...

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]: ...

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None: ...

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]: ...


@dataclass(frozen=True)
class Family:
    """What one method family registers (see the module docstring)."""

    name: str
    slots: tuple[SlotSpec, ...] = ()
    facet: Callable[[FaceState], Any] | None = None
    layer: Callable[[], Any] | None = None  # -> Layer
    order: float = 0.0
    file_part: FilePart | None = None
    #: ``animate(view, sample) -> {slot: value}``: its slots' values at a timeline sample
    #: (``view`` has the sampled weights; ``sample`` is what the ``"sampler"`` hook returned)
    animate: Callable[[StateView, Any], Mapping[str, Any]] | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)


_FAMILIES: dict[str, Family] = {}
_HOOKS: dict[str, Any] = {}


def register_family(family: Family) -> Family:
    """Register (or replace, on module reload) a family; returns it."""
    _FAMILIES[family.name] = family
    return family


def families() -> tuple[Family, ...]:
    """Registered families in layer order (then registration order)."""
    return tuple(sorted(_FAMILIES.values(), key=lambda f: f.order))


def family(name: str) -> Family:
    try:
        return _FAMILIES[name]
    except KeyError:
        raise KeyError(f"no method family {name!r}; registered: {sorted(_FAMILIES)}") from None


def set_hook(name: str, value: Any) -> None:
    """Register a single global service (``"sampler"``, ``"model_class"``) by name."""
    _HOOKS[name] = value


def hook(name: str) -> Any:
    try:
        return _HOOKS[name]
    except KeyError:
        raise LookupError(
            f"nothing registered as {name!r}: import workbench (it registers every family)"
        ) from None
