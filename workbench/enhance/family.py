"""Registers performance enhancement: the ``enhancement`` slot, the ``enhance`` layer, ``model.enhance``.

The slot holds the database and the *Enhanced* preview switch (:mod:`.layer`);
the layer runs last (after wrinkles), so it enhances the whole edited face. No
file part: the database is its own file (:meth:`PerformanceDatabase.save`), and
the preview is a view setting, off when a face is opened. A retimed transition
is timeline keys, which the timeline family saves. Found by
:func:`workbench.core.families.discover` like every family.
"""

from __future__ import annotations

from workbench.core.families import Family, SlotSpec, register_family
from workbench.enhance.facet import EnhanceFacet
from workbench.enhance.layer import EnhanceLayer, EnhancementState, check_state

FAMILY = register_family(
    Family(
        name="enhance",
        slots=(SlotSpec("enhancement", lambda m: EnhancementState(), deforms=True, check=check_state),),
        facet=EnhanceFacet,
        layer=EnhanceLayer,
        order=96,
        tab="widgets.tabs.enhance",
    )
)
