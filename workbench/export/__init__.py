"""Export an animated face: one module per format behind a small registry.

``export(model, timeline, path)`` picks the writer from the file suffix (or
``format=``) and returns the files it wrote:

========  ===============  ==========================================================
format    suffixes         what is written
========  ===============  ==========================================================
gltf      .glb, .gltf      mesh + morph targets + weights animation (:mod:`.gltf`)
usd       .usd/.usda/.usdc UsdSkel blend shapes + per-frame weights (:mod:`.usd`)
pc2       .pc2             baked point cache, little-endian (:mod:`.pointcache`)
mdd       .mdd             baked point cache, big-endian (:mod:`.pointcache`)
obj       .obj             one OBJ per frame, ``<stem>_<frame>.obj`` (:mod:`.pointcache`)
csv       .csv             per-frame weights, re-importable (:mod:`.csv`)
fbx       .fbx             animated shape keys, written by Blender (:mod:`.blender`)
abc       .abc             Alembic point cache, written by Blender (:mod:`.blender`)
========  ===============  ==========================================================

Every format reproduces :meth:`FaceModel.evaluate_at` — the blend *and every
editing layer* (regions, handles, paint, and layers registered later such as
wrinkles) — at every exported frame, within float32 round-off. Layers that are
linear in the keyed weights and handle offsets are written exactly as a few
morph targets / blend shapes; the others are baked per frame
(:mod:`.encoding` has the decomposition, each writer's docstring its
encoding). ``export`` returns an :class:`ExportResult`: the files written,
with ``.layers`` saying how each layer was encoded (``"linear"``,
``"baked"``, ``"inactive"`` or ``"omitted"``); baked and omitted layers are
also logged as warnings on the ``workbench.export`` logger.

Every file is written to a temporary name in the target folder and renamed
into place (:func:`atomic_path`) with the permissions of a normal new file
(``0o666 & ~umask``), so a crash never leaves a half-written file under the
final name. Positions are written in metres (the model's units are
scaled by ``model.metadata.metres_per_unit``), +y up, as glTF and USD expect.

The registry is a dict rather than entry points: the formats are few and all
live here; writers are imported lazily by module name (so ``pxr`` is only
needed for USD) and import only :mod:`.base` (errors, result, atomic
writing), never this module, so there is no import cycle.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from workbench.export.base import (
    ExportError,
    ExportResult,
    LayerReport,
    atomic_path,
    atomic_write_bytes,
)

if TYPE_CHECKING:
    from workbench.animation.tracks import Timeline
    from workbench.model import FaceModel

__all__ = [
    "FORMATS",
    "ExportError",
    "ExportFormat",
    "ExportResult",
    "LayerReport",
    "atomic_path",
    "atomic_write_bytes",
    "export",
    "format_for_path",
]


logger = logging.getLogger("workbench.export")


@dataclass(frozen=True)
class ExportFormat:
    """A registered writer: ``module.write(model, timeline, path, *, bake, **options) -> list[Path]``."""

    name: str
    suffixes: tuple[str, ...]
    module: str
    description: str

    def writer(self) -> Callable[..., list[Path]]:
        mod = importlib.import_module(self.module)
        fn: Callable[..., list[Path]] = mod.write
        return fn


FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat(
            "gltf", (".glb", ".gltf"), "workbench.export.gltf", "glTF 2.0 morph targets + weights animation"
        ),
        ExportFormat(
            "usd", (".usd", ".usda", ".usdc"), "workbench.export.usd", "USD with UsdSkel blend shapes"
        ),
        ExportFormat("pc2", (".pc2",), "workbench.export.pointcache", "PC2 point cache"),
        ExportFormat("mdd", (".mdd",), "workbench.export.pointcache", "MDD point cache"),
        ExportFormat("obj", (".obj",), "workbench.export.pointcache", "OBJ sequence, one file per frame"),
        ExportFormat("csv", (".csv",), "workbench.export.csv", "CSV of per-frame weights"),
        ExportFormat("fbx", (".fbx",), "workbench.export.blender", "FBX with animated shape keys (through Blender)"),
        ExportFormat("abc", (".abc",), "workbench.export.blender", "Alembic point cache (through Blender)"),
    )
}


def format_for_path(path: str | Path, format: str | None = None) -> ExportFormat:
    """The registered format for ``format`` (a name) or for the suffix of ``path``."""
    if format is not None:
        if format not in FORMATS:
            raise ExportError(f"unknown export format {format!r}; known: {sorted(FORMATS)}")
        return FORMATS[format]
    suffix = Path(path).suffix.lower()
    for f in FORMATS.values():
        if suffix in f.suffixes:
            return f
    known = sorted(s for f in FORMATS.values() for s in f.suffixes)
    raise ExportError(f"{Path(path).name}: cannot tell the format from suffix {suffix!r}; known: {known}")


def export(
    model: FaceModel,
    timeline: Timeline,
    path: str | Path,
    *,
    fps: float | None = None,
    bake: bool = False,
    format: str | None = None,
    **options: Any,
) -> list[Path]:
    """Write ``model`` animated by ``timeline`` to ``path``.

    Parameters
    ----------
    model : FaceModel
    timeline : Timeline
        Checked against the model (:meth:`Timeline.check_model`: shape names, family tracks).
    path : str or Path
        Output file; the suffix picks the format unless ``format`` is given.
    fps : float, optional
        Frame rate for baked/per-frame output (default ``timeline.fps``).
    bake : bool
        glTF: resample every curve at each frame (LINEAR) instead of writing
        the keys; USD: write plain per-frame points instead of UsdSkel blend
        shapes. Point caches, OBJ and CSV are always per frame.
    format : str, optional
        One of :data:`FORMATS`.
    **options
        Format-specific (see each writer's ``write``).

    Returns
    -------
    ExportResult
        The files written (a list of Path); ``.layers`` reports how every
        editing layer was encoded.
    """
    from workbench.animation.curves import TrackError

    fmt = format_for_path(path, format)
    tl = timeline
    if fps is not None:
        if not fps > 0:
            raise ExportError(f"fps must be positive, got {fps!r}")
        tl = tl.replace(fps=float(fps))
    if tl.end <= tl.start and tl.key_range is not None:
        tl = tl.fit_range()
    try:
        tl.check_model(model)
    except TrackError as exc:
        raise ExportError(str(exc)) from None
    if fmt.name in ("pc2", "mdd", "obj", "fbx", "abc"):
        options.setdefault("kind", fmt.name)
    written = fmt.writer()(model, tl, Path(path), bake=bake, **options)
    result = written if isinstance(written, ExportResult) else ExportResult(written)
    for r in result.layers:
        # warn when a layer could not go into the file as it is, or only frame by frame
        # although the format has morph targets / blend shapes
        lossy = r.encoding == "omitted" or (r.encoding == "baked" and fmt.name in ("gltf", "usd") and not bake)
        level = logging.WARNING if lossy else logging.INFO
        logger.log(level, "%s: layer %r %s: %s", Path(path).name, r.name, r.encoding, r.detail)
    return result
