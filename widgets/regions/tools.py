"""The Regions panel's pointer tools: what a marker drag in the viewport does.

The viewport hands marker drags to ``viewport.drag_handler``
(:class:`widgets.viewport.tools.HookedDrag`: ``begin(index, vertex)``,
``move(index, position) -> ms``, ``end()``, ``cancel()``). The panel installs
one of these with :class:`MarkerMode`:

* :class:`RegionDragHandler` (*Drag to sculpt*): a pin drag is
  ``model.regions.begin_drag(...)`` → :class:`~workbench.methods.regions.drag.RegionDrag`
  (Joshi et al. 2003 §4), one undo step;
* :class:`RegionBrushHandler` (*Paint region*): a stroke is
  ``model.regions.begin_paint(...)`` → :class:`~workbench.methods.regions.drag.RegionStroke`,
  one undo step;
* :class:`RegionSeedPicker` (*Split…*): a press picks the marker's vertex.

The handlers keep no model state: the core objects hold the interaction
token, and tell the handler (``on_close``) when another widget's edit closed
it; the handler then reports the drag as ended. An abandoned drag (page
closed) is ended by the viewport's gesture watchdog.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np


def _listeners(fns: list[Callable[[dict[str, Any]], Any]], stats: dict[str, Any]) -> None:
    for fn in list(fns):
        fn(dict(stats))


def _position(position: Any, what: str) -> np.ndarray:
    p = np.asarray(position, dtype=np.float64).reshape(-1)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise ValueError(f"{what}: position must be 3 finite numbers, got {position!r}")
    return p


class RegionDragHandler:
    """Turns pin drags in the viewport into region-weight solves (paper §4).

    Installed as ``viewport.drag_handler`` by the panel in drag mode; usable on
    its own (``begin`` / ``move`` / ``end`` / ``cancel``).

    Parameters
    ----------
    model : workbench.FaceModel
        Must hold regions (``model.regions.segment()``).
    pins : callable returning (p,) int
        The pin vertices (the viewport's markers; ``index`` in :meth:`begin` is
        into this array).
    damping, hold_others, regularization
        Passed to ``model.regions.begin_drag``.
    """

    def __init__(self, model: Any, pins: Callable[[], np.ndarray], *, damping: bool = True,
                 hold_others: bool = False, regularization: float = 1e-3) -> None:
        self.model = model
        self.pins = pins
        self.damping = bool(damping)
        self.hold_others = bool(hold_others)
        self.regularization = float(regularization)
        #: ms of each solve (solve_region_drag only) and of each move (solve + model update)
        self.solve_ms: deque[float] = deque(maxlen=512)
        self.move_ms: deque[float] = deque(maxlen=512)
        #: called with a dict of stats after every drag that was kept
        self.listeners: list[Callable[[dict[str, Any]], Any]] = []
        self.last_drag: dict[str, Any] = {}
        self._drag: Any = None  # the open RegionDrag
        self._ms: list[float] = []

    @property
    def dragging(self) -> bool:
        d = self._drag
        return d is not None and d.open

    def begin(self, index: int, vertex: int | None = None) -> None:
        """Start dragging pin ``index`` (at ``vertex``): opens the drag's interaction.

        Raises
        ------
        RegionError / ModelError
            No regions yet, or the pin lies in the background of the shown level.
        """
        self.end()
        pins = np.asarray(self.pins(), dtype=np.int64).reshape(-1)
        if vertex is None:
            if not 0 <= index < pins.size:
                raise ValueError(f"RegionDragHandler.begin: no pin {index} (have {pins.size})")
            vertex = int(pins[index])
        self._ms = []
        self._drag = self.model.regions.begin_drag(
            int(vertex), pins=pins, damping=self.damping, hold_others=self.hold_others,
            regularization=self.regularization, on_close=self._closed_elsewhere,
        )  # fmt: skip

    def move(self, index: int, position: Any) -> float:
        """Solve for the pointer at ``position`` (3,) model space; returns ms (0 without a drag)."""
        p = _position(position, "RegionDragHandler.move")
        d = self._drag
        if d is None or not d.open:
            return 0.0
        t0 = time.perf_counter()
        d.move(p)
        ms = (time.perf_counter() - t0) * 1e3
        self.solve_ms.append(d.solve_ms[-1])
        self.move_ms.append(ms)
        self._ms.append(ms)
        return ms

    def end(self) -> None:
        """End the open drag (one undo step); no-op without one."""
        d, self._drag = self._drag, None
        if d is None:
            return
        stats = d.end()
        ms = self._ms
        self.last_drag = {**stats, "median_ms": float(np.median(ms)) if ms else float("nan")}
        _listeners(self.listeners, self.last_drag)

    def cancel(self) -> None:
        """Cancel the open drag: the weights as at the press, no undo step."""
        d, self._drag = self._drag, None
        if d is not None:
            d.cancel()

    def _closed_elsewhere(self) -> None:
        # another widget's edit closed the drag's interaction, keeping its edits
        self.end()


class RegionBrushHandler:
    """Paints a region with a round brush (``viewport.drag_handler`` of paint mode).

    A press on a marker starts ``model.regions.begin_paint(level, region, ...)``
    and dabs there; while dragging, the brush follows the skin vertex nearest
    the pointer (:meth:`RegionStroke.move`); release ends the stroke: one undo
    step. A dab the model refuses is skipped and its reason kept in
    :attr:`last_error`, so the stroke goes on.

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

    def __init__(self, model: Any, target: Callable[[], tuple[int, str] | None], *,
                 radius: float = 0.05, erase: bool = False) -> None:
        self.model = model
        self.target = target
        self.radius = float(radius)
        self.erase = bool(erase)
        self.listeners: list[Callable[[dict[str, Any]], Any]] = []
        self.last_stroke: dict[str, Any] = {}
        self.last_error = ""
        self._stroke: Any = None  # the open RegionStroke

    @property
    def dragging(self) -> bool:
        st = self._stroke
        return st is not None and st.open

    def dab(self, center: int) -> int:
        """Brush at vertex ``center`` (in the open stroke, else its own undo step); returns changed vertices."""
        from workbench.methods.regions.hierarchy import RegionError

        st = self._stroke
        if st is not None and st.open:
            n = int(st.dab(int(center)))
            self.last_error = st.last_error
            return n
        tgt = self.target()
        if tgt is None:
            raise ValueError("region brush: select a region first")
        try:
            n = int(self.model.regions.brush(tgt[0], tgt[1], int(center), self.radius, erase=self.erase))
        except RegionError as exc:
            self.last_error = str(exc)
            return 0
        self.last_error = ""
        return n

    def begin(self, index: int, vertex: int | None = None) -> None:
        """Start a stroke at marker ``index`` (vertex ``vertex``) and dab there."""
        if vertex is None:
            raise ValueError("region brush: the press needs the marker's vertex")
        self.end()
        tgt = self.target()
        if tgt is None or not self.model.regions.segmented:
            raise ValueError("region brush: find regions and select a region first")
        self._stroke = self.model.regions.begin_paint(
            tgt[0], tgt[1], radius=self.radius, erase=self.erase, on_close=self._closed_elsewhere
        )
        self.dab(int(vertex))

    def move(self, index: int, position: Any) -> float:
        """Move the brush to the skin vertex nearest ``position`` (3,); returns ms."""
        p = _position(position, "RegionBrushHandler.move")
        st = self._stroke
        if st is None or not st.open:
            return 0.0
        t0 = time.perf_counter()
        st.move(p)
        self.last_error = st.last_error
        return (time.perf_counter() - t0) * 1e3

    def end(self) -> None:
        """End the open stroke (one undo step); no-op without one."""
        st, self._stroke = self._stroke, None
        if st is None:
            return
        self.last_stroke = st.end()
        _listeners(self.listeners, self.last_stroke)

    def cancel(self) -> None:
        """Cancel the open stroke: the regions as at the press, no undo step."""
        st, self._stroke = self._stroke, None
        if st is not None:
            st.cancel()

    def _closed_elsewhere(self) -> None:
        self.end()


