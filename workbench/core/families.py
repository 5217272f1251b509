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
  :meth:`FaceState.evaluate_at`);
* ``tab`` — optionally, the module (in a UI package) that registers its tab of
  the Workbench (:mod:`widgets.tabs`);
* ``viewport`` — optionally, the module (in a UI package) that registers its
  viewport tools (:mod:`widgets.viewport.tools`: what the pointer does, the
  markers and surface tint it draws);
* ``tracks`` — the timeline tracks it keys (:class:`TrackSpec`: value shape,
  title, what keying it now records); its ``animate`` reads them from the
  sample (``sample.others``); ``check_tracks`` checks its tracks together (the
  timeline itself knows only weights and the head pose);
* ``weight_products`` — shapes whose weight is not set or keyed but derived:
  the product of other shapes' weights (combination / corrective shapes,
  :class:`WeightProducts`). :func:`derive_weights` applies every family's
  rules; the state view (:class:`~workbench.core.pipeline.StateView`), so the
  blend, every layer and every exporter, and ``model.weights`` go through it,
  and the blend's cache key includes the rules' slots (:func:`weight_product_reads`).

The state module never imports a family; families import the state (for
types only). Adding a family is a new folder plus one ``register_family``
call, never an edit of :mod:`workbench.core.state` or of a list elsewhere:
:func:`discover` (run before the first model is made) imports the ``family``
module of every package of ``workbench`` and of ``workbench.methods``, and
every module another installed package names in the entry-point group
:data:`ENTRY_POINT_GROUP` (``[project.entry-points."face_workbench.families"]
my_family = "my_package.family"`` in its ``pyproject.toml``).
"""

from __future__ import annotations

import importlib
import importlib.metadata
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from workbench.core.manifest import Checker, Spec
    from workbench.core.pipeline import StateView
    from workbench.core.shapes import BlendShape
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
class WeightProducts:
    """Shape weights a family derives: each the product of other shapes' weights.

    ``rules(slots) -> {shape: (driver, ...)}`` reads only the slots named in
    ``reads`` (the blend is cached on their versions). A derived shape plays
    ``clamp(prod_d w_d)`` into its own slider range, with ``w_d`` each driver's
    weight as played (clamped; 0 when the driver is muted or missing); its own
    stored or keyed weight is ignored. Drivers must not be derived themselves
    (the family checks that), so the order of the rules does not matter.
    """

    reads: tuple[str, ...]
    rules: Callable[[Mapping[str, Any]], Mapping[str, tuple[str, ...]]]


@dataclass(frozen=True)
class TrackSpec:
    """One kind of timeline track a family keys (a name, or names under a prefix).

    Parameters
    ----------
    value_shape : callable
        ``value_shape(model, track) -> shape`` of a key's value on ``model``;
        raises ``ModelError`` (saying what is expected) when the model cannot
        take ``track``.
    title : callable, optional
        ``title(track) -> str``: a short name for undo labels and timeline rows
        (default: the track name).
    current : callable, optional
        ``current(model, track) -> value``: what keying the track "now" records
        (the model's current value, e.g. the handle offsets); without it, the
        value the track has at the model's time.
    """

    value_shape: Callable[[FaceState, str], tuple[int, ...]]
    title: Callable[[str], str] | None = None
    current: Callable[[FaceState, str], Any] | None = None


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
    #: optional: shapes whose weight is the product of other weights (see :class:`WeightProducts`)
    weight_products: WeightProducts | None = None
    #: timeline tracks it keys: ``{name: TrackSpec}`` (a name ending in "/" is a prefix; a bare
    #: ``value_shape`` callable stands for ``TrackSpec(value_shape)``)
    tracks: Mapping[str, TrackSpec | Callable[[FaceState, str], tuple[int, ...]]] = field(default_factory=dict)
    #: optional: ``check_tracks(model, {name: Track})`` checks its keyed tracks together (e.g. all
    #: on one level); raises ``ModelError``
    check_tracks: Callable[[FaceState, Mapping[str, Any]], None] | None = None
    #: optional: the module that registers its Workbench tab (imported by the widgets, never by the core)
    tab: str = ""
    #: optional: the module that registers its viewport tools (imported by the widgets, never by the core)
    viewport: str = ""
    #: optional: ``recipe_slots(slots) -> {slot: value}``: its slots as a saved expression's recipe
    #: (weights and handle offsets) plays back, without the edits a recipe does not record
    recipe_slots: Callable[[Mapping[str, Any]], Mapping[str, Any]] | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)


_FAMILIES: dict[str, Family] = {}
_HOOKS: dict[str, Any] = {}
_PRODUCTS: tuple[WeightProducts, ...] = ()
_ORDERED: tuple[Family, ...] = ()  # _FAMILIES in layer order, made again on every registration
_OWNERS: dict[str, tuple[Family, TrackSpec] | None] = {}  # track name -> its family, cleared likewise

#: the entry-point group in which other packages name the module that registers their family
ENTRY_POINT_GROUP = "face_workbench.families"
#: packages whose sub-packages may hold a ``family`` module
_FAMILY_ROOTS = ("workbench", "workbench.methods")
_discovered = False


def discover() -> None:
    """Import every family module once (see the module docstring); later calls do nothing.

    Only packages that have a ``family.py`` are imported, so discovery does not
    pull in the I/O, export or batch packages. A declared module that fails to
    import raises, naming the entry point.
    """
    global _discovered
    if _discovered:
        return
    _discovered = True  # first: family modules may call families() while importing
    for root in _FAMILY_ROOTS:
        package = importlib.import_module(root)
        for folder in sorted(Path(p) for p in package.__path__):
            for sub in sorted(folder.iterdir()):
                if (sub / "__init__.py").is_file() and (sub / "family.py").is_file():
                    importlib.import_module(f"{root}.{sub.name}.family")
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            importlib.import_module(ep.value)
        except Exception as exc:
            raise ImportError(f"method family {ep.name!r} ({ENTRY_POINT_GROUP} entry point of "
                              f"{ep.dist.name if ep.dist else 'a package'}): cannot import {ep.value!r}: {exc}") from exc


def register_family(family: Family) -> Family:
    """Register (or replace, on module reload) a family; returns it."""
    global _PRODUCTS, _ORDERED
    _FAMILIES[family.name] = family
    _ORDERED = tuple(sorted(_FAMILIES.values(), key=lambda f: f.order))
    _OWNERS.clear()
    _PRODUCTS = tuple(f.weight_products for f in _ORDERED if f.weight_products is not None)
    return family


def families() -> tuple[Family, ...]:
    """Registered families in layer order (then registration order); discovers them first."""
    discover()
    return _ORDERED


def family(name: str) -> Family:
    discover()
    try:
        return _FAMILIES[name]
    except KeyError:
        raise KeyError(f"no method family {name!r}; registered: {sorted(_FAMILIES)}") from None


def track_owner(track: str) -> tuple[Family, TrackSpec] | None:
    """The family keying ``track`` and its :class:`TrackSpec` (None: no family keys it)."""
    fams = families()
    if track not in _OWNERS:
        _OWNERS[track] = next(
            ((f, spec if isinstance(spec, TrackSpec) else TrackSpec(spec))
             for f in fams for name, spec in f.tracks.items()
             if track == name or (name.endswith("/") and track.startswith(name))),
            None,
        )
    return _OWNERS[track]


def track_value_shape(model: FaceState, track: str) -> tuple[int, ...] | None:
    """The value shape a family gives ``track`` on ``model`` (None: no family keys it)."""
    owner = track_owner(track)
    return None if owner is None else tuple(owner[1].value_shape(model, track))


def family_track_title(track: str) -> str:
    """A family track's short name (its :attr:`TrackSpec.title`, else the track name)."""
    owner = track_owner(track)
    return track if owner is None or owner[1].title is None else owner[1].title(track)


def check_family_tracks(model: FaceState, tracks: Mapping[str, Any]) -> None:
    """Run every family's ``check_tracks`` on the tracks it keys (``ModelError`` when they do not fit)."""
    mine: dict[str, dict[str, Any]] = {}
    for name, tr in tracks.items():
        owner = track_owner(name)
        if owner is not None:
            mine.setdefault(owner[0].name, {})[name] = tr
    for fam_name, own in mine.items():
        check = _FAMILIES[fam_name].check_tracks
        if check is not None:
            check(model, own)


def track_names() -> list[str]:
    """Every registered track name (prefixes end in "/")."""
    return [name for f in families() for name in f.tracks]


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


# ------------------------------------------------------------------ derived weights
def weight_product_reads() -> tuple[str, ...]:
    """Slots the registered weight-product rules read (part of the blend's cache key)."""
    return tuple(r for p in _PRODUCTS for r in p.reads)


def weight_products(slots: Mapping[str, Any]) -> dict[str, tuple[str, ...]]:
    """Every registered rule for the given slot values: ``{derived shape: (driver, ...)}``."""
    out: dict[str, tuple[str, ...]] = {}
    for p in _PRODUCTS:
        if all(r in slots for r in p.reads):
            out.update(p.rules(slots))
    return out


def derive_weights(
    shapes: Iterable[BlendShape], weights: Mapping[str, Any], slots: Mapping[str, Any]
) -> dict[str, Any]:
    """``weights`` with every derived shape's weight replaced by the product of its drivers'.

    ``weights`` are clamped weights by shape name: floats (one state) or (F,)
    float64 arrays (F frames, :class:`workbench.export.encoding.MeshEncoding`);
    both go through the same operations in the same order, so a frame of an
    export and :meth:`FaceState.evaluate_at` agree bit for bit. A muted driver
    counts as 0 (it plays nothing, so neither does its combination).
    """
    out = dict(weights)
    rules = weight_products(slots) if _PRODUCTS else {}
    if not rules:
        return out
    by_name = {s.name: s for s in shapes}
    for name, drivers in rules.items():
        s = by_name.get(name)
        if s is None or name not in out:
            continue
        w: Any = 1.0
        for d in drivers:
            ds = by_name.get(d)
            w = w * (0.0 if ds is None or ds.mute else weights.get(d, 0.0))
        if isinstance(w, np.ndarray):
            out[name] = np.clip(w, s.slider_min, s.slider_max)
        else:
            out[name] = min(max(float(w), s.slider_min), s.slider_max)
    return out
