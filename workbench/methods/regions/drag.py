"""Region sculpting by dragging (Joshi et al. 2003, §4) and the region brush, each one undo step.

:class:`RegionDrag` is the core of the Regions tab's *Drag to sculpt* mode and
of any script that wants the same: press on a vertex inside a region, move it
to 3D positions, release. Each move solves the weights of the regions under
the pin (:func:`~workbench.methods.regions.blend.solve_region_drag`, always
from the weights at the press: the blend is linear in the weights, so one
solve from the start is exact and path-independent) and stores them in the
``regions`` slot inside an interaction, so the whole drag is one undo step, or
nothing when cancelled.

:class:`RegionStroke` is the *Paint region* brush the same way: dabs of a
round brush (:func:`brush_vertices`) assign skin to a region, the stroke is
one undo step. :func:`spread_vertices` and :func:`region_markers` pick the
markers the panel shows over a region. Both interactions hold an
:class:`~workbench.core.interactions.InteractionToken`; ``on_close`` tells the
owner when a discrete edit elsewhere closed it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from workbench.methods.regions.blend import RegionWeights, damp_drag, solve_region_drag
from workbench.methods.regions.hierarchy import RegionError

if TYPE_CHECKING:
    from workbench.core.interactions import InteractionToken
    from workbench.core.state import FaceState


class RegionDrag:
    """One pin drag on the regions of ``model`` (see the module docstring).

    Parameters
    ----------
    model : FaceModel
        Must hold regions.
    vertex : int
        The pressed vertex; it must lie inside a region of the shown level.
    pins : (p,) int, optional
        Other pins (markers); with ``hold_others`` those inside the touched
        regions stay where they are.
    damping : bool
        Scale the mouse motion by :func:`~workbench.methods.regions.blend.drag_damping`.
    hold_others : bool
    regularization : float
        Passed to :func:`~workbench.methods.regions.blend.solve_region_drag`.
    on_close : callable, optional
        Called (no arguments) when somebody else closes the drag's interaction
        (``model.close_interaction()`` before a discrete edit); the edits so far
        are kept as one undo step and :attr:`open` turns False.

    Raises
    ------
    RegionError
        No regions, or the vertex lies in the background of the shown level.
    ModelError
        Another interaction is open.
    """

    def __init__(self, model: FaceState, vertex: int, *, pins: ArrayLike = (), damping: bool = True,
                 hold_others: bool = False, regularization: float = 1e-3,
                 on_close: Callable[[], None] | None = None) -> None:
        st = model.slot("regions")
        if st is None:
            raise RegionError("region drag: no regions yet; press 'Find regions' first")
        R, lv = st.regions, st.level
        v = int(vertex)
        if not 0 <= v < model.n_vertices:
            raise RegionError(f"region drag: vertex must be in 0..{model.n_vertices - 1}, got {vertex}")
        under = R.regions_at(lv, v)
        if not under:
            raise RegionError(
                f"region drag: vertex {v} lies in the background of level {lv}; "
                "drag a marker inside a coloured region (or lower t)"
            )
        main = max(under, key=lambda r: under[r])
        self.model = model
        self.vertex = v
        self.level = lv
        self.regions = R
        self.touched = sorted(under)
        self.name = R.names[lv][main]
        self.damping = bool(damping)
        self.regularization = float(regularization)
        self._rw0 = st.weights if st.weights is not None else RegionWeights.from_global(model, R, lv)
        self._X0 = np.array(model.evaluate(posed=False), dtype=np.float64)
        others = np.array([p for p in np.asarray(pins, np.int64).reshape(-1).tolist() if p != v], np.int64)
        self.held: list[int] = []
        if hold_others and others.size:
            W = R.weight_matrix(lv)[others][:, self.touched]
            self.held = others[np.asarray(W.sum(axis=1)).ravel() > 0].tolist()
        self.solve_ms: list[float] = []
        self._t0 = time.perf_counter()
        self._on_close = on_close
        self._token = model.begin_interaction(f"Region drag {self.name}", on_close=self._closed)
        self._open = True

    @property
    def open(self) -> bool:
        """True until :meth:`end`, :meth:`cancel` or somebody else closes the interaction."""
        return self._open

    def _closed(self) -> None:
        self._open = False  # somebody else closed our interaction (a discrete edit)
        if self._on_close is not None:
            self._on_close()

    def move(self, position: ArrayLike) -> RegionWeights:
        """Solve for the pin at ``position`` (3,) in model space; returns the new weights."""
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"RegionDrag.move: position must be 3 finite numbers, got {position!r}")
        if not self._open:
            raise RegionError("RegionDrag.move: the drag has ended")
        m = self.model
        v = self.vertex
        delta = p - self._X0[v]
        if self.damping:
            delta = damp_drag(m, v, delta)
        pinned = {v: self._X0[v] + delta}
        for o in self.held:
            pinned[o] = self._X0[o]
        with m.lock:
            if m.interaction_token != self._token:
                raise RegionError("RegionDrag.move: the drag has ended")
            ts = time.perf_counter()
            rw = solve_region_drag(m, self.regions, self.level, self._rw0, pinned,
                                   regularization=self.regularization, current_positions=self._X0)
            self.solve_ms.append((time.perf_counter() - ts) * 1e3)
            m.regions.set_weights(rw, f"Region drag {self.name}")  # type: ignore[attr-defined]
        return rw

    def end(self) -> dict[str, Any]:
        """Release: one undo step with the drag's weights; returns :meth:`stats`."""
        _close(self.model, self._token, keep=True)
        self._open = False
        return self.stats()

    def cancel(self) -> None:
        """Put the weights back as they were at the press (no undo step)."""
        _close(self.model, self._token, keep=False)
        self._open = False

    def stats(self) -> dict[str, Any]:
        """Name, vertex, level, touched region names, held pins, moves, seconds, median solve ms."""
        sms = self.solve_ms
        return {
            "name": self.name,
            "vertex": self.vertex,
            "level": self.level,
            "regions": [self.regions.names[self.level][r] for r in self.touched],
            "held": len(self.held),
            "moves": len(sms),
            "seconds": time.perf_counter() - self._t0,
            "median_solve_ms": float(np.median(sms)) if sms else float("nan"),
        }


