"""Painterly expression blending (Pighin et al. 1998, §4.2 inside the SIGGRAPH 2006 course).

A new expression is a locally varying convex combination of existing ones:
every painted expression ``e`` has a blend function ``W_e(v)`` over the
vertices. We keep, at every vertex,

    W_e(v) >= 0,      sum_e W_e(v) <= 1,

and give the **remainder** ``1 - sum_e W_e(v)`` to the *base*: whatever the
layers below paint produce (the global blend of the sliders, the region blend
when region weights are set, and the handle layer; the neutral face when all
are at rest). The painted face is therefore

    x(v) = (1 - sum_e W_e) base(v) + sum_e W_e (neutral(v) + D_e(v)),

i.e. the paint layer adds ``sum_e W_e (D_e - D_base)`` on top of the base.
Global blend is ``W_e`` constant, regional blend is ``W_e`` constant per
softly feathered region (:func:`regional_mix`), and the brush paints ``W_e``
directly on the rendered face.

Brush (one dab): the brush covers the vertices within ``radius`` of the dab
centre measured *along the surface* — shortest paths on the mesh's edge graph
of the neutral (Dijkstra; it overestimates the true geodesic by a few percent
on a regular triangulation, and never jumps across the mouth or between the
eyelids as a straight-line radius would). Strength ``s = opacity *
falloff(d / radius)``; modes:

* ``add``: alpha-over compositing ``W <- (1 - s) W + s [e]`` (convexity kept;
  opacity 1 with a hard falloff reproduces the expression exactly);
* ``subtract``: ``W_e <- (1 - s) W_e`` (the freed share goes to the base);
* ``smooth``: ``W <- (1 - s) W + s * mean of the 1-ring`` for every expression.

X-mirror applies the same dab centred at the dab centre's mirror partner:
the vertex at the reflection of the centre about the mid-plane ``x = mid`` —
on a model, the middle of the skin's x range, the plane the region
segmentation mirrors about (:func:`workbench.methods.regions.segmentation.segment_blend_regions`)
— found within the same tolerance, ``1e-3`` of the bounding-box diagonal
(:func:`mirror_map`). A centre without a partner there (an asymmetric mesh)
gets no mirrored dab: the dab paints on its own side only, rather than at
whichever vertex happens to be nearest to the reflection.

Storage: every painted expression keeps a *dense* ``(n,)`` float32 map, in
memory and in the ``.fwb`` file (``paint_maps`` ``(P, n) <f4``,
:mod:`workbench.fileformat`), although most strokes touch a small part of the
face. Dense is the deliberate choice: a map is 0.3 MB at 80k vertices per
expression (a handful are painted), the copy-on-write per dab copies only the
maps the dab changes, the layer's evaluation is a dense
``sum_e W_e (D_e - base)`` over (n, 3) arrays that a sparse map would have to
scatter first, and the file format's schema stores dense maps — a sparse
``ids + values`` form would change the on-disk schema for a few hundred
kilobytes.

Written here because no kept library offers expression painting; graph
search is scipy's.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import dijkstra

from workbench.methods.shapes.symmetry import nearest_reflected

Falloff = Literal["smooth", "linear", "constant", "sphere"]
Mode = Literal["add", "subtract", "smooth"]


def falloff_curve(x: NDArray[np.float64], kind: Falloff) -> NDArray[np.float64]:
    """Brush profile on normalized distance ``x`` in [0, 1]: 1 at the centre, 0 at the rim.

    ``constant`` is a hard brush (1 everywhere inside).
    """
    x = np.clip(x, 0.0, 1.0)
    if kind == "smooth":
        return (1.0 - x * x) ** 2
    if kind == "linear":
        return 1.0 - x
    if kind == "constant":
        return np.ones_like(x)
    if kind == "sphere":
        return np.sqrt(np.maximum(1.0 - x * x, 0.0))
    raise ValueError(f"falloff must be 'smooth', 'linear', 'constant' or 'sphere', got {kind!r}")


@dataclass(frozen=True)
class Brush:
    """Brush settings.

    Parameters
    ----------
    radius : float
        Surface distance in model units.
    opacity : float
        Strength at the centre, in [0, 1].
    falloff : {"smooth", "linear", "constant", "sphere"}
    mode : {"add", "subtract", "smooth"}
    mirror : bool
        Also paint around the centre's mirror partner (:attr:`PaintSurface.mirror`;
        nothing more where the centre has none).
    """

    radius: float = 0.3
    opacity: float = 0.5
    falloff: Falloff = "smooth"
    mode: Mode = "add"
    mirror: bool = False

    def __post_init__(self) -> None:
        if not (self.radius > 0 and np.isfinite(self.radius)):
            raise ValueError(f"brush radius must be > 0, got {self.radius}")
        if not 0.0 <= self.opacity <= 1.0:
            raise ValueError(f"brush opacity must be in [0, 1], got {self.opacity}")
        if self.mode not in ("add", "subtract", "smooth"):
            raise ValueError(f"brush mode must be 'add', 'subtract' or 'smooth', got {self.mode!r}")
        falloff_curve(np.zeros(1), self.falloff)  # validates the name


@dataclass(frozen=True, eq=False)
class PaintMix(Mapping[str, NDArray[np.float32]]):
    """Painted blend functions: expression name -> (n,) float32 weights (read-only).

    Immutable: every dab makes a new mix (unchanged maps are shared, not copied),
    so undo can keep the old one as it was.
    """

    maps: Mapping[str, NDArray[np.float32]] = field(default_factory=dict)

    def __getitem__(self, name: str) -> NDArray[np.float32]:
        return self.maps[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.maps)

    def __len__(self) -> int:
        return len(self.maps)

    def total(self, n: int) -> NDArray[np.float32]:
        """(n,) float32: sum of all painted weights (<= 1)."""
        out = np.zeros(n, np.float32)
        for w in self.maps.values():
            out += w
        return out


def _freeze(maps: dict[str, NDArray[np.float32]]) -> dict[str, NDArray[np.float32]]:
    for w in maps.values():
        w.setflags(write=False)
    return maps


def mirror_map(
    vertices: ArrayLike, mid: float | None = None, tolerance: float | None = None
) -> NDArray[np.int64]:
    """Mirror partner of every vertex across the plane ``x = mid`` (itself if it has none).

    Parameters
    ----------
    vertices : (n, 3) float
    mid : float, optional
        The mirror plane (default: the middle of the vertices' x range).
    tolerance : float, optional
        Largest distance between a vertex's reflection and its partner (default
        ``1e-3`` of the bounding-box diagonal, as the region segmentation uses).

    Returns
    -------
    (n,) int64
        ``mirror[v]`` is the vertex nearest to the reflection of ``v`` if it lies
        within ``tolerance`` (``v`` itself on the plane), else ``v`` itself: no
        partner, so a mirrored dab there has nothing to add (as in
        :func:`workbench.methods.regions.segmentation.segment_blend_regions`, identity where unmirrored).
    """
    V = np.asarray(vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"vertices must be (n, 3), got {V.shape}")
    if V.shape[0] == 0:
        return np.zeros(0, np.int64)
    m = 0.5 * float(V[:, 0].min() + V[:, 0].max()) if mid is None else float(mid)
    tol = 1e-3 * float(np.linalg.norm(V.max(0) - V.min(0))) if tolerance is None else float(tolerance)
    if not (np.isfinite(m) and np.isfinite(tol) and tol >= 0):
        raise ValueError(
            f"mirror_map: mid must be finite and tolerance finite and >= 0, got mid={mid}, tolerance={tolerance}"
        )
    j, d = nearest_reflected(V, axis=0, mid=m)
    return np.where(d <= tol, j, np.arange(V.shape[0])).astype(np.int64)


class PaintSurface:
    """Per-mesh precompute for painting: edge graph, 1-ring averaging, mirror map.

    Parameters
    ----------
    vertices : (n, 3) float
        Rest pose (distances are measured on it).
    faces : (m, 3) int
    mirror_plane : float, optional
        ``x`` of the mirror plane (default: the middle of the x range).
    mirror_tolerance : float, optional
        See :func:`mirror_map`.

    Attributes
    ----------
    mirror : (n,) int64
        :func:`mirror_map`: each vertex's partner across the mirror plane (itself if none).
    """

    def __init__(
        self,
        vertices: ArrayLike,
        faces: ArrayLike,
        *,
        mirror_plane: float | None = None,
        mirror_tolerance: float | None = None,
    ) -> None:
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        self.n = V.shape[0]
        A = sp.coo_matrix(igl.adjacency_matrix(F))
        A.resize((self.n, self.n))
        i, j = A.row, A.col
        lengths = np.linalg.norm(V[i] - V[j], axis=1)
        self.graph = sp.csr_matrix((lengths, (i, j)), shape=(self.n, self.n))
        deg = np.asarray((A > 0).sum(axis=1)).ravel().astype(np.float64)
        deg[deg == 0] = 1.0
        self.ring_mean = sp.csr_matrix(sp.diags(1.0 / deg) @ (A > 0).astype(np.float64))
        self.vertices = V
        self.mirror = mirror_map(V, mirror_plane, mirror_tolerance)

    def within(self, center: int, radius: float) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Vertices within surface distance ``radius`` of ``center`` and their distances."""
        d = dijkstra(self.graph, directed=False, indices=int(center), limit=radius)
        ids = np.flatnonzero(np.isfinite(d))
        return ids, d[ids]


