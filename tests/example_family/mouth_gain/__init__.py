"""A toy method family: a gain on the face's motion inside a soft mask (the README's worked example).

``model.mouth_gain.set(1.5)`` makes the mouth move 1.5× as far as the rig says;
the gain can be keyed (``model.mouth_gain.key(t, g)``). It is one folder:
``layer.py`` (the layer and what it says of itself), ``facet.py`` (its undoable
edits), ``tool.py`` (its viewport tool: a brush for the mask), ``family.py``
(its registration: slot, facet, layer, file part, timeline, viewport tool).
Nothing else in the workbench is edited: the exporters and the
viewport's GPU path ask the layer whether it is linear and what its terms are.
"""
