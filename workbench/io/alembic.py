"""Alembic (.abc) reader: a point cache (mesh sequence) as a frame sequence, through Blender's importer.

The registry's module for ``.abc`` (``detect``, ``read``, ``DESCRIPTION``).
There is no Alembic reader on PyPI for this Python, so the file is imported by
Blender's own Alembic importer (mesh sequence cache), run in the bpy venv
(:mod:`.blender_bridge`), which dumps every mesh's evaluated vertices at each
sample time of the archive. What the face holds:

* **neutral**: frame 0 (the first sample), every mesh under its world transform
  (several meshes become face groups named after the objects), y up, in the
  file's coordinates (Alembic states no unit: it is inferred from the size);
* **frames** (:attr:`ImportedFace.frames`, a :class:`FrameSequence`): every
  sample's positions and times, for the capture step;
* **shapes** ``frame_0001`` ... ``frame_<F-1>``: frame k minus frame 0, so the
  cache is a rig like any other; :func:`read_alembic_animation` gives the
  timeline that plays it (frame k's shape at weight 1 at its time, linear
  between neighbours: exactly the cache at its samples, linear in between, as
  Blender's vertex interpolation).

The sample times come from the archive itself: before Blender runs, the Ogawa
container is walked by a checked reader (:func:`read_time_samplings`): every
group and data offset is checked against the file size, and the time samplings
(uniform, cyclic or acyclic) are decoded; the sampling with the most samples
drives the frames (Blender's scene rate is set to it). A truncated or damaged
container, an unfinished file (written by a crashed exporter) or an HDF5
archive (Blender reads Ogawa only) fails with a :class:`MeshFormatError` naming
the file and the field before Blender runs. A mesh whose vertex count changes
between samples is not a point cache and is refused.
"""

from __future__ import annotations

import itertools
import logging
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from workbench.animation.baked_frames import baked_frames_timeline, frame_shape_name
from workbench.geometry.mesh_checks import MeshFormatError
from workbench.io.base import FrameSequence, ImportedFace
from workbench.io.blender_bridge import run_dump
from workbench.io.parts import Part, merge_parts, polygons_from_counts, reverse_winding, to_y_up

__all__ = [
    "DESCRIPTION",
    "TimeSampling",
    "detect",
    "frame_shape_name",
    "read",
    "read_alembic",
    "read_alembic_animation",
    "read_time_samplings",
]

log = logging.getLogger("workbench.io")

DESCRIPTION = (
    "an Alembic .abc point cache (a mesh sequence: frame 0 is the neutral, each later frame a "
    "shape frame_NNNN; read by Blender's importer in the bpy venv, WORKBENCH_BPY_PYTHON)"
)

OGAWA_MAGIC = b"Ogawa"
HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_DATA_BIT = 1 << 63
#: Alembic's time per cycle of an acyclic sampling (DBL_MAX / 32)
ACYCLIC_TPC = 1.7976931348623157e308 / 32.0
_MAX_NODES = 5_000_000
#: most frames read from one cache
MAX_FRAMES = 100_000


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() == ".abc"


def read(path: Path) -> ImportedFace:
    return read_alembic(path)


