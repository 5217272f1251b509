"""Unique names for the shapes and expressions a panel creates (bake, save as)."""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["next_free_name"]


def next_free_name(name: str, taken: Iterable[str]) -> str:
    """``name`` if it is free, else the first free ``stem_k`` counting on from its number.

    ``sculpt_1`` with ``sculpt_1`` taken gives ``sculpt_2``; ``bump`` with
    ``bump`` taken gives ``bump_1``; a trailing ``_0`` counts from 1.
    """
    used = set(taken)
    stem, _, num = name.rpartition("_")
    if not stem or not num.isdigit():
        stem, num = name, "0"
    k = max(int(num), 1)
    cand = name if name not in used else f"{stem}_{k}"
    while cand in used:
        k += 1
        cand = f"{stem}_{k}"
    return cand
