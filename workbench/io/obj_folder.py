"""A folder of same-topology OBJ files: one neutral plus one file per expression.

This is how many sculptors hand over blendshapes (one posed mesh per shape,
absolute positions). Each expression becomes ``delta = V_expression - V_neutral``.
The files must share the neutral's vertex count and polygon list exactly, since
the deltas are matched vertex by vertex. Built on :mod:`workbench.io.obj`; no
library reads shape folders.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.base import ImportedFace, check_shape_names
from workbench.io.obj import read_obj

__all__ = ["DESCRIPTION", "NEUTRAL_STEMS", "detect", "read", "read_obj_folder"]

DESCRIPTION = (
    "a folder of .obj files with one topology: neutral.obj (or base.obj) + one file per shape"
)
NEUTRAL_STEMS = ("neutral", "base")


def _obj_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() == ".obj")


def detect(path: Path) -> bool:
    return path.is_dir() and len(_obj_files(path)) >= 2


def read(path: Path) -> ImportedFace:
    return read_obj_folder(path)


def read_obj_folder(folder: str | Path, neutral: str | Path | None = None) -> ImportedFace:
    """Read a neutral OBJ and expression OBJs from one folder.

    Parameters
    ----------
    folder : str or Path
        Folder holding the .obj files (sub-folders are not searched).
    neutral : str or Path, optional
        File name (or stem) of the neutral; default ``neutral.obj`` or ``base.obj``.

    Returns
    -------
    ImportedFace
        The neutral mesh and one shape per other file, named by file stem,
        sorted by file name; ``source_files`` starts with the neutral.

    Raises
    ------
    MeshFormatError
        No or ambiguous neutral (the message lists candidates), an expression
        whose vertex count or polygons differ from the neutral, two files whose
        names collide (same ignoring case, or same ARKit shape), or any OBJ error.
    """
    root = Path(folder)
    if not root.is_dir():
        raise MeshFormatError(root, "path", "expected a folder of .obj files")
    files = _obj_files(root)
    if not files:
        raise MeshFormatError(root, "path", "folder has no .obj files")
    names = ", ".join(p.name for p in files)

    if neutral is not None:
        want = Path(neutral).name
        hits = [p for p in files if p.name == want or p.stem == want]
        if not hits:
            raise MeshFormatError(
                root, "neutral", f"neutral {want!r} not found; .obj files: {names}"
            )
    else:
        hits = [p for p in files if p.stem.lower() in NEUTRAL_STEMS]
        if not hits:
            raise MeshFormatError(
                root,
                "neutral",
                "no neutral mesh: name it neutral.obj or base.obj, or pass neutral=<file>; "
                f"candidates: {names}",
            )
    if len(hits) > 1:
        raise MeshFormatError(
            root,
            "neutral",
            f"ambiguous neutral: {', '.join(p.name for p in hits)}; pass neutral=<file>",
        )
    neutral_path = hits[0]
    base = read_obj(neutral_path)
    others = [p for p in files if p != neutral_path]
    check_shape_names([p.stem for p in others], [str(p) for p in others], str(root))

    shapes: list[tuple[str, np.ndarray]] = []
    for p in others:
        face = read_obj(p)
        if face.n_vertices != base.n_vertices:
            raise MeshFormatError(
                p,
                "v",
                f"has {face.n_vertices} vertices but the neutral {neutral_path.name} has "
                f"{base.n_vertices}; every shape must have the neutral's topology",
            )
        if not face.polygons.equals(base.polygons):
            first = _first_difference(face, base)
            raise MeshFormatError(
                p,
                "f",
                f"faces differ from the neutral {neutral_path.name} ({first}); "
                "every shape must have the neutral's topology",
            )
        shapes.append((p.stem, (face.vertices - base.vertices).astype(np.float32)))

    return ImportedFace(
        vertices=base.vertices,
        polygons=base.polygons,
        face_groups=base.face_groups,
        group_names=base.group_names,
        shapes=shapes,
        source_files=[str(neutral_path)] + [str(p) for p in others],
        units=None,
        up_axis=None,
    )


def _first_difference(a: ImportedFace, b: ImportedFace) -> str:
    pa, pb = a.polygons, b.polygons
    if len(pa) != len(pb):
        return f"{len(pa)} faces vs {len(pb)}"
    for i in range(len(pa)):
        if not np.array_equal(pa[i], pb[i]):
            return f"face {i} is {pa[i].tolist()} vs {pb[i].tolist()}"
    return "same faces"  # pragma: no cover - equals() said they differ
