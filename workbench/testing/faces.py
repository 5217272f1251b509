"""Faces the methods have not seen, made from a rig, with the true answer kept.

Every generated face remembers how it was made from its ``source`` rig (the
sample head, at any resolution): its vertices are ``warp(W @ source.vertices)``
(plus new bust vertices), so the true shape ``name`` on it is
``warp(p + W @ delta) - warp(p)`` with ``p = W @ source.vertices``
(:meth:`GeneratedFace.truth`). Transfer, capture and region methods are
checked against that.

Geometry (a :class:`GeneratedFace` in, or a source :class:`FaceModel`):

* :func:`warped` — the same mesh under a smooth warp (optionally with the
  quads cut along their other diagonal), shapes carried exactly;
* :func:`remeshed` — another triangulation and vertex set of the same surface
  (:func:`~workbench.testing.meshes.split_remesh`), then warped;
* :func:`renumbered` — another vertex and triangle order;
* :func:`with_bust`, :func:`cropped`, :func:`with_hole`, :func:`opened` —
  shoulders below the neck; only the front of the face; a hole; the mouth bag
  and eye sockets cut out (the lips and lids become open borders);
* :func:`proportions_warp` — larger or smaller eyes and jaw, as a warp;
* :func:`restyled_shapes` — the same shape names with other motions (an actor's own expressions).

Units, shape and part names, and all of it at once (:func:`foreign_face`):
:mod:`workbench.testing.conventions`.

Everything is deterministic given its seed; nothing is downloaded. Apply the
geometry first, then units and names (the geometry steps rebuild shapes by
their source names). Tests, benchmarks and tutorials use this module; no
method does.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import igl
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from workbench.core.polygons import Polygons
from workbench.model import UNIT_TO_METRES, BlendShape, FaceModel, ModelMetadata
from workbench.testing.meshes import add_bust, keep_vertices, permute_vertices, split_remesh
from workbench.testing.warps import (
    LocalScale,
    Warp,
    identity,
    unit_factor,
)

__all__ = [
    "GeneratedFace",
    "cropped",
    "opened",
    "proportions_warp",
    "remeshed",
    "renumbered",
    "restyled_shapes",
    "warped",
    "with_bust",
    "with_hole",
]

_AXIS = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0),
         "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}


def _axis(name: str) -> NDArray[np.float64]:
    return np.array(_AXIS[name])


def _delta(shape: BlendShape) -> NDArray[np.float64]:
    """A shape's displacement with its vertex mask baked in (mute is a state of the rig, not of the shape)."""
    d = np.asarray(shape.delta, np.float64)
    return d if shape.vertex_mask is None else d * np.asarray(shape.vertex_mask, np.float64)[:, None]


@dataclass(frozen=True, eq=False)
class GeneratedFace:
    """A generated face and the exact map from the rig it was made from.

    Attributes
    ----------
    model : FaceModel
        The new face (with or without shapes).
    source : FaceModel
        The rig it was made from.
    W : (n, n_source) sparse
        Barycentric rows: vertex ``i`` was at ``W[i] @ source.vertices``
        before the warp; rows of vertices not on the source (a bust) are empty.
    points : (n, 3) float
        Every vertex before the warp, in the source's space and units.
    warp : callable
        ``model.vertices == warp(points)``.
    """

    model: FaceModel
    source: FaceModel
    W: sp.csr_matrix
    points: NDArray[np.float64]
    warp: Warp

    @property
    def on_source(self) -> NDArray[np.bool_]:
        """``(n,)``: vertices that lie on the source's surface (not on an added bust)."""
        return np.asarray(self.W.getnnz(axis=1) > 0)

    def truth(self, name: str) -> NDArray[np.float64]:
        """``(n, 3)``: the true displacement of source shape ``name`` on this face, in its units."""
        d = self.W @ _delta(self.source.shape(name))
        return np.asarray(self.warp(self.points + d) - self.warp(self.points))

    def displaced(self, displacement: ArrayLike) -> NDArray[np.float64]:
        """``(n, 3)``: this face with a source displacement ``(n_source, 3)`` on it, pushed through the warp.

        A whole source mesh ``M`` (a sculpted or detailed pose) is ``displaced(M - source.vertices)``.
        """
        d = np.asarray(displacement, np.float64)
        return np.asarray(self.warp(self.points + self.W @ d))

    def pose(self, weights: Mapping[str, float]) -> NDArray[np.float64]:
        """``(n, 3)``: the true mesh of this face with source shapes at ``weights`` (summed before the warp)."""
        d = np.zeros((self.source.n_vertices, 3))
        for name, w in weights.items():
            d += float(w) * _delta(self.source.shape(name))
        return self.displaced(d)

    def place(self, source_vertices: ArrayLike) -> NDArray[np.float64]:
        """``(k, 3)``: where source vertices really are on this face (its warp of them)."""
        ids = np.asarray(source_vertices, np.int64).reshape(-1)
        return np.asarray(self.warp(self.source.vertices[ids]))


