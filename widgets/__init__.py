"""Notebook UI of the Facial Editing Workbench (JupyterLab widgets).

Everything here *observes* a :class:`workbench.FaceModel` through its psygnal
events and edits it only through its methods; the headless core never imports
this package.

- :class:`Viewport`: client-side WebGL (three.js) view, binary partial updates.
- :class:`ExpressionPanel`: blendshape sliders grouped by face region.
- :class:`SculptPanel`: handle-based shell editing controls (the drag itself
  happens in the viewport's "sculpt" tool).
- :class:`WrinklePanel`: pose-space wrinkles while dragging (fit from example
  poses, on/off, strength, feature graph coloured by strain, example editing);
  shown in the Sculpt tab under the SculptPanel.
- :class:`RegionsPanel`: blend regions, region-weight sliders and marker drags.
- :class:`PaintPanel`: painterly expression blending (palette of expression
  thumbnails, brush, global/regional blend, save as expression, bake); the
  strokes happen in the viewport's "paint" tool.
- :class:`TimelineWidget`: keyframe tracks and playback.
- :class:`ExportPanel`: write the animation (.glb, .usd, ...).
- :class:`ExpressionGallery`: the thumbnail grid (also the paint palette).
- :class:`Workbench` / :func:`show_workbench`: the composed app: one viewport
  beside a tab of the panels ("Shapes", "Sculpt", "Regions", "Paint",
  "Export"), the timeline under it, undo/redo, a wireframe toggle and a status
  line on top, and a shared Output that callback errors go to.
- :class:`RigStudio` / :func:`show_rig_studio`: rig your own face from the
  template (two linked views to click landmark pairs, the transfer / refine /
  wrinkle stages with progress bars, the quality report, a before/after
  gallery, the examples with rough-weight sliders; *Open in Workbench*).
- :func:`recovery_prompt`: offer to recover an autosaved session after a
  kernel crash or restart.
- :func:`keep_every_iopub_message`: the kernel's IOPub channel keeps every
  message for a server that fell behind (applied on import and before each
  large burst of widgets; call it before a burst of your own).
"""

from __future__ import annotations

from widgets._iopub import keep_every_iopub_message
from widgets.app import TAB_TITLES, Workbench, show_workbench
from widgets.gallery import ExpressionGallery
from widgets.panels import ExportPanel, ExpressionPanel, PaintPanel, SculptPanel
from widgets.recovery import RecoveryPrompt, recovery_prompt
from widgets.regions import RegionsPanel
from widgets.rigging import RigStudio, show_rig_studio
from widgets.timeline import TimelineWidget
from widgets.viewport import Viewport
from widgets.wrinkles import WrinklePanel

# before any widget exists: on a busy machine no comm_open may be dropped (widgets._iopub)
keep_every_iopub_message()

__all__ = [
    "TAB_TITLES",
    "ExportPanel",
    "ExpressionGallery",
    "ExpressionPanel",
    "PaintPanel",
    "RecoveryPrompt",
    "RegionsPanel",
    "RigStudio",
    "SculptPanel",
    "TimelineWidget",
    "Viewport",
    "Workbench",
    "WrinklePanel",
    "keep_every_iopub_message",
    "recovery_prompt",
    "show_rig_studio",
    "show_workbench",
]
