"""Mapping file column / target names to a model's shapes.

Column names are matched to the model's shapes exactly first, then by ARKit
meaning (:func:`workbench.arkit.canonical_arkit_name`, so ``EyeBlinkLeft``,
``eyeBlink_L`` and ``eyeBlinkLeft`` agree). Live Link Face and plain CSV
columns reach any rig
(:func:`map_columns_to_rig`, :func:`workbench.arkit.rig_weights`): an ARKit
column drives the rig's shape of that meaning in any spelling, *both* halves
of a split shape (``BrowInnerUp`` → ``browInnerUp_L`` and ``browInnerUp_R``)
and, for a rig with one shape for a left/right pair (``mouthSmile``), the
mean of the pair. An ARKit column the rig has no shape for is skipped when it
is 0 in every row (nothing is lost) and is an error otherwise, like a column
that means nothing to the rig (``on_unknown="ignore"`` skips both).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from workbench.animation.importers.errors import AnimationImportError
from workbench.arkit import canonical_arkit_name, rig_weights

__all__ = ["map_columns_to_rig", "map_shape_names"]


def map_shape_names(
    columns: Sequence[str], shape_names: Sequence[str], source: str | Path = "<columns>"
) -> dict[str, str | None]:
    """Map file column/target names to model shape names.

    Exact matches win; otherwise two names match if they have the same
    canonical ARKit name. Returns ``{column: shape or None}``.

    Raises
    ------
    AnimationImportError
        If two columns map to the same shape.
    """
    by_arkit: dict[str, str] = {}
    for s in shape_names:
        c = canonical_arkit_name(s)
        if c is not None:
            by_arkit.setdefault(c, s)
    exact = set(shape_names)
    out: dict[str, str | None] = {}
    used: dict[str, str] = {}
    for col in columns:
        target: str | None = None
        if col in exact:
            target = col
        else:
            c = canonical_arkit_name(col)
            if c is not None:
                target = by_arkit.get(c)
        if target is not None:
            if target in used:
                raise AnimationImportError(
                    source, f"columns {used[target]!r} and {col!r} both map to shape {target!r}"
                )
            used[target] = col
        out[col] = target
    return out


def map_columns_to_rig(
    columns: Sequence[str], shape_names: Sequence[str], source: str | Path = "<columns>"
) -> tuple[list[tuple[int, str, float]], list[int], list[int]]:
    """How file columns drive the shapes of any rig (see the module docstring).

    A column named exactly like a shape drives it; any other column with an
    ARKit meaning is put on the rig by :func:`workbench.arkit.rig_weights`
    (other spellings, split halves, one shape for a left/right pair).

    Parameters
    ----------
    columns : sequence of str
        Column names (empty names are skipped).
    shape_names : sequence of str
        The rig's shapes.

    Returns
    -------
    drives : list of (int, str, float)
        ``(column index, shape, coefficient)``: the shape's weight is the sum
        of coefficient x column over its entries (1 per column, except 0.5 for
        each side of a left/right pair driving one unsided shape).
    missing : list of int
        Columns with an ARKit meaning the rig has no shape for.
    unknown : list of int
        Columns with no shape of that name and no ARKit meaning.

    Raises
    ------
    AnimationImportError
        Two columns with the same ARKit meaning, or a column aimed at a shape
        another column names exactly.
    """
    exact = set(shape_names)
    drives: list[tuple[int, str, float]] = []
    missing: list[int] = []
    unknown: list[int] = []
    by_exact: dict[str, str] = {}
    by_meaning: dict[str, str] = {}
    arkit_cols: list[tuple[int, str]] = []
    for i, col in enumerate(columns):
        if not col.strip():
            continue
        if col in exact:
            by_exact[col] = col
            drives.append((i, col, 1.0))
            continue
        c = canonical_arkit_name(col)
        if c is None:
            unknown.append(i)
            continue
        if c in by_meaning:
            raise AnimationImportError(
                source, f"columns {by_meaning[c]!r} and {col!r} both mean ARKit shape {c!r}"
            )
        by_meaning[c] = col
        arkit_cols.append((i, c))
    for i, c in arkit_cols:
        on_rig, _ = rig_weights({c: 1.0}, shape_names)
        if not on_rig:
            missing.append(i)
            continue
        for shape, coef in on_rig.items():
            if shape in by_exact:
                raise AnimationImportError(
                    source, f"columns {by_exact[shape]!r} and {columns[i]!r} both map to shape {shape!r}"
                )
            drives.append((i, shape, float(coef)))
    return drives, missing, unknown


def _resolve_columns(
    columns: Sequence[str],
    shape_names: Sequence[str],
    src: str,
    on_unknown: str,
    skip: Iterable[str] = (),
) -> list[tuple[int, str]]:
    """(column index, shape name) pairs; unknown columns raise unless ``on_unknown="ignore"``."""
    skip_l = {s.lower() for s in skip}
    mapping = map_shape_names(columns, shape_names, src)
    out: list[tuple[int, str]] = []
    unknown: list[str] = []
    for i, col in enumerate(columns):
        if col.strip().lower() in skip_l or not col.strip():
            continue
        target = mapping[col]
        if target is None:
            unknown.append(col)
        else:
            out.append((i, target))
    if unknown and on_unknown != "ignore":
        raise AnimationImportError(
            src,
            f"unknown shape names in columns {unknown[:10]}{'...' if len(unknown) > 10 else ''} "
            f"(the model has no shape of that name or ARKit meaning; pass on_unknown='ignore' "
            f"to skip them)",
        )
    if not out:
        raise AnimationImportError(src, "no column matches a shape of the model")
    return out
