"""What the timeline's front end draws: the tracks and keys, and the curve view's samples.

Pure functions of a :class:`workbench.animation.tracks.Timeline` (no widget
state): :func:`timeline_state` is the ``_tracks`` trait, :func:`curve_samples`
the ``_curve`` trait.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from workbench.animation.curves import WEIGHTS_PREFIX
from workbench.animation.timeline import track_title
from workbench.animation.tracks import Timeline
from workbench.core.families import track_owner

#: samples of the curve view over the visible range (plus two per key for steps)
CURVE_SAMPLES = 240


def track_label(name: str) -> str:
    """The row label of track ``name`` ("jawOpen", "head pose", a family's title of its track)."""
    return track_title(name)


def track_kind(name: str) -> str:
    """"weight", "head_pose", or the name of the method family keying the track."""
    if name.startswith(WEIGHTS_PREFIX):
        return "weight"
    owner = track_owner(name)
    return name if owner is None else owner[0].name


def view_range(tl: Timeline) -> tuple[float, float]:
    """Visible time range: from min(0, start) past the end, so keys can be dragged later."""
    v0 = min(0.0, tl.start)
    v1 = max(tl.end, v0 + 1.0)
    return v0, v1 + max(0.25, 0.1 * (v1 - v0))


def timeline_state(tl: Timeline) -> dict[str, Any]:
    """JSON the front end draws: fps, range, visible range and every track's keys.

    Scalar (weight) tracks carry values and tangent slopes; vector tracks
    (handles, head pose, region weights) only times and interpolations (no
    curve view).
    """
    tracks = []
    for name, tr in tl.tracks.items():
        scalar = tr.shape_name is not None
        tracks.append(
            {
                "name": name,
                "label": track_label(name),
                "kind": track_kind(name),
                "times": [float(x) for x in tr.times],
                "values": [float(k.value) for k in tr.keys] if scalar else None,
                "in": [float(k.in_tangent) for k in tr.keys] if scalar else None,
                "out": [float(k.out_tangent) for k in tr.keys] if scalar else None,
                "interp": list(tr.interpolations),
                "mode": [k.tangent_mode for k in tr.keys],
            }
        )
    # weights first (alphabetical, as Timeline sorts them), then the others by name
    tracks.sort(key=lambda d: (d["kind"] != "weight", d["name"]))
    return {
        "fps": tl.fps,
        "start": tl.start,
        "end": tl.end,
        "view": list(view_range(tl)),
        "tracks": tracks,
    }


def curve_samples(tl: Timeline, track: str, n: int = CURVE_SAMPLES) -> dict[str, Any]:
    """``{"track", "times", "values"}``: the scalar track sampled over the visible range.

    Sampled with the model's own evaluation (the front end never re-implements
    the interpolation); each key time is added, and a time just before it, so
    step keys draw as vertical jumps.
    """
    tr = tl.tracks.get(track)
    if tr is None or tr.shape_name is None:
        return {"track": track, "times": [], "values": []}
    v0, v1 = view_range(tl)
    ts = np.linspace(v0, v1, n)
    eps = 1e-6 * max(v1 - v0, 1.0)
    ts = np.unique(np.concatenate([ts, tr.times, tr.times - eps]))
    vals = tr.sample(ts)[:, 0]
    return {"track": track, "times": ts.tolist(), "values": vals.tolist()}
