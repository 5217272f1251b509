"""``model.regions``: blend regions (Joshi et al. 2003) and their undoable edits.

``model.regions.state`` is the :class:`RegionState` in the ``regions`` slot
(None until :meth:`RegionsFacet.segment`); ``.regions``, ``.level`` and
``.weights`` read through it. Every edit replaces the slot, so undo restores
the previous state object bit-exactly. Per-region blend weights follow an
edit's ``origins``: a merged region keeps the weights of the larger region,
both halves of a split inherit the split region's, painting keeps everyone's.

The edits: ``segment``, ``set_level``, ``set_weights`` / ``set_region`` /
``reset_region`` (per-region weights; ``effective_weights`` is what the blend
uses), ``merge``, ``split``, ``rename``, ``paint`` / ``brush`` (one dab of the
round region brush). Gestures spanning several messages open an interaction
and are one undo step on release, none when cancelled: ``begin_drag``
(:class:`~workbench.methods.regions.drag.RegionDrag`) and ``begin_paint``
(:class:`~workbench.methods.regions.drag.RegionStroke`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.shapes import ModelError
from workbench.methods.regions.blend import RegionState, RegionWeights
from workbench.methods.regions.hierarchy import Regions
from workbench.methods.regions.tracks import region_level, region_track_name

if TYPE_CHECKING:
    from workbench.animation.curves import Interpolation
    from workbench.core.state import FaceState
    from workbench.methods.regions.drag import RegionDrag, RegionStroke
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
        """The stored per-region weights (None: every region follows the global weights)."""
        return self.require("weights").weights

    @property
    def effective_weights(self) -> RegionWeights:
        """The per-region weights in effect on the shown level.

        The stored :attr:`weights`, or, when there are none, the model's global
        weights repeated for every region of the shown level (what the blend
        shows then). Raises ModelError without regions.
        """
        st = self.require("effective_weights")
        if st.weights is not None:
            return st.weights
        return RegionWeights.from_global(self._model, st.regions, st.level)

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
                   hold_others: bool = False, regularization: float = 1e-3,
                   on_close: Callable[[], None] | None = None) -> RegionDrag:
        """Press on ``vertex`` to sculpt with the regions under it; see :class:`RegionDrag`.

        Opens an interaction: the drag's ``end()`` is one undo step, ``cancel()`` none.
        """
        from workbench.methods.regions.drag import RegionDrag

        with self._model.lock:
            return RegionDrag(self._model, vertex, pins=pins, damping=damping, hold_others=hold_others,
                              regularization=regularization, on_close=on_close)

    def begin_paint(self, level: int, region: int | str, *, radius: float, erase: bool = False,
                    on_close: Callable[[], None] | None = None) -> RegionStroke:
        """Start a region-brush stroke (one undo step); see :class:`RegionStroke`.

        Dab with ``stroke.dab(vertex)`` / ``stroke.move(point)``, then ``end()``
        or ``cancel()``.
        """
        from workbench.methods.regions.drag import RegionStroke

        with self._model.lock:
            return RegionStroke(self._model, level, region, radius=radius, erase=erase, on_close=on_close)

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

    def set_region(self, region: int | str, values: Mapping[str, float], label: str | None = None) -> RegionWeights:
        """Some shape weights of one region of the shown level (the others keep theirs); undoable.

        Parameters
        ----------
        region : int or str
            Index or name on the shown level.
        values : mapping {shape name: weight}
        label : str, optional
            Undo label (default ``"Region <name>: <shapes>"``).

        Returns
        -------
        RegionWeights
            The new weights (every other region keeps :attr:`effective_weights`).
        """
        with self._model.lock:
            rw = self.effective_weights
            r = rw.region_index(region)
            new = rw.with_region(r, values)
            name = rw.region_names[r]
            self.set_weights(new, label if label is not None else f"Region {name}: {', '.join(values)}")
            return new

    def reset_region(self, region: int | str) -> RegionWeights | None:
        """Put one region of the shown level back on the global weights; undoable.

        Returns the new weights (None and no undo step when there were no
        per-region weights: every region follows the global ones already).
        """
        m = self._model
        with m.lock:
            st = self.require("reset_region")
            if st.weights is None:
                return None
            r = st.weights.region_index(region)
            g = {nm: float(m.weights[nm]) for nm in m.shape_names}
            return self.set_region(r, g, f"Reset region {st.weights.region_names[r]}")

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

    def brush(self, level: int, region: int | str, center: int, radius: float, *, erase: bool = False) -> int:
        """One dab of the round region brush: :meth:`paint` the skin around ``center`` (undoable).

        Parameters
        ----------
        level : int
        region : int or str
        center : int
            Vertex under the brush.
        radius : float
            Model units; the brush covers :func:`~workbench.methods.regions.drag.brush_vertices`.
        erase : bool
            Return the covered vertices to the background instead.

        Returns
        -------
        int
            How many of the covered vertices changed label (0: nothing to do, no undo step).

        Raises
        ------
        RegionError
            ``center`` is not on the segmented skin, or the edit is refused (see :meth:`paint`).
        """
        from workbench.methods.regions.drag import brush_vertices
        from workbench.methods.regions.hierarchy import RegionError

        with self._model.lock:
            R = self.require("brush_region").regions
            lv = R.check_level(level)
            verts = brush_vertices(self._model, center, radius)
            if verts.size == 0:
                raise RegionError(f"vertex {int(center)} is not on the segmented skin")
            before = R.labels[lv]
            after = self.paint(lv, region, verts, add=not erase).regions.labels[lv]
            return int(np.count_nonzero(after[verts] != before[verts]))

    # ------------------------------------------------------------- marker fits
    def key_marker_fit(self, fit: Any, start: float = 0.0, every: int = 1, *,
                       interpolation: Interpolation = "linear") -> NDArray[np.float64]:
        """Key a marker fit (Joshi et al. 2003 §3) on the timeline frame by frame; one undo step; the key times.

        Frame ``f`` is keyed at ``start + f / fps``: the fitted global weights of
        every shape and the fitted weights of every region of ``fit.level``
        (``"regions/<level>/<region>"``); the model's region level is set to
        ``fit.level`` in the same undo step. The RBF residual is not keyed (the
        timeline has no track for a displacement field): use
        ``fit.positions(model, regions, f)`` per frame when it is needed.
        ``every`` >= 1 keys every ``every``-th frame (and always the last).
        """
        from workbench.animation.curves import weight_track_name
        from workbench.animation.tracks import add_keys
        from workbench.methods.regions.marker_fit import MarkerFit

        m = self._model
        if not isinstance(fit, MarkerFit):
            raise ModelError(f"key_marker_fit: fit must be a MarkerFit, got {type(fit).__name__}")
        if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
            raise ModelError(f"key_marker_fit: every must be an int >= 1, got {every!r}")
        t0 = float(start)
        if not math.isfinite(t0):
            raise ModelError(f"key_marker_fit: start must be finite seconds, got {start!r}")
        with m.lock:
            st = self.require("key_marker_fit")
            if tuple(fit.shape_names) != tuple(m.shape_names):
                raise ModelError(
                    f"key_marker_fit: fit was made for {len(fit.shape_names)} shapes "
                    f"{list(fit.shape_names[:4])}..., the model has {len(m.shape_names)} "
                    f"{m.shape_names[:4]}... (shape list edited since fitting: fit again)"
                )
            L = int(fit.level)
            R = st.regions
            if L >= R.n_levels or tuple(R.names[L]) != tuple(fit.region_names):
                raise ModelError(
                    f"key_marker_fit: fit was made for other regions on level {L} "
                    "(the regions were edited or re-segmented since fitting: fit again)"
                )
            timeline: Any = m.timeline  # type: ignore[attr-defined]
            tl = timeline.value
            keyed_level = region_level(tl)
            if keyed_level is not None and keyed_level != L:
                raise ModelError(
                    f"key_marker_fit: the timeline has region keys on level {keyed_level}, "
                    f"the fit is on level {L}; delete those keys or fit on level {keyed_level}"
                )
            T = fit.n_frames
            frames = np.arange(0, T, int(every))
            if frames[-1] != T - 1:
                frames = np.append(frames, T - 1)
            times = t0 + frames / tl.fps
            G = np.asarray(fit.global_weights, np.float64)[frames]
            RW = np.asarray(fit.region_weights, np.float64)[frames]
            for k, name in enumerate(m.shape_names):
                tl = add_keys(tl, weight_track_name(name), times, G[:, k], interpolation=interpolation)
            for r, region in enumerate(fit.region_names):
                tl = add_keys(tl, region_track_name(L, region), times, RW[:, r, :], interpolation=interpolation)
            tl = tl.replace(start=min(tl.start, float(times[0])), end=max(tl.end, float(times[-1])))
            label = f"Key marker fit ({frames.size} frames from {t0:g}s)"
            with m.undo_group(label):
                if st.level != L:
                    self.set_level(L)
                timeline.set(tl, label)
            return times
