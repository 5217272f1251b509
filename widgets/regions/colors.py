"""Region colours: the overlay the Regions panel puts on the viewport.

:func:`region_palette` gives each region its own colour, :func:`region_colors`
the per-vertex overlay of one level (overlaps blended by the region weights,
so the one-ring seams show as gradients; the background grey), and
:class:`ColorSlots` keeps the colours of untouched regions across region
edits, so a merge or split does not repaint the whole face.
"""

from __future__ import annotations

import colorsys
from collections.abc import Iterable
from typing import Any

import numpy as np

#: Colour of vertices in no region (sRGB, [0, 1]).
BACKGROUND_GREY = (0.62, 0.62, 0.62)


def region_palette(n: int) -> np.ndarray:
    """(n, 3) float32 sRGB colours, pairwise distinct, none of them grey.

    Golden-angle hues with three saturation/value bands, so that neighbours in
    index order (often neighbours on the face) differ in hue *and* brightness.
    """
    out = np.empty((n, 3), np.float32)
    for i in range(n):
        h = (i * 0.618033988749895) % 1.0
        s = (0.75, 0.55, 0.9)[i % 3]
        v = (0.95, 0.8, 0.65)[(i // 3) % 3]
        out[i] = colorsys.hsv_to_rgb(h, s, v)
    return out


def region_colors(
    regions: Any,
    level: int,
    background: Iterable[float] = BACKGROUND_GREY,
    slots: Any = None,
) -> np.ndarray:
    """Per-vertex overlay colours of one level's regions.

    Parameters
    ----------
    regions : workbench.methods.regions.hierarchy.Regions
    level : int
    background : (3,) float
        Colour of the background (weight ``regions.background[level]``).
    slots : (R,) int, optional
        Palette entry of each region (default: its index); see :class:`ColorSlots`.

    Returns
    -------
    (n, 3) float32
        ``sum_r W_r(v) palette[r] + W_bg(v) background``: a vertex inside one
        region's core has exactly that region's colour, overlap vertices a blend.
    """
    lv = regions.check_level(level)
    R = regions.n_regions(lv)
    idx = np.arange(R) if slots is None else np.asarray(slots, np.int64).reshape(-1)
    if idx.shape != (R,):
        raise ValueError(f"region_colors: slots must have one entry per region ({R}), got {idx.shape}")
    pal = region_palette(int(idx.max()) + 1 if R else 0)[idx].astype(np.float64)
    W = regions.weight_matrix(lv)
    bg = (
        np.asarray(regions.background[lv], np.float64)[:, None]
        * np.asarray(list(background), np.float64)[None, :]
    )
    c = np.asarray(W @ pal) + bg
    return np.clip(c, 0.0, 1.0).astype(np.float32)


class ColorSlots:
    """Palette entries of regions that stay put across region edits.

    A fresh segmentation colours region ``r`` with palette entry ``r``. After
    an edit (same segmentation: the edits keep its ``deformation`` array)
    every region whose name survives keeps its colour, a renamed region keeps
    its colour, and new regions (split halves) take the lowest free entries.
    Every name ever seen keeps its entry, so undoing an edit brings the
    colours back.
    """

    def __init__(self) -> None:
        # (deformation, {level: (labels, names, {name: slot})})
        self._memory: tuple[Any, dict[int, tuple[Any, tuple[str, ...], dict[str, int]]]] | None = None

    def __call__(self, regions: Any, level: int) -> np.ndarray:
        """(R,) int64 palette entry of each region of ``level``."""
        names = tuple(regions.names[level])
        prev = self._memory
        if prev is None or prev[0] is not regions.deformation:
            prev = (regions.deformation, {})
            self._memory = prev
        per_level = prev[1]
        old = per_level.get(level)
        if old is None:
            table = {nm: i for i, nm in enumerate(names)}
        else:
            old_labels, old_names, table = old[0], old[1], dict(old[2])
            new = [nm for nm in names if nm not in table]
            gone = [nm for nm in old_names if nm not in names]
            if old_labels is regions.labels[level] and len(gone) == len(new) == 1:
                table[new[0]] = table[gone[0]]  # a rename (same labels): same colour
            used = set(table.values())
            free = (i for i in range(len(used) + len(names) + 1) if i not in used)
            for nm in names:
                if nm not in table:
                    table[nm] = next(free)
        per_level[level] = (regions.labels[level], names, table)
        slots = np.array([table[nm] for nm in names], np.int64)
        if np.unique(slots).size != slots.size:  # (two names that once shared an entry)
            slots = np.arange(len(names), dtype=np.int64)
        return slots
