"""CSV of per-frame blendshape weights (re-importable with :mod:`workbench.animation.importers`).

Two layouts:

``style="plain"`` (default)
    ``time,<shape>,<shape>,...`` — time in seconds, one row per frame, one
    column per model shape, values with 9 significant digits (float32 exact).
``style="livelink"``
    Live Link Face's ``Timecode,BlendShapeCount,<Name>,...`` with SMPTE-like
    ``HH:MM:SS:FF.fff`` timecodes at the timeline fps and ARKit shapes spelled
    as Live Link Face does (``EyeBlinkLeft``); non-ARKit shapes keep their name.

Rows hold what the model plays at each frame
(:meth:`workbench.export.encoding.MeshEncoding.weights`): unkeyed shapes at
their current weight, keyed weights clamped to the slider range, muted shapes
0. A CSV carries weights only: the editing layers (regions, handles, paint,
wrinkles) cannot go into it; every active one is reported as ``"omitted"``
in the returned :class:`~workbench.export.ExportResult` and logged as a
warning — export a mesh format (glTF, USD, PC2/MDD) to keep them. Written
with the csv module into a temporary file, then renamed.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import TYPE_CHECKING

from workbench.animation.tracks import Timeline
from workbench.arkit import canonical_arkit_name
from workbench.export.base import ExportError, ExportResult, LayerReport, atomic_path
from workbench.export.encoding import MeshEncoding

if TYPE_CHECKING:
    from workbench.model import FaceModel

__all__ = ["timecode", "write"]


def timecode(t: float, fps: float) -> str:
    """``HH:MM:SS:FF.fff`` for ``t`` seconds at ``fps`` (FF = frame within the second)."""
    frames_total = t * fps
    whole = math.floor(frames_total + 1e-9)
    frac = max(frames_total - whole, 0.0)
    per_sec = round(fps)
    if abs(per_sec - fps) > 1e-9:
        raise ExportError(f"Live Link Face timecodes need a whole fps, got {fps}")
    secs, ff = divmod(int(whole), per_sec)
    h, rem = divmod(secs, 3600)
    m, s = divmod(rem, 60)
    return f"{h:02d}:{m:02d}:{s:02d}:{ff:02d}.{round(frac * 1000):03d}"


def write(
    model: FaceModel, timeline: Timeline, path: Path, *, bake: bool = True, style: str = "plain"
) -> ExportResult:
    """Write the weights of every shape at every frame (see module docstring)."""
    if style not in ("plain", "livelink"):
        raise ExportError(f"CSV style must be 'plain' or 'livelink', got {style!r}")
    enc = MeshEncoding(model, timeline)
    times = timeline.frame_times()
    W = enc.weights(times)
    # registered (non-built-in) layers are not evaluated here: reported as omitted
    layers = [
        LayerReport(r.name, "omitted", f"a CSV holds weights only; {r.detail}")
        if r.encoding in ("linear", "baked") else r
        for r in enc.layers
    ]
    names = list(model.shape_names)
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        if style == "plain":
            w.writerow(["time", *names])
            for t, row in zip(times, W, strict=True):
                w.writerow([f"{t:.9g}", *(f"{x:.9g}" for x in row)])
        else:
            cols = []
            for n in names:
                c = canonical_arkit_name(n)
                cols.append(c[0].upper() + c[1:] if c is not None else n)
            w.writerow(["Timecode", "BlendShapeCount", *cols])
            for t, row in zip(times, W, strict=True):
                w.writerow([timecode(float(t), timeline.fps), len(names), *(f"{x:.9g}" for x in row)])
    return ExportResult([path], layers)
