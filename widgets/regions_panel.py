"""``RegionsPanel``: local blend regions, coarse-to-fine region sculpting (Joshi et al. 2003, §2–§4).

Paper: "Learning Controls for Blend Shape Based Realistic Facial Animation"
(``shared/papers/siggraph2006-course-performance-driven-facial-animation.md``).
The numerics live in the headless core (:mod:`workbench.methods.regions.segmentation`,
:mod:`workbench.methods.regions.blend`); this panel is the notebook front of them:

* **Find regions** + a threshold ``t`` slider: segmentation runs again when the
  slider is released (``model.segment_regions``, undoable), with a progress bar
  and the time it took;
* a **level** slider (coarse ↔ fine; ``model.set_region_level``, the weights
  carry over to the new level);
* a **colour overlay** on the viewport: each region its own colour, the
  background grey, overlaps blended by the per-vertex region weights (so the
  one-ring seams show as gradients). The overlay replaces ``viewport.vertex_colors``
  while the panel is active and the previous colours come back on
  :meth:`RegionsPanel.deactivate` / :meth:`RegionsPanel.close`;
* a **region** dropdown with one slider per *driver* shape of that region (the
  shapes that move it most, :attr:`workbench.methods.regions.segmentation.Regions.drivers`; more can
  be added), editing that region's weights only
  (:meth:`RegionWeights.with_region` → ``model.set_region_weights``). A slider drag
  is one undo step (:class:`widgets._threading.InteractionGrouper`, as in the
  expression panel). "Reset region" puts the region back on the global weights;
* **Drag to sculpt**: the viewport shows pin markers (the mocap-like default
  marker set plus the model's handles) in its sculpt tool, and dragging a pin
  solves the region weights under it (:func:`workbench.methods.regions.blend.solve_region_drag`,
  bounded least squares, paper §4) with motion damping
  (:func:`workbench.methods.regions.blend.damp_drag`); the face follows while dragging and
  the drag is one undo step. Optionally the other pins of the touched regions are
  held where they are ("hold other pins");
* **Edit regions** (the selected region, on the shown level; each one undo step
  through ``model.rename_region`` / ``merge_regions`` / ``split_region`` /
  ``paint_region``, see :mod:`workbench.methods.regions.segmentation` for the rules): *Rename* (text +
  button); *Merge* with a touching region chosen in a dropdown (the merged region
  keeps the larger one's name and weights); *Split…*: markers spread over the
  region, click two and the region is cut halfway between them along the surface
  (geodesic Voronoi; on coarser levels whole finer regions are grouped);
  *Paint region*: markers over and around the region, drag from one and a round
  brush (radius slider, "erase" to take vertices out) assigns the skin under it
  to the region, one undo step per stroke. Split seeds and brush strokes come
  through the viewport's ``drag_handler`` hook (:class:`RegionSeedPicker`,
  :class:`RegionBrushHandler`), as the pin drags do: the viewport has no hook
  that reports a plain click on the surface without adding a model handle;
  :meth:`RegionsPanel.pick_seed` and :meth:`RegionsPanel.paint_at` take a vertex
  id for when it has;
* a status line: regions per level, segmentation time, solve time per drag update.

The drag messages reach :class:`RegionDragHandler` through the viewport's
``drag_handler`` hook (set only while drag mode is on; otherwise the viewport
moves model handles as usual). Like the other panels it keeps no model state of
its own: it edits the model through its methods and follows ``model.events``.

Hand-written because it is the UI of this project's own region model; the
widgets are ipywidgets.
"""

from __future__ import annotations

import colorsys
import html
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

import ipywidgets as W
import numpy as np

from widgets._threading import (
    ErrorSink,
    InteractionGrouper,
    close_interactions,
    register_interaction_closer,
)

#: Colour of vertices in no region (sRGB, [0, 1]).
BACKGROUND_GREY = (0.62, 0.62, 0.62)

#: A region drag with no message from the front end for this long is ended (page closed).
DRAG_WATCHDOG_S = 30.0

_HELP = (
    "<div style='line-height:1.35'>"
    "<b>Find regions</b> splits the face where its shapes bend the skin (Joshi et al. 2003). "
    "Move <b>t</b> for bigger/smaller regions and <b>level</b> for coarse/fine. "
    "In <b>Drag to sculpt</b> mode drag a marker: the weights of the region(s) under it are "
    "solved so the point follows the mouse; Shift-click the face to add a marker. "
    "<b>Edit regions</b>: rename, merge with a neighbour, split between two clicked markers, "
    "or paint the region with a brush (each one undo step).</div>"
)


#: Step of the per-region weight sliders.
SLIDER_STEP = 0.01

#: Markers shown over the selected region in split mode (click two of them).
SPLIT_MARKERS = 24

#: Markers shown over and around the selected region in paint mode (drag from one).
PAINT_MARKERS = 40


def _snap(value: float, lo: float) -> float:
    """``value`` on the slider grid ``lo + k * SLIDER_STEP`` (what the front end shows)."""
    return float(lo + round((value - lo) / SLIDER_STEP) * SLIDER_STEP)


def _is_echo(slider_value: float, model_value: float, lo: float) -> bool:
    """True if a slider value is the model's value as the front end shows it.

    The browser snaps a slider to its step and sends the snapped value back;
    solved weights (0.0418) are not on the grid, so without this every region
    drag would be followed by one "slider" edit per driver shape.
    """
    return (
        abs(slider_value - model_value) < 1e-6 or abs(slider_value - _snap(model_value, lo)) < 1e-6
    )


