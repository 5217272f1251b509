"""User edits of blend regions: merge, split, rename and paint.

The artist's corrections of the automatic regions of
:func:`workbench.methods.regions.segmentation.segment_blend_regions`
(:func:`merge_regions`, :func:`split_region`, :func:`rename_region`,
:func:`paint_region`; undoable through the ``FaceModel`` methods of the same
names). Each edit changes labels only, on a draft, and then recomputes every
derived array exactly as the segmentation does
(:mod:`~workbench.methods.regions.edits.draft`), so edited regions keep every
invariant of a segmented one.

Merges need touching regions and merge the coarser parents too when they
differ (:mod:`~workbench.methods.regions.edits.merge`); a split is the geodesic
Voronoi partition of two clicked seeds on level 0 and a grouping of whole
children on coarser levels (:mod:`~workbench.methods.regions.edits.split`);
painting assigns skin vertices to a region (its ancestors follow, its
descendants grow by nearest vertex) or returns them to the background, and
refuses to cut a region in pieces (:mod:`~workbench.methods.regions.edits.paint`).
:class:`RegionEdit` ``origins`` say which old region's blend weights each new
region takes (the larger one of a merge; both halves of a split inherit). The
mesh data the edits need is a
:class:`~workbench.methods.regions.topology.RegionTopology`.
"""

from __future__ import annotations

from workbench.methods.regions.edits.draft import RegionEdit, recompute_region_weights
from workbench.methods.regions.edits.merge import merge_regions, rename_region
from workbench.methods.regions.edits.paint import paint_region
from workbench.methods.regions.edits.split import split_region

__all__ = [
    "RegionEdit",
    "merge_regions",
    "paint_region",
    "recompute_region_weights",
    "rename_region",
    "split_region",
]