class RegionSeedPicker:
    """``viewport.drag_handler`` of split mode: a press on a marker picks its vertex.

    The viewport's drag hook is the only per-vertex pick it offers a panel
    without adding model handles, so split mode shows candidate markers over
    the selected region and a press on one calls ``on_pick(vertex)``; the drag
    itself does nothing.
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

    def cancel(self) -> None:
        return None


class MarkerMode:
    """Lends the viewport's marker drags to one of the panel's handlers.

    :meth:`install` ends the viewport's open gesture, sets
    ``viewport.drag_handler``, shows the given markers and switches to the
    sculpt tool (remembering the previous one); :meth:`release` gives the
    viewport its own handle markers and tool back. Switching between the
    panel's handlers keeps the remembered tool.
    """

    def __init__(self, viewport: Any) -> None:
        self.viewport = viewport
        self.handler: Any = None
        self._saved_tool: str | None = None

    def installed(self, *handlers: Any) -> bool:
        """True if one of ``handlers`` (default: any of ours) is the viewport's drag handler."""
        h = getattr(self.viewport, "drag_handler", None)
        if h is None or h is not self.handler:
            return False
        return not handlers or any(h is x for x in handlers)

    def install(self, handler: Any, markers: Any, before: Callable[[], Any] = lambda: None) -> None:
        """Hand marker drags to ``handler`` with ``markers`` shown; ``before`` runs first on a fresh install."""
        vp = self.viewport
        if vp is None or self.installed(handler):
            return
        if self.installed():  # another of our handlers: same markers mechanism, same saved tool
            self.handler = vp.drag_handler = handler
            vp.markers = markers
            return
        before()
        end_drag = getattr(vp, "end_drag", None)
        if end_drag is not None:
            end_drag()  # an open handle drag of the viewport's own
        self.handler = vp.drag_handler = handler
        self._saved_tool = vp.tool
        vp.markers = markers
        vp.tool = "sculpt"

    def show(self, markers: Any) -> None:
        """Show ``markers`` (while installed)."""
        if self.installed():
            self.viewport.markers = markers

    def release(self) -> None:
        """Give the viewport its drag hook, handle markers and tool back; no-op if not installed."""
        vp = self.viewport
        if not self.installed():
            self.handler = None
            return
        vp.drag_handler = None
        self.handler = None
        # the tools' markers (with mirror links) back
        vp.show_tool_markers()
        if self._saved_tool is not None and vp.tool == "sculpt":
            vp.tool = self._saved_tool
        self._saved_tool = None
