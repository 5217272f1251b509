"""Conversions to mesh libraries the headless core must not import.

``FaceModel.to_pyvista()`` / ``FaceModel.from_pyvista()`` are part of the model's
API, but pyvista (VTK) belongs to the UI extra and the import contract keeps it
out of ``workbench``. So the core keeps a registry that the UI module fills when
it is imported (``widgets.render`` registers ``"pyvista"``), the way pandas
finds its plotting backends. Hand-written because it is a dozen lines of
project glue.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple


class MeshConverter(NamedTuple):
    """``to(model, points=None, **kw) -> mesh`` and ``from_(mesh, **kw) -> FaceModel``."""

    to: Callable[..., Any]
    from_: Callable[..., Any]
    provider: str


_CONVERTERS: dict[str, MeshConverter] = {}

# which module registers each known converter, for the error message
_PROVIDERS = {"pyvista": "widgets.render"}


def register_mesh_converter(
    name: str, to: Callable[..., Any], from_: Callable[..., Any], provider: str
) -> None:
    """Register (or replace) the converter ``name``; ``provider`` names the registering module."""
    _CONVERTERS[name] = MeshConverter(to, from_, provider)


def mesh_converter(name: str) -> MeshConverter:
    """The registered converter ``name``.

    Raises
    ------
    ImportError
        If no module registered it yet, naming the module to import.
    """
    try:
        return _CONVERTERS[name]
    except KeyError:
        provider = _PROVIDERS.get(name, "the module that provides it")
        raise ImportError(
            f"no {name!r} mesh converter is registered: `import {provider}` first "
            "(it needs the UI extra: pip install 'face-workbench[ui]')"
        ) from None
