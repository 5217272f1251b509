"""Registers performance capture: the facet ``model.capture`` (track / apply).

Capture builds timelines, it does not deform: no slot, no layer, no file part
(a result is applied to the timeline, which the timeline family saves).

Found by :func:`workbench.core.families.discover` like every family: its modules may
import :mod:`workbench.model` (it builds models), which never imports them back.
"""

from __future__ import annotations

from workbench.capture.facet import CaptureFacet
from workbench.core.families import Family, register_family

FAMILY = register_family(Family(name="capture", facet=CaptureFacet, order=95, tab="widgets.tabs.capture"))
