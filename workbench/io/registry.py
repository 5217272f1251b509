"""How a path is matched to a reader.

Readers register a ``detect(path) -> bool`` and a ``read(path) -> ImportedFace``;
:func:`read_any` picks the first reader whose detector accepts the path. The
built-in readers (OBJ + MakeHuman targets, folder of OBJs, OBJ, glTF/GLB, FBX
and Alembic through Blender, USD through usd-core) are one module (or package) each, listed by name in :data:`BUILTIN_READERS` and imported with
:mod:`importlib` on first use: importing this module stays cheap, and since
the readers import only :mod:`workbench.io.base` (where :class:`ImportedFace`
lives), nothing imports back into the registry. A dozen lines of dispatch did
not justify a plugin library.

A built-in reader module defines ``detect``, ``read`` and ``DESCRIPTION``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.base import ImportedFace, check_shape_names

__all__ = [
    "BUILTIN_READERS",
    "ImportedFace",
    "check_shape_names",
    "read_any",
    "register_reader",
    "supported_inputs",
]


@dataclass(frozen=True)
class _Reader:
    name: str
    detect: Callable[[Path], bool]
    read: Callable[[Path], ImportedFace]
    description: str


#: (reader name, module) of the built-in readers, in the order they are tried.
BUILTIN_READERS: tuple[tuple[str, str], ...] = (
    ("makehuman", "workbench.io.makehuman_target"),
    ("obj_folder", "workbench.io.obj_folder"),
    ("obj", "workbench.io.obj"),
    ("gltf", "workbench.io.gltf"),
    ("fbx", "workbench.io.fbx"),
    ("usd", "workbench.io.usd"),
    ("alembic", "workbench.io.alembic"),
)

_READERS: list[_Reader] = []
_builtins_done = False


def register_reader(
    name: str,
    detect: Callable[[Path], bool],
    read: Callable[[Path], ImportedFace],
    description: str = "",
) -> None:
    """Add (or replace, by ``name``) a reader used by :func:`read_any`.

    Parameters
    ----------
    name : str
        Reader id, e.g. "obj".
    detect : callable(Path) -> bool
        Cheap test: does this reader handle the path (suffix, folder contents)?
    read : callable(Path) -> ImportedFace
        The reader; raises MeshFormatError on bad input.
    description : str
        One line shown in the "unsupported input" error.
    """
    for k, r in enumerate(_READERS):
        if r.name == name:
            _READERS[k] = _Reader(name, detect, read, description or r.description)
            return
    _READERS.append(_Reader(name, detect, read, description or name))


def _register_builtins() -> None:
    global _builtins_done
    if _builtins_done:
        return
    builtins = []
    for name, module in BUILTIN_READERS:
        mod = importlib.import_module(module)
        builtins.append(_Reader(name, mod.detect, mod.read, mod.DESCRIPTION))
    _builtins_done = True
    # built-ins go first; readers registered earlier by the user with the same name win
    user = list(_READERS)
    _READERS.clear()
    _READERS.extend(builtins)
    for r in user:
        register_reader(r.name, r.detect, r.read, r.description)


def supported_inputs() -> list[str]:
    """One line per registered reader describing what it accepts."""
    _register_builtins()
    return [f"{r.name}: {r.description}" for r in _READERS]


def read_any(path: str | Path) -> ImportedFace:
    """Read a face (neutral + shapes) from any supported file or folder.

    Raises
    ------
    FileNotFoundError
        The path does not exist.
    MeshFormatError
        No reader accepts the path (the message lists supported inputs), or the
        chosen reader found the file malformed.
    """
    _register_builtins()
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    for r in _READERS:
        if r.detect(p):
            return r.read(p)
    listing = "\n  ".join(supported_inputs())
    raise MeshFormatError(p, "path", f"not a supported face input. Supported:\n  {listing}")
