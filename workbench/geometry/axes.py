"""Where a face looks: signed axis names and the subject's left / up / front.

A model's ``metadata.up_axis`` and ``front_axis`` are signed axis names
(``"+y"``, ``"-z"``); the face looks toward ``front_axis`` and "left" is always
the subject's left, ``up × front``. :func:`face_axes` turns them into a rotation
whose rows are left, up and front, so ``V @ face_axes(model).T`` puts a head in
a frame where x is the subject's left, y up and z front.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from workbench.core.shapes import ModelMetadata

__all__ = ["AxesError", "axis_vector", "face_axes", "head_axes"]

_AXES = {"x": 0, "y": 1, "z": 2}


class AxesError(ValueError):
    """An axis name that is not one, or an up and a front axis that are not perpendicular."""


class _HasMetadata(Protocol):
    @property
    def metadata(self) -> ModelMetadata: ...


def axis_vector(spec: str) -> NDArray[np.float64]:
    """The unit vector of a signed axis name: ``"+y"`` -> (0, 1, 0), ``"-z"`` -> (0, 0, -1).

    Parameters
    ----------
    spec : str
        ``"x"``, ``"+x"`` or ``"-x"`` (any case; likewise y and z).

    Returns
    -------
    (3,) float64

    Raises
    ------
    AxesError
        ``spec`` names no axis.
    """
    s = str(spec).strip().lower()
    letter = s.lstrip("+-")
    if letter not in _AXES or len(s) - len(letter) > 1:
        raise AxesError(f"expected an axis like '+y' or '-z', got {spec!r}")
    v = np.zeros(3)
    v[_AXES[letter]] = -1.0 if s.startswith("-") else 1.0
    return v


def head_axes(up_axis: str, front_axis: str, what: str = "model") -> NDArray[np.float64]:
    """(3, 3) rotation whose rows are the subject's left (``up × front``), up and front.

    Parameters
    ----------
    up_axis, front_axis : str
        Signed axis names (:func:`axis_vector`).
    what : str
        Names the model in the error message.

    Raises
    ------
    AxesError
        The axes are not perpendicular (or not axis names).
    """
    up, front = axis_vector(up_axis), axis_vector(front_axis)
    if abs(float(up @ front)) > 0.5:
        raise AxesError(
            f"{what}: metadata up_axis {up_axis!r} and front_axis {front_axis!r} are not perpendicular"
        )
    return np.stack([np.cross(up, front), up, front])


def face_axes(model: _HasMetadata) -> NDArray[np.float64]:
    """:func:`head_axes` of a model's ``metadata`` (rows: the subject's left, up, front in model coordinates).

    Parameters
    ----------
    model : FaceModel, FaceState or StateView
        Anything with a ``metadata`` (:class:`~workbench.core.shapes.ModelMetadata`).

    Returns
    -------
    (3, 3) float64
        A rotation: ``V @ face_axes(model).T`` has x left, y up, z front.

    Raises
    ------
    AxesError
        ``up_axis`` and ``front_axis`` are not perpendicular.
    """
    meta = model.metadata
    return head_axes(meta.up_axis, meta.front_axis, meta.name or "model")
