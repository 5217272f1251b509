"""Rigging one face, stage by stage, with undo: the state behind the Rig tab (issue 16).

A :class:`RigSession` holds a template rig and the face to rig, the landmark
pairs and the example poses the user gives, and the result of each stage:

1. :meth:`~RigSession.transfer` — :class:`~workbench.rigging.RigTransfer`
   (alignment, non-rigid fit, correspondence, deformation transfer of every
   template shape onto the target's own topology), with its quality report;
2. :meth:`~RigSession.refine` — :func:`~workbench.rigging.refine_rig` from the
   examples and their rough weights (Li et al. 2010 §3);
3. :meth:`~RigSession.carry_details` — the template's wrinkle examples carried
   through the correspondence and fitted on the rig
   (:func:`~workbench.rigging.transfer_details`, Bickel et al. 2008 §5.4).

Every edit — a landmark pair added or removed, an example or a rough weight
changed, a stage run — replaces one immutable :class:`RigState` and is one
undo step on the session's own :class:`~workbench.core.history.History`, so a
stage is undone as a whole (its later stages with it: rerunning the transfer
drops the refinement made from the old one, in the same step). Views listen to
:attr:`RigSession.events` and change the session only through its methods.

Landmarks are mirror-aware: :meth:`~RigSession.add_landmark` with
``mirror=True`` also adds the pair's mirror image (each vertex's nearest
reflected vertex about its mesh's mid-plane, on the subject's left/right axis
from the model's ``up_axis`` / ``front_axis``) unless both lie on the mid-plane.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from psygnal import Signal, SignalGroup

from workbench.core.families import families
from workbench.core.history import Command, History, payload_nbytes
from workbench.core.shapes import UNIT_TO_METRES
from workbench.geometry.masks import skin_or_all_mask
from workbench.methods.shapes.symmetry import lateral_axis, nearest_reflected
from workbench.model import FaceModel
from workbench.rigging.report import TransferReport
from workbench.rigging.transfer import RigTransfer

if TYPE_CHECKING:
    from workbench.rigging.refine import RefineResult

__all__ = ["STAGES", "RigExample", "RigSession", "RigState"]

logger = logging.getLogger(__name__)

Progress = Callable[[float, str], None] | None

#: the stages, in order
STAGES = ("transfer", "refine", "details")


@dataclass(frozen=True, eq=False)
class RigExample:
    """One example pose of the face to rig.

    Attributes
    ----------
    name : str
    vertices : (n, 3) float64
        The pose in the target's topology and units (read-only).
    weights : dict of str to float
        The user's rough guess of the template shapes it shows (missing = 0).
    """

    name: str
    vertices: NDArray[np.float64]
    weights: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class RigState:
    """Everything a :class:`RigSession` has at one point of its history (immutable).

    Attributes
    ----------
    landmarks : tuple of (template_vertex, target_vertex)
    examples : tuple of RigExample
    transfer : RigTransfer or None
        The set-up of the last transfer (its correspondence carries details).
    transferred : FaceModel or None
        The rig the transfer made.
    report : TransferReport or None
    transfer_landmarks : tuple
        The landmarks the transfer used (the transfer is stale when they differ).
    refined : RefineResult or None
    refine_examples : tuple of RigExample
        The examples the refinement used.
    detailed : FaceModel or None
        The rig with the template's wrinkle details fitted.
    """

    landmarks: tuple[tuple[int, int], ...] = ()
    examples: tuple[RigExample, ...] = ()
    transfer: RigTransfer | None = None
    transferred: FaceModel | None = None
    report: TransferReport | None = None
    transfer_landmarks: tuple[tuple[int, int], ...] = ()
    refined: RefineResult | None = None
    refine_examples: tuple[RigExample, ...] = ()
    detailed: FaceModel | None = None


class RigSessionEvents(SignalGroup):
    """``landmarks``, ``examples``, ``stages`` (a stage ran or was undone) and ``history``."""

    landmarks = Signal()
    examples = Signal()
    stages = Signal()
    history = Signal()


def copy_model(model: FaceModel) -> FaceModel:
    """A new model with ``model``'s mesh, shapes, weights, metadata and every family's slots (no history)."""
    slots = {spec.name: model.slot(spec.name) for fam in families() for spec in fam.slots}
    return type(model)(
        model.vertices, model.faces, list(model.shapes), polygons=model.polygons,
        component_labels=model.component_labels, component_names=model.component_names,
        metadata=model.metadata, weights=dict(model.weights), **slots,
    )


class RigSession:
    """Rig ``target`` from ``template``: landmarks, examples and the three stages, each one undo step.

    Parameters
    ----------
    template : FaceModel
        The template rig (its shapes are transferred), e.g. ``workbench.load_sample("head")``.
    target : FaceModel or path
        The face to rig (a path is read with :func:`workbench.load`).
    max_undo : int
        Undo steps kept.

    Attributes
    ----------
    template, target : FaceModel
        Never modified.
    events : RigSessionEvents
    history : History
    """

    def __init__(self, template: FaceModel, target: FaceModel | str | PathLike[str], *, max_undo: int = 64) -> None:
        if not isinstance(template, FaceModel):
            raise TypeError(f"RigSession: template must be a FaceModel, got {type(template).__name__}")
        if not isinstance(target, FaceModel):
            if not isinstance(target, str | PathLike):
                raise TypeError(f"RigSession: target must be a FaceModel or a path, got {type(target).__name__}")
            from workbench.io import load

            target = load(target)
        if not template.shapes:
            raise ValueError(f"RigSession: the template {template.metadata.name or 'model'} has no blendshapes")
        self.template = template
        self.target = target
        self.events = RigSessionEvents()
        self.history = History(max_steps=max_undo, max_bytes=2**31)
        self._state = RigState()
        self._mirror: dict[str, NDArray[np.int64]] = {}

    # ------------------------------------------------------------------ reading
    @property
    def state(self) -> RigState:
        return self._state

    @property
    def landmarks(self) -> tuple[tuple[int, int], ...]:
        return self._state.landmarks

    @property
    def examples(self) -> tuple[RigExample, ...]:
        return self._state.examples

    @property
    def example_names(self) -> list[str]:
        return [e.name for e in self._state.examples]

    def example(self, name: str) -> RigExample:
        for e in self._state.examples:
            if e.name == name:
                return e
        raise KeyError(f"no example {name!r} (the session has {self.example_names})")

    @property
    def report(self) -> TransferReport | None:
        """The last transfer's quality report."""
        return self._state.report

    @property
    def refined(self) -> RefineResult | None:
        return self._state.refined

    @property
    def stages_done(self) -> tuple[str, ...]:
        """The stages whose result the session holds, in order."""
        s = self._state
        done = [name for name, v in zip(STAGES, (s.transferred, s.refined, s.detailed), strict=True) if v is not None]
        return tuple(done)

    @property
    def stale(self) -> tuple[str, ...]:
        """Stages whose inputs changed since they ran (landmarks after the transfer, examples after the refinement)."""
        s = self._state
        out = []
        if s.transferred is not None and s.landmarks != s.transfer_landmarks:
            out.append("transfer")
        if s.refined is not None and _examples_key(s.examples) != _examples_key(s.refine_examples):
            out.append("refine")
        return tuple(out)

    @property
    def rig(self) -> FaceModel | None:
        """The latest stage's rig (details, else refined, else transferred), or None before the transfer.

        The session's own copy: use :meth:`result` for a model to edit.
        """
        s = self._state
        if s.detailed is not None:
            return s.detailed
        if s.refined is not None:
            return s.refined.model
        return s.transferred

    def result(self) -> FaceModel:
        """A copy of :attr:`rig` to open and edit (the session keeps its own)."""
        rig = self.rig
        if rig is None:
            raise RuntimeError("RigSession: no rig yet; run transfer() first")
        return copy_model(rig)

    # ------------------------------------------------------------------ undo
    @property
    def can_undo(self) -> bool:
        return self.history.can_undo

    @property
    def can_redo(self) -> bool:
        return self.history.can_redo

    def undo(self) -> str | None:
        """Undo the last step; returns its label (None when there is nothing to undo)."""
        cmd = self.history.undo()
        if cmd is not None:
            self.events.history.emit()
        return None if cmd is None else cmd.label

    def redo(self) -> str | None:
        cmd = self.history.redo()
        if cmd is not None:
            self.events.history.emit()
        return None if cmd is None else cmd.label

    def _commit(self, label: str, new: RigState) -> None:
        old = self._state
        if _same(new, old):
            return
        self.history.push(Command(label, lambda: self._set(old, new), lambda: self._set(new, old),
                                  _state_nbytes(new, old)))
        self._set(new, old)
        self.events.history.emit()

    def _set(self, new: RigState, old: RigState) -> None:
        self._state = new
        if new.landmarks != old.landmarks:
            self.events.landmarks.emit()
        if new.examples != old.examples:
            self.events.examples.emit()
        if any(getattr(new, f) is not getattr(old, f) for f in ("transferred", "refined", "detailed")):
            self.events.stages.emit()

    # ------------------------------------------------------------------ landmarks
    def mirror_vertex(self, side: str, vertex: int) -> int:
        """The vertex of the ``"template"`` or ``"target"`` mesh nearest the mirror image of ``vertex``."""
        model = self._side(side)
        m = self._mirror.get(side)
        if m is None:
            m = _mirror_map(model)
            self._mirror[side] = m
        return int(m[self._check_vertex(side, vertex)])

    def _side(self, side: str) -> FaceModel:
        if side == "template":
            return self.template
        if side == "target":
            return self.target
        raise ValueError(f"side must be 'template' or 'target', got {side!r}")

    def _check_vertex(self, side: str, vertex: Any) -> int:
        n = self._side(side).n_vertices
        try:
            v = int(vertex)
        except (TypeError, ValueError):
            raise ValueError(f"{side} vertex must be an integer, got {vertex!r}") from None
        if v != vertex or not 0 <= v < n:
            raise ValueError(f"{side} vertex must be an integer in 0..{n - 1}, got {vertex!r}")
        return v

    def add_landmark(self, template_vertex: int, target_vertex: int, *, mirror: bool = False) -> int:
        """Add the pair (and with ``mirror``, its mirror image); returns how many pairs were added.

        A pair whose template vertex already has a partner replaces it.
        """
        a = self._check_vertex("template", template_vertex)
        b = self._check_vertex("target", target_vertex)
        pairs = [(a, b)]
        if mirror:
            ma, mb = self.mirror_vertex("template", a), self.mirror_vertex("target", b)
            if ma != a:
                pairs.append((ma, mb))
        new_src = {p[0] for p in pairs}
        kept = tuple(p for p in self._state.landmarks if p[0] not in new_src)
        label = f"Landmark {a} \u2194 {b}" + (" (mirrored)" if len(pairs) == 2 else "")
        self._commit(label, dataclasses.replace(self._state, landmarks=kept + tuple(pairs)))
        return len(pairs)

    def set_landmarks(self, pairs: Sequence[tuple[int, int]], label: str = "Set landmarks") -> None:
        """Replace every landmark pair (one undo step)."""
        checked: dict[int, tuple[int, int]] = {}
        for i, p in enumerate(pairs):
            try:
                a, b = p
            except (TypeError, ValueError):
                raise ValueError(f"landmarks[{i}]: expected (template_vertex, target_vertex), got {p!r}") from None
            checked[self._check_vertex("template", a)] = (int(a), self._check_vertex("target", b))
        self._commit(label, dataclasses.replace(self._state, landmarks=tuple(checked.values())))

    def remove_landmark(self, index: int) -> None:
        """Remove pair ``index`` (one undo step)."""
        lm = self._state.landmarks
        if not -len(lm) <= index < len(lm):
            raise IndexError(f"no landmark {index} (the session has {len(lm)})")
        i = index % len(lm)
        a, b = lm[i]
        self._commit(f"Remove landmark {a} \u2194 {b}", dataclasses.replace(self._state, landmarks=lm[:i] + lm[i + 1:]))

    def move_landmark(self, index: int, side: str, vertex: int) -> None:
        """Give pair ``index`` another ``"template"`` or ``"target"`` vertex (one undo step).

        On the template side, a pair already holding that vertex is dropped.
        """
        lm = self._state.landmarks
        if not -len(lm) <= index < len(lm):
            raise IndexError(f"no landmark {index} (the session has {len(lm)})")
        i = index % len(lm)
        v = self._check_vertex(side, vertex)
        a, b = lm[i]
        pair = (v, b) if side == "template" else (a, v)
        if pair == (a, b):
            return
        new = tuple(pair if j == i else p for j, p in enumerate(lm) if j == i or p[0] != pair[0])
        self._commit(f"Move landmark {i + 1} ({side})", dataclasses.replace(self._state, landmarks=new))

    def clear_landmarks(self) -> None:
        if self._state.landmarks:
            self._commit("Clear landmarks", dataclasses.replace(self._state, landmarks=()))

    def suggest_landmarks(self, *, progress: Progress = None) -> int:
        """Add automatic landmark pairs (named template points, placed where the fit puts them); one undo step.

        Pairs the user already gave are kept. Returns how many were added.
        """
        from workbench.rigging.landmarks import suggest_landmarks

        rt = self._setup(progress)
        have = {a for a, _ in self._state.landmarks}
        new = tuple((s.source_vertex, s.target_vertex) for s in suggest_landmarks(rt) if s.source_vertex not in have)
        if new:
            self._commit(f"Suggest {len(new)} landmarks",
                         dataclasses.replace(self._state, landmarks=self._state.landmarks + new))
        return len(new)

    # ------------------------------------------------------------------ examples
    def add_example(
        self,
        pose: ArrayLike | FaceModel | str | PathLike[str],
        weights: Mapping[str, float] | None = None,
        *,
        name: str | None = None,
    ) -> str:
        """Add an example pose (vertices in the target's topology, a model or a file); returns its name.

        A model or file in other units is scaled to the target's.
        """
        if isinstance(pose, str | PathLike):
            from workbench.io import load

            path = pose
            pose = load(path)
            name = name or pose.metadata.name or str(path)
        if isinstance(pose, FaceModel):
            scale = UNIT_TO_METRES[pose.metadata.units] / UNIT_TO_METRES[self.target.metadata.units]
            name = name or pose.metadata.name or None
            X = np.asarray(pose.vertices, np.float64) * scale
        else:
            X = np.array(pose, dtype=np.float64)
        n = self.target.n_vertices
        if X.shape != (n, 3):
            raise ValueError(f"example {name or ''}: expected ({n}, 3) vertices in the target's topology, got {X.shape}")
        if not np.isfinite(X).all():
            raise ValueError(f"example {name or ''}: vertices must be finite")
        X.setflags(write=False)
        taken = set(self.example_names)
        if name is None or name in taken:
            base = name or "example"
            i = 1
            while f"{base} {i}" in taken:
                i += 1
            name = f"{base} {i}"
        ex = RigExample(name, X, self._check_weights(weights or {}, name))
        self._commit(f"Add example {name}", dataclasses.replace(self._state, examples=(*self._state.examples, ex)))
        return name

    def _check_weights(self, weights: Mapping[str, float], what: str) -> dict[str, float]:
        names = set(self.template.shape_names)
        out: dict[str, float] = {}
        for k, v in weights.items():
            if k not in names:
                raise ValueError(f"example {what}: no template shape {k!r}")
            fv = float(v)
            if not np.isfinite(fv):
                raise ValueError(f"example {what}: weight of {k!r} must be finite, got {v!r}")
            out[str(k)] = fv
        return out

    def remove_example(self, name: str) -> None:
        self.example(name)
        self._commit(f"Remove example {name}", dataclasses.replace(
            self._state, examples=tuple(e for e in self._state.examples if e.name != name)))

    def set_example_weights(self, name: str, weights: Mapping[str, float], *, replace: bool = False) -> None:
        """Set rough weights of example ``name`` (merged into its others unless ``replace``); one undo step.

        A weight of 0 removes the shape from the example's guess.
        """
        ex = self.example(name)
        new = {} if replace else dict(ex.weights)
        new.update(self._check_weights(weights, name))
        new = {k: v for k, v in new.items() if v != 0.0}
        label = f"Weights of {name}" if len(weights) != 1 else f"{name}: {next(iter(weights))}"
        exs = tuple(dataclasses.replace(e, weights=new) if e.name == name else e for e in self._state.examples)
        self._commit(label, dataclasses.replace(self._state, examples=exs))

    # ------------------------------------------------------------------ stages
    def _setup(self, progress: Progress) -> RigTransfer:
        s = self._state
        if s.transfer is not None and s.transfer_landmarks == s.landmarks:
                return s.transfer
        return RigTransfer(self.template, self.target, landmarks=list(s.landmarks) or None, progress=progress)

    def transfer(self, *, progress: Progress = None) -> TransferReport:
        """Stage 1: transfer the template's shapes with the current landmarks (one undo step).

        Drops a refinement and details made from an earlier transfer (in the
        same step). Returns the quality report.
        """
        s = self._state
        rt = self._setup(progress)
        res = rt.run(progress=progress)
        new = dataclasses.replace(s, transfer=rt, transferred=res.model, report=res.report,
                                  transfer_landmarks=s.landmarks, refined=None, refine_examples=(), detailed=None)
        self._commit(f"Transfer {len(res.report.shapes)} shapes", new)
        return res.report

    def refine(self, *, iterations: int = 10, progress: Progress = None, **options: Any) -> RefineResult:
        """Stage 2: refine the transferred shapes from the examples (:func:`refine_rig`); one undo step.

        ``options`` go to :func:`~workbench.rigging.refine_rig` (``exclusive``,
        ``beta``, ``gamma``, ...). Drops details carried onto an earlier rig.
        """
        from workbench.rigging.refine import refine_rig

        s = self._state
        if s.transferred is None:
            raise RuntimeError("RigSession.refine: run transfer() first")
        if not s.examples:
            raise ValueError("RigSession.refine: add at least one example pose first")
        res = refine_rig(s.transferred, [e.vertices for e in s.examples], [dict(e.weights) for e in s.examples],
                         iterations=iterations, progress=progress, **options)
        self._commit(f"Refine from {len(s.examples)} examples",
                     dataclasses.replace(s, refined=res, refine_examples=s.examples, detailed=None))
        return res

    def carry_details(self, *, progress: Progress = None) -> FaceModel:
        """Stage 3: carry the template's wrinkle details onto the rig and fit its wrinkles; one undo step."""
        from workbench.rigging.details import transfer_details

        s = self._state
        base = s.refined.model if s.refined is not None else s.transferred
        if base is None or s.transfer is None:
            raise RuntimeError("RigSession.carry_details: run transfer() first")
        if progress is not None:
            progress(0.0, "carrying wrinkle details")
        rig = copy_model(base)
        transfer_details(self.template, rig, s.transfer)
        rig.history.clear()
        if progress is not None:
            progress(1.0, "done")
        self._commit("Carry wrinkle details", dataclasses.replace(s, detailed=rig))
        return rig