@dataclass
class Stroke:
    """State of one stroke (press, move, release) so its opacity is capped.

    Within a stroke every vertex is blended from its weights *before* the
    stroke with the largest brush strength any dab of the stroke gave it, so
    painting over the same spot again in one stroke never exceeds the brush
    opacity (as with an airbrush at that opacity). A new stroke builds on the
    result of the previous ones.

    Parameters
    ----------
    base : PaintMix
        The mix when the stroke started.
    n : int
        Number of vertices.
    """

    base: PaintMix
    n: int
    strength: NDArray[np.float32] = field(init=False)

    def __post_init__(self) -> None:
        self.strength = np.zeros(self.n, np.float32)


def apply_dab(
    mix: PaintMix,
    expression: str,
    surface: PaintSurface,
    brush: Brush,
    center: int,
    stroke: Stroke | None = None,
) -> PaintMix:
    """One brush dab at vertex ``center``; returns the new mix (``mix`` is unchanged).

    With ``stroke`` (add / subtract modes) the strength at each vertex is the
    maximum over the stroke's dabs, applied to the weights from before the
    stroke; without it, dabs compound.
    """
    if not 0 <= center < surface.n:
        raise ValueError(f"dab centre must be a vertex id in 0..{surface.n - 1}, got {center}")
    centers = [int(center)]
    partner = int(surface.mirror[center])
    if brush.mirror and partner != center:  # itself: on the plane or no partner, one dab
        centers.append(partner)
    # copy-on-write: only the maps this dab changes are copied
    maps: dict[str, NDArray[np.float32]] = dict(mix.maps)
    copied: set[str] = set()

    def writable(name: str) -> NDArray[np.float32]:
        if name not in copied:
            maps[name] = maps[name].copy() if name in maps else np.zeros(surface.n, np.float32)
            copied.add(name)
        return maps[name]

    touched_all = []
    capped = stroke is not None and brush.mode in ("add", "subtract")
    for c in centers:
        ids, dist = surface.within(c, brush.radius)
        s = (brush.opacity * falloff_curve(dist / brush.radius, brush.falloff)).astype(np.float32)
        if capped:
            assert stroke is not None
            s = np.maximum(s, stroke.strength[ids])
            stroke.strength[ids] = s
            for name in set(maps) | set(stroke.base.maps) | {expression}:
                base = stroke.base.maps.get(name)
                writable(name)[ids] = 0.0 if base is None else base[ids]
        if brush.mode == "add":
            for name in list(maps):
                writable(name)[ids] *= 1.0 - s
            writable(expression)[ids] += s
        elif brush.mode == "subtract":
            if expression in maps:
                writable(expression)[ids] *= 1.0 - s
        else:  # smooth every map toward its 1-ring mean
            for name in list(maps):
                w = writable(name)
                ring = surface.ring_mean[ids] @ w
                w[ids] = (1.0 - s) * w[ids] + s * ring.astype(np.float32)
        touched_all.append(ids)
    _clip_convex({k: maps[k] for k in copied}, np.concatenate(touched_all))
    # drop maps that became all zero so the layer skips them
    return PaintMix(_freeze({k: v for k, v in maps.items() if k not in copied or np.any(v)}))


