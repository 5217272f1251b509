"""What every importer returns, and how a path is matched to an importer.

Readers register a ``detect(path) -> bool`` and a ``read(path) -> ImportedFace``;
:func:`read_any` picks the first reader whose detector accepts the path. The
built-in readers (OBJ, folder of OBJs, OBJ + MakeHuman targets, glTF/GLB) are
registered lazily on first use so importing this module stays cheap and free of
import cycles. A dozen lines of dispatch did not justify a plugin library.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from workbench.arkit import canonical_arkit_name
from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, label_components

__all__ = [
    "ImportedFace",
    "check_shape_names",
    "read_any",
    "register_reader",
    "supported_inputs",
]


@dataclass
class ImportedFace:
    """A neutral mesh plus its blendshapes, as read from disk.

    Attributes
    ----------
    vertices : (n, 3) float64
        Neutral positions.
    polygons : Polygons
        Faces as in the file (quads and n-gons kept).
    face_groups : (p,) int32 or None
        Group id of each polygon (OBJ ``g``/``o``, glTF primitive), -1 for a
        face outside any group; None when the file has no groups.
    group_names : list of str
        Name of each group id.
    shapes : list of (str, (n, 3) float32)
        Blendshape name (as in the file) and per-vertex delta from the neutral.
    source_files : list of str
        Every file that was read.
    units : str or None
        Length unit if the format defines one ("m" for glTF, "dm" for
        MakeHuman); None when unknown (OBJ).
    up_axis : str or None
        "+y" etc. if the format defines it; None when unknown.
    """

    vertices: NDArray[np.float64]
    polygons: Polygons
    face_groups: NDArray[np.int32] | None = None
    group_names: list[str] = field(default_factory=list)
    shapes: list[tuple[str, NDArray[np.float32]]] = field(default_factory=list)
    source_files: list[str] = field(default_factory=list)
    units: str | None = None
    up_axis: str | None = None

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def shape_names(self) -> list[str]:
        return [name for name, _ in self.shapes]

    def components(self) -> tuple[NDArray[np.int32], list[str]]:
        """Connected parts of the mesh: ``(labels (n,) int32, names)``.

        See :func:`workbench.geometry.mesh_checks.label_components`.
        """
        return label_components(
            self.polygons, self.n_vertices, self.face_groups, self.group_names or None
        )


def check_shape_names(names: Sequence[str], sources: Sequence[str], what: str) -> None:
    """Reject shape names that would collide after normalisation.

    Two shapes are the same when their names are equal ignoring case
    ("Smile" vs "smile": they clash on case-insensitive file systems and in
    most DCC tools) or when they map to the same ARKit name ("eyeBlinkLeft"
    vs "EyeBlink_L").

    Parameters
    ----------
    names : sequence of str
        Shape names.
    sources : sequence of str
        File each name came from (same length), for the message.
    what : str
        The container being read (folder or file), used as the error's source.
    """
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        keys = [name.lower()]
        canon = canonical_arkit_name(name)
        if canon is not None:
            keys.append("arkit:" + canon)
        for key in keys:
            if key in seen:
                j = seen[key]
                why = (
                    f"both are ARKit '{key[6:]}'"
                    if key.startswith("arkit:")
                    else "same name ignoring case"
                )
                raise MeshFormatError(
                    what,
                    "shape names",
                    f"duplicate shape name: '{names[j]}' ({Path(sources[j]).name}) and "
                    f"'{name}' ({Path(sources[i]).name}): {why}",
                )
            seen[key] = i


@dataclass(frozen=True)
class _Reader:
    name: str
    detect: Callable[[Path], bool]
    read: Callable[[Path], ImportedFace]
    description: str


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
    _builtins_done = True
    # imported here: these modules import ImportedFace from this one
    from workbench.io import gltf, makehuman_target, obj, obj_folder

    builtins = [
        ("makehuman", makehuman_target.detect, makehuman_target.read, makehuman_target.DESCRIPTION),
        ("obj_folder", obj_folder.detect, obj_folder.read, obj_folder.DESCRIPTION),
        ("obj", obj.detect, obj.read, obj.DESCRIPTION),
        ("gltf", gltf.detect, gltf.read, gltf.DESCRIPTION),
    ]
    # built-ins go first; readers registered earlier by the user with the same name win
    user = list(_READERS)
    _READERS.clear()
    for name, detect, read, desc in builtins:
        _READERS.append(_Reader(name, detect, read, desc))
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
