"""Registers the timeline: the ``tracks`` slot, ``model.timeline``, and the state's sampling hooks.

``"sampler"`` turns a view's timeline into a :class:`TimelineSample` at the
view's time (the state gives its weights to the blend; the other families'
``animate`` turn it into their slots); ``"head_pose"`` gives the rigid
transform the state applies after the pipeline.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.animation.curves import TrackError, quaternion_to_matrix
from workbench.animation.timeline import TimelineFacet
from workbench.animation.tracks import Timeline, TimelineSample
from workbench.core.families import Family, SlotSpec, register_family, set_hook
from workbench.core.manifest import Checker, Spec, json_path
from workbench.core.shapes import ModelError

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState


def check_timeline(model: FaceState, value: Any) -> Timeline:
    """Slot check: a Timeline that fits the model (:meth:`Timeline.check_model`)."""
    if not isinstance(value, Timeline):
        raise ModelError(f"set_timeline expects a Timeline, got {type(value).__name__}")
    value.check_model(model)
    return value


def sample(view: StateView) -> TimelineSample:
    return view.slot("tracks").evaluate(view.time)


def head_matrix(view: StateView) -> NDArray[np.float64] | None:
    """(4, 4) head transform of the view's timeline at its time, None when the head pose is not keyed."""
    hp = view.slot("tracks").head_pose
    if hp is None:
        return None
    p = hp.sample([view.time])[0]
    M = np.eye(4)
    M[:3, :3] = quaternion_to_matrix(p[3:])
    M[:3, 3] = p[:3]
    return M


class TracksFilePart:
    """``tracks``: the timeline as JSON (:meth:`Timeline.to_json`); no arrays."""

    keys: tuple[str, ...] = ("tracks",)

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]:
        return {"tracks": model.slot("tracks").to_json()}, {}

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        """Structure of the timeline JSON; :meth:`Timeline.from_json` checks the meaning."""
        from workbench.animation.curves import INTERPOLATIONS, TANGENT_MODES

        value = c.key(dict(manifest), "", "tracks", None)
        if value is None:
            return {"tracks": None}
        t = c.obj(value, "tracks")
        for fld in ("fps", "start", "end"):
            if fld in t:
                c.number(t[fld], f"tracks.{fld}")
        for name, keys in c.obj(c.key(t, "tracks", "tracks", {}), "tracks.tracks").items():
            tf = json_path("tracks.tracks", name)
            for i, key in enumerate(c.lst(keys, tf)):
                f = f"{tf}[{i}]"
                k = c.obj(key, f)
                c.number(c.key(k, f, "time"), f"{f}.time")
                c.numeric(c.key(k, f, "value"), f"{f}.value")
                for tan in ("in_tangent", "out_tangent"):
                    if k.get(tan) is not None:
                        c.numeric(k[tan], f"{f}.{tan}")
                for opt, allowed in (("interpolation", INTERPOLATIONS), ("tangent_mode", TANGENT_MODES)):
                    if opt in k and k[opt] not in allowed:
                        c.expect(f"{f}.{opt}", f"one of {list(allowed)}", k[opt])
        return {"tracks": t}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]:
        return {}, set()

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        return None

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        if m["tracks"] is None:
            return {}
        try:
            timeline = Timeline.from_json(m["tracks"])
            timeline.check_model(model)
        except TrackError as exc:
            raise ValueError(str(exc)) from None
        return {"tracks": timeline}


FAMILY = register_family(
    Family(
        name="timeline",
        slots=(SlotSpec("tracks", lambda m: Timeline(), deforms=True, check=check_timeline),),
        facet=TimelineFacet,
        order=90,
        tab="widgets.tabs.export",
        file_part=TracksFilePart(),
    )
)
set_hook("sampler", sample)
set_hook("head_pose", head_matrix)
