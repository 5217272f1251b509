"""The Rig tab: rig your own face from the template (issue 16), over a :class:`workbench.rigging.RigSession`."""

from widgets.rigging.examples import ExamplesPanel
from widgets.rigging.gallery import RigGallery
from widgets.rigging.landmarks import LandmarkPicker
from widgets.rigging.report_view import QualityReport, shape_flags
from widgets.rigging.stages import StagePanel
from widgets.rigging.studio import RIG_TABS, RigStudio, show_rig_studio

__all__ = [
    "RIG_TABS",
    "ExamplesPanel",
    "LandmarkPicker",
    "QualityReport",
    "RigGallery",
    "RigStudio",
    "StagePanel",
    "shape_flags",
    "show_rig_studio",
]
