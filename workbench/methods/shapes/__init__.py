"""Shape tools: left/right symmetry, split, mirror, and corrective (combination) shapes.

``symmetry`` finds the mirror partner of every vertex, ``split`` cuts a shape
into left and right halves, ``mirror`` reflects shapes, expressions and paint,
``correctives`` holds the combination-shape rules; ``facet`` is
``model.shape_tools`` and ``family`` registers it all.
"""
