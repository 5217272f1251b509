"""The length unit of an imported face: stated by the format, given by the user, or inferred.

OBJ files carry no unit. Faces are modelled in millimetres, centimetres,
decimetres (MakeHuman), metres or inches, and a unit taken wrongly makes brush
radii, handle offsets and exported sizes wrong by the same factor (a head in
centimetres read as metres is 25 m tall). A human head is about 0.15-0.3 m
tall; with neck, ears or hair, or only the face, the longest side of a face
mesh's bounding box lies in :data:`HEAD_SIZE` = 0.12-0.48 m. So the unit is
inferred as the one of :data:`UNITS` that makes that side head-sized. Two units
can (centimetres and inches between 12 and 18.9 units; decimetres and inches
around 4.75): then the one nearer a :data:`TYPICAL_HEAD` is taken and the
decision says so. When none does (a tiny test mesh, a full body, a normalised
unit cube) metres are assumed and the decision says that too.

The unit is only recorded (``FaceModel.metadata.units``); coordinates are never
rescaled. A unit given by the user (``units=``) always wins; a unit stated by
the format (glTF: metres, by its specification; MakeHuman: decimetres) is
used as stated, never inferred, and only flagged when the mesh is not
head-sized in it.

No library infers a mesh's unit (trimesh's ``units_from_metadata`` only reads
file headers and names), hence this small module.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "HEAD_SIZE",
    "TYPICAL_HEAD",
    "UNITS",
    "UnitDecision",
    "decide_units",
    "infer_units",
    "unit_name",
]

log = logging.getLogger("workbench.io")

#: unit -> metres per unit, the units a face can be inferred in (smallest first)
UNITS: dict[str, float] = {"mm": 0.001, "cm": 0.01, "in": 0.0254, "dm": 0.1, "m": 1.0}
#: plausible longest bounding-box side of a head mesh, in metres (inclusive)
HEAD_SIZE: tuple[float, float] = (0.12, 0.48)
#: the size an ambiguous mesh is compared with, in metres
TYPICAL_HEAD = 0.25

_ALIASES = {
    "m": "m",
    "meter": "m",
    "metre": "m",
    "meters": "m",
    "metres": "m",
    "dm": "dm",
    "decimeter": "dm",
    "decimetre": "dm",
    "decimeters": "dm",
    "decimetres": "dm",
    "cm": "cm",
    "centimeter": "cm",
    "centimetre": "cm",
    "centimeters": "cm",
    "centimetres": "cm",
    "mm": "mm",
    "millimeter": "mm",
    "millimetre": "mm",
    "millimeters": "mm",
    "millimetres": "mm",
    "in": "in",
    "inch": "in",
    "inches": "in",
}
_LONG = {"mm": "millimetres", "cm": "centimetres", "in": "inches", "dm": "decimetres", "m": "metres"}


def unit_name(name: str) -> str:
    """The short name ("mm", "cm", "in", "dm", "m") of a unit name or its spelling out.

    Raises
    ------
    ValueError
        Not a length unit the workbench knows; the message lists them.
    """
    key = str(name).strip().lower()
    if key not in _ALIASES:
        raise ValueError(f"units: expected one of {sorted(UNITS)} (or their names), got {name!r}")
    return _ALIASES[key]


@dataclass(frozen=True)
class UnitDecision:
    """Which unit a face's coordinates are in, and why.

    Attributes
    ----------
    unit : str
        One of :data:`UNITS`.
    how : str
        "given" (``units=``), "file" (stated by the format), "inferred" (one unit
        makes the mesh head-sized), "ambiguous" (several do; the one nearest
        :data:`TYPICAL_HEAD` was taken) or "assumed" (none does; metres).
    size : float
        Longest side of the mesh's bounding box, in file units.
    detail : str
        One sentence for logs and ``workbench info``.
    doubtful : bool
        The user should check the unit: "ambiguous", "assumed", or a stated
        unit in which the mesh is not head-sized.
    """

    unit: str
    how: str
    size: float
    detail: str
    doubtful: bool = False

    def provenance(self) -> dict[str, str]:
        """The entry recorded in ``metadata.provenance`` (saved with the model)."""
        return {"operation": "units", "units": self.unit, "how": self.how, "detail": self.detail}


def _size(vertices: ArrayLike) -> float:
    V = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if V.shape[0] == 0:
        return 0.0
    return float((V.max(axis=0) - V.min(axis=0)).max())


def _metres(x: float) -> str:
    """A length in metres, readably: '0.342 m', '3.4 cm', '25 m'."""
    if x != 0 and abs(x) < 0.1:
        return f"{x * 100:.3g} cm"
    return f"{x:.3g} m"


def _head_sized(metres: float) -> bool:
    return HEAD_SIZE[0] <= metres <= HEAD_SIZE[1]


def infer_units(vertices: ArrayLike) -> UnitDecision:
    """Infer the unit of a face mesh from its size.

    Parameters
    ----------
    vertices : (n, 3) array_like
        Positions in the file's (unknown) unit.

    Returns
    -------
    UnitDecision
        ``how`` is "inferred" when exactly one unit of :data:`UNITS` makes the
        longest bounding-box side head-sized (:data:`HEAD_SIZE`), "ambiguous"
        when several do (the one whose size is nearest :data:`TYPICAL_HEAD` on a
        log scale is taken), "assumed" (metres) when none does.

    Examples
    --------
    >>> import numpy as np
    >>> infer_units(np.array([[0, 0, 0], [18.0, 25.0, 21.0]])).unit   # a head in cm
    'cm'
    >>> infer_units(np.array([[0, 0, 0], [7.0, 10.0, 8.5]])).unit     # ... in inches
    'in'
    """
    size = _size(vertices)
    fits = [u for u, f in UNITS.items() if _head_sized(size * f)]
    override = "pass units= to override"
    if len(fits) == 1:
        u = fits[0]
        return UnitDecision(
            u,
            "inferred",
            size,
            f"{_LONG[u]}, inferred from the size: the longest side, {size:.4g} units, "
            f"is a {_metres(size * UNITS[u])} head in {u} ({override})",
        )
    if fits:
        fits.sort(key=lambda u: abs(math.log(size * UNITS[u] / TYPICAL_HEAD)))
        u, other = fits[0], fits[1]
        return UnitDecision(
            u,
            "ambiguous",
            size,
            f"{_LONG[u]}, inferred but ambiguous: the longest side, {size:.4g} units, is a "
            f"{_metres(size * UNITS[u])} head in {u} or a {_metres(size * UNITS[other])} head "
            f"in {other}; took {u}, nearer a typical {_metres(TYPICAL_HEAD)} head "
            f"(pass units={other!r} if it is in {_LONG[other]})",
            doubtful=True,
        )
    lo, hi = HEAD_SIZE
    if size * max(UNITS.values()) < lo:
        why = (
            f"too small for a head in any of {', '.join(UNITS)}: "
            f"{_metres(size * UNITS['m'])} even in metres"
        )
    elif size * min(UNITS.values()) > hi:
        why = (
            f"too large for a head in any of {', '.join(UNITS)}: "
            f"{_metres(size * UNITS['mm'])} even in millimetres"
        )
    else:
        below = max((u for u in UNITS if size * UNITS[u] < lo), key=lambda u: UNITS[u])
        above = min((u for u in UNITS if size * UNITS[u] > hi), key=lambda u: UNITS[u])
        why = (
            f"between head sizes: {_metres(size * UNITS[above])} in {above}, "
            f"{_metres(size * UNITS[below])} in {below}"
        )
    return UnitDecision(
        "m",
        "assumed",
        size,
        f"metres, assumed: the longest side, {size:.4g} units, is not head-sized "
        f"({lo:g}-{hi:g} m) in any unit, {why} (pass units= to set it)",
        doubtful=True,
    )


def decide_units(
    vertices: ArrayLike,
    *,
    stated: str | None = None,
    given: str | None = None,
    source: str = "",
) -> UnitDecision:
    """The unit of an imported face: ``given`` wins, then ``stated``, else inferred.

    Logs the decision on the ``workbench.io`` logger: INFO when it is certain,
    WARNING when it is ambiguous, assumed, or the stated unit makes the mesh
    not head-sized (e.g. a glTF exporter that wrote centimetres).

    Parameters
    ----------
    vertices : (n, 3) array_like
        Neutral positions, in the file's unit.
    stated : str, optional
        The unit the file format defines (glTF "m", MakeHuman "dm"); never
        overridden by inference.
    given : str, optional
        The unit the user passed (``workbench.load(path, units=...)``).
    source : str
        What was loaded, for the log line.

    Raises
    ------
    ValueError
        ``given`` or ``stated`` is not a known unit.
    """
    if given is not None:
        u = unit_name(given)
        detail = f"{_LONG[u]}, given (units={given!r})"
        if stated is not None and unit_name(stated) != u:
            detail += f"; the file states {unit_name(stated)}"
        decision = UnitDecision(u, "given", _size(vertices), detail)
    elif stated is not None:
        u = unit_name(stated)
        size = _size(vertices)
        detail = f"{_LONG[u]}, stated by the file format"
        doubtful = not _head_sized(size * UNITS[u])
        if doubtful:
            guess = infer_units(vertices)
            detail += (
                f"; the mesh is not head-sized in {u} (longest side {_metres(size * UNITS[u])})"
            )
            if guess.how in ("inferred", "ambiguous") and guess.unit != u:
                detail += f": if the exporter wrote {_LONG[guess.unit]}, pass units={guess.unit!r}"
        decision = UnitDecision(u, "file", size, detail, doubtful)
    else:
        decision = infer_units(vertices)
    level = logging.WARNING if decision.doubtful else logging.INFO
    log.log(level, "%sunits: %s", f"{source}: " if source else "", decision.detail)
    return decision