def _clip_convex(maps: dict[str, NDArray[np.float32]], ids: NDArray[np.int64]) -> None:
    """Guard against float round-off: W >= 0 and sum <= 1 at ``ids``."""
    if not maps:
        return
    for w in maps.values():
        w[ids] = np.clip(w[ids], 0.0, 1.0)
    total = np.zeros(ids.size, np.float32)
    for w in maps.values():
        total += w[ids]
    over = total > 1.0
    if np.any(over):
        scale = 1.0 / total[over]
        for w in maps.values():
            w[ids[over]] *= scale


def flood(mix: PaintMix, expression: str, opacity: float, n: int, vertices: ArrayLike | None = None) -> PaintMix:
    """Paint ``expression`` with strength ``opacity`` on all (or the given) vertices."""
    if not 0.0 <= opacity <= 1.0:
        raise ValueError(f"opacity must be in [0, 1], got {opacity}")
    ids = np.arange(n) if vertices is None else np.asarray(vertices, dtype=np.int64).reshape(-1)
    maps = {k: v.copy() for k, v in mix.maps.items()}
    for w in maps.values():
        w[ids] *= 1.0 - opacity
    maps.setdefault(expression, np.zeros(n, np.float32))[ids] += opacity
    _clip_convex(maps, ids)
    return PaintMix(_freeze(maps))


