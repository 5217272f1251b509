"""Registers the family: one slot, ``model.mouth_gain``, the layer, its part of the file, its track."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from mouth_gain.facet import MouthGainFacet
from mouth_gain.layer import TRACK, GainState, MouthGainLayer

from workbench.core.families import Family, SlotSpec, TrackSpec, register_family


class GainFilePart:
    """``mouth_gain: {"gain": g}`` and the array ``mouth_gain_mask`` when there is a mask."""

    keys = ("mouth_gain",)

    def save(self, model: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        st: GainState = model.slot("mouth_gain")
        arrays = {} if st.mask is None else {"mouth_gain_mask": st.mask.astype("<f4")}
        return {"mouth_gain": {"gain": st.gain}}, arrays

    def check(self, c: Any, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        part = c.obj(c.key(manifest, "", "mouth_gain", {"gain": 1.0}), "mouth_gain")
        return {"mouth_gain": {"gain": c.number(c.key(part, "mouth_gain", "gain", 1.0), "mouth_gain.gain")}}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Any], set[str]]:
        n = m["mesh"]["n_vertices"]
        return {"mouth_gain_mask": ("<f4", (n,), "(mesh.n_vertices,)")}, set()

    def check_values(self, c: Any, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        pass

    def load(self, model: Any, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        mask = arrays.get("mouth_gain_mask")
        return {"mouth_gain": GainState(m["mouth_gain"]["gain"], None if mask is None else np.asarray(mask))}


def animate(view: Any, sample: Any) -> dict[str, Any]:
    """The keyed gain, when the timeline keys it."""
    g = sample.others.get(TRACK)
    if g is None:
        return {}
    return {"mouth_gain": GainState(float(np.asarray(g).reshape(-1)[0]), view.slot("mouth_gain").mask)}


FAMILY = register_family(Family(
    name="mouth_gain",
    slots=(SlotSpec("mouth_gain", lambda m: GainState()),),
    facet=MouthGainFacet,
    layer=MouthGainLayer,
    order=35,  # after paint, before wrinkles
    file_part=GainFilePart(),
    animate=animate,
    viewport="mouth_gain.tool",  # its viewport tool: brush the mask (tool.py)
    # one number per key; "Key" on its timeline row records the gain the model has now
    tracks={TRACK: TrackSpec(lambda model, track: (1,), title=lambda track: "mouth gain",
                             current=lambda model, track: [model.slot("mouth_gain").gain])},
))
