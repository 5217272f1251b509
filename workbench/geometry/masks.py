"""Vertex masks of a face's parts, by role: the one place that says what "the skin" is.

Every component of a model has a role (:func:`workbench.geometry.parts.model_part_roles`:
from its name, else from its geometry). The masks here select vertices by
those roles; the names say what happens when a model has no such part:

* :func:`skin_mask` — the vertices of the components whose role is ``"skin"``;
  raises :class:`MissingPartError` when no component is skin.
* :func:`skin_or_all_mask` — the same, but every vertex when no component is
  skin (a bare scan or a single unnamed mesh is all face): for tools that work
  on any mesh.
* :func:`skin_surface` — the skin as a surface of its own: the vertices of the
  triangles whose three corners are skin, and those triangles renumbered;
  raises when there is no skin or it has no triangles.
* :func:`role_mask` — the vertices of the components with any of some roles
  (no error: all False when there are none); :func:`eyeball_mask` is the eyeballs.

A model is anything with ``vertices``, ``faces``, ``component_labels``,
``component_names`` and ``metadata`` (a ``FaceModel``, ``FaceState`` or a
pipeline ``StateView``).
"""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.geometry.parts import model_part_roles

__all__ = [
    "MissingPartError",
    "eyeball_mask",
    "role_mask",
    "skin_mask",
    "skin_or_all_mask",
    "skin_surface",
]


class MissingPartError(ValueError):
    """The model has no part with the role asked for; the message names its parts."""


def _name(model: Any) -> str:
    return getattr(getattr(model, "metadata", None), "name", "") or "model"


def role_mask(model: Any, roles: Collection[str]) -> NDArray[np.bool_]:
    """The vertices of the components whose role is one of ``roles``.

    Parameters
    ----------
    model : FaceModel, FaceState or StateView
    roles : collection of str
        Roles of :data:`workbench.geometry.parts.ROLES` (``{"skin"}``, ``RIGID_ROLES`` ...).

    Returns
    -------
    (n,) bool
        All False when no component has one of the roles.
    """
    parts = model_part_roles(model)
    wanted = [i for i, r in enumerate(parts) if r in roles]
    return np.isin(np.asarray(model.component_labels), wanted)


def eyeball_mask(model: Any) -> NDArray[np.bool_]:
    """(n,) bool: the vertices of the eyeballs (left, right or both in one part); all False without eyes."""
    return role_mask(model, ("eyeball_left", "eyeball_right", "eyeball"))


def skin_mask(model: Any) -> NDArray[np.bool_]:
    """(n,) bool: the vertices of the components whose role is ``"skin"``.

    Raises
    ------
    MissingPartError
        No component is skin (the message lists the model's parts).
    """
    on = role_mask(model, ("skin",))
    if not on.any():
        raise MissingPartError(f"{_name(model)}: no skin found among its parts {list(model.component_names)}")
    return on


def skin_or_all_mask(model: Any) -> NDArray[np.bool_]:
    """(n,) bool: :func:`skin_mask`, or every vertex when no component is skin (the whole mesh is the face)."""
    on = role_mask(model, ("skin",))
    return on if on.any() else np.ones(int(model.n_vertices), bool)


def skin_surface(model: Any) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The skin as a surface: the triangles whose three corners are skin, and their vertices.

    Parameters
    ----------
    model : FaceModel, FaceState or StateView

    Returns
    -------
    ids : (s,) int64
        Sorted model ids of the vertices of those triangles (skin vertices on
        no skin triangle are left out).
    faces : (t, 3) int64
        Those triangles, numbered into ``ids``.

    Raises
    ------
    MissingPartError
        No component is skin, or the skin has no triangles.
    """
    on = skin_mask(model)
    F = np.asarray(model.faces, np.int64).reshape(-1, 3)
    Fs = F[on[F].all(1)]
    if Fs.shape[0] == 0:
        raise MissingPartError(f"{_name(model)}: the skin has no triangles")
    ids = np.unique(Fs)
    local = np.full(on.shape[0], -1, np.int64)
    local[ids] = np.arange(ids.size)
    return ids.astype(np.int64), local[Fs]
