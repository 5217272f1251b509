"""Left/right symmetry of a face mesh: the mirror partner of every vertex.

The lateral axis
----------------
"Left" is always the subject's left (:mod:`workbench.arkit`). With the model's
``up_axis`` and ``front_axis`` (the way the face looks), the subject's left
is ``up × front`` — +x for the usual +y up, +z front (the sample head puts
the subject's left at +x). :func:`lateral_axis` gives its index and sign. The
mirror plane is ``coordinate[axis] = mid``; on a model ``mid`` is the middle of
the skin's lateral extent, the plane the paint brush and the region
segmentation mirror about.

The map
-------
``map[v]`` is the vertex at the mirror image of ``v``. It is an involution
(``map[map[v]] == v``), so mirroring anything twice gives back exactly what
was mirrored. It is built in three steps, each only for the vertices the
previous ones left:

1. **positions, verified by edges** — mutual nearest neighbours of the
   reflected vertices within ``tolerance`` (default ``1e-3`` of the skin's
   bounding-box diagonal), kept only if every mesh edge between two of them
   maps onto a mesh edge (polygon edges: quads are compared as quads, however
   they are triangulated);
2. **topology** — the mirror image of the mesh graph grows from those pairs
   (vertices on the mid-plane are their own partners, so a symmetric face
   always has seeds there). Mirroring reverses orientation, so the image of
   polygon ``(p_0 … p_k)`` across its edge ``p_i → p_i+1`` is the polygon
   holding the directed edge ``m(p_i+1) → m(p_i)``, walked the other way. A
   proposed pair is kept when no other polygon proposes otherwise, its edges
   to matched vertices map onto edges, and its partner lies within ``slack``
   (5 % of the diagonal) of its reflection (a guard against a walk gone wrong
   on an asymmetric triangulation). This recovers the partners of vertices
   moved off the symmetric positions (an asymmetrically sculpted cheek) on a
   mesh whose *connectivity* is symmetric;
3. **geometry** (the fallback for meshes whose connectivity is not
   symmetric, e.g. re-triangulated ones): the mutual nearest reflected vertex
   within ``tolerance`` among the vertices still unmatched.

Vertices left over are their own partner, counted in
:attr:`Symmetry.unmatched_fraction` (mirroring reflects their own value there).

Written here (scipy's k-d tree for the nearest neighbours) because no kept
library computes mesh symmetry maps. :func:`nearest_reflected` is also the
geometric mirror of the paint brush (:func:`workbench.methods.paint.painting.mirror_map`)
and of the default handle set (:mod:`workbench.methods.handles.presets`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from workbench.core.polygons import Polygons
from workbench.core.shapes import AXES, ModelError

__all__ = [
    "GEOMETRY",
    "POSITIONS",
    "TOPOLOGY",
    "UNMATCHED",
    "Symmetry",
    "lateral_axis",
    "nearest_reflected",
    "reflect",
    "symmetry_map",
]

#: how a vertex got its partner (:attr:`Symmetry.source`)
UNMATCHED, POSITIONS, TOPOLOGY, GEOMETRY = 0, 1, 2, 3
_SOURCE_NAMES = {UNMATCHED: "unmatched", POSITIONS: "positions", TOPOLOGY: "topology", GEOMETRY: "geometry"}


def _axis_vector(name: str) -> NDArray[np.float64]:
    if name not in AXES:
        raise ModelError(f"axis must be one of {AXES}, got {name!r}")
    v = np.zeros(3)
    v["xyz".index(name[1])] = 1.0 if name[0] == "+" else -1.0
    return v


def lateral_axis(up_axis: str = "+y", front_axis: str = "+z") -> tuple[int, float]:
    """``(axis, sign)``: the subject's left is ``sign`` times coordinate ``axis`` (``up × front``).

    >>> lateral_axis("+y", "+z")
    (0, 1.0)
    >>> lateral_axis("+z", "-y")
    (0, 1.0)
    """
    left = np.cross(_axis_vector(up_axis), _axis_vector(front_axis))
    if not np.any(left):
        raise ModelError(
            f"metadata: up_axis {up_axis!r} and front_axis {front_axis!r} must be different axes "
            "(the left/right axis is up × front)"
        )
    i = int(np.argmax(np.abs(left)))
    return i, float(np.sign(left[i]))


def reflect(points: ArrayLike, axis: int = 0, mid: float = 0.0) -> NDArray[np.float64]:
    """(m, 3) float64 copy of ``points`` reflected about the plane ``coordinate[axis] = mid``."""
    P = np.array(points, dtype=np.float64).reshape(-1, 3)
    P[:, axis] = 2.0 * mid - P[:, axis]
    return P


def nearest_reflected(
    vertices: ArrayLike,
    ids: ArrayLike | None = None,
    candidates: ArrayLike | None = None,
    *,
    axis: int = 0,
    mid: float = 0.0,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """For each vertex in ``ids`` (default all), the candidate nearest to its reflection.

    Returns ``(partner, distance)``: vertex ids (from ``candidates``, default
    all vertices) and the distance between the reflection and the partner.
    The geometric mirror of the paint brush and of the default handle set.
    """
    V = np.asarray(vertices, dtype=np.float64)
    idx = np.arange(V.shape[0]) if ids is None else np.asarray(ids, dtype=np.int64).reshape(-1)
    cand = np.arange(V.shape[0]) if candidates is None else np.asarray(candidates, dtype=np.int64).reshape(-1)
    if idx.size == 0 or cand.size == 0:
        return np.zeros(idx.size, np.int64) if cand.size else idx.copy(), np.full(idx.size, np.inf)
    d, j = cKDTree(V[cand]).query(reflect(V[idx], axis, mid))
    return cand[np.asarray(j, dtype=np.int64)], np.asarray(d, dtype=np.float64)


def _mutual_pairs(
    V: NDArray[np.float64], subset: NDArray[np.int64], axis: int, mid: float, tol: float
) -> NDArray[np.int64]:
    """(len(subset),) partner (a vertex of ``subset``) or -1: mutual nearest reflected within ``tol``."""
    if subset.size == 0:
        return np.zeros(0, np.int64)
    d, j = cKDTree(V[subset]).query(reflect(V[subset], axis, mid))
    j = np.asarray(j, dtype=np.int64)
    ok = (j[j] == np.arange(subset.size)) & (np.asarray(d) <= tol)
    return np.where(ok, subset[j], -1)


@dataclass(frozen=True, eq=False)
class Symmetry:
    """The mirror map of a mesh (see the module docstring).

    Attributes
    ----------
    map : (n,) int64
        Mirror partner of every vertex (an involution; itself on the plane and when unmatched).
    axis : int
        Coordinate index of the left/right axis.
    left_sign : float
        +1 if the subject's left is at larger coordinates, else -1.
    mid : float
        The mirror plane ``coordinate[axis] = mid``.
    tolerance : float
        Largest distance between a reflection and a partner found by position.
    source : (n,) int8
        How each vertex got its partner: :data:`POSITIONS`, :data:`TOPOLOGY`,
        :data:`GEOMETRY`, or :data:`UNMATCHED`.
    max_error : float
        Largest distance between a matched vertex's reflection and its partner.
    """

    map: NDArray[np.int64]
    axis: int
    left_sign: float
    mid: float
    tolerance: float
    source: NDArray[np.int8]
    max_error: float

    @property
    def n_vertices(self) -> int:
        return int(self.map.size)

    @property
    def unmatched(self) -> NDArray[np.bool_]:
        """(n,) bool: vertices without a partner (mirrored onto themselves)."""
        out: NDArray[np.bool_] = self.source == UNMATCHED
        return out

    @property
    def unmatched_fraction(self) -> float:
        return float(np.count_nonzero(self.unmatched)) / max(self.n_vertices, 1)

    @property
    def counts(self) -> dict[str, int]:
        """Vertices per :attr:`source` (``"positions"``, ``"topology"``, ``"geometry"``, ``"unmatched"``)."""
        c = np.bincount(self.source, minlength=4)
        return {name: int(c[code]) for code, name in _SOURCE_NAMES.items()}

    @property
    def method(self) -> str:
        """``"topology"`` when the mesh graph gave every partner found, else ``"geometry"`` (the fallback ran)."""
        return "geometry" if np.any(self.source == GEOMETRY) else "topology"

    def summary(self) -> str:
        c = self.counts
        return (
            f"{'xyz'[self.axis]} = {self.mid:.6g} ({'+' if self.left_sign > 0 else '-'}{'xyz'[self.axis]} is the "
            f"subject's left): {c['positions']} vertices matched by position, {c['topology']} by topology, "
            f"{c['geometry']} by the geometric fallback, {c['unmatched']} unmatched "
            f"({100 * self.unmatched_fraction:.2f} %); largest mismatch {self.max_error:.3g}"
        )

    def lateral(self, points: ArrayLike) -> NDArray[np.float64]:
        """(m,) signed distance of ``points`` from the plane, positive on the subject's left."""
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out: NDArray[np.float64] = self.left_sign * (P[:, self.axis] - self.mid)
        return out

    def mirror_vectors(self, vectors: ArrayLike) -> NDArray[np.float32]:
        """(n, 3) float32: the mirror image of a per-vertex vector field (a delta).

        ``out[v] = R d[map[v]]`` with ``R`` negating the lateral component:
        an exact involution (taking values and negating are exact).
        """
        D = np.asarray(vectors, dtype=np.float32)
        if D.shape != (self.n_vertices, 3):
            raise ModelError(f"mirror: expected ({self.n_vertices}, 3) vectors, got {D.shape}")
        out = D[self.map]
        out[:, self.axis] = -out[:, self.axis]
        return out

    def mirror_scalars(self, values: ArrayLike) -> NDArray[np.float32]:
        """(n,) float32: a per-vertex scalar field (a painted weight, a mask) taken from the partners."""
        w = np.asarray(values, dtype=np.float32).reshape(-1)
        if w.shape != (self.n_vertices,):
            raise ModelError(f"mirror: expected ({self.n_vertices},) values, got {w.shape}")
        return w[self.map]