# ----------------------------------------------------------------------------- building


def _units_after(source: FaceModel, warp: Warp, units: str | None) -> str:
    if units is not None:
        return units
    mpu = source.metadata.metres_per_unit / unit_factor(warp)
    for name, m in UNIT_TO_METRES.items():
        if np.isclose(m, mpu, rtol=1e-9):
            return name
    raise ValueError(f"the warp's unit factor {unit_factor(warp)} gives {mpu} m per unit, no known unit; pass units=")


def _true_shapes(source: FaceModel, points: NDArray[np.float64], W: sp.csr_matrix, warp: Warp) -> list[BlendShape]:
    base = warp(points)
    return [BlendShape(s.name, (warp(points + W @ _delta(s)) - base).astype(np.float32), slider_min=s.slider_min,
                       slider_max=s.slider_max, mute=s.mute) for s in source.shapes]


def _make(source: FaceModel, points: NDArray[np.float64], F: ArrayLike, W: sp.csr_matrix, labels: ArrayLike,
          warp: Warp, *, names: Sequence[str], metadata: ModelMetadata, shapes: bool,
          polygons: Polygons | None = None) -> GeneratedFace:
    W = sp.csr_matrix(W)
    model = FaceModel(warp(points), np.asarray(F, np.int64),
                      _true_shapes(source, points, W, warp) if shapes else (), polygons=polygons,
                      component_labels=np.asarray(labels), component_names=list(names), metadata=metadata)
    return GeneratedFace(model, source, W, points, warp)


def _metadata(source: FaceModel, warp: Warp, units: str | None, name: str, up_axis: str | None,
              front_axis: str | None, how: Mapping[str, object]) -> ModelMetadata:
    """The result's metadata: the source's provenance (its licence) plus how it was generated."""
    return ModelMetadata(name=name, units=_units_after(source, warp, units),
                         up_axis=up_axis or source.metadata.up_axis, front_axis=front_axis or source.metadata.front_axis,
                         provenance=(*source.metadata.provenance, {"generated_from": source.metadata.name, **how}))


def _rebuild(face: GeneratedFace, points: NDArray[np.float64], F: ArrayLike, W: sp.csr_matrix,
             labels: ArrayLike) -> GeneratedFace:
    """``face`` with new geometry: same warp, names and metadata; shapes recomputed if it had the source's."""
    have = face.model.shape_names
    if have and sorted(have) != sorted(face.source.shape_names):
        raise ValueError("change the geometry before renaming or splitting shapes (they are rebuilt by source name)")
    return _make(face.source, points, F, W, labels, face.warp, names=face.model.component_names,
                 metadata=face.model.metadata, shapes=bool(have))


