"""``model.regions``: blend regions (Joshi et al. 2003) and their undoable edits.

``model.regions.state`` is the :class:`RegionState` in the ``regions`` slot
(None until :meth:`RegionsFacet.segment`); ``.regions``, ``.level`` and
``.weights`` read through it. Every edit replaces the slot, so undo restores
the previous state object bit-exactly. Per-region blend weights follow an
edit's ``origins``: a merged region keeps the weights of the larger region,
both halves of a split inherit the split region's, painting keeps everyone's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from numpy.typing import ArrayLike

from workbench.core.shapes import ModelError
from workbench.methods.regions.blend import RegionState, RegionWeights
from workbench.methods.regions.hierarchy import Regions

if TYPE_CHECKING:
    from workbench.core.state import FaceState
    from workbench.methods.regions.drag import RegionDrag
    from workbench.methods.regions.topology import RegionTopology


def check_state(model: FaceState, value: Any) -> RegionState | None:
    """Slot check: None or a RegionState made for this mesh."""
    if value is None:
        return None
    if not isinstance(value, RegionState):
        raise ModelError(f"regions: expected a RegionState or None, got {type(value).__name__}")
    if value.regions.n_vertices != model.n_vertices:
        raise ModelError(
            f"regions: made for {value.regions.n_vertices} vertices, the model has {model.n_vertices}"
        )
    return value


class RegionsFacet:
    """The blend-region tool of one model (see the module docstring)."""

    def __init__(self, model: FaceState) -> None:
        self._model = model
        self._topology: RegionTopology | None = None

    # ------------------------------------------------------------------ reading
    @property
    def state(self) -> RegionState | None:
        return self._model.slot("regions")

    @property
    def segmented(self) -> bool:
        return self.state is not None

    def require(self, what: str) -> RegionState:
        st = self.state
        if st is None:
            raise ModelError(f"{what}: no regions yet; call model.segment_regions() first")
        return st

    @property
    def regions(self) -> Regions:
        return self.require("regions").regions

    @property
    def level(self) -> int:
        return self.require("level").level

    @property
    def weights(self) -> RegionWeights | None:
        return self.require("weights").weights

    def __repr__(self) -> str:
        st = self.state
        if st is None:
            return "<regions: not segmented>"
        return f"<regions: {st.regions.n_levels} levels, showing {st.level}, weights {'set' if st.weights else 'none'}>"

    @property
    def topology(self) -> RegionTopology:
        """Vertex adjacency and skin mask the region edits need (built once per mesh)."""
        if self._topology is None:
            from workbench.methods.regions.topology import region_topology

            self._topology = region_topology(self._model)
        return self._topology

    # -------------------------------------------------------------------- drags
    def begin_drag(self, vertex: int, *, pins: ArrayLike = (), damping: bool = True,
                   hold_others: bool = False, regularization: float = 1e-3) -> RegionDrag:
        """Press on ``vertex`` to sculpt with the regions under it; see :class:`RegionDrag`."""
        from workbench.methods.regions.drag import RegionDrag

        return RegionDrag(self._model, vertex, pins=pins, damping=damping, hold_others=hold_others,
                          regularization=regularization)

    # -------------------------------------------------------------------- edits
    def set(self, state: RegionState | None, label: str = "Regions") -> None:
        self._model.set_slot("regions", state, label)

    def segment(self, threshold: float = 0.25, **options: Any) -> RegionState:
        """Find local blend regions and store them (undoable); weights start as the global ones.

        ``options`` go to :func:`workbench.methods.regions.segmentation.segment_blend_regions`.
        """
        from workbench.methods.regions.segmentation import segment_blend_regions

        m = self._model
        with m.lock:
            regions = segment_blend_regions(m, threshold, **options)
            old = self.state
            level = min(old.level, regions.n_levels - 1) if old is not None else 0
            state = RegionState(regions, level, None)
            self.set(state, f"Segment regions (t={threshold:g})")
            return state

    def set_level(self, level: int) -> None:
        """Show/edit hierarchy ``level`` (weights are carried over to it); undoable."""
        with self._model.lock:
            st = self.require("set_region_level")
            lv = st.regions.check_level(level)
            self.set(RegionState(st.regions, lv, st.weights), f"Region level {lv}")

    def set_weights(self, weights: RegionWeights | None, label: str = "Region weights") -> None:
        """Per-region blend weights (None: regions follow the global sliders); undoable."""
        m = self._model
        with m.lock:
            st = self.require("set_region_weights")
            if weights is not None and tuple(weights.shape_names) != tuple(m.shape_names):
                raise ModelError("set_region_weights: weights were made for other shapes")
            self.set(RegionState(st.regions, st.level, weights), label)

    def _apply_edit(self, edit: Any, label: str) -> RegionState:
        st = self.require(label)
        if edit.regions is st.regions:
            return st
        rw = st.weights
        if rw is not None:
            rw = RegionWeights(rw.level, rw.shape_names, edit.regions.names[rw.level],
                               rw.values[edit.origins[rw.level]])
        state = RegionState(edit.regions, st.level, rw)
        self.set(state, label)
        return state

    def merge(self, level: int, a: int | str, b: int | str, name: str | None = None) -> RegionState:
        """Merge two touching regions of ``level`` (undoable); coarser levels merge too to stay nested."""
        from workbench.methods.regions.edits import merge_regions

        with self._model.lock:
            R = self.require("merge_regions").regions
            edit = merge_regions(R, self.topology, level, a, b, name=name)
            lv = R.check_level(level)
            na, nb = R.names[lv][R.region_index(lv, a)], R.names[lv][R.region_index(lv, b)]
            return self._apply_edit(edit, f"Merge regions {na} + {nb}")

    def split(self, level: int, region: int | str, seeds_a: ArrayLike, seeds_b: ArrayLike,
              names: tuple[str, str] | None = None) -> RegionState:
        """Split a region around two sets of clicked vertices (geodesic Voronoi on level 0); undoable."""
        from workbench.methods.regions.edits import split_region

        with self._model.lock:
            R = self.require("split_region").regions
            edit = split_region(R, self.topology, level, region, seeds_a, seeds_b, names=names)
            lv = R.check_level(level)
            return self._apply_edit(edit, f"Split region {R.names[lv][R.region_index(lv, region)]}")

    def rename(self, level: int, region: int | str, name: str) -> RegionState:
        """Rename a region of ``level`` (undoable; labels and weights unchanged)."""
        from workbench.methods.regions.edits import rename_region

        with self._model.lock:
            st = self.require("rename_region")
            R = st.regions
            lv = R.check_level(level)
            old = R.names[lv][R.region_index(lv, region)]
            if old == name:
                return st
            return self._apply_edit(rename_region(R, lv, region, name), f"Rename region {old} to {name}")

    def paint(self, level: int, region: int | str, vertices: ArrayLike, add: bool = True) -> RegionState:
        """Assign skin vertices to a region (``add``) or return them to the background (undoable)."""
        from workbench.methods.regions.edits import paint_region

        with self._model.lock:
            R = self.require("paint_region").regions
            edit = paint_region(R, self.topology, level, region, vertices, add=add)
            lv = R.check_level(level)
            verb = "Paint region" if add else "Erase from region"
            return self._apply_edit(edit, f"{verb} {R.names[lv][R.region_index(lv, region)]}")