class _Edges:
    """Undirected edge membership and directed half-edge lookup of a polygon mesh."""

    def __init__(self, polygons: Polygons, n: int) -> None:
        idx = polygons.indices.astype(np.int64)
        off = polygons.offsets.astype(np.int64)
        sizes = np.diff(off)
        self.n = n
        self.idx, self.off, self.sizes = idx, off, sizes
        self.poly = np.repeat(np.arange(sizes.size), sizes)
        self.pos = np.arange(idx.size) - off[self.poly]
        self.a = idx
        self.b = idx[off[self.poly] + (self.pos + 1) % sizes[self.poly]]
        lo, hi = np.minimum(self.a, self.b), np.maximum(self.a, self.b)
        self.ukeys = np.unique(lo * n + hi)
        self.u = self.ukeys // n
        self.v = self.ukeys % n
        dkeys = self.a * n + self.b
        self.dorder = np.argsort(dkeys, kind="stable")
        self.dkeys = dkeys[self.dorder]

    def has(self, x: NDArray[np.int64], y: NDArray[np.int64]) -> NDArray[np.bool_]:
        keys = np.minimum(x, y) * self.n + np.maximum(x, y)
        i = np.clip(np.searchsorted(self.ukeys, keys), 0, max(self.ukeys.size - 1, 0))
        out: NDArray[np.bool_] = (self.ukeys.size > 0) & (self.ukeys[i] == keys) & (x != y)
        return out

    def half_edge(self, x: NDArray[np.int64], y: NDArray[np.int64]) -> NDArray[np.int64]:
        """Index (into the polygon corners) of the directed edge ``x -> y``, or -1."""
        keys = x * self.n + y
        i = np.clip(np.searchsorted(self.dkeys, keys), 0, max(self.dkeys.size - 1, 0))
        found = (self.dkeys.size > 0) & (self.dkeys[i] == keys)
        return np.where(found, self.dorder[i], -1)

    def bad_vertices(self, m: NDArray[np.int64]) -> NDArray[np.int64]:
        """Vertices on an edge between two matched vertices whose image is no edge."""
        both = (m[self.u] >= 0) & (m[self.v] >= 0)
        u, v = self.u[both], self.v[both]
        bad = ~self.has(m[u], m[v])
        return np.unique(np.concatenate([u[bad], v[bad]]))


