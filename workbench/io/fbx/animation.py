"""Blender's dump of the shape-key F-curves → a timeline.

Key frame ``f`` at ``f / fps`` seconds with the file's frame rate; constant,
linear and Bézier keys (Bézier handles become user tangents).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any


def _timeline(
    src: str,
    curves: dict[str, tuple[str, list[list[Any]]]],
    shape_names: Sequence[str],
    file_fps: float,
    fps: float,
    on_unknown: str,
) -> Any:
    from workbench.animation.curves import Key, Track, TrackError, weight_track_name
    from workbench.animation.importers import AnimationImportError, map_shape_names
    from workbench.animation.tracks import Timeline

    names = list(curves)
    mapping = map_shape_names(names, shape_names, src)
    unknown = [n for n in names if mapping[n] is None]
    if unknown and on_unknown != "ignore":
        raise AnimationImportError(
            src,
            f"unknown shape names {unknown[:10]}{'...' if len(unknown) > 10 else ''} (the model has no "
            "shape of that name or ARKit meaning; pass on_unknown='ignore' to skip them)",
        )
    tracks = {}
    for name in names:
        shape = mapping[name]
        if shape is None:
            continue
        keys = []
        for k, kp in enumerate(curves[name][1]):
            frame, value, interp = float(kp[0]), float(kp[1]), str(kp[2])
            t = frame / file_fps
            where = f"shape key '{name}' key {k} (frame {frame:g})"
            if not (math.isfinite(t) and math.isfinite(value)):
                raise AnimationImportError(src, f"{where}: time or value is not finite")
            if interp == "CONSTANT":
                keys.append(Key(t, value, "step"))
            elif interp == "LINEAR":
                keys.append(Key(t, value, "linear"))
            elif interp == "BEZIER":
                hlx, hly, hrx, hry = (float(x) for x in kp[3:7])
                s_in = (value - hly) / (frame - hlx) * file_fps if frame > hlx else 0.0
                s_out = (hry - value) / (hrx - frame) * file_fps if hrx > frame else 0.0
                keys.append(Key(t, value, "bezier", s_in, s_out, "user"))
            else:
                raise AnimationImportError(src, f"{where}: interpolation {interp} is not supported (constant, linear, Bézier)")
        if not keys:
            continue
        try:
            tn = weight_track_name(shape)
            tracks[tn] = Track(tn, tuple(keys))
        except TrackError as exc:
            raise AnimationImportError(src, f"shape key '{name}': {exc}") from None
    if not tracks:
        raise AnimationImportError(src, "no animated shape key matches a shape of the model")
    return Timeline(fps=fps, tracks=tracks).fit_range()
