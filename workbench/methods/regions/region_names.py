"""Names of blend regions: from the ARKit groups of the shapes moving them, their side, and the rigid parts' roles.

Step 6 of :mod:`workbench.methods.regions.segmentation`: a skin region is named
after the shape groups with most motion energy in it (``"mouth"``,
``"brow_eye"``) and its side of the mid-plane (``_L`` / ``_R``, none when it
spans it); a rigid part after its role (``"eyeball_L"``, ``"teeth_upper"``);
repeated names are numbered from the top of the face down.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from workbench.arkit import canonical_arkit_name
from workbench.geometry.parts import role_side

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel

__all__ = ["region_stem", "rigid_name", "side_sign", "unique_names"]

#: ARKit shape group -> region stem (eye *lids* on the skin; eyeballs are their own components)
_STEM = {
    "brows": "brow",
    "eyes": "eye",
    "cheeks": "cheek",
    "nose": "nose",
    "mouth": "mouth",
    "jaw": "jaw",
    "tongue": "tongue",
    "other": "region",
}


def side_sign(model: FaceModel, skin: NDArray[np.bool_], mid: float) -> float:
    """+1 if the subject's left is +x (from shapes named ...Left), else -1."""
    V = model.vertices
    score = 0.0
    for s in model.shapes:
        c = canonical_arkit_name(s.name) or s.name
        side = 1.0 if c.endswith("Left") else -1.0 if c.endswith("Right") else 0.0
        if side == 0.0:
            continue
        mag = np.linalg.norm(s.delta, axis=1) * skin
        if mag.sum() > 0:
            score += side * float((mag * (V[:, 0] - mid)).sum() / mag.sum())
    return 1.0 if score >= 0 else -1.0


def unique_names(names: list[str], order: Sequence[float] | None = None) -> tuple[str, ...]:
    """Number repeated names ``_1, _2, ...`` in ascending ``order`` (default: position)."""
    keys = list(order) if order is not None else list(range(len(names)))
    keys += [float("inf")] * (len(names) - len(keys))
    out = list(names)
    for nm in set(names):
        idx = [i for i, x in enumerate(names) if x == nm]
        if len(idx) > 1:
            for c, i in enumerate(sorted(idx, key=lambda i: (keys[i], i)), start=1):
                out[i] = f"{nm}_{c}"
    return tuple(out)


def region_stem(energy: NDArray[np.float64], groups: Sequence[str]) -> str:
    """Name stem from the ARKit groups with most motion energy ("mouth", "brow_eye").

    The second group joins the name when it has at least 60 % of the first's energy.
    """
    tot: dict[str, float] = {}
    for e, g in zip(energy, groups, strict=True):
        tot[g] = tot.get(g, 0.0) + float(e)
    ranked = sorted(tot.items(), key=lambda kv: -kv[1])
    stems = [_STEM.get(ranked[0][0], "region")]
    if len(ranked) > 1 and ranked[1][1] >= 0.6 * ranked[0][1] > 0:
        stems.append(_STEM.get(ranked[1][0], "region"))
    return "_".join(stems)


def rigid_name(component: str, role: str) -> str:
    """Region name of a rigid part: from its role ("eyeball_L", "teeth_upper", "tongue")."""
    if role.startswith("eyeball"):
        side = role_side(role)
        if not side:  # both eyes in one component, or a side only the name tells
            c = component.lower()
            side = "_L" if re.search(r"left|(^|_)l($|_)", c) else "_R" if re.search(r"right|(^|_)r($|_)", c) else ""
        return "eyeball" + (side or "s")
    return role
