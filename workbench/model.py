"""``FaceModel``: the face-model state with every method family's facet hung off it.

:class:`~workbench.core.state.FaceState` is the small evented state; each
method family registers its slots, layer, file part and facet
(:mod:`workbench.core.families`), so a model reads like napari's viewer::

    model.handles.move(3, [0, 0.1, 0])        # workbench.methods.handles
    model.regions.segment(0.25)               # workbench.methods.regions
    model.paint.stroke("smile", ids, brush)   # workbench.methods.paint
    model.expressions.save("smile")
    model.wrinkles.set_strength(2.0)          # workbench.methods.wrinkles
    model.expressions.key(1.0, "jawOpen")     # keyed on model.timeline (workbench.animation)
    model.shape_tools.split("browInnerUp")    # workbench.methods.shapes

The annotations below only tell type checkers what the registered facets
are; adding a family does not require touching this module. A few one-line
delegations keep the README's short API (``move_handle``, ``segment_regions``,
``paint_stroke``, ``key_expression``, ``tracks``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from workbench.converters import mesh_converter
from workbench.core.families import set_hook
from workbench.core.shapes import AXES, UNIT_TO_METRES, BlendShape, ModelError, ModelMetadata
from workbench.core.state import FaceState, InteractionToken
from workbench.fileformat import save_model
from workbench.geometry.parts import model_part_roles
from workbench.methods.handles.handle_set import HandleSet

if TYPE_CHECKING:
    from workbench.animation.curves import Interpolation
    from workbench.animation.timeline import TimelineFacet
    from workbench.animation.tracks import Timeline
    from workbench.capture.facet import CaptureFacet
    from workbench.enhance.facet import EnhanceFacet
    from workbench.methods.handles.facet import HandlesFacet
    from workbench.methods.paint.facet import ExpressionsFacet, PaintFacet
    from workbench.methods.paint.painting import Brush
    from workbench.methods.regions.blend import RegionState
    from workbench.methods.regions.facet import RegionsFacet
    from workbench.methods.shapes.facet import ShapeToolsFacet
    from workbench.methods.wrinkles.facet import WrinklesFacet

__all__ = [
    "AXES",
    "UNIT_TO_METRES",
    "BlendShape",
    "FaceModel",
    "HandleSet",
    "InteractionToken",
    "ModelError",
    "ModelMetadata",
]


class FaceModel(FaceState):
    """Neutral mesh, blendshapes, weights and the method facets, with undo and events.

    Parameters are those of :class:`~workbench.core.state.FaceState`, plus
    ``handles`` (a :class:`HandleSet`, default none).
    """

    handles: HandlesFacet
    regions: RegionsFacet
    paint: PaintFacet
    expressions: ExpressionsFacet
    wrinkles: WrinklesFacet
    timeline: TimelineFacet
    shape_tools: ShapeToolsFacet
    capture: CaptureFacet
    enhance: EnhanceFacet

    def __init__(self, vertices: ArrayLike, faces: ArrayLike | None, shapes: Iterable[BlendShape] = (),
                 *, handles: HandleSet | None = None, **kwargs: Any) -> None:
        super().__init__(vertices, faces, shapes, handles=handles, **kwargs)

    @property
    def part_roles(self) -> tuple[str, ...]:
        """Role of every component ("skin", "eyeball_left", "lashes", "teeth_upper", ...), computed once per mesh.

        Names first, else recognised by geometry: :func:`workbench.geometry.parts.component_roles`.
        """
        return model_part_roles(self)

    # -- the README's short forms
    @property
    def tracks(self) -> Timeline:
        """The keyframe timeline (``model.timeline.value``)."""
        return self.timeline.value

    def move_handle(self, index: int, offset: ArrayLike, *, symmetric: bool = False) -> None:
        """``model.handles.move``: one handle's offset (with ``symmetric``, its mirror's too)."""
        self.handles.move(index, offset, symmetric=symmetric)

    def segment_regions(self, threshold: float = 0.25, **options: Any) -> RegionState:
        """``model.regions.segment``: find local blend regions (undoable)."""
        return self.regions.segment(threshold, **options)

    def paint_stroke(self, expression: str, centers: Iterable[int], brush: Brush | None = None) -> None:
        """``model.paint.stroke``: a brush stroke of ``expression`` as one undo step."""
        self.paint.stroke(expression, centers, brush)

    def key_expression(self, time: float, expression: str, interpolation: Interpolation = "bezier") -> None:
        """``model.expressions.key``: key an expression at ``time`` (one undo step)."""
        self.expressions.key(time, expression, interpolation)

    # -- files and other libraries
    def save(self, path: Any) -> None:
        """Save to a workbench file (``.fwb``): atomic, checksummed; see :mod:`workbench.fileformat`."""
        save_model(self, path)

    def to_trimesh(self, evaluated: bool = True) -> Any:
        """A :class:`trimesh.Trimesh` of the current (or neutral) mesh."""
        import trimesh

        pts = self.evaluate() if evaluated else self.vertices
        return trimesh.Trimesh(np.asarray(pts, np.float64), self.faces, process=False)

    def to_pyvista(self, points: ArrayLike | None = None, **kwargs: Any) -> Any:
        """This model as a ``pyvista.PolyData`` (needs ``import widgets.render``: the core never imports pyvista)."""
        return mesh_converter("pyvista").to(self, points, **kwargs)

    @classmethod
    def from_pyvista(cls, mesh: Any, **kwargs: Any) -> FaceModel:
        """A model (no blendshapes) from a pyvista mesh (``widgets.render.from_pyvista``)."""
        model = mesh_converter("pyvista").from_(mesh, **kwargs)
        if not isinstance(model, cls):
            raise TypeError(f"from_pyvista: the converter returned {type(model).__name__}")
        return model


set_hook("model_class", FaceModel)
