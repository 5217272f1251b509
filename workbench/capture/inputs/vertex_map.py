"""Marker → vertex maps: :func:`read_vertex_map`.

:func:`read_vertex_map` reads ``marker,vertex`` CSV, a JSON object
``{"marker": vertex}`` (or a list of ``{"marker": .., "vertex": ..}``), a dict,
or an (m,) integer array, and returns the (m,) vertex of every marker in the
sequence's order.
"""

from __future__ import annotations

import json
import logging
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.capture.inputs.csv_text import _blank, _csv_rows, _trim
from workbench.capture.inputs.errors import CaptureInputError
from workbench.capture.inputs.markers import _check_names
from workbench.io.markers import MarkerSequence

__all__ = ["read_vertex_map"]

log = logging.getLogger("workbench.capture")


def _as_int(v: Any) -> int | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, str):
        s = v.strip()
        if re.fullmatch(r"[+-]?\d+", s):
            return int(s)
    return None


def _map_from_csv(p: Path) -> tuple[dict[str, int], dict[str, str]]:
    src = str(p)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CaptureInputError(src, f"not UTF-8 text (byte {exc.start})", field="file") from None
    rows = _csv_rows(text)
    out: dict[str, int] = {}
    where: dict[str, str] = {}
    header_seen = False
    cols = ("marker", "vertex")
    for i, r in enumerate(rows):
        if _blank(r):
            continue
        r = _trim(r)
        if len(r) != 2:
            raise CaptureInputError(
                src, f"expected 2 fields (marker, vertex), got {len(r)}", line=i + 1
            )
        name, vtxt = r[0].strip(), r[1].strip()
        if not header_seen and not out and _as_int(vtxt) is None:
            header_seen = True  # a header row such as "marker,vertex"
            cols = (name or "marker", vtxt or "vertex")
            continue
        if not name:
            raise CaptureInputError(src, "empty marker name", line=i + 1, column=cols[0])
        v = _as_int(vtxt)
        if v is None:
            raise CaptureInputError(
                src, f"{vtxt!r:.30} is not a whole vertex index", line=i + 1, column=cols[1]
            )
        if name in out:
            raise CaptureInputError(
                src,
                f"marker {name!r} is mapped twice (also {where[name]})",
                line=i + 1,
                column=cols[0],
            )
        out[name] = v
        where[name] = f"line {i + 1}"
    return out, where


