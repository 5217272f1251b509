"""Region sculpting by dragging (Joshi et al. 2003, §4): one pin drag as one undo step.

:class:`RegionDrag` is the core of the Regions tab's *Drag to sculpt* mode and
of any script that wants the same: press on a vertex inside a region, move it
to 3D positions, release. Each move solves the weights of the regions under
the pin (:func:`~workbench.methods.regions.blend.solve_region_drag`, always
from the weights at the press: the blend is linear in the weights, so one
solve from the start is exact and path-independent) and stores them in the
``regions`` slot inside an interaction, so the whole drag is one undo step, or
nothing when cancelled.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from workbench.methods.regions.blend import RegionWeights, damp_drag, solve_region_drag
from workbench.methods.regions.hierarchy import RegionError

if TYPE_CHECKING:
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

    Raises
    ------
    RegionError
        No regions, or the vertex lies in the background of the shown level.
    ModelError
        Another interaction is open.
    """

    def __init__(self, model: FaceState, vertex: int, *, pins: ArrayLike = (), damping: bool = True,
                 hold_others: bool = False, regularization: float = 1e-3) -> None:
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
        self._token = model.begin_interaction(f"Region drag {self.name}", on_close=self._closed)
        self._open = True

    @property
    def open(self) -> bool:
        return self._open

    def _closed(self) -> None:
        self._open = False  # somebody else closed our interaction (a discrete edit)

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
            ts = time.perf_counter()
            rw = solve_region_drag(m, self.regions, self.level, self._rw0, pinned,
                                   regularization=self.regularization, current_positions=self._X0)
            self.solve_ms.append((time.perf_counter() - ts) * 1e3)
            m.regions.set_weights(rw, f"Region drag {self.name}")  # type: ignore[attr-defined]
        return rw

    def end(self) -> dict[str, Any]:
        """Release: one undo step with the drag's weights; returns stats of the drag."""
        if self._open:
            self._open = False
            self.model.end_interaction(self._token)
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

    def cancel(self) -> None:
        """Put the weights back as they were at the press (no undo step)."""
        if self._open:
            self._open = False
            self.model.cancel_interaction(self._token)


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
