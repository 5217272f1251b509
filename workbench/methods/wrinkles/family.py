"""Registers pose-space wrinkles: the ``wrinkles`` slot, ``model.wrinkles`` and the layer.

The fitted pose space is not saved in the ``.fwb`` file yet (as before the
redesign): it is refitted from the examples after loading.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

from workbench.core.families import Family, SlotSpec, register_family
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.wrinkles.facet import WrinklesFacet, check_state
from workbench.methods.wrinkles.layer import WrinkleLayer, WrinkleState

if TYPE_CHECKING:
    from workbench.core.state import FaceState

FAMILY = register_family(
    Family(
        name="wrinkles",
        slots=(SlotSpec("wrinkles", lambda m: WrinkleState(), deforms=True, check=check_state),),
        facet=WrinklesFacet,
        layer=WrinkleLayer,
        order=40,
    )
)


def fit_sample_wrinkles(
    model: FaceState,
    poses: Mapping[str, Mapping[str, float]] | None = None,
    sculptor: object | None = None,
) -> WrinklesFacet:
    """Procedural example poses (:mod:`.examples`) fitted onto ``model``; returns ``model.wrinkles``.

    Sets the default handles first if the model has none (one undo step each).
    """
    from workbench.methods.wrinkles.examples import EXAMPLE_POSES, WrinkleSculptor

    facet: WrinklesFacet = model.wrinkles  # type: ignore[attr-defined]
    handles = model.handles  # type: ignore[attr-defined]
    if len(handles) == 0:
        handles.set(default_face_handles(model), label="Default handles")
    s = sculptor if isinstance(sculptor, WrinkleSculptor) else WrinkleSculptor(model)
    poses = poses or EXAMPLE_POSES
    facet.fit({k: (w, s.detailed(w)) for k, w in poses.items()})
    return facet