def _unpair(m: NDArray[np.int64], vs: NDArray[np.int64]) -> NDArray[np.int64]:
    """Unmatch ``vs`` and their partners; returns every vertex unmatched."""
    vs = vs[m[vs] >= 0]
    both = np.unique(np.concatenate([vs, m[vs]]))
    m[both] = -1
    return both


def _grow(
    V: NDArray[np.float64], E: _Edges, m: NDArray[np.int64], axis: int, mid: float, slack: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Grow the map ``m`` (in place) over the mesh graph from its matched vertices.

    Returns ``(grown, disputed)``: the vertices it matched, and the vertices
    where the walk contradicted itself (two partners proposed, a partner
    already taken, an edge mapped onto a non-edge) — evidence that the
    connectivity there is not symmetric. Partners farther than ``slack`` from
    the reflection are refused without counting as evidence.
    """
    n = V.shape[0]
    grown = np.zeros(n, bool)
    blocked = np.zeros(n, bool)
    disputed = np.zeros(n, bool)
    max_size = int(E.sizes.max()) if E.sizes.size else 0
    while True:
        matched = m >= 0
        open_v = ~matched & ~blocked
        if not open_v.any():
            break
        open_poly = np.bincount(E.poly, weights=open_v[E.idx], minlength=E.sizes.size) > 0
        he = np.flatnonzero(matched[E.a] & matched[E.b] & open_poly[E.poly])
        if he.size == 0:
            break
        g = E.half_edge(m[E.b[he]], m[E.a[he]])
        ok = g >= 0
        # a matched edge whose mirror edge is missing (or runs the same way): no symmetric connectivity
        disputed[E.a[he[~ok]]] = True
        disputed[E.b[he[~ok]]] = True
        he, g = he[ok], g[ok]
        P, Q = E.poly[he], E.poly[g]
        same = E.sizes[P] == E.sizes[Q]
        disputed[E.idx[E.off[P[~same]]]] = True
        he, g, P, Q = he[same], g[same], P[same], Q[same]
        i, s, k = E.pos[he], E.pos[g], E.sizes[P]
        ps, qs = [], []
        for r in range(max_size):
            sel = r < k
            ps.append(E.idx[E.off[P[sel]] + (i[sel] - r) % k[sel]])
            qs.append(E.idx[E.off[Q[sel]] + (s[sel] + 1 + r) % k[sel]])
        p = np.concatenate(ps) if ps else np.zeros(0, np.int64)
        q = np.concatenate(qs) if qs else np.zeros(0, np.int64)
        # walked onto an already matched vertex: it must be its known partner
        known = matched[p]
        wrong = known & (m[np.where(known, p, 0)] != q)
        disputed[p[wrong]] = True
        want = open_v[p]
        p, q = p[want], q[want]
        if p.size == 0:
            break
        pairs = np.unique(np.stack([p, q], axis=1), axis=0)
        p, q = pairs[:, 0], pairs[:, 1]
        # a vertex proposed two partners, a partner proposed for two vertices, a partner
        # already taken, or the two disagreeing about each other
        pc = np.bincount(p, minlength=n)
        qc = np.bincount(q, minlength=n)
        back = np.full(n, -1, np.int64)
        back[p] = q
        conflict = (pc[p] > 1) | (qc[q] > 1) | matched[q] | ((back[q] >= 0) & (back[q] != p))
        disputed[p[conflict]] = True
        far = np.linalg.norm(reflect(V[p], axis, mid) - V[q], axis=1) > slack
        newly_blocked = np.zeros(n, bool)
        newly_blocked[p[conflict | far | blocked[q]]] = True
        keep = ~(conflict | far | blocked[q])
        p, q = p[keep], q[keep]
        m[p] = q
        m[q] = p
        touch = np.zeros(n, bool)
        touch[p] = True
        touch[q] = True
        # edges from the new pairs to matched vertices must map onto edges
        bad = E.bad_vertices(m)
        bad = bad[touch[bad]]
        if bad.size:
            undone = _unpair(m, bad)
            disputed[undone] = True
            newly_blocked[undone[touch[undone]]] = True
        added = touch & (m >= 0)
        grown |= added
        if not newly_blocked.any() and not added.any():
            break
        blocked |= newly_blocked
    return grown & (m >= 0), disputed


def symmetry_map(
    vertices: ArrayLike,
    polygons: Polygons,
    *,
    axis: int = 0,
    left_sign: float = 1.0,
    mid: float | None = None,
    tolerance: float | None = None,
    slack: float | None = None,
    topology: bool = True,
) -> Symmetry:
    """The mirror map of a mesh (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float
    polygons : Polygons
        The mesh's faces (their edges verify and grow the map).
    axis, left_sign : int, float
        The left/right axis (:func:`lateral_axis`).
    mid : float, optional
        The mirror plane (default: the middle of the vertices' extent along ``axis``).
    tolerance : float, optional
        Largest reflection-to-partner distance for position matches (default
        ``1e-3`` of the bounding-box diagonal).
    slack : float, optional
        Largest reflection-to-partner distance for a topological match
        (default 5 % of the diagonal).
    topology : bool
        False: positions only (the geometric map, no edge checks).
    """
    V = np.asarray(vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ModelError(f"symmetry: vertices must be (n, 3), got {V.shape}")
    n = V.shape[0]
    if axis not in (0, 1, 2):
        raise ModelError(f"symmetry: axis must be 0, 1 or 2, got {axis!r}")
    diag = float(np.linalg.norm(V.max(0) - V.min(0))) if n else 0.0
    mid = 0.5 * float(V[:, axis].min() + V[:, axis].max()) if mid is None else float(mid)
    tol = 1e-3 * diag if tolerance is None else float(tolerance)
    slk = 0.05 * diag if slack is None else float(slack)
    for name, val in (("mid", mid), ("tolerance", tol), ("slack", slk)):
        if not np.isfinite(val) or (name != "mid" and val < 0):
            raise ModelError(f"symmetry: {name} must be finite{'' if name == 'mid' else ' and >= 0'}, got {val!r}")
    source = np.zeros(n, np.int8)
    pos = _mutual_pairs(V, np.arange(n), axis, mid, tol)
    m = pos.copy()
    if topology:
        E = _Edges(polygons, n)
        # seeds: position pairs whose whole neighbourhood is matched and maps onto theirs
        seed = pos >= 0
        for x, y in ((E.u, E.v), (E.v, E.u)):
            ok = (pos[y] >= 0) & (pos[x] >= 0)
            ok[ok] = E.has(pos[x[ok]], pos[y[ok]])
            seed[x[~ok]] = False
        deg = np.bincount(np.concatenate([E.u, E.v]), minlength=n)
        seed &= deg == deg[np.where(pos >= 0, pos, 0)]
        seed &= seed[np.where(pos >= 0, pos, 0)]
        m = np.where(seed, pos, -1)
        grown, disputed = _grow(V, E, m, axis, mid, slk)
        # where the walk contradicted itself the connectivity is not symmetric: that
        # component (and its mirror) falls back to positions entirely
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        graph = coo_matrix((np.ones(E.u.size), (E.u, E.v)), shape=(n, n))
        _, comp = connected_components(graph, directed=False)
        bad_comp = np.zeros(int(comp.max()) + 1 if n else 0, bool)
        bad_comp[comp[disputed]] = True
        partner_comp = np.where(m >= 0, comp[np.where(m >= 0, m, 0)], comp)
        reset = bad_comp[comp] | bad_comp[partner_comp]
        m[reset] = -1
        _unpair(m, E.bad_vertices(m))
        source[m >= 0] = POSITIONS
        source[grown & (m >= 0)] = TOPOLOGY
        rest = np.flatnonzero(m < 0)
        if rest.size:
            pm = _mutual_pairs(V, rest, axis, mid, tol)
            ok = pm >= 0
            m[rest[ok]] = pm[ok]
            source[rest[ok]] = GEOMETRY
    else:
        source[m >= 0] = POSITIONS
    unmatched = m < 0
    m[unmatched] = np.flatnonzero(unmatched)
    source[unmatched] = UNMATCHED
    if not np.array_equal(m[m], np.arange(n)):  # pragma: no cover - a bug, not a mesh property
        raise RuntimeError("symmetry map is not an involution")
    err = np.linalg.norm(reflect(V, axis, mid) - V[m], axis=1)
    max_error = float(err[~unmatched].max()) if np.any(~unmatched) else 0.0
    return Symmetry(m.astype(np.int64), int(axis), float(left_sign), mid, tol, source, max_error)
