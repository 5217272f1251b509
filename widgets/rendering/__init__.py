"""The pieces of :mod:`widgets.render`: mesh conversion, colours and the camera.

Import :mod:`widgets.render` for the public names; these modules are split
from it by concern (:mod:`.convert`, :mod:`.colors`, :mod:`.camera`).
"""

from __future__ import annotations

import os

# Must be set before vtk is first imported (the submodules import pyvista): skips the X11
# attempt (and its warning) on machines without a display and goes straight to EGL/llvmpipe.
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