def _map_from_json(p: Path) -> tuple[dict[str, int], dict[str, str]]:
    src = str(p)
    try:
        obj = json.loads(p.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise CaptureInputError(src, f"not UTF-8 text (byte {exc.start})", field="file") from None
    except json.JSONDecodeError as exc:
        raise CaptureInputError(src, f"not JSON: {exc.msg}", line=exc.lineno) from None
    return _map_from_obj(src, obj)


def _map_from_obj(src: str, obj: Any) -> tuple[dict[str, int], dict[str, str]]:
    out: dict[str, int] = {}
    where: dict[str, str] = {}
    if isinstance(obj, Mapping):
        items = [(str(k), v, f"key {str(k)!r}") for k, v in obj.items()]
    elif isinstance(obj, list):
        items = []
        for i, e in enumerate(obj):
            if not (isinstance(e, Mapping) and "marker" in e and "vertex" in e):
                raise CaptureInputError(
                    src, 'expected an object {"marker": name, "vertex": index}', field=f"entry {i}"
                )
            items.append((str(e["marker"]), e["vertex"], f"entry {i}"))
    else:
        raise CaptureInputError(
            src,
            f"expected an object {{marker: vertex}} or a list of {{marker, vertex}}, got {type(obj).__name__}",
            field="file",
        )
    for name, v, label in items:
        iv = _as_int(v) if not isinstance(v, str) else None
        if iv is None:
            raise CaptureInputError(src, f"vertex {v!r:.30} is not a whole number", field=label)
        if name in out:
            raise CaptureInputError(
                src, f"marker {name!r} is mapped twice (also {where[name]})", field=label
            )
        out[name] = iv
        where[name] = label
    return out, where


def read_vertex_map(
    source: str | Path | Mapping[str, int] | ArrayLike,
    marker_names: Sequence[str] | MarkerSequence,
    n_vertices: int,
    *,
    allow_extra: bool = False,
) -> NDArray[np.int64]:
    """The vertex each marker sits on, in the order of ``marker_names``.

    Parameters
    ----------
    source : str, Path, mapping or (m,) array_like of int
        A ``.csv`` file of ``marker,vertex`` rows (an optional header row; ``#``
        comments), a ``.json`` file holding ``{"marker": vertex, ...}`` or
        ``[{"marker": .., "vertex": ..}, ...]``, a dict, or the (m,) vertex
        indices already in marker order.
    marker_names : sequence of str or MarkerSequence
        The markers, e.g. ``MarkerSequence.names``.
    n_vertices : int
        Number of vertices of the model (valid indices are 0 .. n_vertices-1).
    allow_extra : bool
        Accept map entries for markers the sequence does not have (ignored).

    Returns
    -------
    (m,) int64
        ``ids[j]`` is the vertex of ``marker_names[j]``.

    Raises
    ------
    CaptureInputError
        Naming the file (or ``<mapping>``), the line or key: names the sequence
        does not have (unless ``allow_extra``), markers with no vertex, an index
        that is not a whole number or not in ``[0, n_vertices)``, a marker mapped
        twice, repeated marker names.
    """
    names = list(marker_names.names if isinstance(marker_names, MarkerSequence) else marker_names)
    n_vertices = int(n_vertices)
    where: dict[str, str]
    if isinstance(source, (str, Path)):
        p = Path(source)
        src = str(p)
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no such file")
        suf = p.suffix.lower()
        if suf in (".csv", ".txt"):
            mapping, where = _map_from_csv(p)
        elif suf == ".json":
            mapping, where = _map_from_json(p)
        else:
            raise CaptureInputError(
                src, f"unknown map file type {p.suffix!r}; expected .csv or .json", field="file"
            )
    elif isinstance(source, Mapping):
        src = "<mapping>"
        mapping, where = _map_from_obj(src, source)
    else:
        src = "<array>"
        a = np.asarray(source)
        if a.ndim != 1 or a.shape[0] != len(names) or (a.size and a.dtype.kind not in "iu"):
            raise CaptureInputError(
                src,
                f"expected ({len(names)},) integer vertex indices, got {a.dtype} {a.shape}",
                field="vertex_ids",
            )
        mapping = {n: int(v) for n, v in zip(names, a, strict=True)}
        where = {n: f"entry {j}" for j, n in enumerate(names)}
    _check_names(src, [str(n) for n in names])
    extra = [k for k in mapping if k not in set(names)]
    if extra and not allow_extra:
        raise CaptureInputError(
            src,
            f"{len(extra)} mapped name(s) are not markers of the sequence: {extra[:8]}"
            f"{'...' if len(extra) > 8 else ''} (markers: {names[:8]}{'...' if len(names) > 8 else ''}; "
            f"pass allow_extra=True to ignore them)",
            field=where[extra[0]],
        )
    missing = [n for n in names if n not in mapping]
    if missing:
        raise CaptureInputError(
            src,
            f"{len(missing)} marker(s) have no vertex: {missing[:8]}{'...' if len(missing) > 8 else ''}",
            field="markers",
        )
    ids = np.array([mapping[n] for n in names], np.int64)
    bad = np.flatnonzero((ids < 0) | (ids >= n_vertices))
    if bad.size:
        j = int(bad[0])
        raise CaptureInputError(
            src,
            f"marker {names[j]!r}: vertex {int(ids[j])} is out of range; the model has "
            f"{n_vertices} vertices (0..{n_vertices - 1})",
            field=where[names[j]],
        )
    if len(set(ids.tolist())) != len(ids):
        log.info("%s: several markers share a vertex", Path(src).name)
    return ids
