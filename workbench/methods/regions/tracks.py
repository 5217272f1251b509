"""The regions' timeline tracks: ``"regions/<level>/<region>"`` keys per-region blend weights.

Per-region blend weights (Joshi et al. 2003 §3/§4) animate on tracks named
``"regions/<level>/<region>"``, each a vector track whose value is ``(k,)``: the
weight of every model shape (in the model's shape order, as a row of
:class:`~workbench.methods.regions.blend.RegionWeights`) inside region
``<region>`` of hierarchy level ``<level>``. All region tracks of a timeline
are on one level; while a timeline has region tracks, they define the region
weights of that level: keyed regions take their keyed values and every other
region of the level follows the global weights (no correction there), whatever
static region weights the model holds. ``model.regions.key_marker_fit`` writes
them from a marker fit.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.shapes import ModelError

if TYPE_CHECKING:
    from workbench.animation.curves import Track
    from workbench.animation.tracks import Timeline
    from workbench.core.state import FaceState

REGIONS_PREFIX = "regions/"


def region_track_name(level: int, region: str) -> str:
    """``"regions/<level>/<region>"``: the track name of one region's blend weights."""
    from workbench.animation.curves import TrackError

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


def region_tracks(timeline: Timeline) -> dict[str, Track]:
    """Region tracks by *region* name (all on :func:`region_level`)."""
    out = {}
    for name, tr in timeline.tracks.items():
        r = parse_region_track(name)
        if r is not None:
            out[r[1]] = tr
    return out


def region_level(timeline: Timeline) -> int | None:
    """The hierarchy level the region tracks key, None without region tracks."""
    for name in timeline.tracks:
        r = parse_region_track(name)
        if r is not None:
            return r[0]
    return None


def sampled_region_weights(others: Mapping[str, Any]) -> tuple[int | None, dict[str, np.ndarray]]:
    """``(level, {region: (k,) weights})`` of a timeline sample's region tracks (level None: none)."""
    level, out = None, {}
    for name, value in others.items():
        r = parse_region_track(name)
        if r is not None and (level is None or r[0] == level):
            level = r[0]
            out[r[1]] = value
    return level, out


def region_track_title(track: str) -> str:
    """``"region <name> (L<level>)"``: a region track's label."""
    r = parse_region_track(track)
    return track if r is None else f"region {r[1]} (L{r[0]})"


def region_track_shape(model: FaceState, track: str) -> tuple[int, ...]:
    """A region track keys (k,) shape weights inside one region of the model's regions."""
    r = parse_region_track(track)
    if r is None:
        raise ModelError(f"a region track is named 'regions/<level>/<region>', got {track!r}")
    state = model.slot("regions")
    regions = getattr(state, "regions", None)
    if regions is None:
        raise ModelError("the timeline keys region weights but the model has no regions; "
                         "call segment_regions() first")
    level, region = r
    if level >= regions.n_levels:
        raise ModelError(f"region tracks key level {level} but the model's regions have "
                         f"{regions.n_levels} levels")
    names = regions.names[level]
    if region not in names:
        raise ModelError(f"level {level} has no region {region!r}; its regions are "
                         f"{sorted(names)[:8]}{'...' if len(names) > 8 else ''}")
    return (len(model.shape_names),)


def check_region_tracks(model: FaceState, tracks: Mapping[str, Track]) -> None:
    """All region tracks of a timeline are on one level."""
    levels = sorted({r[0] for r in map(parse_region_track, tracks) if r is not None})
    if len(levels) > 1:
        raise ModelError(f"region tracks must all be on one region level, got levels {levels}")