def region_palette(n: int) -> np.ndarray:
    """(n, 3) float32 sRGB colours, pairwise distinct, none of them grey.

    Golden-angle hues with three saturation/value bands, so that neighbours in
    index order (often neighbours on the face) differ in hue *and* brightness.
    """
    out = np.empty((n, 3), np.float32)
    for i in range(n):
        h = (i * 0.618033988749895) % 1.0
        s = (0.75, 0.55, 0.9)[i % 3]
        v = (0.95, 0.8, 0.65)[(i // 3) % 3]
        out[i] = colorsys.hsv_to_rgb(h, s, v)
    return out


def region_colors(
    regions: Any,
    level: int,
    background: Iterable[float] = BACKGROUND_GREY,
    slots: Any = None,
) -> np.ndarray:
    """Per-vertex overlay colours of one level's regions.

    Parameters
    ----------
    regions : workbench.methods.regions.segmentation.Regions
    level : int
    background : (3,) float
        Colour of the background (weight ``regions.background[level]``).
    slots : (R,) int, optional
        Palette entry of each region (default: its index). The panel keeps the
        colours of untouched regions across region edits this way.

    Returns
    -------
    (n, 3) float32
        ``sum_r W_r(v) palette[r] + W_bg(v) background``: a vertex inside one
        region's core has exactly that region's colour, overlap vertices a blend.
    """
    lv = regions.check_level(level)
    R = regions.n_regions(lv)
    idx = np.arange(R) if slots is None else np.asarray(slots, np.int64).reshape(-1)
    if idx.shape != (R,):
        raise ValueError(f"region_colors: slots must have one entry per region ({R}), got {idx.shape}")
    pal = region_palette(int(idx.max()) + 1 if R else 0)[idx].astype(np.float64)
    W = regions.weight_matrix(lv)
    bg = (
        np.asarray(regions.background[lv], np.float64)[:, None]
        * np.asarray(list(background), np.float64)[None, :]
    )
    c = np.asarray(W @ pal) + bg
    return np.clip(c, 0.0, 1.0).astype(np.float32)


class _DragWatchdog:
    """An abandoned pointer drag (page closed mid-drag) must not leave the model
    inside an interaction: one self-re-arming timer per drag, as the viewport does.

    Subclasses set ``_lock``, ``_watchdog = None`` and ``_last_msg`` and define
    :meth:`_drag_open` and :meth:`end`.
    """

    _lock: threading.RLock
    _watchdog: threading.Timer | None
    _last_msg: float

    def _drag_open(self) -> bool:  # pragma: no cover - overridden
        raise NotImplementedError

    def end(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _arm_watchdog(self) -> None:
        self._last_msg = time.monotonic()
        if self._watchdog is None:
            self._start_watchdog(DRAG_WATCHDOG_S)

    def _start_watchdog(self, delay: float) -> None:
        self._watchdog = threading.Timer(delay, self._on_watchdog)
        self._watchdog.daemon = True
        self._watchdog.start()

    def _cancel_watchdog(self) -> None:
        if self._watchdog is not None:
            self._watchdog.cancel()
            self._watchdog = None

    def _on_watchdog(self) -> None:
        with self._lock:
            if not self._drag_open():
                self._watchdog = None
                return
            idle = time.monotonic() - self._last_msg
            if idle < DRAG_WATCHDOG_S:
                self._start_watchdog(DRAG_WATCHDOG_S - idle)
                return
            self._watchdog = None
            self.end()


class RegionDragHandler(_DragWatchdog):
    """Turns pin drags in the viewport into region-weight solves (paper §4).

    Installed as ``viewport.drag_handler`` by :class:`RegionsPanel` in drag mode;
    usable on its own (tests call :meth:`begin` / :meth:`move` / :meth:`end`).

    Parameters
    ----------
    model : workbench.FaceModel
        Must hold regions (``model.segment_regions()``).
    pins : callable returning (p,) int
        The pin vertices (the viewport's markers; ``index`` in :meth:`begin` and
        :meth:`move` is into this array).
    damping : bool
        Scale the mouse motion by :func:`workbench.methods.regions.blend.drag_damping`.
    hold_others : bool
        Also pin the other pins that lie in the touched regions at their
        current positions.
    regularization : float
        Passed to :func:`workbench.methods.regions.blend.solve_region_drag`.
    """

    def __init__(
        self,
        model: Any,
        pins: Callable[[], np.ndarray],
        *,
        damping: bool = True,
        hold_others: bool = False,
        regularization: float = 1e-3,
    ) -> None:
        self.model = model
        self.pins = pins
        self.damping = bool(damping)
        self.hold_others = bool(hold_others)
        self.regularization = float(regularization)
        #: kernel ms of each solve (solve_region_drag only) and of each move (solve + model update)
        self.solve_ms: deque[float] = deque(maxlen=512)
        self.move_ms: deque[float] = deque(maxlen=512)
        #: called with a dict of stats after every drag
        self.listeners: list[Callable[[dict[str, Any]], Any]] = []
        self.last_drag: dict[str, Any] = {}
        self._lock = threading.RLock()
        self._drag: dict[str, Any] | None = None
        self._cm: Any = None
        self._watchdog: threading.Timer | None = None
        self._last_msg = 0.0
        # other widgets' edits end an open pin drag first (one undo step each)
        register_interaction_closer(model, self.end)

    @property
    def dragging(self) -> bool:
        return self._drag is not None

    def begin(self, index: int, vertex: int | None = None) -> None:
        """Start dragging pin ``index`` (at ``vertex``); enters ``model.interaction``.

        Raises
        ------
        workbench.methods.regions.segmentation.RegionError / workbench.model.ModelError
            No regions yet, or the pin lies in the background of the current level.
        """
        from workbench.methods.regions.blend import RegionWeights
        from workbench.methods.regions.segmentation import RegionError

        model = self.model
        with self._lock:
            self.end()
            pins = np.asarray(self.pins(), dtype=np.int64).reshape(-1)
            if vertex is None:
                if not 0 <= index < pins.size:
                    raise ValueError(f"RegionDragHandler.begin: no pin {index} (have {pins.size})")
                vertex = int(pins[index])
            v = int(vertex)
            with model.lock:
                st = model.regions
                if st is None:
                    raise RegionError("region drag: no regions yet; press 'Find regions' first")
                R, lv = st.regions, st.level
                under = R.regions_at(lv, v)
                if not under:
                    raise RegionError(
                        f"region drag: vertex {v} lies in the background of level {lv}; "
                        "drag a marker inside a coloured region (or lower t)"
                    )
                main = max(under, key=lambda r: under[r])
                rw0 = (
                    st.weights
                    if st.weights is not None
                    else RegionWeights.from_global(model, R, lv)
                )
                X0 = np.array(model.evaluate(), dtype=np.float64)
                held: list[int] = []
                if self.hold_others:
                    others = np.array([p for p in pins.tolist() if p != v], np.int64)
                    if others.size:
                        W = R.weight_matrix(lv)[others][:, sorted(under)]
                        held = others[np.asarray(W.sum(axis=1)).ravel() > 0].tolist()
                name = R.names[lv][main]
                cm = model.interaction(f"Region drag {name}")
                cm.__enter__()
            self._cm = cm
            self._drag = {
                "vertex": v,
                "index": int(index),
                "level": lv,
                "regions": R,
                "touched": sorted(under),
                "main": main,
                "name": name,
                "rw0": rw0,
                "X0": X0,
                "held": held,
                "t0": time.perf_counter(),
                "moves": 0,
                "solve_ms": [],
                "ms": [],
            }
            self._arm_watchdog()

    def move(self, index: int, position: Any) -> float:
        """Solve for the mouse at ``position`` (3,) model space; returns kernel ms (0 without a drag)."""
        from workbench.methods.regions.blend import damp_drag, solve_region_drag

        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(
                f"RegionDragHandler.move: position must be 3 finite numbers, got {position!r}"
            )
        model = self.model
        with self._lock:
            d = self._drag
            if d is None:
                return 0.0
            t0 = time.perf_counter()
            v, X0 = d["vertex"], d["X0"]
            delta = p - X0[v]
            if self.damping:
                delta = damp_drag(model, v, delta)
            pinned = {v: X0[v] + delta}
            for o in d["held"]:
                pinned[o] = X0[o]
            with model.lock:
                ts = time.perf_counter()
                # Always from the weights at the press: the blend is linear in the
                # weights, so one solve from the start is exact and path-independent.
                rw = solve_region_drag(
                    model, d["regions"], d["level"], d["rw0"], pinned,
                    regularization=self.regularization, current_positions=X0,
                )  # fmt: skip
                sms = (time.perf_counter() - ts) * 1e3
                model.set_region_weights(rw, f"Region drag {d['name']}")
            ms = (time.perf_counter() - t0) * 1e3
            d["moves"] += 1
            d["solve_ms"].append(sms)
            d["ms"].append(ms)
            self.solve_ms.append(sms)
            self.move_ms.append(ms)
            self._arm_watchdog()
            return ms

    def end(self) -> None:
        """End the open drag (one undo step); no-op without one."""
        with self._lock:
            self._cancel_watchdog()
            cm, d = self._cm, self._drag
            self._cm, self._drag = None, None
            if cm is None or d is None:
                return
            with self.model.lock:
                cm.__exit__(None, None, None)
            sms, ms = d["solve_ms"], d["ms"]
            self.last_drag = {
                "name": d["name"],
                "vertex": d["vertex"],
                "level": d["level"],
                "regions": [d["regions"].names[d["level"]][r] for r in d["touched"]],
                "held": len(d["held"]),
                "moves": d["moves"],
                "seconds": time.perf_counter() - d["t0"],
                "median_solve_ms": float(np.median(sms)) if sms else float("nan"),
                "median_ms": float(np.median(ms)) if ms else float("nan"),
            }
        for fn in list(self.listeners):
            fn(dict(self.last_drag))

    def _drag_open(self) -> bool:
        return self._drag is not None


def spread_vertices(ids: Any, positions: Any, k: int) -> np.ndarray:
    """Up to ``k`` of ``ids`` spread over their extent (farthest-point sampling).

    Parameters
    ----------
    ids : (m,) int
        Candidate vertex ids.
    positions : (n, 3) float
        Vertex positions (indexed by id).
    k : int

    Returns
    -------
    (min(k, m),) int64
        Starts at the candidate nearest the centroid; each next one is the
        candidate farthest from those chosen.
    """
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    if ids.size == 0 or k <= 0:
        return np.zeros(0, np.int64)
    P = np.asarray(positions, dtype=np.float64)[ids]
    first = int(np.argmin(np.linalg.norm(P - P.mean(axis=0), axis=1)))
    chosen = [first]
    d = np.linalg.norm(P - P[first], axis=1)
    for _ in range(min(k, ids.size) - 1):
        j = int(np.argmax(d))
        if d[j] <= 0:
            break
        chosen.append(j)
        d = np.minimum(d, np.linalg.norm(P - P[j], axis=1))
    return ids[np.array(chosen, np.int64)]


def brush_vertices(model: Any, center: int, radius: float) -> np.ndarray:
    """Skin vertices a round region brush at ``center`` covers.

    The segmented skin vertices within ``radius`` (model units, neutral mesh)
    of ``center`` that are connected to it inside that ball, so a brush at the
    upper lip does not reach across the mouth opening to the lower lip.

    Returns
    -------
    (m,) int64
        Sorted; empty if ``center`` is not a skin vertex.
    """
    from scipy.sparse.csgraph import connected_components

    from workbench.methods.regions.segmentation import region_topology

    topo = region_topology(model)
    c = int(center)
    if not 0 <= c < topo.n_vertices or not topo.skin[c]:
        return np.zeros(0, np.int64)
    V = topo.vertices
    near = np.flatnonzero(topo.skin & (np.linalg.norm(V - V[c], axis=1) <= float(radius)))
    if near.size <= 1:
        return np.array([c], np.int64)
    _, comp = connected_components(topo.adjacency[near][:, near], directed=False)
    return near[comp == comp[int(np.searchsorted(near, c))]].astype(np.int64)


class RegionSeedPicker:
    """``viewport.drag_handler`` of split mode: a press on a marker picks its vertex.

    The viewport's drag hook (see :class:`RegionDragHandler`) is the only
    per-vertex pick the viewport offers a panel without adding model handles,
    so split mode shows candidate markers over the selected region and a click
    on one calls ``on_pick(vertex)``; the drag itself does nothing.
    """

    def __init__(self, on_pick: Callable[[int], Any], markers: Callable[[], np.ndarray]) -> None:
        self.on_pick = on_pick
        self.markers = markers

    @property
    def dragging(self) -> bool:
        return False

    def begin(self, index: int, vertex: int | None = None) -> None:
        if vertex is None:
            m = np.asarray(self.markers(), np.int64).reshape(-1)
            if not 0 <= index < m.size:
                raise ValueError(f"RegionSeedPicker.begin: no marker {index} (have {m.size})")
            vertex = int(m[index])
        self.on_pick(int(vertex))

    def move(self, index: int, position: Any) -> float:
        return 0.0

    def end(self) -> None:
        return None


class RegionBrushHandler(_DragWatchdog):
    """Paints a region with a round brush (``viewport.drag_handler`` of paint mode).

    A press on a marker opens ``model.interaction("Paint region <name>")`` and
    paints a dab there; while dragging, the brush sits on the skin vertex
    nearest to the pointer (the viewport sends the pointer on the view plane
    through the pressed marker; the nearest vertex of the face shown is the
    one under it for the front of the face); release ends the stroke: one undo
    step. Every dab is ``model.paint_region(level, region, brush_vertices(...),
    add=not erase)``; a dab the model refuses (not touching the region, or one
    that would cut another region in pieces) is skipped and its message kept
    in :attr:`last_error`, so the stroke goes on. Usable without a viewport
    (tests call :meth:`begin` / :meth:`move` / :meth:`end`, or :meth:`dab`).

    Parameters
    ----------
    model : workbench.FaceModel
    target : callable returning (level, region name) or None
        The region to paint (the panel's selection).
    radius : float
        Brush radius in model units.
    erase : bool
        Take the brushed vertices out of the region (to the background).
    """

    def __init__(
        self,
        model: Any,
        target: Callable[[], tuple[int, str] | None],
        *,
        radius: float = 0.05,
        erase: bool = False,
    ) -> None:
        self.model = model
        self.target = target
        self.radius = float(radius)
        self.erase = bool(erase)
        self.listeners: list[Callable[[dict[str, Any]], Any]] = []
        self.last_stroke: dict[str, Any] = {}
        self.last_error = ""
        self._lock = threading.RLock()
        self._stroke: dict[str, Any] | None = None
        self._cm: Any = None
        self._watchdog: threading.Timer | None = None
        self._last_msg = 0.0
        register_interaction_closer(model, self.end)

    @property
    def dragging(self) -> bool:
        return self._stroke is not None

    def _drag_open(self) -> bool:
        return self._stroke is not None

    def dab(self, center: int) -> int:
        """Paint (or erase) the brush at vertex ``center``; returns the vertices that changed label."""
        from workbench.methods.regions.segmentation import RegionError

        tgt = self.target()
        if tgt is None:
            raise ValueError("region brush: select a region first")
        level, name = tgt
        verts = brush_vertices(self.model, int(center), self.radius)
        if verts.size == 0:
            self.last_error = f"vertex {int(center)} is not on the segmented skin"
            return 0
        model = self.model
        with model.lock:
            st = model.regions
            if st is None:
                raise ValueError("region brush: no regions yet; press 'Find regions' first")
            before = st.regions.labels[level]
            try:
                after = model.paint_region(level, name, verts, add=not self.erase)
            except RegionError as exc:
                self.last_error = str(exc)
                return 0
            self.last_error = ""
            changed = int(np.count_nonzero(after.regions.labels[level][verts] != before[verts]))
        if self._stroke is not None:
            self._stroke["dabs"] += 1
            self._stroke["changed"] += changed
        return changed

    def begin(self, index: int, vertex: int | None = None) -> None:
        """Start a stroke at marker ``index`` (vertex ``vertex``); enters ``model.interaction``."""
        from scipy.spatial import cKDTree

        if vertex is None:
            raise ValueError("region brush: the press needs the marker's vertex")
        model = self.model
        with self._lock:
            self.end()
            tgt = self.target()
            if tgt is None or model.regions is None:
                raise ValueError("region brush: find regions and select a region first")
            from workbench.methods.regions.segmentation import region_topology

            skin = np.flatnonzero(region_topology(model).skin)
            with model.lock:
                X = np.asarray(model.evaluate(), dtype=np.float64)
                verb = "Erase from region" if self.erase else "Paint region"
                cm = model.interaction(f"{verb} {tgt[1]}")
                cm.__enter__()
            self._cm = cm
            self._stroke = {
                "name": tgt[1],
                "tree": cKDTree(X[skin]),
                "skin": skin,
                "X": X,
                "last": int(vertex),
                "dabs": 0,
                "changed": 0,
                "t0": time.perf_counter(),
            }
            self._arm_watchdog()
        self.dab(int(vertex))

    def move(self, index: int, position: Any) -> float:
        """Move the brush to the skin vertex nearest ``position`` (3,); returns kernel ms."""
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"RegionBrushHandler.move: position must be 3 finite numbers, got {position!r}")
        with self._lock:
            st = self._stroke
            if st is None:
                return 0.0
            t0 = time.perf_counter()
            _, j = st["tree"].query(p)
            v = int(st["skin"][int(j)])
            self._arm_watchdog()
            if v == st["last"] or np.linalg.norm(st["X"][v] - st["X"][st["last"]]) < 0.25 * self.radius:
                return 0.0
            st["last"] = v
        self.dab(v)
        return (time.perf_counter() - t0) * 1e3

    def end(self) -> None:
        """End the open stroke (one undo step); no-op without one."""
        with self._lock:
            self._cancel_watchdog()
            cm, st = self._cm, self._stroke
            self._cm, self._stroke = None, None
            if cm is None or st is None:
                return
            with self.model.lock:
                cm.__exit__(None, None, None)
            self.last_stroke = {
                "name": st["name"],
                "dabs": st["dabs"],
                "changed": st["changed"],
                "erase": self.erase,
                "seconds": time.perf_counter() - st["t0"],
                "error": self.last_error,
            }
        for fn in list(self.listeners):
            fn(dict(self.last_stroke))


class RegionsPanel(W.VBox):
    """Blend-region controls for a FaceModel and its viewport (see the module docstring).

    Parameters
    ----------
    model : workbench.FaceModel
    viewport : widgets.Viewport, optional
        Gets the colour overlay and, in drag mode, the pin markers and the
        ``drag_handler``.
    errors : ipywidgets.Output, optional
        Where callback errors are shown.
    threshold : float
        Initial ``t``.
    idle_s : float
        Idle time that ends a weight-slider drag's undo step.
    before_edit : iterable of callables
        Called before undo/redo and whole-model edits (e.g. another panel's
        ``grouper.flush``).

    Notes
    -----
    A host that shows this panel in a tab should call :meth:`activate` when the
    tab is shown and :meth:`deactivate` when it is hidden: the overlay and the
    drag mode then come and go with the tab.
    """

    def __init__(
        self,
        model: Any,
        viewport: Any = None,
        *,
        errors: W.Output | None = None,
        threshold: float = 0.25,
        idle_s: float = 0.5,
        before_edit: Iterable[Callable[[], Any]] = (),
    ) -> None:
        self._model = model
        self.viewport = viewport
        self.errors = ErrorSink(
            errors
            if errors is not None
            else getattr(getattr(viewport, "errors", None), "output", None)
        )
        self.grouper = InteractionGrouper(model, idle_s=idle_s, errors=self.errors)
        self._before_edit = list(before_edit)
        self.drag_handler = RegionDragHandler(model, self._pin_vertices)
        # region edits: split seeds are picked, and the region brush painted, through
        # the same viewport drag hook as the pin drags (markers over the region)
        self.seed_picker = RegionSeedPicker(self.pick_seed, lambda: self._edit_markers)
        self.brush_handler = RegionBrushHandler(model, self._brush_target)
        self._edit_markers = np.zeros(0, np.int64)
        self._split_seeds: list[int] = []
        self._slot_memory: Any = None  # (deformation, {level: (labels, names, {name: slot})})
        self.edit_message = ""
        self._default_pins: np.ndarray | None = None
        self._active = False
        self._saved_colors: Any = None
        self._saved_tool: str | None = None
        self._overlay_key: Any = None
        self._extra_shapes: list[str] = []
        self.segment_ms: float | None = None
        self.weight_sliders: dict[str, W.FloatSlider] = {}

        def button(desc: str, cls: str, tip: str, icon: str = "") -> W.Button:
            b = W.Button(description=desc, tooltip=tip, icon=icon, layout=W.Layout(width="auto"))
            b.add_class(cls)
            return b

        self.find_button = button(
            "Find regions", "fwb-find-regions", "Segment the face into blend regions", "search"
        )
        self.threshold = W.FloatSlider(
            value=float(threshold), min=0.0, max=0.95, step=0.05, description="t (threshold)",
            continuous_update=False, readout_format=".2f",
            style={"description_width": "110px"}, layout=W.Layout(width="98%"),
        )  # fmt: skip
        self.threshold.add_class("fwb-region-threshold")
        self.progress = W.FloatProgress(
            value=0.0,
            min=0.0,
            max=1.0,
            bar_style="info",
            layout=W.Layout(width="98%", visibility="hidden"),
        )
        self.progress.add_class("fwb-region-progress")
        self.progress_label = W.HTML("")
        self.progress_label.add_class("fwb-region-progress-label")
        self.level = W.SelectionSlider(
            options=[("—", 0)], value=0, description="level", continuous_update=False,
            style={"description_width": "110px"}, layout=W.Layout(width="98%"), disabled=True,
        )  # fmt: skip
        self.level.add_class("fwb-region-level")
        self.overlay = W.Checkbox(
            value=True, description="region colours", indent=False, layout=W.Layout(width="150px")
        )
        self.overlay.add_class("fwb-region-overlay")
        self.region = W.Dropdown(options=[], description="region", style={"description_width": "60px"},
                                 layout=W.Layout(width="260px"), disabled=True)  # fmt: skip
        self.region.add_class("fwb-region-select")
        self.reset_region_button = button(
            "Reset region",
            "fwb-reset-region",
            "This region follows the global sliders again",
            "undo",
        )
        self.reset_all_button = button(
            "Reset all", "fwb-reset-all-regions", "Every region follows the global sliders"
        )
        self.add_shape = W.Dropdown(
            options=[("+ shape…", "")], value="", layout=W.Layout(width="200px")
        )
        self.add_shape.add_class("fwb-region-add-shape")
        self.sliders_box = W.VBox(layout=W.Layout(width="100%"))
        self.drag_mode = W.ToggleButton(value=False, description="Drag to sculpt", icon="hand-paper-o",
                                        tooltip="Drag a marker to solve the weights of the region(s) under it",
                                        layout=W.Layout(width="150px"))  # fmt: skip
        self.drag_mode.add_class("fwb-region-drag")
        self.damping = W.Checkbox(
            value=True, description="motion damping", indent=False, layout=W.Layout(width="140px")
        )
        self.damping.add_class("fwb-region-damping")
        self.hold = W.Checkbox(
            value=False, description="hold other pins", indent=False, layout=W.Layout(width="140px")
        )
        self.hold.add_class("fwb-region-hold")
        # ---- region edits (merge / split / rename / paint)
        self.rename_text = W.Text(
            value="", placeholder="new name", layout=W.Layout(width="180px"), disabled=True
        )
        self.rename_text.add_class("fwb-region-rename-text")
        self.rename_button = button("Rename", "fwb-region-rename", "Rename the selected region")
        self.merge_with = W.Dropdown(options=[], description="merge with",
                                     style={"description_width": "80px"},
                                     layout=W.Layout(width="260px"), disabled=True)  # fmt: skip
        self.merge_with.add_class("fwb-region-merge-with")
        self.merge_button = button(
            "Merge", "fwb-region-merge", "Merge the selected region with the touching one chosen"
        )
        self.split_mode = W.ToggleButton(value=False, description="Split…", icon="scissors",
                                         tooltip="Click two markers on the selected region: it is "
                                         "cut halfway between them along the surface",
                                         layout=W.Layout(width="110px"))  # fmt: skip
        self.split_mode.add_class("fwb-region-split")
        self.paint_mode = W.ToggleButton(value=False, description="Paint region", icon="paint-brush",
                                         tooltip="Drag from a marker to paint the selected region "
                                         "over the face (one undo step per stroke)",
                                         layout=W.Layout(width="130px"))  # fmt: skip
        self.paint_mode.add_class("fwb-region-paint")
        r0 = self._default_brush_radius()
        self.paint_radius = W.FloatSlider(
            value=r0, min=r0 / 4, max=r0 * 4, step=r0 / 20, description="radius",
            readout_format=".3f", continuous_update=False,
            style={"description_width": "50px"}, layout=W.Layout(width="230px"),
        )  # fmt: skip
        self.paint_radius.add_class("fwb-region-paint-radius")
        self.paint_erase = W.Checkbox(
            value=False, description="erase", indent=False, layout=W.Layout(width="80px")
        )
        self.paint_erase.add_class("fwb-region-paint-erase")
        self.edit_status = W.HTML("")
        self.edit_status.add_class("fwb-region-edit-status")
        self.edit_box = W.VBox(
            [
                W.HTML("<b>Edit regions</b> (the selected region, on the shown level)"),
                W.HBox([self.rename_text, self.rename_button]),
                W.HBox([self.merge_with, self.merge_button]),
                W.HBox([self.split_mode, self.paint_mode, self.paint_radius, self.paint_erase]),
                self.edit_status,
            ],
            layout=W.Layout(width="100%", border="1px solid #ddd", padding="4px"),
        )
        self.edit_box.add_class("fwb-region-edit")
        self.undo_button = button("Undo", "fwb-region-undo", "", "undo")
        self.redo_button = button("Redo", "fwb-region-redo", "", "repeat")
        self.status = W.HTML("")
        self.status.add_class("fwb-region-status")

        super().__init__(
            [
                W.HTML(_HELP),
                W.HBox([self.find_button, self.overlay]),
                self.threshold,
                self.progress,
                self.progress_label,
                self.level,
                W.HBox([self.region, self.reset_region_button, self.reset_all_button]),
                self.sliders_box,
                self.add_shape,
                W.HBox([self.drag_mode, self.damping, self.hold]),
                self.edit_box,
                W.HBox([self.undo_button, self.redo_button]),
                self.status,
            ],
            layout=W.Layout(width="100%", min_width="400px"),
        )
        self.add_class("fwb-regions-panel")

        g = self.errors.guard
        self.find_button.on_click(g("find regions")(self._on_find))
        self.threshold.observe(g("threshold")(self._on_threshold), "value")
        self.level.observe(g("region level")(self._on_level), "value")
        self.overlay.observe(g("region overlay")(lambda _c: self._update_overlay()), "value")
        self.region.observe(g("region select")(self._on_region_select), "value")
        self.reset_region_button.on_click(g("reset region")(self._on_reset_region))
        self.reset_all_button.on_click(g("reset all regions")(self._on_reset_all))
        self.add_shape.observe(g("add shape slider")(self._on_add_shape), "value")
        self.drag_mode.observe(g("drag mode")(self._on_drag_mode), "value")
        self.damping.observe(g("damping")(self._on_drag_options), "value")
        self.hold.observe(g("hold pins")(self._on_drag_options), "value")
        self.undo_button.on_click(g("undo")(self._on_undo))
        self.redo_button.on_click(g("redo")(self._on_redo))
        self.rename_button.on_click(g("rename region")(self._on_rename))
        self.merge_button.on_click(g("merge regions")(self._on_merge))
        self.split_mode.observe(g("split mode")(self._on_split_mode), "value")
        self.paint_mode.observe(g("paint mode")(self._on_paint_mode), "value")
        self.paint_radius.observe(g("brush radius")(self._on_brush_options), "value")
        self.paint_erase.observe(g("brush erase")(self._on_brush_options), "value")
        self.brush_handler.listeners.append(g("region brush stats")(self._on_stroke_end))
        self.drag_handler.listeners.append(g("region drag stats")(self._on_drag_end))
        self._cb_regions = g("RegionsPanel regions")(self._on_model_regions)
        self._cb_weights = g("RegionsPanel weights")(self._on_model_weights)
        self._cb_history = g("RegionsPanel history")(self._on_model_history)
        self._cb_shapes = g("RegionsPanel shapes")(self._on_model_shapes)
        self._cb_handles = g("RegionsPanel handles")(self._on_model_handles)
        ev = model.events
        ev.regions.connect(self._cb_regions)
        ev.weights.connect(self._cb_weights)
        ev.weights_changing.connect(self._cb_weights)
        ev.history.connect(self._cb_history)
        ev.shapes.connect(self._cb_shapes)
        ev.handles.connect(self._cb_handles)
        self._connected = True
        self._shown_regions: Any = None
        self._syncing = False  # True while model -> UI updates set widget values
        self._on_model_shapes()
        self._on_model_regions()
        self._on_model_history()
        self.activate()

    @property
    def model(self) -> Any:
        return self._model

    # ------------------------------------------------------------ activation
    def activate(self) -> None:
        """Show the overlay (and drag mode, if on) on the viewport."""
        if self._active:
            return
        self._active = True
        vp = self.viewport
        if vp is not None:
            self._saved_colors = vp.vertex_colors
            self._overlay_key = None
        self._update_overlay()
        if self.drag_mode.value:
            self._enter_drag_mode()
        elif self.split_mode.value or self.paint_mode.value:
            self._enter_edit_mode()

    def deactivate(self) -> None:
        """Leave drag mode and give the viewport its previous colours back."""
        if not self._active:
            return
        self._leave_drag_mode()
        self._leave_edit_mode()
        self._active = False
        vp = self.viewport
        if vp is not None and self._overlay_key is not None:
            vp.vertex_colors = self._saved_colors
        self._overlay_key = None

    # ------------------------------------------------------- UI -> model
    def _flush(self) -> None:
        close_interactions(self._model)  # this panel's grouper and pin drag too
        for fn in self._before_edit:
            fn()

    def segment(self, threshold: float | None = None) -> Any:
        """Run the segmentation at ``threshold`` (default: the slider's); returns the RegionState."""
        t = float(self.threshold.value if threshold is None else threshold)
        self._flush()
        self.progress.value = 0.0
        self.progress.layout.visibility = "visible"
        self.progress_label.value = f"<i>segmenting at t = {t:.2f} …</i>"
        t0 = time.perf_counter()
        try:
            state = self._model.segment_regions(t, progress=self._on_progress)
        finally:
            self.progress.layout.visibility = "hidden"
        self.segment_ms = (time.perf_counter() - t0) * 1e3
        counts = " / ".join(
            str(state.regions.n_regions(lv)) for lv in range(state.regions.n_levels)
        )
        self.progress_label.value = (
            f"t = {t:.2f}: {counts} regions (fine → coarse) in {self.segment_ms:.0f} ms"
        )
        self._update_status()
        return state

    def _on_progress(self, fraction: float, message: str) -> None:
        self.progress.value = min(max(float(fraction), 0.0), 1.0)
        self.progress_label.value = f"<i>segmenting: {message}</i>"

    def _on_find(self, _b: Any = None) -> None:
        self.segment()

    def _on_threshold(self, change: Any) -> None:
        if self._syncing:
            return  # the slider follows the model (undo/redo)
        st = self._model.regions
        if st is not None and abs(st.regions.threshold - float(change["new"])) < 1e-9:
            return
        self.segment(float(change["new"]))

    def _on_level(self, change: Any) -> None:
        st = self._model.regions
        if self._syncing or st is None or change["new"] is None or int(change["new"]) == st.level:
            return
        self._flush()
        self._model.set_region_level(int(change["new"]))

    def _current_weights(self) -> Any:
        from workbench.methods.regions.blend import RegionWeights

        st = self._model.regions
        if st is None:
            return None
        return (
            st.weights
            if st.weights is not None
            else RegionWeights.from_global(self._model, st.regions, st.level)
        )

    def set_region_weight(self, region: int | str, shape: str, value: float) -> None:
        """One weight of one region (what a weight slider does, grouped into one undo step per drag)."""
        model = self._model
        with model.lock:
            rw = self._current_weights()
            if rw is None:
                raise ValueError("RegionsPanel: no regions yet; press 'Find regions' first")
            r = rw.region_index(region)
            if _is_echo(float(value), rw.region(r)[shape], model.shape(shape).slider_min):
                return  # an echo of a model update
            name = rw.region_names[r]
            self.grouper.touch(f"Region {name}: {shape}")
            model.set_region_weights(
                rw.with_region(r, {shape: float(value)}), f"Region {name}: {shape}"
            )

    def _on_weight_slider(self, shape: str, value: float) -> None:
        if self.region.value is None:
            return
        self.set_region_weight(int(self.region.value), shape, value)

    def _on_reset_region(self, _b: Any = None) -> None:
        rw = self._current_weights()
        if rw is None or self.region.value is None:
            return
        self._flush()
        model = self._model
        r = int(self.region.value)
        g = {nm: float(model.weights[nm]) for nm in model.shape_names}
        model.set_region_weights(rw.with_region(r, g), f"Reset region {rw.region_names[r]}")

    def _on_reset_all(self, _b: Any = None) -> None:
        st = self._model.regions
        if st is None or st.weights is None:
            return
        self._flush()
        self._model.set_region_weights(None, "Reset all regions")

    def _on_add_shape(self, change: Any) -> None:
        nm = change["new"]
        if not nm:
            return
        if nm not in self._extra_shapes:
            self._extra_shapes.append(nm)
        self.add_shape.value = ""
        self._build_sliders()

    def _on_undo(self, _b: Any = None) -> None:
        self._flush()
        self._model.undo()

    def _on_redo(self, _b: Any = None) -> None:
        self._flush()
        self._model.redo()

    # ------------------------------------------------------------ drag mode
    def _pin_vertices(self) -> np.ndarray:
        """(p,) int: the default marker set plus the model's handles (the drag-mode markers)."""
        from workbench.methods.handles.presets import default_face_handles

        if self._default_pins is None:
            try:
                self._default_pins = np.asarray(
                    default_face_handles(self._model).vertices, np.int64
                )
            except Exception:  # a model without shapes / skin: only user handles
                self._default_pins = np.zeros(0, np.int64)
        extra = np.asarray(self._model.handles.vertices, np.int64)
        extra = extra[~np.isin(extra, self._default_pins)]
        return np.concatenate([self._default_pins, extra])

    @property
    def pins(self) -> np.ndarray:
        """(p,) int vertex ids of the drag-mode markers (marker ``k`` is ``pins[k]``)."""
        return self._pin_vertices()

    def _on_drag_options(self, _change: Any = None) -> None:
        self.drag_handler.damping = bool(self.damping.value)
        self.drag_handler.hold_others = bool(self.hold.value)

    def _on_drag_mode(self, change: Any) -> None:
        if change["new"]:  # one pointer mode at a time
            self.split_mode.value = False
            self.paint_mode.value = False
        if not self._active:
            return
        if change["new"]:
            self._enter_drag_mode()
        else:
            self._leave_drag_mode()

    def _enter_drag_mode(self) -> None:
        vp = self.viewport
        if vp is None or getattr(vp, "drag_handler", None) is self.drag_handler:
            return
        self._flush()
        if hasattr(vp, "end_drag"):
            vp.end_drag()
        self._on_drag_options()
        vp.drag_handler = self.drag_handler
        self._saved_tool = vp.tool
        vp.handles = self._pin_vertices()
        vp.tool = "sculpt"
        self._update_status()

    def _leave_drag_mode(self) -> None:
        vp = self.viewport
        self.drag_handler.end()
        if vp is None or getattr(vp, "drag_handler", None) is not self.drag_handler:
            return
        vp.drag_handler = None
        # Give the viewport the model's handle markers (with mirror links) back.
        vp._model_handles_sent = None
        vp._sync_handles()
        if self._saved_tool is not None and vp.tool == "sculpt":
            vp.tool = self._saved_tool
        self._saved_tool = None
        self._update_status()

    def _on_model_handles(self) -> None:
        # Shift-click in drag mode adds a model handle: it becomes a pin too.
        vp = self.viewport
        if vp is not None and getattr(vp, "drag_handler", None) is self.drag_handler:
            vp.handles = self._pin_vertices()
        elif vp is not None and self._edit_handler_installed():
            vp.handles = self._edit_markers  # the viewport re-sent the model's handles

    def _on_drag_end(self, stats: dict[str, Any]) -> None:
        self._select_region(stats["name"])
        self._update_status()

    def _select_region(self, name: str) -> None:
        for label, idx in self.region.options:
            if label == name:
                self.region.value = idx
                return

    # ------------------------------------------------------- region edits
    def _default_brush_radius(self) -> float:
        from widgets.viewport import default_brush_radius

        try:
            return float(default_brush_radius(self._model))
        except Exception:  # a degenerate mesh
            return 0.05

    def _topology(self) -> Any:
        from workbench.methods.regions.segmentation import region_topology

        return region_topology(self._model)

    def _selected(self) -> tuple[Any, int, int] | None:
        """(Regions, level, region index) of the selection, or None."""
        st = self._model.regions
        if st is None or self.region.value is None:
            return None
        r = int(self.region.value)
        if not 0 <= r < st.regions.n_regions(st.level):
            return None
        return st.regions, st.level, r

    def _brush_target(self) -> tuple[int, str] | None:
        sel = self._selected()
        if sel is None:
            return None
        R, lv, r = sel
        return lv, R.names[lv][r]

    def _say(self, text: str, error: bool = False) -> None:
        self.edit_message = text
        esc = html.escape(text, quote=False)
        self.edit_status.value = f"<span style='color:#b00020'>{esc}</span>" if error else esc

    def _select_index(self, r: int) -> None:
        if any(idx == r for _label, idx in self.region.options):
            self.region.value = r

    def _on_region_select(self, _change: Any = None) -> None:
        if self._syncing:
            return
        self._build_sliders()
        self._refresh_edit_controls()

    def _refresh_edit_controls(self) -> None:
        """Merge candidates, rename placeholder and edit-mode markers for the selection."""
        from workbench.methods.regions.segmentation import adjacent_regions

        self._split_seeds = []
        sel = self._selected()
        if sel is None:
            self.merge_with.options = []
            self.merge_button.disabled = True
            self.rename_text.placeholder = "new name"
            self._refresh_edit_markers()
            return
        R, lv, r = sel
        nb = adjacent_regions(R, self._topology(), lv, r) if R.kinds[lv][r] == "skin" else []
        self.merge_with.options = [(R.names[lv][i], i) for i in nb]
        self.merge_with.value = nb[0] if nb else None
        self.merge_button.disabled = not nb
        self.rename_text.placeholder = R.names[lv][r]
        self._refresh_edit_markers()

    def rename(self, name: str | None = None) -> None:
        """Rename the selected region to ``name`` (default: the text box); one undo step."""
        sel = self._selected()
        new = (self.rename_text.value if name is None else name).strip()
        if sel is None or not new:
            self._say("select a region and type its new name", error=True)
            return
        R, lv, r = sel
        self._flush()
        old = R.names[lv][r]
        try:
            self._model.rename_region(lv, r, new)
        except ValueError as exc:
            self._say(str(exc), error=True)
            return
        self.rename_text.value = ""
        self._select_index(r)
        self._say(f"renamed {old} to {new}")

    def _on_rename(self, _b: Any = None) -> None:
        self.rename()

    def merge(self, other: int | str | None = None) -> None:
        """Merge the selected region with ``other`` (default: the "merge with" choice); one undo step.

        The merged region keeps the lower index and the name and weights of the
        larger of the two (:meth:`workbench.FaceModel.merge_regions`).
        """
        sel = self._selected()
        b = self.merge_with.value if other is None else other
        if sel is None or b is None:
            self._say("select a region and a touching region to merge with", error=True)
            return
        R, lv, r = sel
        self._flush()
        try:
            bi = R.region_index(lv, b)
            st = self._model.merge_regions(lv, r, bi)
        except ValueError as exc:
            self._say(str(exc), error=True)
            return
        keep = min(r, bi)
        self._select_index(keep)
        self._say(f"merged {R.names[lv][r]} and {R.names[lv][bi]} into {st.regions.names[lv][keep]}")

    def _on_merge(self, _b: Any = None) -> None:
        self.merge()

    def split(self, seed_a: int, seed_b: int) -> None:
        """Split the selected region between two vertices (geodesic Voronoi); one undo step."""
        sel = self._selected()
        if sel is None:
            self._say("select a region to split", error=True)
            return
        R, lv, r = sel
        self._flush()
        try:
            st = self._model.split_region(lv, r, int(seed_a), int(seed_b))
        except ValueError as exc:
            self._say(str(exc), error=True)
            return
        self._select_index(r)
        names = st.regions.names[lv]
        self._say(f"split {R.names[lv][r]} into {names[r]} and {names[r + 1]}")
        self.split_mode.value = False

    def pick_seed(self, vertex: int) -> None:
        """A click on the face in split mode: the first picks seed A, the second splits.

        What a click on a split-mode marker does (and what a future viewport
        click hook would call with the vertex under the pointer).
        """
        sel = self._selected()
        if sel is None:
            self._say("select a region to split", error=True)
            return
        R, lv, r = sel
        v = int(vertex)
        if R.labels[lv][v] != r:
            self._say(f"vertex {v} is not in {R.names[lv][r]}: click a marker on it", error=True)
            return
        if self._split_seeds and self._split_seeds[0] == v:
            return  # the same marker again
        self._split_seeds.append(v)
        if len(self._split_seeds) == 1:
            self._say(f"split {R.names[lv][r]}: first point at vertex {v}; click a second marker")
            return
        a, b = self._split_seeds[:2]
        self._split_seeds = []
        self.split(a, b)

    def paint_at(self, vertex: int) -> int:
        """One brush dab of the region brush at ``vertex`` (its own undo step outside a stroke).

        Returns the number of vertices whose label changed; a refused dab shows
        its reason in the edit status and returns 0.
        """
        self._flush()
        changed = self.brush_handler.dab(int(vertex))
        if self.brush_handler.last_error:
            self._say(self.brush_handler.last_error, error=True)
        else:
            tgt = self._brush_target()
            verb = "erased from" if self.brush_handler.erase else "painted into"
            self._say(f"{changed} vertices {verb} {tgt[1] if tgt else '?'}")
        return changed

    def _on_stroke_end(self, stats: dict[str, Any]) -> None:
        verb = "erased from" if stats["erase"] else "painted into"
        msg = f"{stats['changed']} vertices {verb} {stats['name']} ({stats['dabs']} dabs)"
        if stats["error"]:
            self._say(f"{msg}; last dab refused: {stats['error']}", error=True)
        else:
            self._say(msg)
        st = self._model.regions
        if st is not None and stats["name"] in st.regions.names[st.level]:
            self._select_index(st.regions.names[st.level].index(stats["name"]))
        self._refresh_edit_markers()

    def _on_brush_options(self, _change: Any = None) -> None:
        self.brush_handler.radius = float(self.paint_radius.value)
        self.brush_handler.erase = bool(self.paint_erase.value)
        self._refresh_edit_markers()

    def _edit_markers_for(self, mode: str) -> np.ndarray:
        from scipy.spatial import cKDTree

        sel = self._selected()
        if sel is None:
            return np.zeros(0, np.int64)
        R, lv, r = sel
        topo = self._topology()
        core = np.flatnonzero((R.labels[lv] == r) & topo.skin)
        if core.size == 0:
            return np.zeros(0, np.int64)
        V = topo.vertices
        if mode == "split":
            return spread_vertices(core, V, SPLIT_MARKERS)
        # paint: the region and a band of three brush radii around it
        skin = np.flatnonzero(topo.skin)
        d, _ = cKDTree(V[core]).query(V[skin])
        band = skin[d <= 3.0 * float(self.paint_radius.value)]
        return spread_vertices(band, V, PAINT_MARKERS)

    def _refresh_edit_markers(self) -> None:
        mode = "split" if self.split_mode.value else "paint" if self.paint_mode.value else None
        if mode is None or self.brush_handler.dragging:
            return  # (markers never change under a stroke: the drag addresses them by index)
        self._edit_markers = self._edit_markers_for(mode)
        vp = self.viewport
        if vp is not None and self._edit_handler_installed():
            vp.handles = self._edit_markers
        self._update_status()

    def _edit_handler_installed(self) -> bool:
        h = getattr(self.viewport, "drag_handler", None)
        return h is not None and (h is self.seed_picker or h is self.brush_handler)

    def _on_split_mode(self, change: Any) -> None:
        if change["new"]:
            self.drag_mode.value = False
            self.paint_mode.value = False
            self._split_seeds = []
            sel = self._selected()
            if sel is not None:
                R, lv, r = sel
                self._say(f"split {R.names[lv][r]}: click two markers on it")
            if self._active:
                self._enter_edit_mode()
        else:
            self._split_seeds = []
            if not self.paint_mode.value:
                self._leave_edit_mode()

    def _on_paint_mode(self, change: Any) -> None:
        if change["new"]:
            self.drag_mode.value = False
            self.split_mode.value = False
            self._on_brush_options()
            self._say("drag from a marker to paint the selected region (tick erase to remove)")
            if self._active:
                self._enter_edit_mode()
        elif not self.split_mode.value:
            self._leave_edit_mode()

    def _enter_edit_mode(self) -> None:
        handler = self.seed_picker if self.split_mode.value else self.brush_handler
        self._refresh_edit_markers()
        vp = self.viewport
        if vp is None or not self._active:
            return
        if getattr(vp, "drag_handler", None) is handler:
            return
        if self._edit_handler_installed():
            vp.drag_handler = handler  # split <-> paint: same markers mechanism
            self._refresh_edit_markers()
            return
        self._flush()
        if hasattr(vp, "end_drag"):
            vp.end_drag()
        vp.drag_handler = handler
        self._saved_tool = vp.tool
        vp.handles = self._edit_markers
        vp.tool = "sculpt"
        self._update_status()

    def _leave_edit_mode(self) -> None:
        self.brush_handler.end()
        vp = self.viewport
        if vp is None or not self._edit_handler_installed():
            return
        vp.drag_handler = None
        vp._model_handles_sent = None
        vp._sync_handles()
        if self._saved_tool is not None and vp.tool == "sculpt":
            vp.tool = self._saved_tool
        self._saved_tool = None
        self._update_status()

    # ------------------------------------------------------- model -> UI
    def _on_model_shapes(self) -> None:
        names = list(self._model.shape_names)
        self._extra_shapes = [nm for nm in self._extra_shapes if nm in names]
        self.add_shape.options = [("+ shape…", ""), *((nm, nm) for nm in names)]
        self.add_shape.value = ""
        self._default_pins = None
        self._build_sliders()

    def _on_model_regions(self) -> None:
        st = self._model.regions
        has = st is not None
        for w in (
            self.level,
            self.region,
            self.reset_region_button,
            self.reset_all_button,
            self.drag_mode,
            self.rename_text,
            self.rename_button,
            self.merge_with,
            self.merge_button,
            self.split_mode,
            self.paint_mode,
        ):
            w.disabled = not has
        if not has:
            self._shown_regions = None
            self.region.options = []
            self._build_sliders()
            self._refresh_edit_controls()
            self._update_overlay()
            self._update_status()
            return
        R, lv = st.regions, st.level
        key = (id(R), lv)
        if self._shown_regions != key:
            self._shown_regions = key
            self._syncing = True
            try:
                self._show_regions(R, lv)
            finally:
                self._syncing = False
            self._build_sliders()
            self._refresh_edit_controls()
            self._update_overlay()
        else:
            self._refresh_slider_values()
        self._update_status()

    def _show_regions(self, R: Any, lv: int) -> None:
        """Level slider, threshold slider and region dropdown for ``R`` shown on level ``lv``."""
        keep = self.region.label
        L = R.n_levels
        opts = []
        for i in range(L - 1, -1, -1):  # left = coarse, right = fine
            tag = " coarse" if i == L - 1 and L > 1 else " fine" if i == 0 else ""
            opts.append((f"L{i}{tag} ({R.n_regions(i)})", i))
        if list(self.level.options) != opts:
            self.level.options = opts
        if self.level.value != lv:
            self.level.value = lv
        if abs(self.threshold.value - R.threshold) > 1e-9:
            self.threshold.value = R.threshold
        ropts = [(nm, i) for i, nm in enumerate(R.names[lv])]
        self.region.options = ropts
        if keep in R.names[lv]:
            self.region.value = R.names[lv].index(keep)
        elif ropts:
            # default: the first skin region (rigid parts have nothing to sculpt)
            skin = [i for i, k in enumerate(R.kinds[lv]) if k == "skin"]
            self.region.value = skin[0] if skin else 0

    def _on_model_weights(self, _values: Any = None) -> None:
        st = self._model.regions
        if st is not None and st.weights is None:
            self._refresh_slider_values()

    def _on_model_history(self) -> None:
        model = self._model
        self.undo_button.disabled = not model.can_undo
        self.redo_button.disabled = not model.can_redo
        u, r = model.history.undo_labels, model.history.redo_labels
        self.undo_button.tooltip = f"Undo {u[-1]}" if u else "Nothing to undo"
        self.redo_button.tooltip = f"Redo {r[-1]}" if r else "Nothing to redo"

    def _slider_shapes(self) -> list[str]:
        st = self._model.regions
        if st is None or self.region.value is None:
            return []
        drivers = list(st.regions.drivers[st.level][int(self.region.value)])
        return drivers + [nm for nm in self._extra_shapes if nm not in drivers]

    def _build_sliders(self) -> None:
        for s in self.weight_sliders.values():
            s.close()
        self.weight_sliders = {}
        rw = self._current_weights()
        shapes = self._slider_shapes()
        if rw is None or not shapes:
            self.sliders_box.children = [W.HTML("<i>no region selected</i>")]
            return
        values = rw.region(int(self.region.value))
        model = self._model
        for nm in shapes:
            sh = model.shape(nm)
            s = W.FloatSlider(
                value=_snap(values[nm], sh.slider_min), min=sh.slider_min, max=sh.slider_max,
                step=SLIDER_STEP, description=nm,
                continuous_update=True, readout_format=".2f",
                style={"description_width": "140px"}, layout=W.Layout(width="98%"),
            )  # fmt: skip
            s.add_class("fwb-region-weight")
            s.add_class(f"fwb-region-weight-{nm}")
            s.observe(
                self.errors.guard(f"region weight {nm}")(
                    lambda ch, nm=nm: self._on_weight_slider(nm, ch["new"])
                ),
                "value",
            )
            self.weight_sliders[nm] = s
        self.sliders_box.children = list(self.weight_sliders.values())

    def _refresh_slider_values(self) -> None:
        rw = self._current_weights()
        if rw is None or self.region.value is None or not self.weight_sliders:
            return
        if int(self.region.value) >= len(rw.region_names):
            return
        values = rw.region(int(self.region.value))
        for nm, s in self.weight_sliders.items():
            v = values.get(nm)
            if v is not None and not _is_echo(s.value, v, s.min):
                s.value = _snap(v, s.min)

    def _update_overlay(self) -> None:
        vp = self.viewport
        if vp is None or not self._active:
            return
        st = self._model.regions
        if st is None or not self.overlay.value:
            if self._overlay_key is not None:
                vp.vertex_colors = self._saved_colors
                self._overlay_key = None
            return
        key = (id(st.regions), st.level)
        if key != self._overlay_key:
            slots = self.color_slots(st.regions, st.level)
            vp.vertex_colors = region_colors(st.regions, st.level, slots=slots)
            self._overlay_key = key

    def color_slots(self, regions: Any, level: int) -> np.ndarray:
        """(R,) palette entry of each region: stable across region edits.

        A fresh segmentation colours region ``r`` with palette entry ``r``. After
        an edit (same segmentation: the edits keep its ``deformation`` array)
        every region whose name survives keeps its colour, a renamed region keeps
        its colour, and new regions (split halves) take the lowest free entries,
        so an edit does not repaint the whole face.
        """
        names = regions.names[level]
        prev = self._slot_memory
        if prev is None or prev[0] is not regions.deformation:
            prev = (regions.deformation, {})
            self._slot_memory = prev
        per_level: dict[int, tuple[Any, tuple[str, ...], dict[str, int]]] = prev[1]
        old = per_level.get(level)
        if old is None:
            table = {nm: i for i, nm in enumerate(names)}
        else:
            # every name ever seen keeps its entry, so undoing an edit brings the colours back
            old_labels, old_names, table = old[0], old[1], dict(old[2])
            new = [nm for nm in names if nm not in table]
            gone = [nm for nm in old_names if nm not in names]
            if old_labels is regions.labels[level] and len(gone) == len(new) == 1:
                table[new[0]] = table[gone[0]]  # a rename (same labels): same colour
            used = set(table.values())
            free = (i for i in range(len(used) + len(names) + 1) if i not in used)
            for nm in names:
                if nm not in table:
                    table[nm] = next(free)
        per_level[level] = (regions.labels[level], names, table)
        slots = np.array([table[nm] for nm in names], np.int64)
        if np.unique(slots).size != slots.size:  # (two names that once shared an entry)
            slots = np.arange(len(names), dtype=np.int64)
        return slots

    def _update_status(self) -> None:
        st = self._model.regions
        if st is None:
            self.status.value = "no regions yet: press <b>Find regions</b>"
            return
        R = st.regions
        per = ", ".join(f"L{lv}: {R.n_regions(lv)}" for lv in range(R.n_levels))
        parts = [f"regions per level ({per})", f"level <b>{st.level}</b>"]
        if self.segment_ms is not None:
            parts.append(f"segmentation {self.segment_ms:.0f} ms")
        d = self.drag_handler.last_drag
        if d:
            parts.append(
                f"last drag <i>{d['name']}</i>: solve {d['median_solve_ms']:.2f} ms "
                f"(update {d['median_ms']:.1f} ms), {d['moves']} updates"
            )
        vp = self.viewport
        if vp is not None and getattr(vp, "drag_handler", None) is self.drag_handler:
            parts.append(f"drag mode: {len(self._pin_vertices())} markers")
        elif self._edit_handler_installed():
            mode = "split" if self.split_mode.value else "paint"
            parts.append(f"{mode} mode: {len(self._edit_markers)} markers")
        self.status.value = " · ".join(parts)

    # ------------------------------------------------------------ closing
    def close(self) -> None:
        """End open drags, restore the viewport, disconnect from the model, close the widgets."""
        if getattr(self, "_connected", False):
            try:
                self.grouper.flush()
                self.deactivate()
            finally:
                ev = self._model.events
                ev.regions.disconnect(self._cb_regions)
                ev.weights.disconnect(self._cb_weights)
                ev.weights_changing.disconnect(self._cb_weights)
                ev.history.disconnect(self._cb_history)
                ev.shapes.disconnect(self._cb_shapes)
                ev.handles.disconnect(self._cb_handles)
                self._connected = False
        for s in self.weight_sliders.values():
            s.close()
        super().close()
