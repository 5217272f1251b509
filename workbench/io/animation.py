"""The animation a face file carries, read onto a timeline whatever its format.

:func:`read_file_animation` dispatches by suffix: glTF weights channels
(:func:`workbench.animation.importers.read_gltf_animation`), FBX shape-key
curves (:func:`workbench.io.fbx.read_fbx_animation`), UsdSkel weight samples
(:func:`workbench.io.usd.read_usd_animation`), an Alembic point cache replayed
frame by frame (:func:`workbench.io.alembic.read_alembic_animation`), and weight
CSVs (plain, Live Link Face, Face Cap). :func:`workbench.io.load` uses
:func:`animation_of` to put a file's own animation on the new model's timeline.
It lives in ``io`` (not ``animation``) because the format readers import the
animation types; the dispatch on top of both keeps the import graph acyclic.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from workbench.animation.importers import AnimationImportError, read_animation
from workbench.animation.tracks import Timeline

__all__ = ["ANIMATED_SUFFIXES", "animation_of", "read_file_animation"]

#: suffixes whose files can carry a weights animation besides the mesh
ANIMATED_SUFFIXES = (".glb", ".gltf", ".fbx", ".usd", ".usda", ".usdc", ".usdz", ".abc")


def read_file_animation(path: str | Path, shape_names: Sequence[str], **kw: Any) -> Timeline:
    """Read the weights animation of ``path`` into a :class:`Timeline`.

    Parameters
    ----------
    path : str or Path
        ``.glb``/``.gltf``, ``.fbx``, ``.usd``/``.usda``/``.usdc``/``.usdz``,
        ``.abc``, or a weights ``.csv``/``.txt``.
    shape_names : sequence of str
        The model's shapes; curves are matched exactly, else by ARKit meaning.
    **kw
        Passed to the format's reader (``fps``, ``on_unknown``, and for CSVs
        ``up_axis``/``front_axis``).

    Raises
    ------
    AnimationImportError
        The file has no weights animation, or it is malformed (file and field named).
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".fbx":
        from workbench.io.fbx import read_fbx_animation

        return read_fbx_animation(p, shape_names, **_only(kw, "fps", "on_unknown"))
    if suffix in (".usd", ".usda", ".usdc", ".usdz"):
        from workbench.io.usd import read_usd_animation

        return read_usd_animation(p, shape_names, **_only(kw, "fps", "on_unknown"))
    if suffix == ".abc":
        from workbench.io.alembic import read_alembic_animation

        return read_alembic_animation(p, shape_names, **_only(kw, "fps"))
    return read_animation(p, shape_names, **kw)


def animation_of(path: str | Path, shape_names: Sequence[str]) -> Timeline | None:
    """The animation a face file carries, or None when it has none (or is no animated format).

    Errors other than "there is no animation" propagate: a file whose mesh
    loads but whose animation is malformed is refused as a whole.
    """
    p = Path(path)
    if not p.is_file() or p.suffix.lower() not in ANIMATED_SUFFIXES:
        return None
    try:
        tl = read_file_animation(p, shape_names, on_unknown="ignore")
    except AnimationImportError as exc:
        if _says_no_animation(str(exc)):
            return None
        raise
    return tl if tl.tracks else None


def _only(kw: dict[str, Any], *names: str) -> dict[str, Any]:
    return {k: v for k, v in kw.items() if k in names and v is not None}


def _says_no_animation(message: str) -> bool:
    text = message.lower()
    return any(
        s in text
        for s in (
            "has no animations",
            "no animation has a 'weights' channel",
            "has no shape-key animation",
            "has no skelanimation",
            "no skelanimation has blendshapeweights",
            "no animated blend shape matches",
            "the archive is static",
        )
    )