def normalize(mix: PaintMix, n: int) -> PaintMix:
    """Scale the painted weights to sum to 1 wherever anything is painted (no base left there)."""
    total = mix.total(n)
    painted = np.flatnonzero(total > 0)
    maps = {k: v.copy() for k, v in mix.maps.items()}
    for w in maps.values():
        w[painted] /= total[painted]
    _clip_convex(maps, painted)
    return PaintMix(_freeze(maps))


def regional_mix(
    region_weights: NDArray[np.float64], mixes: Sequence[Mapping[str, float]], n: int
) -> PaintMix:
    """Regional blend: expression weights constant per softly feathered region.

    Parameters
    ----------
    region_weights : (r, n) float
        Feathered region memberships, summing to <= 1 per vertex.
    mixes : sequence of r mappings
        Expression name -> weight for each region; each mapping's weights must
        be >= 0 and sum to <= 1.
    """
    R = np.asarray(region_weights, dtype=np.float64)
    if R.shape != (len(mixes), n):
        raise ValueError(f"region_weights must be ({len(mixes)}, {n}), got {R.shape}")
    maps: dict[str, NDArray[np.float32]] = {}
    for r, mx in enumerate(mixes):
        vals = np.array(list(mx.values()), dtype=np.float64)
        if vals.size and (vals.min() < 0 or vals.sum() > 1 + 1e-9):
            raise ValueError(f"mix of region {r}: weights must be >= 0 and sum to <= 1, got {dict(mx)}")
        for name, wt in mx.items():
            maps.setdefault(name, np.zeros(n, np.float32))
            maps[name] += (wt * R[r]).astype(np.float32)
    _clip_convex(maps, np.arange(n))
    return PaintMix(_freeze(maps))


def eyes_vertical_extent(
    vertices: NDArray[np.float64], component_labels: NDArray[np.integer], component_names: Sequence[str]
) -> tuple[float, float] | None:
    """``(bottom, top)`` height (y) of the eyeball components, or None without any.

    Eyeballs are components named ``eye`` / ``eye_*`` (not eyelashes or eyebrows),
    as the importers label them.
    """
    ids = [i for i, nm in enumerate(component_names) if nm == "eye" or nm.startswith("eye_")]
    mask = np.isin(np.asarray(component_labels), ids)
    if not mask.any():
        return None
    y = np.asarray(vertices, dtype=np.float64)[mask, 1]
    return float(y.min()), float(y.max())


def feathered_presets(
    vertices: NDArray[np.float64],
    preset: str,
    feather: float,
    *,
    eyes_y: tuple[float, float] | None = None,
) -> tuple[list[str], NDArray[np.float64]]:
    """Pighin's regional presets as soft memberships, (r, n), summing to 1.

    ``preset``: ``"upper_lower"`` (forehead+eyes / lower face) or ``"six"``
    (forehead, eyes, lower face, each split left/right at x = 0). Region borders
    are horizontal planes (y up) and the mid-plane; ``feather`` is the
    transition half-width in model units.

    Parameters
    ----------
    vertices : (n, 3) float
    preset : str
    feather : float
    eyes_y : (bottom, top) float, optional
        Height range of the eyes (:func:`eyes_vertical_extent`). The eye band
        then runs from a quarter of the eye height under the eyes (above the
        nose wings) to a tenth above them (the brows go with the forehead).
        Without it the borders sit at fractions of the 5th–99.5th percentile
        height range that give the same bands on the sample head.
    """
    V = np.asarray(vertices, dtype=np.float64)
    y = V[:, 1]

    def step(t: NDArray[np.float64]) -> NDArray[np.float64]:
        # smooth 0 -> 1 transition over [-feather, feather]
        u = np.clip((t / max(feather, 1e-12) + 1.0) / 2.0, 0.0, 1.0)
        return u * u * (3.0 - 2.0 * u)

    if eyes_y is not None:
        bottom, top = eyes_y
        h = top - bottom
        eyes_line, brow_line = bottom - 0.25 * h, top + 0.1 * h
    else:
        lo, hi = np.percentile(y, 5), np.percentile(y, 99.5)
        eyes_line, brow_line = lo + 0.394 * (hi - lo), lo + 0.581 * (hi - lo)
    if preset == "upper_lower":
        upper = step(y - eyes_line)
        return ["upper", "lower"], np.stack([upper, 1.0 - upper])
    if preset == "six":
        fore = step(y - brow_line)
        eyes = step(y - eyes_line) - fore
        lower = 1.0 - fore - eyes
        left = step(V[:, 0])
        names, rows = [], []
        for name, band in (("forehead", fore), ("eyes", eyes), ("lower", lower)):
            names += [f"{name}_L", f"{name}_R"]
            rows += [band * left, band * (1.0 - left)]
        return names, np.stack(rows)
    raise ValueError(f"preset must be 'upper_lower' or 'six', got {preset!r}")
