"""What every reader returns, and the checks readers share.

Reader modules (one per format: :mod:`.obj`, :mod:`.obj_folder`,
:mod:`.makehuman_target`, :mod:`.gltf`) import only this module from the
package; :mod:`.registry` finds them by module name, so no module here
imports back into the registry (no import cycle).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from workbench.arkit import canonical_arkit_name
from workbench.core.polygons import Polygons
from workbench.geometry.mesh_checks import MeshFormatError, label_components

__all__ = ["FrameSequence", "ImportedFace", "check_shape_names"]


@dataclass
class FrameSequence:
    """Per-frame vertex positions of a point cache (an Alembic mesh sequence).

    Attributes
    ----------
    times : (F,) float64
        Seconds of each frame, strictly increasing.
    positions : (F, n, 3) float32
        Every vertex at every frame, in the face's coordinates and unit
        (frame 0 is :attr:`ImportedFace.vertices`).
    fps : float
        Frames per second of the cache (1 / the sampling interval).
    """

    times: NDArray[np.float64]
    positions: NDArray[np.float32]
    fps: float

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])


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
    frames : FrameSequence or None
        Only for point caches (Alembic): every frame's positions, for the
        capture step; None for blendshape rigs. The reader also gives each
        frame after the first as a shape (``frame_0001``...) so the face can
        be played and edited like any rig.
    """

    vertices: NDArray[np.float64]
    polygons: Polygons
    face_groups: NDArray[np.int32] | None = None
    group_names: list[str] = field(default_factory=list)
    shapes: list[tuple[str, NDArray[np.float32]]] = field(default_factory=list)
    source_files: list[str] = field(default_factory=list)
    units: str | None = None
    up_axis: str | None = None
    frames: FrameSequence | None = None

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
