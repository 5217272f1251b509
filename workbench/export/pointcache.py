"""Baked vertex animation: PC2 and MDD point caches and an OBJ-per-frame sequence.

All three store the evaluated mesh — :meth:`FaceModel.evaluate_at` at every
frame of the timeline range: blendshapes, every editing layer (regions,
handles, paint, wrinkles and other registered layers) and the head pose,
computed by :meth:`workbench.export.encoding.MeshEncoding.points` (the same
decomposition the glTF/USD writers use; layers that are not linear in the
keyed quantities are evaluated frame by frame) — in metres, in the model's
axes (+y up). Vertex order is the model's. Every layer is therefore "baked"
in the returned :class:`~workbench.export.ExportResult`.

Byte layouts (written with numpy dtypes, so the byte order is explicit)
------------------------------------------------------------------------
**PC2** (Maya/3ds Max/Blender point cache 2), little-endian::

    offset  size  type        field
    0       12    char[12]    signature b"POINTCACHE2\\0"
    12      4     int32       file version = 1
    16      4     int32       number of points P
    20      4     float32     start frame (timeline start * fps)
    24      4     float32     sample rate (frames between samples) = 1.0
    28      4     int32       number of samples S
    32      S*P*12 float32    x, y, z of every point, sample after sample

**MDD** (LightWave/Blender), big-endian::

    0       4     int32       number of frames S
    4       4     int32       number of points P
    8       S*4   float32     time of each frame in seconds
    8+S*4   S*P*12 float32    x, y, z of every point, frame after frame

(No "rest frame" before the first frame: the LightWave layout; Blender's
MESH_CACHE modifier reads frames from right after the time table.)

**OBJ sequence**: ``<stem>_<frame>.obj`` (frame = round(t * fps), zero-padded
to 4 digits) next to the given path, each a complete OBJ with ``v`` lines and
the original polygons as ``f`` lines (1-based).

Hand-written because these formats are a header plus a float array; no kept
library writes them.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.animation.tracks import Timeline
from workbench.export.base import ExportError, ExportResult, LayerReport, atomic_path
from workbench.export.encoding import MeshEncoding

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["PC2_HEADER", "write", "write_mdd", "write_obj_sequence", "write_pc2"]

#: numpy dtype of the 32-byte PC2 header
PC2_HEADER = np.dtype(
    [
        ("signature", "S12"),
        ("version", "<i4"),
        ("points", "<i4"),
        ("start_frame", "<f4"),
        ("sample_rate", "<f4"),
        ("samples", "<i4"),
    ]
)
_CHUNK = 16  # frames evaluated at once (bounds memory at 100k vertices)


def _frames(
    model: FaceModel, timeline: Timeline
) -> tuple[NDArray[np.float64], Iterator[NDArray[np.float32]], list[LayerReport]]:
    """Frame times, an iterator of (chunk, n, 3) float32 positions in metres, and the layer report."""
    enc = MeshEncoding(model, timeline)
    times = timeline.frame_times()
    mpu = np.float32(model.metadata.metres_per_unit)
    enc.fold_constant_baked(times)
    enc.baked_report(times, "per-frame positions")
    enc.all_baked_report("in the per-frame positions")

    def gen() -> Iterator[NDArray[np.float32]]:
        for a in range(0, times.size, _CHUNK):
            P = enc.points(times[a : a + _CHUNK])
            if mpu != 1:
                P *= mpu
            yield P

    return times, gen(), enc.layers


def write_pc2(model: FaceModel, timeline: Timeline, path: Path) -> ExportResult:
    """Write a PC2 point cache (layout in the module docstring)."""
    times, chunks, layers = _frames(model, timeline)
    header = np.zeros((), PC2_HEADER)
    header["signature"] = b"POINTCACHE2\0"
    header["version"] = 1
    header["points"] = model.n_vertices
    header["start_frame"] = timeline.start * timeline.fps
    header["sample_rate"] = 1.0
    header["samples"] = times.size
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(header.tobytes())
        for P in chunks:
            fh.write(P.astype("<f4").tobytes())
        fh.flush()
        os.fsync(fh.fileno())
    return ExportResult([path], layers)


def write_mdd(model: FaceModel, timeline: Timeline, path: Path) -> ExportResult:
    """Write an MDD point cache (layout in the module docstring)."""
    times, chunks, layers = _frames(model, timeline)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(np.array([times.size, model.n_vertices], ">i4").tobytes())
        fh.write(times.astype(">f4").tobytes())
        for P in chunks:
            fh.write(P.astype(">f4").tobytes())
        fh.flush()
        os.fsync(fh.fileno())
    return ExportResult([path], layers)


def _face_lines(model: FaceModel) -> str:
    polys = model.polygons
    sizes = polys.sizes
    idx1 = polys.indices.astype(np.int64) + 1
    if np.all(sizes == sizes[0]):
        fmt = "f" + " %d" * int(sizes[0]) + "\n"
        return (fmt * len(polys)) % tuple(idx1.tolist())
    return "".join(
        "f " + " ".join(map(str, idx1[polys.offsets[i] : polys.offsets[i + 1]])) + "\n"
        for i in range(len(polys))
    )


def write_obj_sequence(model: FaceModel, timeline: Timeline, path: Path) -> ExportResult:
    """Write ``<stem>_<frame:04d>.obj`` files (one per frame); returns their paths."""
    times, chunks, layers = _frames(model, timeline)
    faces = _face_lines(model)
    frames = np.rint(times * timeline.fps).astype(np.int64)
    if np.unique(frames).size != frames.size:
        raise ExportError(f"{path.name}: frame numbers collide; use a whole fps")
    n = model.n_vertices
    vfmt = "v %.7g %.7g %.7g\n" * n
    out: list[Path] = []
    f = 0
    for P in chunks:
        for frame_pts in P:
            p = path.with_name(f"{path.stem}_{frames[f]:04d}.obj")
            text = (
                f"# Facial Editing Workbench, frame {frames[f]} (t = {times[f]:.6g} s), metres\n"
                f"o {model.metadata.name or 'face'}\n"
                + vfmt % tuple(frame_pts.astype(np.float64).reshape(-1).tolist())
                + faces
            )
            with atomic_path(p) as tmp:
                tmp.write_text(text, encoding="utf-8")
            out.append(p)
            f += 1
    return ExportResult(out, layers)


def write(
    model: FaceModel, timeline: Timeline, path: Path, *, bake: bool = True, kind: str | None = None
) -> ExportResult:
    """Registry entry: ``kind`` (or the suffix) picks PC2, MDD or OBJ; ``bake`` is implied."""
    k = kind or path.suffix.lower().lstrip(".")
    if k == "pc2":
        return write_pc2(model, timeline, path)
    if k == "mdd":
        return write_mdd(model, timeline, path)
    if k == "obj":
        return write_obj_sequence(model, timeline, path)
    raise ExportError(f"{path.name}: unknown point-cache kind {k!r} (pc2, mdd, obj)")