def warped(
    source: FaceModel, warp: Warp | None = None, *, units: str | None = None, retriangulate: bool = False,
    shapes: bool = True, name: str = "warped", up_axis: str | None = None, front_axis: str | None = None,
) -> GeneratedFace:
    """The same mesh (same vertices, same order) under a smooth ``warp``, its shapes carried exactly.

    Parameters
    ----------
    source : FaceModel
    warp : callable, optional
        Default the identity (with ``retriangulate``: only the faces change).
    units : str, optional
        Units of the result; default the source's divided by the warp's unit factor.
    retriangulate : bool
        Cut every quad along its other diagonal (triangles stay; other polygons
        are fanned from their second corner): same vertices, other edges.
    shapes : bool
        Give the result the true shapes (``warp(V + delta) - warp(V)``; vertex
        masks baked in).
    name, up_axis, front_axis
        Metadata of the result (axes default to the source's).
    """
    w = identity if warp is None else warp
    n = source.n_vertices
    polygons: Polygons | None = source.polygons
    F: NDArray[np.int64] = np.asarray(source.faces, np.int64)
    if retriangulate:  # every polygon fanned from its second corner: a quad's other diagonal
        P = source.polygons
        first = np.repeat(np.asarray(P.offsets[:-1], np.int64), P.sizes)
        corner = np.arange(first.size) - first
        rolled = np.asarray(P.indices)[first + (corner + 1) % np.repeat(P.sizes, P.sizes)]
        F = Polygons(rolled, P.offsets).triangulate()[0].astype(np.int64)
        polygons = None
    return _make(source, np.asarray(source.vertices, np.float64), F, sp.identity(n, format="csr"),
                 source.component_labels, w, names=source.component_names,
                 metadata=_metadata(source, w, units, name, up_axis, front_axis,
                                    {"by": "workbench.testing.warped", "retriangulate": retriangulate}),
                 shapes=shapes, polygons=polygons)


def remeshed(
    source: FaceModel, *, seed: int = 0, warp: Warp | None = None, units: str | None = None, shapes: bool = False,
    slide: float = 0.2, flips: float = 0.3, name: str = "remeshed", up_axis: str | None = None,
    front_axis: str | None = None,
) -> GeneratedFace:
    """The source's surface re-triangulated (4x the triangles, no vertex where one was), then warped.

    Parameters
    ----------
    source : FaceModel
    seed : int
        Of :func:`~workbench.testing.meshes.split_remesh` (edge points, slides, flips).
    warp : callable, optional
        Default the identity.
    units : str, optional
        Default the source's divided by the warp's unit factor.
    shapes : bool
        Give the result the true shapes (default none: a face to rig).
    slide, flips
        See :func:`~workbench.testing.meshes.split_remesh`.
    name, up_axis, front_axis
        Metadata of the result.

    Returns
    -------
    GeneratedFace
        Every vertex has the component of the source vertex it leans on most.
    """
    w = identity if warp is None else warp
    V2, F2, W = split_remesh(source.vertices, source.faces, seed=seed, slide=slide, flips=flips)
    labels = source.component_labels[np.asarray(W.argmax(axis=1)).ravel()]
    return _make(source, V2, F2, W, labels, w, names=source.component_names,
                 metadata=_metadata(source, w, units, name, up_axis, front_axis,
                                    {"by": "workbench.testing.remeshed", "seed": seed}), shapes=shapes)


def renumbered(face: GeneratedFace, *, seed: int = 0) -> GeneratedFace:
    """The same face with its vertices (and triangles) in a random order."""
    order, F = permute_vertices(face.model.faces, face.model.n_vertices, seed=seed)
    return _rebuild(face, face.points[order], F, face.W[order], face.model.component_labels[order])


def _skin_label(face: GeneratedFace) -> int:
    roles = face.source.part_roles
    return roles.index("skin") if "skin" in roles else 0


def with_bust(face: GeneratedFace, *, rings: int = 12, drop: float = 0.25, flare: float = 1.6) -> GeneratedFace:
    """Shoulders: ``rings`` rings below the skin's lowest open border (the neck), flaring out.

    See :func:`~workbench.testing.meshes.add_bust` for ``drop`` and ``flare``.
    The new vertices are skin, lie on no source surface (their rows of ``W``
    are empty) and stay still in every true shape.
    """
    up = _axis(face.source.metadata.up_axis)
    F = np.asarray(face.model.faces, np.int64)
    skin = _skin_label(face)
    lab = face.model.component_labels
    loops = igl.boundary_loop_all(F[lab[F[:, 0]] == skin])
    if not loops:
        raise ValueError("the skin has no open border to hang a bust from")
    loop = min(loops, key=lambda lp: float((face.points[lp] @ up).mean()))  # the lowest: the neck
    P, F3 = add_bust(face.points, F, loop, rings=rings, drop=drop, flare=flare, up=up)
    extra = P.shape[0] - face.points.shape[0]
    W = sp.vstack([face.W, sp.csr_matrix((extra, face.W.shape[1]))]).tocsr()
    labels = np.concatenate([lab, np.full(extra, skin, lab.dtype)])
    return _rebuild(face, P, F3, W, labels)


