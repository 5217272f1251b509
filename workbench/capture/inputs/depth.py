"""Depth frames → points: :func:`depth_to_points` and :func:`read_depth_frames`.

:func:`depth_to_points` back-projects one (H, W) depth image through a pinhole
camera (OpenCV convention: pixel ``(u, v)`` is column ``u``, row ``v``, integer
coordinates at pixel centres; ``x = (u − cx) z / fx``, ``y = (v − cy) z / fy``;
no lens distortion — give rectified depth). Zero (and NaN) depth is "no
measurement" and dropped. Returned axes: ``axes="y_up"`` (default) is the
workbench's frame, +x right, **+y up, +z toward the camera**, so a face looking
into the camera looks along +z like the sample head (``up_axis="+y"``,
``front_axis="+z"``); ``axes="opencv"`` is the camera's own frame, +x right,
+y down, +z forward (away from the camera); the two differ by the sign of y
and z. :func:`read_depth_frames` reads a folder of 16-bit single-channel PNGs
(Pillow) with :func:`~workbench.capture.inputs.intrinsics.read_intrinsics`
(``fx, fy, cx, cy``, or Open3D's ``intrinsic_matrix``, or ``K``; optional
``width``, ``height``, ``depth_scale`` in metres per depth unit, ``fps``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.inputs.clouds import PointCloudSequence, _natural_key
from workbench.capture.inputs.errors import CaptureInputError
from workbench.capture.inputs.intrinsics import (
    CameraIntrinsics,
    _check_depth_scale,
    read_intrinsics,
)
from workbench.capture.inputs.units import DEFAULT_FPS
from workbench.core.shapes import UNIT_TO_METRES

__all__ = ["DEPTH_RANGE", "depth_to_points", "read_depth_frames"]

log = logging.getLogger("workbench.capture")

#: (smallest, largest) plausible median depth in metres of a depth frame
DEPTH_RANGE: tuple[float, float] = (0.02, 50.0)


_AXES = ("y_up", "opencv")


def depth_to_points(
    depth: ArrayLike,
    intrinsics: CameraIntrinsics | Mapping[str, Any] | ArrayLike,
    *,
    depth_scale: float = 0.001,
    stride: int = 1,
    max_depth: float | None = None,
    min_depth: float = 0.0,
    roi: tuple[int, int, int, int] | None = None,
    axes: str = "y_up",
) -> NDArray[np.float64]:
    """Back-project a depth image through a pinhole camera (module docstring for conventions).

    Parameters
    ----------
    depth : (H, W) array_like of unsigned int or float
        Depth along the optical axis (not the ray length) in depth units; 0 or
        NaN = no measurement.
    intrinsics : CameraIntrinsics, mapping, (fx, fy, cx, cy) or (3, 3)
        Pinhole intrinsics in pixels (see :func:`read_intrinsics`).
    depth_scale : float
        Metres per depth unit (0.001: millimetres, as Kinect / RealSense PNGs).
    stride : int
        Use every ``stride``-th pixel in both directions (rows and columns
        0, stride, 2 stride, ...).
    max_depth, min_depth : float
        Keep points with ``min_depth < z <= max_depth`` metres (``max_depth``
        None: no limit).
    roi : (u0, v0, u1, v1), optional
        Keep pixels with ``u0 <= u < u1`` and ``v0 <= v < v1`` (e.g. the face box).
    axes : {"y_up", "opencv"}
        "y_up": +x right, +y up, +z toward the camera (the workbench's frame);
        "opencv": +x right, +y down, +z forward.

    Returns
    -------
    (p, 3) float64
        Points in metres, in row-major pixel order (row by row, left to right).

    Raises
    ------
    ValueError
        ``depth`` not 2-D or not numeric, negative depth, bad intrinsics,
        ``depth_scale``, ``stride``, ``roi`` or ``axes``.

    Examples
    --------
    >>> d = np.full((2, 2), 1000, np.uint16)              # a wall 1 m away
    >>> depth_to_points(d, (100.0, 100.0, 0.5, 0.5), axes="opencv")
    array([[-0.005, -0.005,  1.   ],
           [ 0.005, -0.005,  1.   ],
           [-0.005,  0.005,  1.   ],
           [ 0.005,  0.005,  1.   ]])
    """
    K = read_intrinsics(intrinsics)
    D = np.asarray(depth)
    if D.ndim != 2:
        raise ValueError(f"depth: expected an (H, W) image, got shape {D.shape}")
    if D.dtype.kind not in "uif" or D.dtype == np.bool_:
        raise ValueError(f"depth: expected unsigned integers or floats, got dtype {D.dtype}")
    _check_depth_scale("<depth>", float(depth_scale), "depth_scale")
    if axes not in _AXES:
        raise ValueError(f"axes: expected one of {_AXES}, got {axes!r}")
    if int(stride) != stride or stride < 1:
        raise ValueError(f"stride: expected a whole number >= 1, got {stride!r}")
    H, W = D.shape
    box = (0, 0, W, H) if roi is None else tuple(int(x) for x in roi)
    if len(box) != 4:
        raise ValueError(f"roi: expected (u0, v0, u1, v1), got {roi!r}")
    u0, v0, u1, v1 = box
    if not (0 <= u0 < u1 <= W and 0 <= v0 < v1 <= H):
        raise ValueError(f"roi: expected 0 <= u0 < u1 <= {W} and 0 <= v0 < v1 <= {H}, got {roi}")
    s = int(stride)
    sub = D[v0:v1:s, u0:u1:s].astype(np.float64)
    if D.dtype.kind in "if":
        neg = np.nan_to_num(sub, nan=0.0) < 0
        if neg.any():
            r, c = (int(x) for x in np.argwhere(neg)[0])
            raise ValueError(
                f"depth: negative value {sub[r, c]:g} at row {v0 + r * s}, column {u0 + c * s}"
            )
        if np.isinf(sub).any():
            r, c = (int(x) for x in np.argwhere(np.isinf(sub))[0])
            raise ValueError(f"depth: infinite value at row {v0 + r * s}, column {u0 + c * s}")
    z = sub * float(depth_scale)
    ok = np.isfinite(z) & (z > max(float(min_depth), 0.0))
    if max_depth is not None:
        ok &= z <= float(max_depth)
    vv, uu = np.nonzero(ok)
    zz = z[vv, uu]
    u = (u0 + uu * s).astype(np.float64)
    v = (v0 + vv * s).astype(np.float64)
    x = (u - K.cx) * zz / K.fx
    y = (v - K.cy) * zz / K.fy
    if axes == "y_up":
        return np.column_stack([x, -y, -zz])
    return np.column_stack([x, y, zz])


def _read_depth_png(f: Path, t: int) -> NDArray[np.uint16]:
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - pillow is a dependency of the core
        raise ImportError(
            "reading depth PNGs needs Pillow: pip install pillow"
        ) from None
    try:
        with Image.open(f) as im:
            im.load()
            mode = im.mode
            fmt = im.format
            a = np.asarray(im)
    except Exception as exc:  # PIL raises UnidentifiedImageError, OSError, SyntaxError ...
        raise CaptureInputError(
            str(f), f"cannot read the image: {exc}", frame=t, field="file"
        ) from None
    if fmt != "PNG":
        raise CaptureInputError(str(f), f"expected a PNG, got {fmt}", frame=t, field="file")
    if mode in ("I;16", "I;16B", "I;16L"):
        return np.asarray(a, np.uint16)
    if (
        mode == "I" and a.size and a.min() >= 0 and a.max() <= 65535
    ):  # older Pillow opens 16-bit grey as I
        return a.astype(np.uint16)
    raise CaptureInputError(
        str(f),
        f"expected a 16-bit single-channel (grayscale) depth PNG, got mode {mode!r}"
        f"{' (8-bit: depth would be quantised to 256 levels)' if mode == 'L' else ''}",
        frame=t,
        field="image mode",
    )


def read_depth_frames(
    folder: str | Path,
    intrinsics: str | Path | Mapping[str, Any] | ArrayLike | CameraIntrinsics,
    *,
    depth_scale: float | None = None,
    stride: int = 1,
    max_depth: float | None = None,
    min_depth: float = 0.0,
    roi: tuple[int, int, int, int] | None = None,
    axes: str = "y_up",
    fps: float | None = None,
    allow_empty: bool = False,
    check_units: bool = True,
) -> PointCloudSequence:
    """A folder of 16-bit depth PNGs (sorted naturally) → point clouds in metres.

    Parameters
    ----------
    folder : str or Path
        Folder of ``.png`` depth images, one per frame, all the same size.
    intrinsics : str, Path, mapping, (fx, fy, cx, cy), (3, 3) or CameraIntrinsics
        See :func:`read_intrinsics` (a JSON file path is typical).
    depth_scale : float, optional
        Metres per depth unit; wins over the intrinsics' ``depth_scale``;
        0.001 (millimetres) when neither gives it.
    stride, max_depth, min_depth, roi, axes
        As :func:`depth_to_points`.
    fps : float, optional
        Frames per second; wins over the intrinsics' ``fps`` (else 30, warned).
    allow_empty : bool
        Accept frames with no valid depth (flagged by ``.empty``).
    check_units : bool
        Refuse frames whose median depth is not 2 cm – 50 m (a wrong
        ``depth_scale``), naming the frame.

    Returns
    -------
    PointCloudSequence
        ``units`` is "mm" for ``depth_scale=0.001`` (the unit of the depth
        values: "m" for 1, "cm" for 0.01, ...; "m" for any other scale).

    Raises
    ------
    FileNotFoundError
        No such folder.
    CaptureInputError
        Naming the file, the frame and what is wrong: not a 16-bit
        single-channel PNG, a size other than the intrinsics' or the first
        frame's, an empty frame, an implausible depth.
    """
    p = Path(folder)
    src = str(p)
    if not p.is_dir():
        raise FileNotFoundError(f"{p}: no such folder")
    K = read_intrinsics(intrinsics)
    ds = (
        depth_scale
        if depth_scale is not None
        else (K.depth_scale if K.depth_scale is not None else 0.001)
    )
    _check_depth_scale(src, float(ds), "depth_scale")
    if axes not in _AXES:
        raise ValueError(f"axes: expected one of {_AXES}, got {axes!r}")
    files = sorted(
        (f for f in p.iterdir() if f.is_file() and f.suffix.lower() == ".png"),
        key=lambda f: _natural_key(f.name),
    )
    if not files:
        raise CaptureInputError(src, "the folder has no .png files", field="folder")
    frames = []
    size: tuple[int, int] | None = None
    lo, hi = DEPTH_RANGE
    for t, f in enumerate(files):
        D = _read_depth_png(f, t)
        H, W = D.shape
        if (K.width is not None and W != K.width) or (K.height is not None and H != K.height):
            raise CaptureInputError(
                str(f),
                f"the image is {W}x{H} pixels, the intrinsics are for {K.width}x{K.height}",
                frame=t,
                field="image size",
            )
        if size is not None and (H, W) != size:
            raise CaptureInputError(
                str(f),
                f"the image is {W}x{H} pixels, frame 0 ({files[0].name}) is {size[1]}x{size[0]}",
                frame=t,
                field="image size",
            )
        size = (H, W)
        try:
            P = depth_to_points(
                D,
                K,
                depth_scale=float(ds),
                stride=stride,
                max_depth=max_depth,
                min_depth=min_depth,
                roi=roi,
                axes=axes,
            )
        except ValueError as exc:
            raise CaptureInputError(str(f), str(exc), frame=t, field="depth") from None
        if P.shape[0] == 0 and not allow_empty:
            raise CaptureInputError(
                str(f),
                "no pixel has a valid depth (pass allow_empty=True to keep such frames, flagged)",
                frame=t,
                field="depth",
            )
        if check_units and P.shape[0]:
            med = float(np.median(np.abs(P[:, 2])))
            if not lo <= med <= hi:
                raw = med / float(ds)
                raise CaptureInputError(
                    str(f),
                    f"median depth {med:.4g} m with depth_scale={float(ds):g} ({raw:.4g} depth units), not "
                    f"{lo:g}-{hi:g} m: is depth_scale right? (0.001 for millimetre depth; or check_units=False)",
                    frame=t,
                    field="depth_scale",
                )
        frames.append(P)
    unit = next((u for u, m in UNIT_TO_METRES.items() if math.isclose(m, float(ds))), "m")
    rate = fps if fps is not None else K.fps
    if rate is None:
        log.warning("%s: no frame rate given; %g fps assumed (pass fps=)", p.name, DEFAULT_FPS)
        rate = DEFAULT_FPS
    if not (math.isfinite(rate) and rate > 0):
        raise CaptureInputError(src, f"fps must be > 0, got {rate!r}", field="fps")
    return PointCloudSequence(
        tuple(frames), float(rate), unit, None, tuple(f.name for f in files), src
    )
