"""Point clouds from files → :class:`~workbench.capture.inputs.clouds.PointCloudSequence`.

:func:`read_point_clouds` reads a folder of ``.ply`` files (one frame each,
sorted *naturally*: ``f2.ply`` before ``f10.ply``; read with trimesh; ``nx ny
nz`` vertex properties become normals; a ``comment units: mm`` header line
states the unit), one ``.ply`` (one frame), or one ``.npz`` holding either

* ``points_0000, points_0001, ...`` — one (p_t, 3) array per frame, numbered
  from 0 without gaps (any zero padding), optional ``normals_0000, ...``;
* ``points`` (P, 3) all frames concatenated, with ``counts`` (T,) points per
  frame *or* ``offsets`` (T+1,) (frame t is ``points[offsets[t]:offsets[t+1]]``),
  optional ``normals`` (P, 3);
* ``points`` (T, p, 3) — equal-sized frames, optional ``normals`` (T, p, 3);

plus optional ``fps`` and ``units`` (0-d). An empty frame is an error naming
it unless ``allow_empty=True`` (then :attr:`PointCloudSequence.empty` flags it).
"""

from __future__ import annotations

import io
import logging
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.capture.inputs.clouds import PointCloudSequence, _natural_key
from workbench.capture.inputs.errors import CaptureInputError
from workbench.capture.inputs.npz import _npz_array, _npz_scalar, _open_npz
from workbench.capture.inputs.units import (
    DEFAULT_FPS,
    _check_span,
    _frame_span,
    _resolve_unit,
)

__all__ = ["read_point_clouds"]

log = logging.getLogger("workbench.capture")

_PLY_UNITS = re.compile(rb"^comment\s+units?\s*[:=]?\s*(\S+)", re.IGNORECASE | re.MULTILINE)


def _unit_normals(N: NDArray[np.float64]) -> NDArray[np.float64]:
    n = np.linalg.norm(N, axis=1, keepdims=True)
    return np.divide(N, n, out=np.zeros_like(N), where=n > 0)


def _check_points(src: str, P: NDArray[Any], frame: int, field: str) -> NDArray[np.float64]:
    if P.dtype.kind not in "fiu":
        raise CaptureInputError(
            src, f"expected numbers, got dtype {P.dtype}", frame=frame, field=field
        )
    Q = np.asarray(P, np.float64)
    if Q.shape == (0,):
        Q = Q.reshape(0, 3)
    if Q.ndim != 2 or Q.shape[1] != 3:
        raise CaptureInputError(
            src, f"expected (points, 3), got shape {Q.shape}", frame=frame, field=field
        )
    bad = ~np.isfinite(Q).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise CaptureInputError(
            src,
            f"point {i} is not finite ({Q[i].tolist()}); {int(bad.sum())} such point(s)",
            frame=frame,
            field=field,
        )
    return Q


def _read_ply(
    p: Path, frame: int
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, str | None]:
    """(points, normals or None, the header's unit or None) of one PLY file, in its unit."""
    src = str(p)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise CaptureInputError(src, f"cannot read: {exc}", frame=frame, field="file") from None
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise CaptureInputError(
            src, "not a PLY file (no 'ply' ... 'end_header' header)", frame=frame, field="header"
        )
    head = data[:end]
    m = re.search(rb"^element\s+vertex\s+(\d+)", head, re.MULTILINE)
    if not m:
        raise CaptureInputError(
            src, "the header declares no 'element vertex'", frame=frame, field="header"
        )
    n_declared = int(m.group(1))
    vblock = head[m.end() :]
    nxt = re.search(rb"^element\s", vblock, re.MULTILINE)
    vprops = re.findall(
        rb"^property\s+\S+\s+(\S+)", vblock[: nxt.start()] if nxt else vblock, re.MULTILINE
    )
    names = [v.decode("ascii", "replace") for v in vprops]
    for ax in "xyz":
        if ax not in names:
            raise CaptureInputError(
                src,
                f"the vertex element has no '{ax}' property (has {names})",
                frame=frame,
                field="element vertex",
            )
    um = _PLY_UNITS.search(head)
    unit = um.group(1).decode("ascii", "replace") if um else None
    if n_declared == 0:
        return np.zeros((0, 3)), None, unit
    from trimesh.exchange.ply import load_ply

    try:
        kw = load_ply(io.BytesIO(data), fix_texture=False, skip_materials=True)
    except Exception as exc:  # trimesh raises ValueError, IndexError, struct errors ...
        raise CaptureInputError(
            src, f"trimesh cannot read the PLY (truncated or damaged?): {exc}", frame=frame, field="file"
        ) from None
    V = np.asarray(kw.get("vertices", np.zeros((0, 3))), np.float64)
    if V.shape != (n_declared, 3):
        raise CaptureInputError(
            src,
            f"read {V.shape[0]} vertices, the header declares {n_declared} (truncated?)",
            frame=frame,
            field="element vertex",
        )
    P = _check_points(src, V, frame, "element vertex")
    N = None
    if all(k in names for k in ("nx", "ny", "nz")) and "vertex_normals" in kw:
        N = np.asarray(kw["vertex_normals"], np.float64).reshape(-1, 3)
        if N.shape != P.shape or not np.isfinite(N).all():
            raise CaptureInputError(
                src, "normals (nx, ny, nz) are not finite", frame=frame, field="element vertex"
            )
        N = _unit_normals(N)
    return P, N, unit