def _close(model: FaceState, token: InteractionToken, *, keep: bool) -> None:
    """End (``keep``) or cancel ``token``'s interaction if it is still the open one."""
    with model.lock:
        if model.interaction_token != token:
            return  # already closed (by us, or elsewhere: the owner's on_close was told)
        if keep:
            model.end_interaction(token)
        else:
            model.cancel_interaction(token)


class RegionStroke:
    """One stroke of the round region brush on ``region`` of ``level``: one undo step.

    The interaction opens at construction ("Paint region <name>", or "Erase
    from region <name>" with ``erase``). :meth:`dab` paints the brush at a
    vertex (``model.regions.brush``); :meth:`move` puts the brush on the skin
    vertex nearest a 3D point (the pointer on the view plane through the
    pressed marker: for the front of the face the vertex under it) and dabs
    once the brush moved a quarter radius. A dab the model refuses (not
    touching the region, or cutting another region in pieces) is skipped and
    its reason kept in :attr:`last_error`, so the stroke goes on.

    Parameters
    ----------
    model : FaceModel
        Must hold regions.
    level : int
    region : int or str
    radius : float
        Brush radius in model units (> 0).
    erase : bool
        Return the brushed vertices to the background instead.
    on_close : callable, optional
        Called when somebody else closes the stroke's interaction (see :class:`RegionDrag`).

    Attributes
    ----------
    dabs, changed : int
        Dabs applied and vertices whose label they changed.

    Raises
    ------
    RegionError
        No regions, bad level / region / radius.
    ModelError
        Another interaction is open.
    """

    def __init__(self, model: FaceState, level: int, region: int | str, *, radius: float,
                 erase: bool = False, on_close: Callable[[], None] | None = None) -> None:
        from scipy.spatial import cKDTree

        st = model.slot("regions")
        if st is None:
            raise RegionError("region brush: no regions yet; press 'Find regions' first")
        R = st.regions
        lv = R.check_level(level)
        self.name = R.names[lv][R.region_index(lv, region)]
        r = float(radius)
        if not (np.isfinite(r) and r > 0):
            raise RegionError(f"region brush: radius must be a finite number > 0, got {radius!r}")
        self.model = model
        self.level = lv
        self.radius = r
        self.erase = bool(erase)
        self.dabs = 0
        self.changed = 0
        self.last_error = ""
        self._skin = np.flatnonzero(model.regions.topology.skin)  # type: ignore[attr-defined]
        self._X = np.array(model.evaluate(posed=False), dtype=np.float64)
        self._tree = cKDTree(self._X[self._skin]) if self._skin.size else None
        self._last = -1
        self._t0 = time.perf_counter()
        self._on_close = on_close
        verb = "Erase from region" if self.erase else "Paint region"
        self._token = model.begin_interaction(f"{verb} {self.name}", on_close=self._closed)
        self._open = True

    @property
    def open(self) -> bool:
        """True until :meth:`end`, :meth:`cancel` or somebody else closes the interaction."""
        return self._open

    def _closed(self) -> None:
        self._open = False
        if self._on_close is not None:
            self._on_close()

    def dab(self, center: int) -> int:
        """Paint (or erase) the brush at vertex ``center``; returns the vertices that changed label (0: refused)."""
        m = self.model
        with m.lock:
            if m.interaction_token != self._token:
                raise RegionError("RegionStroke.dab: the stroke has ended")
            self._last = int(center)
            try:
                n = m.regions.brush(self.level, self.name, center, self.radius,  # type: ignore[attr-defined]
                                    erase=self.erase)
            except RegionError as exc:
                self.last_error = str(exc)
                return 0
        self.last_error = ""
        self.dabs += 1
        self.changed += n
        return n

    def move(self, position: ArrayLike) -> int:
        """Brush at the skin vertex nearest ``position`` (3,) model space; returns :meth:`dab`'s count.

        No dab (0) while the brush is within a quarter radius of the last dab.
        """
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"RegionStroke.move: position must be 3 finite numbers, got {position!r}")
        if self._tree is None:
            return 0
        _, j = self._tree.query(p)
        v = int(self._skin[int(j)])
        last = self._last
        if last >= 0 and (v == last or np.linalg.norm(self._X[v] - self._X[last]) < 0.25 * self.radius):
            return 0
        return self.dab(v)

    def end(self) -> dict[str, Any]:
        """Release: one undo step with every dab; returns :meth:`stats`."""
        _close(self.model, self._token, keep=True)
        self._open = False
        return self.stats()

    def cancel(self) -> None:
        """Put the regions back as they were at the press (no undo step)."""
        _close(self.model, self._token, keep=False)
        self._open = False

    def stats(self) -> dict[str, Any]:
        """Region name, dabs, changed vertices, erase, seconds, the last refused dab's reason."""
        return {
            "name": self.name,
            "level": self.level,
            "dabs": self.dabs,
            "changed": self.changed,
            "erase": self.erase,
            "seconds": time.perf_counter() - self._t0,
            "error": self.last_error,
        }