@dataclass(frozen=True)
class TimeSampling:
    """One time sampling of an Alembic archive.

    ``max_samples`` is the most samples any property written with it has;
    ``time_per_cycle`` and ``cycle_times`` as stored (uniform: one time,
    cyclic: several, acyclic: every time with ``time_per_cycle`` = :data:`ACYCLIC_TPC`).
    """

    max_samples: int
    time_per_cycle: float
    cycle_times: tuple[float, ...]

    @property
    def acyclic(self) -> bool:
        return self.time_per_cycle >= ACYCLIC_TPC * 0.999

    def times(self, n: int | None = None) -> NDArray[np.float64]:
        """The first ``n`` (default ``max_samples``) sample times, seconds."""
        n = self.max_samples if n is None else n
        c = np.asarray(self.cycle_times, np.float64)
        if self.acyclic:
            return c[:n].copy()
        k = np.arange(n)
        return c[k % c.size] + (k // c.size) * self.time_per_cycle

    @property
    def fps(self) -> float:
        if self.acyclic:
            t = self.times()
            return float(1.0 / np.median(np.diff(t))) if t.size > 1 else 24.0
        return len(self.cycle_times) / self.time_per_cycle


class _Ogawa:
    """Checked access to an Ogawa container: groups and data blocks inside the file."""

    def __init__(self, data: bytes, src: str) -> None:
        self.d = data
        self.src = src
        self.size = len(data)
        self.seen = 0

    def fail(self, where: str, msg: str) -> NoReturn:
        raise MeshFormatError(self.src, where, f"{where}: {msg}")

    def group(self, off: int, where: str) -> list[int]:
        if off == 0:
            return []
        if off + 8 > self.size:
            self.fail(where, f"group at byte {off} lies beyond the end of the file ({self.size} bytes): truncated")
        n = struct.unpack_from("<Q", self.d, off)[0]
        if off + 8 + 8 * n > self.size:
            self.fail(where, f"group at byte {off} lists {n} children, which run past the end of the file ({self.size} bytes)")
        return list(struct.unpack_from(f"<{n}Q", self.d, off + 8))

    def data(self, ref: int, where: str) -> bytes:
        if not ref & _DATA_BIT:
            self.fail(where, f"expected a data block, found a group (reference {ref:#x})")
        off = ref & ~_DATA_BIT
        if off == 0:
            return b""
        if off + 8 > self.size:
            self.fail(where, f"data block at byte {off} lies beyond the end of the file ({self.size} bytes): truncated")
        n = struct.unpack_from("<Q", self.d, off)[0]
        if off + 8 + n > self.size:
            self.fail(where, f"data block at byte {off} holds {n} bytes, which run past the end of the file ({self.size} bytes)")
        return self.d[off + 8 : off + 8 + n]

    def walk(self, off: int, where: str, depth: int = 0) -> None:
        """Check every group and data block reachable from ``off`` lies inside the file."""
        stack = [(off, where, depth)]
        visited: set[int] = set()
        while stack:
            o, w, dep = stack.pop()
            if o in visited:
                continue
            visited.add(o)
            if dep > 256:
                self.fail(w, "groups nested more than 256 deep (a damaged or cyclic container)")
            for i, c in enumerate(self.group(o, w)):
                self.seen += 1
                if self.seen > _MAX_NODES:
                    self.fail(w, f"more than {_MAX_NODES} blocks (a damaged container)")
                if c & _DATA_BIT:
                    off_c = c & ~_DATA_BIT
                    if off_c:
                        self.data(c, f"{w}[{i}]")
                elif c:
                    stack.append((c, f"{w}[{i}]", dep + 1))


def _open(path: Path) -> tuple[_Ogawa, list[int]]:
    src = str(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MeshFormatError(src, "file", f"cannot read: {exc}") from None
    if data[:8] == HDF5_MAGIC:
        raise MeshFormatError(
            src, "header",
            "header: this is an HDF5 Alembic archive; Blender (and current Alembic tools) read Ogawa "
            "archives only: re-export it with Ogawa",
        )
    if len(data) < 16:
        raise MeshFormatError(src, "header", f"header: the file has {len(data)} bytes, fewer than Ogawa's 16-byte header")
    if data[:5] != OGAWA_MAGIC:
        raise MeshFormatError(src, "header", f"header: not an Alembic (Ogawa) file (expected {OGAWA_MAGIC!r}, found {data[:5]!r})")
    if data[5] != 0xFF:
        raise MeshFormatError(
            src, "header.frozen",
            "header.frozen: the archive was never finished by its writer (the exporter crashed or is "
            "still writing); nothing in it can be trusted",
        )
    version = struct.unpack_from(">H", data, 6)[0]
    if version != 1:
        raise MeshFormatError(src, "header.version", f"header.version: Ogawa version {version}, only 1 is known")
    og = _Ogawa(data, src)
    root = struct.unpack_from("<Q", data, 8)[0]
    if root & _DATA_BIT or root == 0:
        og.fail("header.root", f"the root reference {root:#x} is not a group")
    children = og.group(root, "root")
    if len(children) < 6:
        og.fail("root", f"the archive's root group has {len(children)} children, 6 expected (versions, objects, metadata, time samplings, indexed metadata)")
    return og, children


def read_time_samplings(path: str | Path) -> list[TimeSampling]:
    """Check an Alembic (Ogawa) archive's container and decode its time samplings.

    Raises
    ------
    MeshFormatError
        HDF5 or not Alembic, unfinished, truncated or damaged; names the field.
    """
    p = Path(path)
    og, ch = _open(p)
    for i, name in ((0, "archive version"), (1, "library version")):
        if len(og.data(ch[i], f"root[{i}] ({name})")) != 4:
            og.fail(f"root[{i}] ({name})", "expected a 4-byte integer")
    og.walk(ch[2], "objects")
    og.data(ch[3], "archive metadata")
    raw = og.data(ch[4], "time samplings")
    og.data(ch[5], "indexed metadata")
    out: list[TimeSampling] = []
    i = 0
    while i < len(raw):
        where = f"time samplings[{len(out)}]"
        if i + 16 > len(raw):
            og.fail(where, f"cut off after {len(raw) - i} bytes (16 expected: samples, time per cycle, count)")
        max_s, tpc, n = struct.unpack_from("<IdI", raw, i)
        i += 16
        if i + 8 * n > len(raw):
            og.fail(where, f"lists {n} times but only {(len(raw) - i) // 8} follow")
        times = struct.unpack_from(f"<{n}d", raw, i)
        i += 8 * n
        if n == 0:
            og.fail(where, "has no sample time")
        if not (math.isfinite(tpc) and tpc > 0):
            og.fail(f"{where}.timePerCycle", f"must be a positive finite number of seconds, got {tpc!r}")
        if not all(math.isfinite(t) for t in times):
            og.fail(f"{where}.times", f"not finite: {list(times)[:5]}")
        if any(b <= a for a, b in itertools.pairwise(times)):
            og.fail(f"{where}.times", "must be strictly increasing")
        ts = TimeSampling(int(max_s), float(tpc), tuple(float(t) for t in times))
        if not ts.acyclic and n > 1 and times[-1] - times[0] >= tpc:
            og.fail(f"{where}.times", f"a cycle of {tpc:g} s cannot hold times {times[0]:g} to {times[-1]:g}")
        if ts.acyclic and max_s > n:
            og.fail(f"{where}.maxSample", f"{max_s} samples but only {n} acyclic times")
        out.append(ts)
    if not out:
        og.fail("time samplings", "none (every archive has at least the identity sampling)")
    return out


def _sampling(tss: list[TimeSampling], src: str) -> TimeSampling | None:
    """The sampling that drives the frames: the one with most samples (None: a static archive)."""
    anim = [t for t in tss[1:] if t.max_samples > 1]
    if not anim and tss[0].max_samples > 1:
        anim = [tss[0]]
    if not anim:
        return None
    best = max(anim, key=lambda t: t.max_samples)
    if best.max_samples > MAX_FRAMES:
        raise MeshFormatError(src, "time samplings", f"time samplings: {best.max_samples} samples, more than {MAX_FRAMES} frames")
    return best


def _frames_for(times: NDArray[np.float64], fps: float) -> list[tuple[int, float]]:
    out = []
    for t in times:
        f = t * fps
        r = round(f)
        if abs(f - r) < 1e-6:
            out.append((int(r), 0.0))
        else:
            fl = math.floor(f)
            out.append((int(fl), float(f - fl)))
    return out


def read_alembic(path: str | Path) -> ImportedFace:
    """Read an Alembic point cache (see the module docstring).

    Raises
    ------
    FileNotFoundError
        No such file.
    MeshFormatError
        Malformed archive (checked before Blender runs), Blender's importer
        failed, non-finite points, or a mesh whose vertex count changes.
    workbench.io.blender_bridge.BlenderMissingError
        No Python with bpy.
    """
    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    tss = read_time_samplings(p)
    ts = _sampling(tss, src)
    times = ts.times() if ts is not None else np.zeros(1)
    fps = ts.fps if ts is not None else 24.0
    if not (math.isfinite(fps) and 0 < fps <= 1e5):
        raise MeshFormatError(src, "time samplings", f"time samplings: a frame rate of {fps!r} per second is not usable")
    dump = run_dump(p, "abc", fps=fps, frames=_frames_for(times, fps))
    parts: list[Part] = []
    stacks: list[NDArray[np.float64]] = []
    for i, ob in enumerate(dump.meta.get("objects", [])):
        what = f"object '{ob.get('name', i)}'"
        if "frame_error" in ob:
            f, sub, n = ob["frame_error"]
            raise MeshFormatError(
                src, what,
                f"{what}: has {n} vertices at frame {f + sub:g}, {ob['n']} at the first: the vertex count "
                "changes, so this is not a point cache of one mesh",
            )
        co = dump.array(f"o{i}_co", src, what)
        counts = dump.array(f"o{i}_counts", src, what)
        corners = dump.array(f"o{i}_corners", src, what)
        if co.shape[0] == 0 or counts.size == 0:
            log.info("%s: %s has no faces; skipped", p.name, what)
            continue
        P = np.asarray(dump.array(f"o{i}_frames", src, what), np.float64)
        M = np.asarray(dump.array(f"o{i}_frame_matrices", src, what), np.float64)
        if P.shape != (times.size, co.shape[0], 3) or M.shape != (times.size, 4, 4):
            raise MeshFormatError(
                src, what,
                f"{what}: Blender gave {P.shape[0]} frames of {P.shape[1:]} points, {times.size} x ({co.shape[0]}, 3) expected",
            )
        bad = ~np.isfinite(P).all(axis=(1, 2))
        if bad.any():
            k = int(np.argmax(bad))
            row = int(np.argmax(~np.isfinite(P[k]).all(axis=1)))
            raise MeshFormatError(src, f"{what}: P", f"{what}: P: frame {k} (t={times[k]:g} s) vertex {row} is not finite ({P[k, row].tolist()})")
        W = np.einsum("fij,fnj->fni", M[:, :3, :3], P) + M[:, None, :3, 3]
        W = to_y_up(W, "+z")
        polys = polygons_from_counts(counts, corners, co.shape[0], src, f"{what}: faces")
        if np.linalg.det(M[0, :3, :3]) < 0:
            polys = reverse_winding(polys)
        parts.append(Part(str(ob.get("name", i)), W[0], polys, [], what))
        stacks.append(W)
    if not parts:
        raise MeshFormatError(src, "objects", "objects: the archive has no polygon mesh")
    allW = np.concatenate(stacks, axis=1)
    frames = None
    if times.size > 1:
        frames = FrameSequence(times=times.astype(np.float64), positions=allW.astype(np.float32), fps=float(fps))
    face = merge_parts(parts, src, units=None, up_axis="+y", frames=frames)
    if frames is not None:
        base = allW[0]
        face.shapes = [(frame_shape_name(k), (allW[k] - base).astype(np.float32)) for k in range(1, times.size)]
    log.info(
        "%s: %d frames at %.6g fps from t=%.6g s (Alembic time sampling)",
        p.name, times.size, fps, float(times[0]),
    )
    return face


def read_alembic_animation(path: str | Path, shape_names: Sequence[str], *, fps: float | None = None) -> Any:
    """The timeline that plays a point cache read by :func:`read_alembic`.

    Shape ``frame_k`` has weight 1 at frame k's time and 0 at its neighbours'
    (linear keys), so every sample is reproduced exactly and positions are
    interpolated linearly in between.

    Raises
    ------
    AnimationImportError
        The archive is static or malformed, or the model lacks a frame shape.
    """
    from workbench.animation.importers import AnimationImportError

    p = Path(path)
    try:
        ts = _sampling(read_time_samplings(p), str(p))
    except MeshFormatError as exc:
        raise AnimationImportError(str(p), exc.detail) from None
    if ts is None:
        raise AnimationImportError(str(p), "the archive is static (one sample): no animation")
    t = ts.times()
    have = set(shape_names)
    missing = [frame_shape_name(k) for k in range(1, t.size) if frame_shape_name(k) not in have]
    if missing:
        raise AnimationImportError(
            str(p), f"the model has no shapes {missing[:5]}{'...' if len(missing) > 5 else ''} "
            f"(read the face with read_alembic first: frames 1..{t.size - 1} are its shapes)",
        )
    return baked_frames_timeline(t, fps or ts.fps)
