"""The method families, one folder each (see :mod:`workbench.core.families`).

handles (thin-shell handle editing), wrinkles (pose-space deformation),
regions (blend regions, marker fitting), paint (expressions, painterly
blending) and shape tools (split, mirror, corrective shapes). Each folder's
``family.py`` registers its family; :func:`workbench.core.families.discover`
imports them (and those of ``workbench.animation``, ``workbench.capture``,
``workbench.enhance``) before the first model is made, so nothing here lists them.
"""