def spread_vertices(ids: ArrayLike, positions: ArrayLike, k: int) -> np.ndarray:
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


def brush_vertices(model: FaceState, center: int, radius: float) -> np.ndarray:
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

    topo = model.regions.topology  # type: ignore[attr-defined]
    c = int(center)
    if not 0 <= c < topo.n_vertices or not topo.skin[c]:
        return np.zeros(0, np.int64)
    V = topo.vertices
    near = np.flatnonzero(topo.skin & (np.linalg.norm(V - V[c], axis=1) <= float(radius)))
    if near.size <= 1:
        return np.array([c], np.int64)
    _, comp = connected_components(topo.adjacency[near][:, near], directed=False)
    return near[comp == comp[int(np.searchsorted(near, c))]].astype(np.int64)


def region_markers(model: FaceState, level: int, region: int | str, k: int, *, band: float = 0.0) -> np.ndarray:
    """Up to ``k`` skin vertices spread over a region (the markers the panel shows on it).

    Parameters
    ----------
    model : FaceModel
        Must hold regions.
    level : int
    region : int or str
    k : int
    band : float
        > 0: also the skin within ``band`` (model units, neutral mesh) of the
        region's core, e.g. where a brush can grow it; 0: the core only.

    Returns
    -------
    (min(k, m),) int64
        :func:`spread_vertices` of the region's core skin vertices (and the
        band); empty if the region has no skin core.
    """
    from scipy.spatial import cKDTree

    st = model.slot("regions")
    if st is None:
        raise RegionError("region markers: no regions yet; press 'Find regions' first")
    R = st.regions
    lv = R.check_level(level)
    r = R.region_index(lv, region)
    topo = model.regions.topology  # type: ignore[attr-defined]
    core = np.flatnonzero((R.labels[lv] == r) & topo.skin)
    if core.size == 0:
        return np.zeros(0, np.int64)
    V = topo.vertices
    if float(band) <= 0:
        return spread_vertices(core, V, k)
    skin = np.flatnonzero(topo.skin)
    d, _ = cKDTree(V[core]).query(V[skin])
    return spread_vertices(skin[d <= float(band)], V, k)
