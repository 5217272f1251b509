"""Faces with a known answer for the rigging tests: moved to :mod:`workbench.testing`.

The remesh, warp, bust and hole builders now live in the one public module of
generated test faces (:mod:`workbench.testing.meshes`,
:mod:`workbench.testing.warps`; the face-level builders with their true shapes
in :mod:`workbench.testing.faces`). These names stay importable from here for
the notebooks and tests that use them; nothing in the transfer itself does.
"""

from __future__ import annotations

from workbench.testing.meshes import add_bust, cut_hole, split_remesh
from workbench.testing.warps import SmoothWarp, sample_head_warp

__all__ = ["SmoothWarp", "add_bust", "cut_hole", "sample_head_warp", "split_remesh"]
