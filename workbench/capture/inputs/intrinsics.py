"""Pinhole depth-camera intrinsics: :class:`CameraIntrinsics` and :func:`read_intrinsics`.

:func:`read_intrinsics` takes ``fx, fy, cx, cy``, or Open3D's
``intrinsic_matrix``, or ``K`` (from a JSON file or a dict), ``(fx, fy, cx,
cy)`` or a (3, 3) matrix; optional ``width``, ``height``, ``depth_scale`` in
metres per depth unit, ``fps``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.inputs.errors import CaptureInputError

__all__ = ["CameraIntrinsics", "read_intrinsics"]


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole depth camera (OpenCV convention, pixels).

    Attributes
    ----------
    fx, fy : float
        Focal lengths in pixels (> 0).
    cx, cy : float
        Principal point in pixels (column, row of the optical axis).
    width, height : int or None
        Image size the intrinsics are for, if known (checked against the images).
    depth_scale : float or None
        Metres per depth unit (0.001 for millimetre depth), if the file gives it.
    fps : float or None
        Frame rate, if the file gives it.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int | None = None
    height: int | None = None
    depth_scale: float | None = None
    fps: float | None = None

    @property
    def K(self) -> NDArray[np.float64]:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def _num(src: str, v: Any, name: str, *, positive: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise CaptureInputError(
            src, f"expected a number, got {v!r:.30}", field=f"intrinsics {name!r}"
        )
    x = float(v)
    if not math.isfinite(x) or (positive and x <= 0):
        raise CaptureInputError(
            src,
            f"expected a finite {'positive ' if positive else ''}number, got {x!r}",
            field=f"intrinsics {name!r}",
        )
    return x


def read_intrinsics(
    source: str | Path | Mapping[str, Any] | ArrayLike | CameraIntrinsics,
) -> CameraIntrinsics:
    """Pinhole intrinsics from a JSON file, a dict, ``(fx, fy, cx, cy)`` or a (3, 3) matrix.

    JSON / dict keys: ``fx, fy, cx, cy``; or ``intrinsic_matrix`` (9 numbers,
    column-major, as Open3D's ``PinholeCameraIntrinsic`` JSON); or ``K`` (3x3,
    row-major). Optional: ``width``, ``height`` (pixels), ``depth_scale``
    (metres per depth unit, ≤ 1; Open3D's ``depth_scale`` is the inverse,
    units per metre), ``fps``.

    Raises
    ------
    CaptureInputError
        Naming the file and the field: missing or non-numeric values, a
        non-positive focal length, a matrix that is not a pinhole camera.
    """
    if isinstance(source, CameraIntrinsics):
        return source
    if isinstance(source, (str, Path)):
        p = Path(source)
        src = str(p)
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no such file")
        try:
            obj = json.loads(p.read_text(encoding="utf-8-sig"))
        except UnicodeDecodeError as exc:
            raise CaptureInputError(
                src, f"not UTF-8 text (byte {exc.start})", field="file"
            ) from None
        except json.JSONDecodeError as exc:
            raise CaptureInputError(src, f"not JSON: {exc.msg}", line=exc.lineno) from None
        if not isinstance(obj, Mapping):
            raise CaptureInputError(
                src, f"expected a JSON object, got {type(obj).__name__}", field="file"
            )
    elif isinstance(source, Mapping):
        src, obj = "<intrinsics>", source
    else:
        src = "<intrinsics>"
        a = np.asarray(source, dtype=np.float64)
        if a.shape == (4,):
            return read_intrinsics(dict(zip(("fx", "fy", "cx", "cy"), a.tolist(), strict=True)))
        if a.shape == (3, 3):
            return read_intrinsics({"K": a.tolist()})
        raise CaptureInputError(
            src,
            f"expected (fx, fy, cx, cy) or a (3, 3) matrix, got shape {a.shape}",
            field="intrinsics",
        )
    if all(k in obj for k in ("fx", "fy", "cx", "cy")):
        vals = [obj[k] for k in ("fx", "fy", "cx", "cy")]
        names = ["fx", "fy", "cx", "cy"]
    elif "intrinsic_matrix" in obj or "K" in obj:
        key = "intrinsic_matrix" if "intrinsic_matrix" in obj else "K"
        try:
            M = np.asarray(obj[key], dtype=np.float64)
        except (TypeError, ValueError):
            raise CaptureInputError(src, "expected numbers", field=f"intrinsics {key!r}") from None
        if key == "intrinsic_matrix":
            if M.size != 9:
                raise CaptureInputError(
                    src,
                    f"expected 9 numbers (column-major 3x3), got {M.size}",
                    field="intrinsics 'intrinsic_matrix'",
                )
            M = M.reshape(3, 3).T
        elif M.shape != (3, 3):
            raise CaptureInputError(
                src, f"expected a 3x3 matrix, got shape {M.shape}", field="intrinsics 'K'"
            )
        if (
            not np.isfinite(M).all()
            or abs(M[0, 1]) > 1e-9
            or np.any(np.abs(M[2] - [0, 0, 1]) > 1e-9)
            or abs(M[1, 0]) > 1e-9
        ):
            raise CaptureInputError(
                src,
                f"not a pinhole camera matrix [[fx,0,cx],[0,fy,cy],[0,0,1]]: {M.tolist()}",
                field=f"intrinsics {key!r}",
            )
        vals = [M[0, 0], M[1, 1], M[0, 2], M[1, 2]]
        names = [f"{key}[fx]", f"{key}[fy]", f"{key}[cx]", f"{key}[cy]"]
    else:
        raise CaptureInputError(
            src,
            f"expected fx, fy, cx, cy (or 'intrinsic_matrix' / 'K'); the object has {sorted(obj)[:10]}",
            field="intrinsics",
        )
    fx = _num(src, vals[0], names[0], positive=True)
    fy = _num(src, vals[1], names[1], positive=True)
    cx = _num(src, vals[2], names[2])
    cy = _num(src, vals[3], names[3])
    size: list[int | None] = []
    for k in ("width", "height"):
        if k in obj and obj[k] is not None:
            v = _num(src, obj[k], k, positive=True)
            if v != int(v):
                raise CaptureInputError(
                    src, f"expected whole pixels, got {v}", field=f"intrinsics {k!r}"
                )
            size.append(int(v))
        else:
            size.append(None)
    ds = None
    if obj.get("depth_scale") is not None:
        ds = _num(src, obj["depth_scale"], "depth_scale", positive=True)
        _check_depth_scale(src, ds, "intrinsics 'depth_scale'")
    rate = _num(src, obj["fps"], "fps", positive=True) if obj.get("fps") is not None else None
    return CameraIntrinsics(fx, fy, cx, cy, size[0], size[1], ds, rate)


def _check_depth_scale(src: str, ds: float, field: str) -> None:
    if not (math.isfinite(ds) and 0 < ds <= 1):
        hint = f" ({ds:g} looks like Open3D's units per metre: use {1 / ds:g})" if ds > 1 else ""
        raise CaptureInputError(
            src,
            f"depth_scale is metres per depth unit, 0 < depth_scale <= 1, got {ds:g}{hint}",
            field=field,
        )
