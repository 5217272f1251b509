"""What a rig transfer did and how good it is: per-shape stretch, flips and self-intersections, registration, parts, warnings.

:class:`TransferReport` is returned by :func:`workbench.rigging.transfer_rig_report`
and saved (as JSON) in the rig's ``metadata.provenance`` entry ``"method":
"rig transfer"``; :meth:`TransferReport.from_model` reads it back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "FLAG_COUNT_RATIO",
    "FLAG_STRETCH_FLOOR",
    "FLAG_STRETCH_RATIO",
    "METHOD",
    "RigTransferError",
    "ShapeQuality",
    "StretchMeter",
    "TransferReport",
    "triangle_stretch",
]

#: the provenance entry's ``"method"``
METHOD = "rig transfer"

#: a shape is flagged when its largest stretch on the target is above this floor ...
FLAG_STRETCH_FLOOR = 1.5
#: ... and above this many times its largest stretch on the template
FLAG_STRETCH_RATIO = 1.3
#: a shape is flagged when it flips, or newly self-intersects, more than this many times as many triangles
#: on the target as on the template, once the two meshes' densities are allowed for (:meth:`ShapeQuality.concerns`)
FLAG_COUNT_RATIO = 2.0

class RigTransferError(ValueError):
    """The transfer cannot be done on these inputs; the message names the input and the problem."""


class StretchMeter:
    """Per-triangle stretch and flips of displacements of one rest mesh (rest frames computed once).

    The stretch of a triangle is its largest principal stretch ``max(s1, 1 / s2)``,
    ``s1 >= s2`` the singular values of the in-plane map taking the rest
    triangle onto the deformed one (1 for a rigid motion); a triangle is
    flipped when its normal turns by more than 90 degrees. Degenerate rest
    triangles get stretch 1 and are never flipped.
    """

    def __init__(self, V0: NDArray[np.float64], F: NDArray[np.int64]) -> None:
        self.V0 = np.asarray(V0, np.float64)
        self.F = np.asarray(F, np.int64)
        e1 = self.V0[self.F[:, 1]] - self.V0[self.F[:, 0]]
        e2 = self.V0[self.F[:, 2]] - self.V0[self.F[:, 0]]
        n0 = np.cross(e1, e2)
        a0 = np.linalg.norm(n0, axis=1)
        self.ok = a0 > 1e-12 * max(float(np.median(a0)) if a0.size else 0.0, 1e-300)
        # rest coordinates in an orthonormal frame (u along e1): e1 = (a, 0), e2 = (c, d)
        a = np.linalg.norm(e1, axis=1)
        u = e1 / np.maximum(a[:, None], 1e-300)
        v = np.cross(n0 / np.maximum(a0[:, None], 1e-300), u)
        c, d = (e2 * u).sum(1), (e2 * v).sum(1)
        det = np.where(np.abs(a * d) > 1e-300, a * d, 1.0)
        # inverse of [[a, c], [0, d]]
        self._inv = (d / det, -c / det, a / det)  # i00, i01, i11 (i10 = 0)
        self.n0 = n0

    def measure(
        self, D: NDArray[np.float64], faces: NDArray[np.int64] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """(stretch, flipped) of the displacement ``D`` (n, 3) per triangle (of ``faces``, default all)."""
        sel = np.arange(self.F.shape[0]) if faces is None else faces
        F = self.F[sel]
        V1 = self.V0 + D
        f1 = V1[F[:, 1]] - V1[F[:, 0]]
        f2 = V1[F[:, 2]] - V1[F[:, 0]]
        i00, i01, i11 = (x[sel] for x in self._inv)
        J0 = f1 * i00[:, None]
        J1 = f1 * i01[:, None] + f2 * i11[:, None]
        g00 = np.einsum("ij,ij->i", J0, J0)
        g01 = np.einsum("ij,ij->i", J0, J1)
        g11 = np.einsum("ij,ij->i", J1, J1)
        tr, dt = g00 + g11, g00 * g11 - g01 * g01
        disc = np.sqrt(np.maximum(tr * tr / 4 - dt, 0.0))
        s1 = np.sqrt(np.maximum(tr / 2 + disc, 0.0))
        s2 = np.sqrt(np.maximum(tr / 2 - disc, 0.0))
        stretch = np.maximum(s1, 1.0 / np.maximum(s2, 1e-12))
        ok = self.ok[sel]
        flipped = ok & (np.einsum("ij,ij->i", self.n0[sel], np.cross(f1, f2)) <= 0.0)
        return np.where(ok, stretch, 1.0), flipped

    def shape_quality(self, D: NDArray[np.float64]) -> tuple[float, float, int, int]:
        """(max stretch, median stretch over moved triangles, flipped count, moved vertex count) of ``D``."""
        mag2 = np.einsum("ij,ij->i", D, D)
        top = float(mag2.max()) if mag2.size else 0.0
        if top <= 0:
            return 1.0, 1.0, 0, 0
        moving = mag2 > 1e-4 * top
        tri = np.flatnonzero(moving[self.F].any(1))
        st, fl = self.measure(D, tri)
        return float(st.max()), float(np.median(st)), int(fl.sum()), int(moving.sum())


def triangle_stretch(
    V0: NDArray[np.float64], V1: NDArray[np.float64], F: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Per triangle: the largest principal stretch ``max(s1, 1 / s2)`` from ``V0`` to ``V1`` and whether it flipped.

    See :class:`StretchMeter`.
    """
    V0 = np.asarray(V0, np.float64)
    return StretchMeter(V0, F).measure(np.asarray(V1, np.float64) - V0)


