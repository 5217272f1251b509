"""Registers performance enhancement: the facet ``model.enhance`` (retime a key pair from a take).

No slot, no layer, no file part (a retimed transition is timeline keys, which the
timeline family saves). Imported by ``workbench/__init__.py``, like capture's
family: enhancement builds timelines from takes and may import what builds models.
"""

from __future__ import annotations

from workbench.core.families import Family, register_family
from workbench.enhance.facet import EnhanceFacet

FAMILY = register_family(Family(name="enhance", facet=EnhanceFacet, order=96))