def _same(a: RigState, b: RigState) -> bool:
    """Equal landmarks, the same examples and stage results (by identity: they hold arrays)."""
    for f in dataclasses.fields(RigState):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name in ("landmarks", "transfer_landmarks"):
            if x != y:
                return False
        elif f.name in ("examples", "refine_examples"):
            if len(x) != len(y) or any(p is not q for p, q in zip(x, y, strict=True)):
                return False
        elif x is not y:
            return False
    return True


def _examples_key(examples: tuple[RigExample, ...]) -> tuple[Any, ...]:
    return tuple((e.name, id(e.vertices), tuple(sorted(e.weights.items()))) for e in examples)


def _state_nbytes(new: RigState, old: RigState) -> int:
    """Memory a step holds beyond the other state (the models a stage made)."""
    total = 0
    for a, b in ((new.transferred, old.transferred), (new.detailed, old.detailed)):
        for m in (a, b):
            if m is not None and a is not b:
                total += sum(payload_nbytes(s.delta) for s in m.shapes)
    return total + 16


def _mirror_map(model: FaceModel) -> NDArray[np.int64]:
    """Each vertex's nearest reflected vertex about the skin's mid-plane (other vertices map among themselves)."""
    meta = model.metadata
    axis, _ = lateral_axis(meta.up_axis, meta.front_axis)
    V = np.asarray(model.vertices, np.float64)
    skin = skin_or_all_mask(model)
    ref = V[skin]
    mid = 0.5 * float(ref[:, axis].min() + ref[:, axis].max())
    out = np.arange(V.shape[0], dtype=np.int64)
    for ids in (np.flatnonzero(skin), np.flatnonzero(~skin)):
        if ids.size:
            out[ids], _ = nearest_reflected(V, ids, ids, axis=axis, mid=mid)
    return out
