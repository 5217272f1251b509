"""Track names and the error of this package: what a track animates is in its name.

* ``"weights/<shape>"`` — scalar tracks, one per keyed blendshape weight;
* ``"handles"`` — a vector track whose values are the handle-layer offsets,
  ``(h, 3)`` in model units (the "pose keys" of the handle layer);
* ``"head_pose"`` — a rigid head transform, value ``(7,)`` =
  translation ``(tx, ty, tz)`` in model units + unit quaternion ``(qx, qy, qz, qw)``
  (glTF order). The transform maps a model point ``p`` to ``R(q) p + t``;
  :func:`head_rotation_from_euler` / :func:`head_euler_from_rotation` convert
  yaw/pitch/roll about the model's axes;
* ``"regions/<level>/<region>"`` — per-region blend weights (Joshi et al. 2003
  §3/§4), a vector track whose value is ``(k,)``: the weight of every model
  shape (in the model's shape order, as a row of
  :class:`workbench.methods.regions.blend.RegionWeights`) inside region ``<region>`` of
  hierarchy level ``<level>`` (the rules for a timeline's region tracks are
  in :mod:`workbench.animation.tracks`).
"""

from __future__ import annotations

import numpy as np

WEIGHTS_PREFIX = "weights/"
HANDLES = "handles"
HEAD_POSE = "head_pose"
REGIONS_PREFIX = "regions/"


class TrackError(ValueError):
    """A key, track or timeline that cannot be built or edited as asked."""


def weight_track_name(shape: str) -> str:
    """``"weights/<shape>"``: the track name of a blendshape weight."""
    return WEIGHTS_PREFIX + shape


def region_track_name(level: int, region: str) -> str:
    """``"regions/<level>/<region>"``: the track name of one region's blend weights."""
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        raise TrackError(f"region track level must be an int >= 0, got {level!r}")
    if not isinstance(region, str) or not region:
        raise TrackError(f"region track region must be a non-empty name, got {region!r}")
    return f"{REGIONS_PREFIX}{int(level)}/{region}"


def parse_region_track(name: str) -> tuple[int, str] | None:
    """``(level, region)`` of a ``"regions/<level>/<region>"`` name, else None."""
    if not isinstance(name, str) or not name.startswith(REGIONS_PREFIX):
        return None
    level, sep, region = name[len(REGIONS_PREFIX) :].partition("/")
    if not sep or not region or not level.isdigit() or not level.isascii():
        return None
    return int(level), region
