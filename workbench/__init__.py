"""Facial Editing Workbench — the headless core.

Everything here runs without any UI package: the shared :class:`FaceModel`
state object, file import/export, and the numerical methods. The notebook
widgets live in the separate ``widgets`` package and only observe the model.
"""

from __future__ import annotations

from workbench._version import __version__
from workbench.animation.tracks import Timeline
from workbench.io import load
from workbench.methods.handles.shell import ShellDeformer
from workbench.methods.paint.painting import Brush
from workbench.methods.regions.hierarchy import Regions
from workbench.methods.regions.segmentation import segment_blend_regions
from workbench.model import BlendShape, FaceModel, HandleSet, ModelError, ModelMetadata
from workbench.samples import load_sample

__all__ = [
    "BlendShape",
    "Brush",
    "FaceModel",
    "HandleSet",
    "ModelError",
    "ModelMetadata",
    "Regions",
    "ShellDeformer",
    "Timeline",
    "__version__",
    "load",
    "load_sample",
    "segment_blend_regions",
]