def _subset(face: GeneratedFace, keep: NDArray[np.bool_]) -> GeneratedFace:
    _, F2, kept = keep_vertices(face.points, face.model.faces, keep)
    return _rebuild(face, face.points[kept], F2, face.W[kept], face.model.component_labels[kept])


def _pieces(F: NDArray[np.int64], n: int, among: NDArray[np.bool_]) -> NDArray[np.int64]:
    """``(n,)``: connected piece of every vertex in ``among`` along the edges of ``F`` among them, -1 elsewhere."""
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    e = e[among[e[:, 0]] & among[e[:, 1]]]
    A = sp.coo_matrix((np.ones(e.shape[0]), (e[:, 0], e[:, 1])), shape=(n, n))
    _, piece = connected_components(A, directed=False)
    return np.where(among, piece, -1).astype(np.int64)


def _largest(F: NDArray[np.int64], n: int, among: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The largest connected piece of ``among`` (all False if it is empty)."""
    piece = _pieces(F, n, among)
    if not among.any():
        return among.copy()
    return np.asarray(piece == np.bincount(piece[among]).argmax())


def _without_skin_islands(face: GeneratedFace, cut: NDArray[np.bool_]) -> GeneratedFace:
    """Remove ``cut``, then every piece of skin cut off from the largest one."""
    F = np.asarray(face.model.faces, np.int64)
    n = face.model.n_vertices
    skin = face.model.component_labels == _skin_label(face)
    kept = ~cut
    for _ in range(20):  # a vertex where two cut borders touch (a bow tie) goes too
        F_kept = F[kept[F].all(axis=1) & skin[F[:, 0]]]
        e = np.sort(np.concatenate([F_kept[:, [0, 1]], F_kept[:, [1, 2]], F_kept[:, [2, 0]]]), axis=1)
        edges, count = np.unique(e, axis=0, return_counts=True)
        pinched = np.bincount(edges[count == 1].ravel(), minlength=n) > 2
        if not pinched.any():
            break
        kept &= ~pinched
    F_kept = F[kept[F].all(axis=1)]
    main = _largest(F_kept, n, skin & kept)
    return _subset(face, kept & (main | ~skin))


def with_hole(face: GeneratedFace, centre: ArrayLike, radius: float) -> GeneratedFace:
    """Remove the surface within ``radius`` of ``centre`` (both in the source's space and units)."""
    near = np.linalg.norm(face.points - np.asarray(centre, np.float64), axis=1) < radius
    return _subset(face, ~near)


def cropped(face: GeneratedFace, *, depth: float = 0.5) -> GeneratedFace:
    """Only the front of the head, like a face scan: what lies in the front ``depth`` of the skin's depth.

    Depth is measured along the source's front axis over the skin; pieces of
    skin cut off from the largest one are removed too.
    """
    front = _axis(face.source.metadata.front_axis)
    s = face.points @ front
    skin = face.model.component_labels == _skin_label(face)
    lo, hi = float(s[skin].min()), float(s[skin].max())
    return _without_skin_islands(face, s < hi - depth * (hi - lo))


def _eyeballs(model: FaceModel) -> list[tuple[NDArray[np.float64], float]]:
    """Centre and radius of every eyeball part (found by role)."""
    out = []
    for k, role in enumerate(model.part_roles):
        if role.startswith("eyeball"):
            E = model.vertices[model.component_labels == k]
            c = E.mean(0)
            out.append((c, float(np.linalg.norm(E - c, axis=1).max())))
    if not out:
        raise ValueError("the model has no eyeball parts")
    return out


def opened(face: GeneratedFace, *, mouth: bool = True, eyes: bool = True, reach: float = 0.1,
           socket: float = 1.1) -> GeneratedFace:
    """Open mouth and eye topology: the mouth bag and the eye sockets cut out of the skin.

    The lips and the lid margins become open borders, as on many artist-made
    heads. Parts are found by their roles on the source (teeth and tongue,
    eyeballs): the mouth cut is the skin within ``reach`` of the mouth parts'
    width from them, an eye's the skin within ``socket`` times the eyeball's
    radius from its centre (each its largest connected piece); skin left
    hanging inside (the back of the bag) goes too.
    """
    roles = face.source.part_roles
    src_lab = face.source.component_labels
    V = face.source.vertices
    lab = face.model.component_labels
    F = np.asarray(face.model.faces, np.int64)
    n = face.model.n_vertices
    skin = lab == _skin_label(face)
    cut = np.zeros(n, bool)
    if mouth:
        parts = [k for k, r in enumerate(roles) if r.startswith("teeth") or r == "tongue"]
        if not parts:
            raise ValueError("opened(mouth=True): the source has no teeth or tongue to find the mouth by")
        M = V[np.isin(src_lab, parts)]
        side = np.cross(_axis(face.source.metadata.up_axis), _axis(face.source.metadata.front_axis))
        width = float(np.ptp(M @ side))
        near = cKDTree(M).query(face.points)[0] < reach * width
        cut |= _largest(F, n, skin & near)
    if eyes:
        for c, r in _eyeballs(face.source):
            cut |= _largest(F, n, skin & (np.linalg.norm(face.points - c, axis=1) < socket * r))
    return _without_skin_islands(face, cut)


def proportions_warp(model: FaceModel, *, eyes: float = 1.0, jaw: float = 1.0) -> LocalScale:
    """A warp that scales the eyes and the jaw of ``model`` about their centres (1: unchanged).

    Eyes: each eyeball part (by role) with the skin around it, exactly inside
    1.05 of the eyeball's radius, fading out at twice it. Jaw: the region
    ``jawOpen`` moves, about its displacement-weighted centre, exactly inside
    its weighted RMS radius, fading out at 1.75 times it.
    """
    V = model.vertices
    centres: list[NDArray[np.float64]] = []
    inner: list[float] = []
    outer: list[float] = []
    factors: list[float] = []
    if eyes != 1.0:
        for c, r in _eyeballs(model):
            centres.append(c)
            inner.append(1.05 * r)
            outer.append(2.0 * r)
            factors.append(eyes)
    if jaw != 1.0:
        if "jawOpen" not in model.shape_names:
            raise ValueError("proportions_warp(jaw=...): the model has no jawOpen shape to find the jaw by")
        w = np.linalg.norm(_delta(model.shape("jawOpen")), axis=1)
        w = w / w.sum()
        c = w @ V
        r = float(np.sqrt(w @ ((V - c) ** 2).sum(1)))
        centres.append(c)
        inner.append(r)
        outer.append(1.75 * r)
        factors.append(jaw)
    return LocalScale(np.reshape(centres, (-1, 3)), np.asarray(inner), np.asarray(outer), np.asarray(factors))


def restyled_shapes(model: FaceModel, *, seed: int = 0, gain: float = 0.35, turn: float = 0.3,
                    wavelength: float = 0.4) -> FaceModel:
    """The same face and shape names, other motions: an actor who makes each expression their own way.

    Shape ``i``'s displacement at every vertex is scaled by ``1 + gain sin(.)``
    and turned by ``turn cos(.)`` radians about a random axis, both smooth
    waves of ``wavelength`` (a share of the model's size) along a random
    direction, drawn from ``numpy.random.default_rng(seed + i)``. ``gain = turn
    = 0`` gives the shapes back. Vertex masks are baked in.
    """
    V = model.vertices
    centre = V.mean(axis=0)
    length = wavelength * float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    shapes = []
    for i, sh in enumerate(model.shapes):
        rng = np.random.default_rng(seed + i)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        phase = rng.uniform(0, 2 * np.pi, 2)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        x = 2 * np.pi * ((V - centre) @ d) / length
        scale = 1 + gain * np.sin(x + phase[0])
        ang = turn * np.cos(x + phase[1])
        v = _delta(sh)
        # Rodrigues: R v = v cos + (k x v) sin + k (k . v)(1 - cos)
        turned = (v * np.cos(ang)[:, None] + np.cross(axis[None], v) * np.sin(ang)[:, None]
                  + np.outer((v @ axis) * (1 - np.cos(ang)), axis))
        shapes.append(sh.replace(delta=scale[:, None] * turned, vertex_mask=None))
    return FaceModel(V, model.faces, shapes, polygons=model.polygons, component_labels=model.component_labels,
                     component_names=model.component_names, metadata=model.metadata)

