"""Registers performance capture: the facet ``model.capture`` (track / apply).

Capture builds timelines, it does not deform: no slot, no layer, no file part
(a result is applied to the timeline, which the timeline family saves).

Imported by ``workbench/__init__.py``, not by :mod:`workbench.model` like the
method families: capture builds models (the adapted rig), so its modules may
import :mod:`workbench.model`, and the model module must not import them back
(an import cycle). Every ``FaceModel`` is made after ``import workbench`` has run
(importing ``workbench.model`` runs the package first), so it has ``model.capture``.
"""

from __future__ import annotations

from workbench.capture.facet import CaptureFacet
from workbench.core.families import Family, register_family

FAMILY = register_family(Family(name="capture", facet=CaptureFacet, order=95))
