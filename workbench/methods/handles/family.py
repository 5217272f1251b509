"""Registers the handle-editing family: slots, ``model.handles``, the shell layer, its file part."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.families import Family, SlotSpec, TrackSpec, register_family
from workbench.core.manifest import Checker, Spec
from workbench.core.shapes import ModelError
from workbench.methods.handles.facet import (
    HANDLES_TRACK,
    HandlesFacet,
    check_handles,
    check_stiffness,
)
from workbench.methods.handles.handle_set import HandleSet
from workbench.methods.handles.layer import HandleLayer
from workbench.methods.handles.shell import DEFAULT_K_B, DEFAULT_K_S

if TYPE_CHECKING:
    from workbench.core.pipeline import StateView
    from workbench.core.state import FaceState

_ARRAYS = ("handle_vertices", "handle_offsets", "handle_mirror")


class HandlesFilePart:
    """``handles: {"names": [...], "stiffness": [k_s, k_b]}`` and the three ``handle_*`` arrays.

    ``stiffness`` is new in this release; files without it get the default.
    """

    keys: tuple[str, ...] = ("handles",)

    def save(self, model: FaceState) -> tuple[dict[str, Any], dict[str, Any]]:
        h = model.slot("handles")
        k_s, k_b = model.slot("shell_stiffness")
        arrays = {
            "handle_vertices": h.vertices.astype("<i4"),
            "handle_offsets": h.offsets.astype("<f4"),
            "handle_mirror": h.mirror.astype("<i4"),
        }
        return {"handles": {"names": list(h.names), "stiffness": [k_s, k_b]}}, arrays

    def check(self, c: Checker, manifest: Mapping[str, Any], m: Mapping[str, Any]) -> dict[str, Any]:
        handles = c.obj(c.key(manifest, "", "handles", {}), "handles")
        out: dict[str, Any] = {"names": c.strings(c.key(handles, "handles", "names", []), "handles.names")}
        st = c.key(handles, "handles", "stiffness", None)
        if st is not None:
            ks, kb = (c.number(x, f"handles.stiffness[{i}]") for i, x in enumerate(c.lst(st, "handles.stiffness", 2)))
            if ks < 0 or kb < 0 or ks == kb == 0:
                c.fail("handles.stiffness", f"expected k_s >= 0, k_b >= 0, not both 0, got {[ks, kb]}")
            out["stiffness"] = (ks, kb)
        return {"handles": out}

    def specs(self, m: Mapping[str, Any], present: set[str]) -> tuple[dict[str, Spec], set[str]]:
        h = len(m["handles"]["names"])
        specs: dict[str, Spec] = {
            "handle_vertices": ("<i4", (h,), "(len(handles.names),)"),
            "handle_offsets": ("<f4", (h, 3), "(len(handles.names), 3)"),
            "handle_mirror": ("<i4", (h,), "(len(handles.names),)"),
        }
        # all three arrays or none (every writer writes all three)
        required = set(_ARRAYS) if h or set(_ARRAYS) & present else set()
        return specs, required

    def check_values(self, c: Checker, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        n = m["mesh"]["n_vertices"]
        c.in_range(dict(arrays), "handle_vertices", 0, n - 1, "vertex ids")
        c.in_range(dict(arrays), "handle_mirror", -1, len(m["handles"]["names"]) - 1,
                   "mirror handle indices (-1 = none)")

    def load(self, model: FaceState, m: Mapping[str, Any], arrays: Mapping[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if "handle_vertices" in arrays:
            out["handles"] = HandleSet(arrays["handle_vertices"], arrays["handle_offsets"],
                                       tuple(m["handles"]["names"]), arrays["handle_mirror"])
        if "stiffness" in m["handles"]:
            out["shell_stiffness"] = m["handles"]["stiffness"]
        return out


def handles_track_shape(model: FaceState, track: str) -> tuple[int, ...]:
    """``"handles"`` keys (h, 3) offsets: one per handle of the model."""
    n = len(model.slot("handles"))
    if not n:
        raise ModelError(f"track {track!r}: the model has no handles")
    return (n, 3)


def current_offsets(model: FaceState, track: str) -> np.ndarray:
    """What keying the ``"handles"`` track now records: the current offsets."""
    return np.asarray(model.slot("handles").offsets, np.float64)


def animate(view: StateView, sample: Any) -> dict[str, Any]:
    """Keyed handle offsets (when their count matches the handle set)."""
    h = view.slot("handles")
    o = sample.others.get(HANDLES_TRACK)
    if o is None or o.shape != h.offsets.shape:
        return {}
    return {"handles": dataclasses.replace(h, offsets=np.asarray(o, np.float32))}


FAMILY = register_family(
    Family(
        name="handles",
        slots=(
            SlotSpec("handles", lambda m: HandleSet(), deforms=True, changing=True, check=check_handles),
            SlotSpec("shell_stiffness", lambda m: (DEFAULT_K_S, DEFAULT_K_B), check=check_stiffness),
        ),
        facet=HandlesFacet,
        layer=HandleLayer,
        order=20,
        tab="widgets.tabs.sculpt",
        viewport="widgets.panels.sculpt_tool",
        file_part=HandlesFilePart(),
        animate=animate,
        tracks={HANDLES_TRACK: TrackSpec(handles_track_shape, title=lambda t: "handles (pose)",
                                         current=current_offsets)},
    )
)
