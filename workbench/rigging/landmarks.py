"""Default landmarks for a rig transfer: named points found on an ARKit rig, and where they land on the target.

A user who rigs a face without landmark pairs (issue 16) gets a starting set
to check and correct instead of an empty table:

* :func:`template_landmarks` finds named skin vertices on any rig with
  ARKit-named shapes, from what its shapes move and from its geometry, never
  from fixed vertex ids: the vertex a sided shape moves most (mouth corners from
  ``mouthSmile*``, upper eyelids from ``eyeBlink*``, brows from
  ``browOuterUp*`` / ``browInnerUp``, cheeks from ``cheekPuff``), and the most
  frontal point near the mid-plane among the vertices a shape moves (lips from
  ``mouthRollUpper`` / ``mouthRollLower``, the chin from ``jawOpen`` below the
  lower lip, the nose tip between the mouth and the eyes). Axes come from the
  model's metadata (``up_axis``, ``front_axis``), so units and orientation do
  not matter; shape names are read through
  :func:`workbench.arkit.canonical_arkit_name` (``mouthSmile_L``,
  ``blendShape1.eyeBlinkLeft``), the halves of split shapes (``jawOpen_L`` +
  ``jawOpen_R``) are summed, and one unsided shape standing for a pair
  (``mouthSmile``) serves both sides.
* :func:`suggest_landmarks` takes a set-up :class:`RigTransfer`, follows each
  template landmark through the non-rigid fit (``transfer.fit.positions``) and
  returns the target skin vertex nearest to where the fitted template puts it:
  ``[(s.source_vertex, s.target_vertex) for s in suggestions]`` is a landmark
  list for :class:`RigTransfer`.

Left and right are the subject's, as in the ARKit names.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from workbench.arkit import canonical_arkit_name, split_half_of
from workbench.geometry.axes import AxesError, face_axes
from workbench.geometry.masks import MissingPartError, skin_surface
from workbench.geometry.normals import vertex_normals
from workbench.model import FaceModel
from workbench.rigging.report import RigTransferError
from workbench.rigging.transfer import RigTransfer

__all__ = ["LANDMARK_NAMES", "SuggestedLandmark", "read_landmark_pairs", "suggest_landmarks", "template_landmarks"]

#: every landmark :func:`template_landmarks` can find, in the order it returns them
LANDMARK_NAMES: tuple[str, ...] = (
    "mouth_corner_left",
    "mouth_corner_right",
    "eyelid_left",
    "eyelid_right",
    "brow_outer_left",
    "brow_outer_right",
    "brow_inner_left",
    "brow_inner_right",
    "cheek_left",
    "cheek_right",
    "upper_lip",
    "lower_lip",
    "chin",
    "nose_tip",
)

# sided landmarks: name stem -> shapes tried in order (ARKit names; "{side}" is Left / Right)
_SIDED: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("mouth_corner", ("mouthSmile{side}", "mouthStretch{side}")),
    ("eyelid", ("eyeBlink{side}",)),
    ("brow_outer", ("browOuterUp{side}",)),
    ("brow_inner", ("browInnerUp",)),
    ("cheek", ("cheekPuff",)),
)
# the shapes whose strongly moved vertices hold a lip (a pair of sided shapes counts as one)
_UPPER_LIP = (("mouthRollUpper",), ("mouthShrugUpper",), ("mouthUpperUpLeft", "mouthUpperUpRight"))
_LOWER_LIP = (("mouthRollLower",), ("mouthShrugLower",), ("mouthLowerDownLeft", "mouthLowerDownRight"))
#: a vertex is "moved by" a shape when it moves at least this share of the shape's largest skin displacement
STRONG = 0.5
#: the front-facing skin: the cosine between its outward normal and the front axis is above this
FACING = 0.5
#: half-width of the band around the mid-plane searched for midline landmarks, as a share of the skin's width
MIDLINE_BAND = 0.03


@dataclass(frozen=True)
class SuggestedLandmark:
    """One suggested landmark pair for :class:`RigTransfer`.

    Attributes
    ----------
    name : str
        One of :data:`LANDMARK_NAMES`.
    source_vertex : int
        The template (source) vertex, from :func:`template_landmarks`.
    target_vertex : int
        The target skin vertex nearest to where the fitted template puts it.
    distance : float
        From the fitted template point to that vertex, in the target's units.
    """

    name: str
    source_vertex: int
    target_vertex: int
    distance: float

    @property
    def pair(self) -> tuple[int, int]:
        """``(source_vertex, target_vertex)``, an entry of ``RigTransfer(landmarks=...)``."""
        return (self.source_vertex, self.target_vertex)


class _Rig:
    """A model's skin seen in its own canonical axes (x the subject's left, y up, z front), model units."""

    def __init__(self, model: FaceModel) -> None:
        try:
            R = face_axes(model)
            # the skin's vertices on skin triangles, as the transfer's
            self.skin, local = skin_surface(model)
        except (AxesError, MissingPartError) as e:
            raise RigTransferError(str(e)) from None
        self.model = model
        self.P = np.asarray(model.vertices, np.float64) @ R.T  # (n, 3)
        S = self.P[self.skin]
        lo, hi = S.min(0), S.max(0)
        self.size = float(np.linalg.norm(hi - lo))
        self.mid = 0.5 * float(lo[0] + hi[0])  # refined from the left/right pairs once they are found
        F = self.skin[local]
        edge = float(np.median(np.linalg.norm(self.P[F[:, 1]] - self.P[F[:, 0]], axis=1)))
        self.band = max(MIDLINE_BAND * float(hi[0] - lo[0]), edge)
        # outer surface facing front (not the inside of the lips or the mouth): normals turned outward as a whole
        N = vertex_normals(self.P, F)[self.skin]
        if float(((S - S.mean(0)) * N).sum()) < 0:
            N = -N
        self.facing = N[:, 2] > FACING
        self._shapes = _arkit_deltas(model)
        self._norms: dict[str, NDArray[np.float64]] = {}

    def moves(self, name: str) -> NDArray[np.float64] | None:
        """(n_skin,) displacement length of the ARKit shape ``name`` on the skin, or None when the rig lacks it."""
        if name not in self._norms:
            d = self._shapes.get(name)
            if d is None:
                return None
            self._norms[name] = np.linalg.norm(d[self.skin], axis=1)
        return self._norms[name]

    def strongly_moved(self, group: Iterable[str]) -> NDArray[np.bool_] | None:
        """(n_skin,) vertices moved by any shape of ``group`` by at least :data:`STRONG` of its largest move."""
        out = None
        for name in group:
            m = self.moves(name)
            if m is None or not m.max() > 0:
                return None
            on = m >= STRONG * m.max()
            out = on if out is None else out | on
        return out

    def side(self, left: bool) -> NDArray[np.bool_]:
        x = self.P[self.skin, 0]
        return x > self.mid if left else x < self.mid

    def midline(self) -> NDArray[np.bool_]:
        return np.abs(self.P[self.skin, 0] - self.mid) <= self.band

    def most(self, score: NDArray[np.float64], where: NDArray[np.bool_], tol: float) -> int | None:
        """Model id of the skin vertex with the highest ``score`` in ``where`` (ties within ``tol``: lowest id)."""
        if not where.any():
            return None
        s = np.where(where, score, -np.inf)
        top = float(s.max())
        if not np.isfinite(top):
            return None
        return int(self.skin[np.flatnonzero(s >= top - tol)].min())

    def frontmost(self, where: NDArray[np.bool_]) -> int | None:
        """The most frontal front-facing skin vertex in ``where``, a step off the mid-plane costing as a step back."""
        S = self.P[self.skin]
        return self.most(S[:, 2] - np.abs(S[:, 0] - self.mid), where & self.facing, 1e-6 * self.size)

    def y(self, v: int) -> float:
        return float(self.P[v, 1])


def _arkit_deltas(model: FaceModel) -> dict[str, NDArray[np.float64]]:
    """(n, 3) float64 delta of each ARKit shape the rig has, by Apple's name.

    Any spelling :func:`canonical_arkit_name` reads counts (the first shape of a
    name wins); split halves (``browInnerUp_L`` + ``_R``) are summed into their
    whole; an unsided shape naming a left/right pair (``mouthSmile``) stands for
    both sides (the landmarks look for it on one side of the face only).
    """
    exact: dict[str, NDArray[np.float64]] = {}
    halves: dict[str, list[NDArray[np.float64]]] = {}
    pairs: dict[str, NDArray[np.float64]] = {}
    for s in model.shapes:
        d = np.asarray(s.delta, np.float64)
        canon = canonical_arkit_name(s.name)
        if canon is not None:
            exact.setdefault(canon, d)
            continue
        half = split_half_of(s.name)
        if half is not None:
            halves.setdefault(half[0], []).append(d)
            continue
        left, right = canonical_arkit_name(s.name + "_Left"), canonical_arkit_name(s.name + "_Right")
        if left is not None and right is not None:
            pairs.setdefault(left, d)
            pairs.setdefault(right, d)
    out = dict(pairs)
    out.update({name: np.sum(parts, axis=0) for name, parts in halves.items()})
    out.update(exact)
    return out


def template_landmarks(model: FaceModel) -> dict[str, int]:
    """Named skin landmarks of a rig, found from its ARKit shapes and its geometry.

    Parameters
    ----------
    model : FaceModel
        A rig with ARKit-named shapes (any spelling, split or paired) and
        ``metadata.up_axis`` / ``front_axis`` saying where up and front are;
        any units, any topology.

    Returns
    -------
    dict of str to int
        Landmark name -> model vertex id (a skin vertex), in the order of
        :data:`LANDMARK_NAMES`; a landmark whose shapes the rig lacks is left out
        (the nose tip needs none). ``*_left`` / ``*_right`` are the subject's sides:

        * ``mouth_corner_*``: the vertex ``mouthSmileLeft`` / ``Right`` moves most
          (else ``mouthStretch*``);
        * ``eyelid_*``: the upper-lid vertex ``eyeBlink*`` moves most;
        * ``brow_outer_*``, ``brow_inner_*``, ``cheek_*``: the vertex on that side
          that ``browOuterUp*``, ``browInnerUp`` and ``cheekPuff`` move most;
        * ``upper_lip`` / ``lower_lip``: the most frontal front-facing point near the
          mid-plane among the vertices ``mouthRollUpper`` / ``mouthRollLower``
          move by at least half their largest move (else ``mouthShrug*``,
          ``mouthUpperUp*`` / ``mouthLowerDown*``);
        * ``chin``: the most frontal point near the mid-plane that ``jawOpen``
          moves strongly, below the lower lip and not on it (so it needs a
          lower-lip shape too);
        * ``nose_tip``: the most frontal point near the mid-plane between the
          mouth and the eyes (anywhere on the mid-plane without them).

        Midline points are on the outer surface (normal within 60 degrees of
        the front) and a step off the mid-plane counts as a step back.

        The mid-plane is the mean of the left/right pairs' midpoints (the skin's
        bounding-box centre without any pair); "near" is within 3 % of the
        skin's width; "frontal" follows ``front_axis``.

    Raises
    ------
    RigTransferError
        The model has no skin part or its axes are not perpendicular.
    """
    rig = _Rig(model)
    found: dict[str, int] = {}
    # 1. sided: the vertex a shape moves most on its side
    for stem, shapes in _SIDED:
        for side, left in (("left", True), ("right", False)):
            for pattern in shapes:
                m = rig.moves(pattern.format(side=side.capitalize()))
                if m is None or not m.max() > 0:
                    continue
                v = rig.most(m, rig.side(left) & (m > 0), 1e-6 * float(m.max()))
                if v is not None:
                    found[f"{stem}_{side}"] = v
                    break
    pairs = [(found[f"{s}_left"], found[f"{s}_right"]) for s, _ in _SIDED if f"{s}_left" in found and f"{s}_right" in found]
    if pairs:
        rig.mid = float(np.mean([0.5 * (rig.P[a, 0] + rig.P[b, 0]) for a, b in pairs]))
    # 2. on the mid-plane: the most frontal point of what a shape moves
    mid = rig.midline()
    Y = rig.P[rig.skin, 1]
    lips: dict[str, NDArray[np.bool_]] = {}
    for name, groups in (("upper_lip", _UPPER_LIP), ("lower_lip", _LOWER_LIP)):
        for group in groups:
            moved = rig.strongly_moved(group)
            if moved is None:
                continue
            v = rig.frontmost(mid & moved)
            if v is not None:
                found[name], lips[name] = v, moved
                break
    jaw = rig.strongly_moved(("jawOpen",))
    if jaw is not None and "lower_lip" in found:  # (without the lip, the lip would pass for the chin)
        v = rig.frontmost(mid & jaw & ~lips["lower_lip"] & (Y < rig.y(found["lower_lip"])))
        if v is not None:
            found["chin"] = v
    below = [found[k] for k in ("upper_lip", "mouth_corner_left", "mouth_corner_right", "lower_lip") if k in found]
    above = [found[k] for k in ("eyelid_left", "eyelid_right", "brow_inner_left", "brow_inner_right",
                                "brow_outer_left", "brow_outer_right") if k in found]
    where = mid.copy()
    if below:
        where &= Y > max(rig.y(v) for v in below)
    if above:
        where &= Y < min(rig.y(v) for v in above)
    v = rig.frontmost(where)
    if v is None:
        v = rig.frontmost(mid)
    if v is not None:
        found["nose_tip"] = v
    return {k: found[k] for k in LANDMARK_NAMES if k in found}


def suggest_landmarks(transfer: RigTransfer, names: Sequence[str] | None = None) -> list[SuggestedLandmark]:
    """Landmark pairs for a transfer: each template landmark and the target vertex the fit puts it on.

    Parameters
    ----------
    transfer : RigTransfer
        A set-up transfer (its non-rigid fit is done at construction).
    names : sequence of str, optional
        The landmarks wanted (of :data:`LANDMARK_NAMES`); default every one
        :func:`template_landmarks` finds on the template.

    Returns
    -------
    list of SuggestedLandmark
        In the order of :data:`LANDMARK_NAMES`: the template vertex, the target
        skin vertex nearest to where the fitted template skin
        (``transfer.fit.positions``, working frame) puts it, and that distance
        in the target's units. ``[s.pair for s in result]`` is a ``landmarks``
        argument of :class:`RigTransfer`.

    Raises
    ------
    ValueError
        ``names`` holds a name that is not a landmark, or one the template's
        shapes do not give.
    """
    found = template_landmarks(transfer.source)
    if names is not None:
        names = list(names)
        unknown = [n for n in names if n not in LANDMARK_NAMES]
        if unknown:
            raise ValueError(f"suggest_landmarks: unknown landmark names {unknown}; known: {list(LANDMARK_NAMES)}")
        lacking = [n for n in names if n not in found]
        if lacking:
            raise ValueError(
                f"suggest_landmarks: the template {transfer.source.metadata.name or ''!r} has no shapes to find "
                f"{lacking} (found {list(found)})"
            )
        found = {k: found[k] for k in LANDMARK_NAMES if k in names}
    if not found:
        return []
    src, tgt = transfer.src, transfer.tgt
    verts = np.array(list(found.values()), np.int64)
    local = np.searchsorted(src.skin_ids, verts)
    ok = (local < src.skin_ids.size) & (src.skin_ids[np.minimum(local, src.skin_ids.size - 1)] == verts)
    if not ok.all():  # cannot happen: both take the skin as the triangles whose corners are all skin
        raise RigTransferError(f"suggest_landmarks: template vertices {verts[~ok].tolist()} are not on the fitted skin")
    P = transfer.fit.positions[local]  # (k, 3) working frame
    d, nn = cKDTree(tgt.X[tgt.skin_ids]).query(P)
    per_unit = tgt.frame.scale  # working-frame length per target unit
    return [
        SuggestedLandmark(name, int(v), int(tgt.skin_ids[j]), float(dist / per_unit))
        for name, v, j, dist in zip(found, verts, nn, d, strict=True)
    ]


def read_landmark_pairs(path: str | Path, n_template: int, n_target: int, *, what: str = "landmarks"
                        ) -> list[tuple[int, int]]:
    """``template_vertex,target_vertex`` pairs from a CSV with a header row.

    Raises ValueError naming ``what``, the file and the line: missing file, no
    header, a row without two integers, a vertex id out of range.
    """
    import csv

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{what} {p}: no such file")
    pairs: list[tuple[int, int]] = []
    with p.open(newline="", encoding="utf-8-sig") as fh:
        rows = [(i + 1, r) for i, r in enumerate(csv.reader(fh)) if any(c.strip() for c in r)]
    if not rows:
        raise ValueError(f"{what} {p}: empty file (expected a header and template_vertex,target_vertex rows)")
    head_line, header = rows[0]
    if len(header) == 2 and all(_is_int(c) for c in header):
        raise ValueError(f"{what} {p}: line {head_line}: expected a header row "
                           "(e.g. template_vertex,target_vertex), got numbers")
    for line, row in rows[1:]:
        cells = [c.strip() for c in row]
        if len(cells) != 2 or not all(_is_int(c) for c in cells):
            raise ValueError(f"{what} {p}: line {line}: expected two integer vertex ids, got {','.join(row)!r}")
        a, b = int(cells[0]), int(cells[1])
        if not 0 <= a < n_template:
            raise ValueError(f"{what} {p}: line {line}: template vertex {a} out of range "
                               f"(the template has {n_template} vertices)")
        if not 0 <= b < n_target:
            raise ValueError(f"{what} {p}: line {line}: target vertex {b} out of range "
                               f"(the target has {n_target} vertices)")
        pairs.append((a, b))
    if not pairs:
        raise ValueError(f"{what} {p}: no pairs after the header")
    return pairs


def _is_int(text: str) -> bool:
    try:
        int(text.strip())
    except ValueError:
        return False
    return True
