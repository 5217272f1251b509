"""The same face written down by another studio: units, shape names, part names.

Each function takes a :class:`~workbench.model.FaceModel` or a
:class:`~workbench.testing.faces.GeneratedFace` and returns the same kind (a
generated face keeps its truth: :func:`in_units` scales its warp too):

* :func:`in_units` — the face in cm, mm, ... (``metres_per_unit`` times
  coordinates unchanged);
* :func:`renamed_shapes` / :func:`rename_shape` — other spellings
  (``eyeBlink_L``, ``JawOpen``, ``eye_blink_left``, ``jawOpen.001``,
  ``blendShape1.jawOpen``);
* :func:`split_sides` — symmetric shapes split into ``_L`` / ``_R`` halves
  that sum to the whole;
* :func:`unnamed_parts` — component names dropped (``mesh_0``, ...) or all
  parts merged into one;
* :func:`foreign_face` — a face unlike the source in every way at once.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace
from typing import overload

import numpy as np
from numpy.typing import ArrayLike

from workbench.model import UNIT_TO_METRES, BlendShape, FaceModel, ModelMetadata
from workbench.testing.faces import (
    GeneratedFace,
    _axis,
    _delta,
    opened,
    proportions_warp,
    remeshed,
    renumbered,
    with_bust,
)
from workbench.testing.warps import SmoothWarp, Warp, compose, random_warp

__all__ = [
    "STYLES",
    "foreign_face",
    "in_units",
    "rename_shape",
    "renamed_shapes",
    "split_sides",
    "unnamed_parts",
]


def _with_model(x: FaceModel | GeneratedFace, model: FaceModel, warp: Warp | None = None) -> FaceModel | GeneratedFace:
    if isinstance(x, GeneratedFace):
        return replace(x, model=model, warp=x.warp if warp is None else warp)
    return model


def _model_of(x: FaceModel | GeneratedFace) -> FaceModel:
    return x.model if isinstance(x, GeneratedFace) else x


def _copy(m: FaceModel, *, vertices: ArrayLike | None = None, shapes: Iterable[BlendShape] | None = None,
          labels: ArrayLike | None = None, names: Sequence[str] | None = None,
          metadata: ModelMetadata | None = None) -> FaceModel:
    return FaceModel(m.vertices if vertices is None else vertices, m.faces, m.shapes if shapes is None else shapes,
                     polygons=m.polygons, component_labels=m.component_labels if labels is None else labels,
                     component_names=m.component_names if names is None else names,
                     metadata=m.metadata if metadata is None else metadata)


@overload
def in_units(x: FaceModel, units: str) -> FaceModel: ...
@overload
def in_units(x: GeneratedFace, units: str) -> GeneratedFace: ...
def in_units(x: FaceModel | GeneratedFace, units: str) -> FaceModel | GeneratedFace:
    """The same face in other units: coordinates and shapes scaled so ``metres_per_unit * x`` is unchanged."""
    m = _model_of(x)
    k = m.metadata.metres_per_unit / UNIT_TO_METRES[units]
    shapes = [s.replace(delta=np.asarray(s.delta, np.float64) * k) for s in m.shapes]
    model = _copy(m, vertices=m.vertices * k, shapes=shapes, metadata=replace(m.metadata, units=units))
    if isinstance(x, GeneratedFace):
        return _with_model(x, model, compose(x.warp, SmoothWarp(unit=k)))
    return model


#: spellings :func:`rename_shape` knows
STYLES = ("LR", "pascal", "snake", "numbered", "namespaced")
_SIDE = re.compile(r"(Left|Right)$")


def rename_shape(name: str, style: str) -> str:
    """``name`` in another rig's spelling.

    ``"LR"``: ``eyeBlinkLeft`` -> ``eyeBlink_L``; ``"pascal"``: ``JawOpen``;
    ``"snake"``: ``eye_blink_left``; ``"numbered"``: ``jawOpen.001`` (a
    Blender duplicate); ``"namespaced"``: ``blendShape1.jawOpen`` (Maya).
    """
    if style == "LR":
        return _SIDE.sub(lambda m: "_" + m.group(1)[0], name)
    if style == "pascal":
        return name[:1].upper() + name[1:]
    if style == "snake":
        return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower()
    if style == "numbered":
        return name + ".001"
    if style == "namespaced":
        return "blendShape1." + name
    raise ValueError(f"unknown style {style!r}; styles are {STYLES}")


Renaming = str | Sequence[str] | Mapping[str, str] | Callable[[str], str]


def _renamer(style: Renaming) -> Callable[[str], str]:
    if isinstance(style, str):
        return lambda n: rename_shape(n, style)
    if isinstance(style, Mapping):
        table = dict(style)
        return lambda n: table.get(n, n)
    if callable(style):
        return style
    steps = list(style)

    def chain(n: str) -> str:
        for s in steps:
            n = rename_shape(n, s)
        return n

    return chain


@overload
def renamed_shapes(x: FaceModel, style: Renaming) -> FaceModel: ...
@overload
def renamed_shapes(x: GeneratedFace, style: Renaming) -> GeneratedFace: ...
def renamed_shapes(x: FaceModel | GeneratedFace, style: Renaming) -> FaceModel | GeneratedFace:
    """The same face with its shapes renamed: a style of :func:`rename_shape`, several in order, a table or a function."""
    m = _model_of(x)
    fn = _renamer(style)
    return _with_model(x, _copy(m, shapes=[s.replace(name=fn(s.name)) for s in m.shapes]))


@overload
def split_sides(x: FaceModel, names: Iterable[str] | None = ..., *, blend: float = ...,
                suffixes: tuple[str, str] = ...) -> FaceModel: ...
@overload
def split_sides(x: GeneratedFace, names: Iterable[str] | None = ..., *, blend: float = ...,
                suffixes: tuple[str, str] = ...) -> GeneratedFace: ...
def split_sides(x: FaceModel | GeneratedFace, names: Iterable[str] | None = None, *, blend: float = 0.05,
                suffixes: tuple[str, str] = ("_L", "_R")) -> FaceModel | GeneratedFace:
    """Split shapes into the subject's left and right halves, which sum to the whole.

    Parameters
    ----------
    names : iterable of str, optional
        Shapes to split; default every shape whose name does not already end in
        a side (``Left``, ``Right``, ``_L``, ``_R``).
    blend : float
        Width of the cross-fade across the mid-plane, as a share of the model's width.
    suffixes : (str, str)
        Appended for the left and the right half (each replaces the shape in place).
    """
    m = _model_of(x)
    side = np.cross(_axis(m.metadata.up_axis), _axis(m.metadata.front_axis))  # the subject's left
    s = m.vertices @ side
    mid, width = 0.5 * (s.min() + s.max()), float(np.ptp(s))
    t = np.clip((s - mid) / max(blend * width, 1e-300) + 0.5, 0.0, 1.0)
    left = t * t * (3.0 - 2.0 * t)
    chosen = set(names) if names is not None else {
        n for n in m.shape_names if not re.search(r"(Left|Right|_L|_R)$", n)}
    unknown = chosen - set(m.shape_names)
    if unknown:
        raise ValueError(f"split_sides: unknown shapes {sorted(unknown)}")
    shapes: list[BlendShape] = []
    for sh in m.shapes:
        if sh.name not in chosen:
            shapes.append(sh)
            continue
        d = _delta(sh)
        shapes += [sh.replace(name=sh.name + suffixes[0], delta=d * left[:, None], vertex_mask=None),
                   sh.replace(name=sh.name + suffixes[1], delta=d - d * left[:, None], vertex_mask=None)]
    return _with_model(x, _copy(m, shapes=shapes))


@overload
def unnamed_parts(x: FaceModel, *, merge: bool = ...) -> FaceModel: ...
@overload
def unnamed_parts(x: GeneratedFace, *, merge: bool = ...) -> GeneratedFace: ...
def unnamed_parts(x: FaceModel | GeneratedFace, *, merge: bool = False) -> FaceModel | GeneratedFace:
    """The component names dropped (``mesh_0``, ``mesh_1``, ... as many exporters write), or all parts merged into one."""
    m = _model_of(x)
    if merge:
        return _with_model(x, _copy(m, labels=np.zeros(m.n_vertices, np.int32), names=["mesh"]))
    return _with_model(x, _copy(m, names=[f"mesh_{i}" for i in range(len(m.component_names))]))


def foreign_face(source: FaceModel, *, seed: int = 0, units: str = "cm", strength: float = 0.02,
                 degrees: float = 10.0, eyes: float = 0.93, jaw: float = 1.08, bust: bool | int = True,
                 open_mouth_and_eyes: bool = True, names: Renaming = "LR") -> GeneratedFace:
    """A face unlike the source in every way at once, with its true shapes.

    The source remeshed and renumbered, under its own proportions (``eyes``,
    ``jaw``) and a :func:`~workbench.testing.warps.random_warp` (``strength``,
    ``degrees``), with shoulders (``bust``: True for a ring per 2,000 face vertices, at
    least 4, or a number of rings; False or 0 for none) and open mouth and eyes, in
    ``units``; its symmetric shapes split into halves, every shape renamed
    (``names``) and its parts unnamed. Deterministic given ``seed``.
    """
    warp = compose(proportions_warp(source, eyes=eyes, jaw=jaw),
                   random_warp(source.vertices, seed=seed, strength=strength, degrees=degrees))
    face = remeshed(source, seed=seed, warp=warp, shapes=True, name=f"foreign face {seed}")
    if bust:  # True, or a number of rings (0 rings: none, like False)
        rings = max(4, face.model.n_vertices // 2000) if bust is True else int(bust)
        face = with_bust(face, rings=rings)
    if open_mouth_and_eyes:
        face = opened(face)
    face = in_units(renumbered(face, seed=seed), units)
    return unnamed_parts(renamed_shapes(split_sides(face), names))
