"""Split a symmetric shape into left and right halves that sum to it exactly.

With ``x`` the signed distance from the mirror plane toward the subject's
left (:meth:`workbench.methods.shapes.symmetry.Symmetry.lateral`) and a band
of width ``falloff`` (model units) centred on the plane, the left half's
share is the smoothstep

    f_L(x) = s(x / falloff + 1/2),   s(u) = 3u² − 2u³ on [0, 1] (0 below, 1 above),

and the right half's ``f_R = 1 − f_L``: the left half is exactly zero beyond
the band on the right, the right half beyond it on the left, and the two
blend smoothly (C¹) across it. ``falloff = 0`` is a hard cut (each vertex
on the plane gets half and half).

Exact sum
---------
``δ_L + δ_R == δ`` holds bit for bit in float32 (what the model stores): per
component, the half with the larger share is rounded, ``h = fl(f δ)`` with
``f ≥ 1/2`` so ``δ/2 ≤ h ≤ δ``, and the other half is ``δ − h``, which is
exact by Sterbenz's lemma; their float32 sum is then ``δ`` itself.

Names
-----
Halves are named so that :func:`workbench.arkit.canonical_arkit_name` and
:func:`workbench.arkit.split_half_of` read them as what they are: a shape
standing for an ARKit left/right pair gets Apple's spelling
(``mouthSmile`` → ``mouthSmileLeft`` / ``mouthSmileRight``); any other name,
ARKit's unsided shapes included, gets the rig convention ``_L`` / ``_R``
(``browInnerUp`` → ``browInnerUp_L`` / ``browInnerUp_R``, read as the halves of
``browInnerUp``; ``jawOpen`` → ``jawOpen_L``). Split pairs sum to their whole,
which is how :func:`workbench.arkit.rig_weights` plays ARKit weights on them.
"""

from __future__ import annotations

import re

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.arkit import canonical_arkit_name
from workbench.core.shapes import ModelError

__all__ = ["DEFAULT_FALLOFF_FRACTION", "side_weights", "split_delta", "split_names"]

#: default band width as a fraction of the head's width (the skin's left/right extent)
DEFAULT_FALLOFF_FRACTION = 0.05


def side_weights(lateral: ArrayLike, falloff: float) -> NDArray[np.float64]:
    """(n,) float64 share ``f_L`` of the left half, from signed distances toward the left."""
    x = np.asarray(lateral, dtype=np.float64).reshape(-1)
    f = float(falloff)
    if not (np.isfinite(f) and f >= 0.0):
        raise ModelError(f"split: falloff must be a finite width >= 0 (model units), got {falloff!r}")
    if f == 0.0:
        return np.where(x > 0, 1.0, np.where(x < 0, 0.0, 0.5))
    u = np.clip(x / f + 0.5, 0.0, 1.0)
    out: NDArray[np.float64] = u * u * (3.0 - 2.0 * u)
    return out


def split_delta(delta: ArrayLike, f_left: ArrayLike) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``(δ_L, δ_R)`` float32 with ``δ_L + δ_R == δ`` exactly (module docstring)."""
    D = np.asarray(delta, dtype=np.float32)
    f = np.asarray(f_left, dtype=np.float64).reshape(-1)
    if D.ndim != 2 or D.shape[1] != 3 or f.shape != (D.shape[0],):
        raise ModelError(f"split: need an (n, 3) delta and (n,) shares, got {D.shape} and {f.shape}")
    left_major = (f >= 0.5)[:, None]
    share = np.where(f >= 0.5, f, 1.0 - f).astype(np.float32)[:, None]  # >= 1/2 in float32 too
    major = D * share
    minor = D - major  # exact (Sterbenz): D/2 <= major <= D
    dL = np.where(left_major, major, minor).astype(np.float32)
    dR = np.where(left_major, minor, major).astype(np.float32)
    return dL, dR


_SEPARATORS = re.compile(r"[_\-.:| ]")


def split_names(name: str) -> tuple[str, str]:
    """Default ``(left, right)`` names of the halves of ``name`` (module docstring)."""
    if not isinstance(name, str) or not name.strip():
        raise ModelError(f"split: shape name must be a non-empty string, got {name!r}")
    if not _SEPARATORS.search(name):
        left = canonical_arkit_name(name + "Left")
        if left is not None and left.endswith("Left") and left.lower() == (name + "Left").lower():
            return name + "Left", name + "Right"
    return f"{name}_L", f"{name}_R"