_NPZ_CLOUD_META = ("fps", "units")


def _read_cloud_npz(
    p: Path,
) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]] | None, str | None, float | None]:
    src = str(p)
    data = _open_npz(p)
    if isinstance(data, np.ndarray):
        raise CaptureInputError(
            src, "a .npy holds one array; point clouds need an .npz (see layouts)", field="file"
        )
    with data as z:
        keys = list(z.files)
        units = _npz_scalar(src, z, "units", str) if "units" in keys else None
        fps = _npz_scalar(src, z, "fps", float) if "fps" in keys else None
        per = {k for k in keys if re.fullmatch(r"(points|normals)_\d+", k)}
        rest = [k for k in keys if k not in per and k not in _NPZ_CLOUD_META]
        layouts = (
            "'points_0000', 'points_0001', ... (optional 'normals_0000', ...); or 'points' (P, 3) with "
            "'counts' (T,) or 'offsets' (T+1,) (optional 'normals'); or 'points' (T, p, 3); "
            "plus optional 'fps', 'units'"
        )
        if per:
            if rest:
                raise CaptureInputError(
                    src,
                    f"unexpected arrays {rest} next to 'points_NNNN'; expected {layouts}",
                    field="arrays",
                )
            idx = {int(k.split("_")[1]): k for k in per if k.startswith("points_")}
            nidx = {int(k.split("_")[1]): k for k in per if k.startswith("normals_")}
            if len(idx) != sum(k.startswith("points_") for k in per) or len(nidx) != sum(
                k.startswith("normals_") for k in per
            ):
                raise CaptureInputError(
                    src,
                    "two arrays have the same frame number (e.g. points_1 and points_001)",
                    field="arrays",
                )
            T = max(idx) + 1 if idx else 0
            missing = [t for t in range(T) if t not in idx]
            if missing:
                raise CaptureInputError(
                    src,
                    f"the arrays 'points_NNNN' must number the frames 0, 1, 2, ... without gaps; "
                    f"there is none for frame {missing[0]} (frames found: {sorted(idx)[:10]})",
                    frame=missing[0],
                    field="arrays",
                )
            if nidx and set(nidx) != set(idx):
                t = min(set(nidx) ^ set(idx))
                raise CaptureInputError(
                    src,
                    "normals are given for some frames but not this one",
                    frame=t,
                    field="arrays",
                )
            frames: list[NDArray[np.float64]] = [
                _check_points(src, _npz_array(src, z, idx[t]), t, f"array {idx[t]!r}")
                for t in range(T)
            ]
            normals: list[NDArray[np.float64]] | None = None
            if nidx:
                normals = []
                for t in range(T):
                    N = _check_points(src, _npz_array(src, z, nidx[t]), t, f"array {nidx[t]!r}")
                    if N.shape != frames[t].shape:
                        raise CaptureInputError(
                            src,
                            f"normals {N.shape} do not match points {frames[t].shape}",
                            frame=t,
                            field=f"array {nidx[t]!r}",
                        )
                    normals.append(_unit_normals(N))
            return frames, normals, units, fps
        if "points" not in keys:
            raise CaptureInputError(
                src, f"no point arrays; expected {layouts}; the file has {keys}", field="arrays"
            )
        extra = [k for k in rest if k not in ("points", "counts", "offsets", "normals")]
        if extra:
            raise CaptureInputError(
                src, f"unexpected arrays {extra}; expected {layouts}", field="arrays"
            )
        P = _npz_array(src, z, "points")
        Nall = _npz_array(src, z, "normals") if "normals" in keys else None
        if P.dtype.kind not in "fiu":
            raise CaptureInputError(
                src, f"expected numbers, got dtype {P.dtype}", field="array 'points'"
            )
        if Nall is not None and Nall.shape != P.shape:
            raise CaptureInputError(
                src, f"normals {Nall.shape} do not match points {P.shape}", field="array 'normals'"
            )
        if "counts" in keys and "offsets" in keys:
            raise CaptureInputError(src, "give 'counts' or 'offsets', not both", field="arrays")
        if P.ndim == 3:
            if "counts" in keys or "offsets" in keys:
                raise CaptureInputError(
                    src, "(T, p, 3) points take no counts/offsets", field="array 'points'"
                )
            if P.shape[2] != 3:
                raise CaptureInputError(
                    src, f"expected (T, p, 3), got {P.shape}", field="array 'points'"
                )
            bounds = np.arange(P.shape[0] + 1) * P.shape[1]
            P = P.reshape(-1, 3)
            Nall = None if Nall is None else Nall.reshape(-1, 3)
        else:
            if P.ndim != 2 or P.shape[1] != 3:
                raise CaptureInputError(
                    src, f"expected (P, 3) or (T, p, 3), got {P.shape}", field="array 'points'"
                )
            if "counts" in keys:
                c = _npz_array(src, z, "counts")
                if c.ndim != 1 or c.dtype.kind not in "iu" or (c < 0).any():
                    raise CaptureInputError(
                        src,
                        f"expected (T,) non-negative integers, got {c.dtype} {c.shape}",
                        field="array 'counts'",
                    )
                if int(c.sum()) != P.shape[0]:
                    raise CaptureInputError(
                        src,
                        f"counts sum to {int(c.sum())}, 'points' has {P.shape[0]} rows",
                        field="array 'counts'",
                    )
                bounds = np.concatenate([[0], np.cumsum(c)])
            elif "offsets" in keys:
                o = _npz_array(src, z, "offsets")
                if o.ndim != 1 or o.dtype.kind not in "iu" or o.size < 2:
                    raise CaptureInputError(
                        src,
                        f"expected (T+1,) integers, got {o.dtype} {o.shape}",
                        field="array 'offsets'",
                    )
                if o[0] != 0 or o[-1] != P.shape[0]:
                    raise CaptureInputError(
                        src,
                        f"must start at 0 and end at {P.shape[0]} (rows of 'points'), got {int(o[0])} .. {int(o[-1])}",
                        field="array 'offsets'",
                    )
                dec = np.flatnonzero(np.diff(o) < 0)
                if dec.size:
                    raise CaptureInputError(
                        src, "offsets decrease", frame=int(dec[0]), field="array 'offsets'"
                    )
                bounds = o.astype(np.int64)
            else:
                raise CaptureInputError(
                    src,
                    "(P, 3) points need 'counts' or 'offsets' to split them into frames",
                    field="array 'points'",
                )
        frames = []
        normals = [] if Nall is not None else None
        for t in range(len(bounds) - 1):
            a, b = int(bounds[t]), int(bounds[t + 1])
            frames.append(_check_points(src, P[a:b], t, "array 'points'"))
            if normals is not None and Nall is not None:
                normals.append(_unit_normals(_check_points(src, Nall[a:b], t, "array 'normals'")))
        return frames, normals, units, fps