@dataclass(frozen=True)
class ShapeQuality:
    """One transferred shape at weight 1 on the target skin.

    Attributes
    ----------
    name : str
    max_stretch, median_stretch : float
        Largest principal stretch ``max(s1, 1/s2)`` (1 = rigid) over the
        target skin triangles, and its median over the triangles the shape
        moves (1 if it moves none).
    flipped : int
        Target triangles whose normal turns over.
    source_max_stretch : float
        The same on the template, for comparison (a shape that stretches the
        template 1.6x may stretch the target as much).
    source_flipped : int
    moved : int
        Target vertices the shape moves (by more than 1 % of its largest displacement).
    intersecting : int
        Target skin triangles that cross another triangle of the skin at
        weight 1 and did not at rest (pairs sharing a vertex do not count; see
        :class:`workbench.rigging.intersections.SelfIntersections`): a lip
        pushed through the other, an eyelid through the cheek. 0 in reports
        saved before it was measured, and when numba is not installed (the
        check is skipped; the transfer logs it).
    source_intersecting : int
        The same on the template skin, for comparison (a template whose
        ``mouthClose`` already presses the lips through each other passes it on).
    triangles, source_triangles : int
        Skin triangles of the target and of the template, to compare the
        counts of two meshes of different density (0 in reports saved before
        they were recorded).
    """

    name: str
    max_stretch: float
    median_stretch: float
    flipped: int
    source_max_stretch: float
    source_flipped: int
    moved: int
    intersecting: int = 0
    source_intersecting: int = 0
    triangles: int = 0
    source_triangles: int = 0

    def concerns(self) -> tuple[str, ...]:
        """Why this shape needs a look: where it does worse on the target than on the template (empty: fine).

        The rule, per measure:

        * stretch: the largest stretch is above :data:`FLAG_STRETCH_FLOOR`
          and :data:`FLAG_STRETCH_RATIO` times the template's;
        * flips: more flipped triangles than :data:`FLAG_COUNT_RATIO` times
          the template's count scaled by ``triangles / source_triangles``
          (a flipped patch is an area: its triangle count grows with the
          density);
        * self-intersections: more new self-intersecting triangles than
          :data:`FLAG_COUNT_RATIO` times the template's count scaled by
          ``sqrt(triangles / source_triangles)`` (the triangles that cross
          lie along a curve: their count grows with the edge density).

        So any flip or self-intersection the template's shape does not have
        is flagged, and one it has is flagged only when the target has it
        much worse. Without the triangle counts (older reports) the scale is 1.
        """
        density = self.triangles / self.source_triangles if self.triangles > 0 and self.source_triangles > 0 else 1.0
        out = []
        if self.max_stretch > max(FLAG_STRETCH_FLOOR, FLAG_STRETCH_RATIO * self.source_max_stretch):
            out.append(f"stretch {self.max_stretch:.2f} (template {self.source_max_stretch:.2f})")
        if self.flipped > FLAG_COUNT_RATIO * self.source_flipped * density:
            out.append(f"flipped triangles {self.flipped} (template {self.source_flipped})")
        if self.intersecting > FLAG_COUNT_RATIO * self.source_intersecting * np.sqrt(density):
            out.append(f"self-intersecting triangles {self.intersecting} (template {self.source_intersecting})")
        return tuple(out)


_SHAPE_FIELDS = frozenset(f.name for f in fields(ShapeQuality))
#: flagged shapes listed by :meth:`TransferReport.summary`
_SUMMARY_FLAGGED = 8