def read_point_clouds(
    path: str | Path,
    *,
    units: str | None = None,
    fps: float | None = None,
    allow_empty: bool = False,
    check_units: bool = True,
) -> PointCloudSequence:
    """Read a point-cloud sequence: a folder of PLY files, one PLY, or one NPZ (module docstring).

    Parameters
    ----------
    path : str or Path
        A folder of ``.ply`` files (sorted naturally), a ``.ply`` or an ``.npz``.
    units : str, optional
        Unit of the coordinates; wins over the file's (``comment units: mm`` in
        a PLY header, ``units`` in the NPZ). One of them is required.
    fps : float, optional
        Frames per second; wins over the NPZ ``fps`` (30 with a warning when
        none is given).
    allow_empty : bool
        Accept frames without points (flagged by ``.empty``); else an empty
        frame is an error naming it.
    check_units : bool
        Refuse clouds whose spread is not 1 cm – 10 m in the unit.

    Returns
    -------
    PointCloudSequence
        Frames (p_t, 3) in metres, unit normals when the files have them.

    Raises
    ------
    FileNotFoundError
        No such file or folder.
    CaptureInputError
        Naming the file, the frame and the array/element at fault.
    """
    p = Path(path)
    src = str(p)
    labels: list[str]
    if p.is_dir():
        files = sorted(
            (f for f in p.iterdir() if f.is_file() and f.suffix.lower() == ".ply"),
            key=lambda f: _natural_key(f.name),
        )
        if not files:
            raise CaptureInputError(src, "the folder has no .ply files", field="folder")
        frames, nlist, file_units = [], [], []
        for t, f in enumerate(files):
            P, N, u = _read_ply(f, t)
            frames.append(P)
            nlist.append(N)
            file_units.append(u)
        stated = _agree_units([(files[t], t, u) for t, u in enumerate(file_units)], units is None)
        normals: list[NDArray[np.float64]] | None = None
        lacking = [
            t
            for t, (N, P) in enumerate(zip(nlist, frames, strict=True))
            if N is None and P.shape[0]
        ]
        if any(N is not None for N in nlist):
            if lacking:
                t = lacking[0]
                log.warning(
                    "%s: frame %d (%s) has no normals, other frames do; normals dropped",
                    p.name,
                    t,
                    files[t].name,
                )
            else:
                normals = [N if N is not None else np.zeros((0, 3)) for N in nlist]
        labels = [f.name for f in files]
        file_fps = None
        err_src = {t: str(files[t]) for t in range(len(files))}
    elif p.is_file() and p.suffix.lower() == ".ply":
        P, N, stated = _read_ply(p, 0)
        frames, normals, labels, file_fps = [P], (None if N is None else [N]), [p.name], None
        err_src = {0: src}
    elif p.is_file() and p.suffix.lower() == ".npz":
        frames, normals, stated, file_fps = _read_cloud_npz(p)
        labels = []
        err_src = {}
    elif not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    else:
        raise CaptureInputError(
            src, f"expected a folder of .ply files, a .ply or an .npz, got {p.name!r}", field="file"
        )
    if not frames:
        raise CaptureInputError(src, "no frames", field="file")
    u, mpu = _resolve_unit(
        src,
        units,
        stated,
        "add a 'comment units: mm' line to the PLY header / a 'units' array to the .npz",
    )
    counts = [f.shape[0] for f in frames]
    if not allow_empty and 0 in counts:
        t = counts.index(0)
        raise CaptureInputError(
            err_src.get(t, src),
            "the point cloud is empty (pass allow_empty=True to keep such frames, flagged)",
            frame=t,
            field="points",
        )
    frames = [f * mpu for f in frames]
    if check_units:
        _check_span(src, (_frame_span(f) for f in frames), u, mpu, "point clouds")
    rate = fps if fps is not None else file_fps
    if rate is None:
        log.warning("%s: no frame rate given; %g fps assumed (pass fps=)", p.name, DEFAULT_FPS)
        rate = DEFAULT_FPS
    if not (math.isfinite(rate) and rate > 0):
        raise CaptureInputError(src, f"fps must be > 0, got {rate!r}", field="fps")
    return PointCloudSequence(
        tuple(frames),
        float(rate),
        u,
        None if normals is None else tuple(normals),
        tuple(labels),
        src,
    )


def _agree_units(found: list[tuple[Path, int, str | None]], needed: bool) -> str | None:
    """The unit the PLY headers state; they must agree (when the caller gave none)."""
    stated = [(f, t, u) for f, t, u in found if u is not None]
    if not stated or not needed:
        return stated[0][2] if stated else None
    f0, t0, u0 = stated[0]
    for f, t, u in stated[1:]:
        if u is not None and u.lower() != u0.lower():
            raise CaptureInputError(
                str(f),
                f"the header states units {u!r}, frame {t0} ({f0.name}) states {u0!r}",
                frame=t,
                field="header",
            )
    return u0