@dataclass(frozen=True)
class TransferReport:
    """How a rig transfer went (see :func:`workbench.rigging.transfer_rig_report`).

    Attributes
    ----------
    source, target : str
        Model names.
    shapes : tuple of ShapeQuality
        One per transferred shape, in the rig's order.
    alignment : dict
        ``scale`` (target units per template unit), ``rotation_deg``, ``method``
        ("landmarks", "eyes", "head top") and the rigid fit's accepted share.
    registration : dict
        The template skin fitted onto the target: ``coverage`` (share of its
        face that found target surface, less what lies over the target's holes),
        ``over_holes`` (share of its face over holes or open borders of the
        target: an open mouth bag, eye sockets), ``median_residual`` and
        ``p95_residual`` (target units), ``distortion`` (area share of template
        triangles stretched beyond 2x or flipped by the fit), ``iterations``.
    correspondence : dict
        ``mapped``: share of target skin vertices with a template partner;
        ``pinned``: share held still (no partner, or still in every shape).
    parts : dict
        Per target component: ``"skin"``, ``"matched <source part>"``,
        ``"fixed"``, ``"rigid with the skin"`` or ``"follows the skin"``.
    landmarks : list
        The landmark pairs used (source vertex, target vertex); automatic
        alignment points are named in ``alignment["method"]``.
    warnings : tuple of str
        Problems found that did not stop the transfer.
    timings : dict
        Seconds: ``setup`` (alignment, fit, correspondence, factorisation) and ``transfer``.
    """

    source: str
    target: str
    shapes: tuple[ShapeQuality, ...]
    alignment: Mapping[str, Any] = field(default_factory=dict)
    registration: Mapping[str, Any] = field(default_factory=dict)
    correspondence: Mapping[str, Any] = field(default_factory=dict)
    parts: Mapping[str, str] = field(default_factory=dict)
    landmarks: tuple[tuple[int, int], ...] = ()
    warnings: tuple[str, ...] = ()
    timings: Mapping[str, float] = field(default_factory=dict)

    def shape(self, name: str) -> ShapeQuality:
        """The quality entry of one shape."""
        for s in self.shapes:
            if s.name == name:
                return s
        raise KeyError(f"no transferred shape {name!r}")

    @property
    def worst(self) -> ShapeQuality | None:
        """The shape with the largest stretch (None if no shapes)."""
        return max(self.shapes, key=lambda s: s.max_stretch, default=None)

    @property
    def flagged(self) -> tuple[ShapeQuality, ...]:
        """The shapes that do worse on the target than on the template (:meth:`ShapeQuality.concerns`), in rig order."""
        return tuple(s for s in self.shapes if s.concerns())

    def summary(self) -> str:
        """A few lines for people."""
        lines = [f"rig transfer {self.source} -> {self.target}: {len(self.shapes)} shapes"]
        reg = self.registration
        if reg:
            lines.append(
                f"  fit: coverage {reg.get('coverage', 0):.0%} ({reg.get('over_holes', 0):.0%} of the face over "
                f"holes of the target), residual median {reg.get('median_residual', 0):.3g} / "
                f"p95 {reg.get('p95_residual', 0):.3g} (target units), distortion {reg.get('distortion', 0):.1%}"
            )
        w = self.worst
        if w is not None:
            flips = sum(s.flipped for s in self.shapes)
            lines.append(f"  worst stretch {w.max_stretch:.2f} ({w.name}), flipped triangles in all shapes: {flips}")
            crossing = [s for s in self.shapes if s.intersecting]
            src_crossing = [s for s in self.shapes if s.source_intersecting]
            lines.append(
                f"  new self-intersections at weight 1: {len(crossing)} shapes, "
                f"{sum(s.intersecting for s in crossing)} triangles (template: {len(src_crossing)} shapes, "
                f"{sum(s.source_intersecting for s in src_crossing)} triangles)"
            )
        flagged = self.flagged
        if flagged:
            lines.append(f"  flagged, worse than on the template: {len(flagged)} shapes")
            lines += [f"    {s.name}: {'; '.join(s.concerns())}" for s in flagged[:_SUMMARY_FLAGGED]]
            if len(flagged) > _SUMMARY_FLAGGED:
                lines.append(f"    ... and {len(flagged) - _SUMMARY_FLAGGED} more (TransferReport.flagged)")
        lines += [f"  warning: {x}" for x in self.warnings]
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (the provenance entry, with ``"method": "rig transfer"``)."""
        out = asdict(self)
        out["shapes"] = [asdict(s) for s in self.shapes]
        out["landmarks"] = [list(p) for p in self.landmarks]
        out["warnings"] = list(self.warnings)
        return {"method": METHOD, **_plain(out)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TransferReport:
        """The report from :meth:`to_json` (also of older versions: missing per-shape entries take their defaults)."""
        return cls(
            source=str(d.get("source", "")),
            target=str(d.get("target", "")),
            # keys this version does not know are dropped; ones added since the report was saved take their defaults
            shapes=tuple(ShapeQuality(**{k: v for k, v in s.items() if k in _SHAPE_FIELDS}) for s in d.get("shapes", [])),
            alignment=dict(d.get("alignment", {})),
            registration=dict(d.get("registration", {})),
            correspondence=dict(d.get("correspondence", {})),
            parts=dict(d.get("parts", {})),
            landmarks=tuple((int(a), int(b)) for a, b in d.get("landmarks", [])),
            warnings=tuple(d.get("warnings", [])),
            timings=dict(d.get("timings", {})),
        )

    @classmethod
    def from_model(cls, model: Any) -> TransferReport:
        """The report of the last rig transfer that made ``model`` (from its provenance)."""
        for entry in reversed(model.metadata.provenance):
            if entry.get("method") == METHOD:
                return cls.from_json(entry)
        raise KeyError(f"{model.metadata.name or 'model'}: no rig transfer in its provenance")


def _plain(x: Any) -> Any:
    """numpy scalars and tuples to JSON types."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
