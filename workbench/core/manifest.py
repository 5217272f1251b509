"""Checked reading of the ``.fwb`` manifest: typed JSON reads whose errors name the JSON path.

Shared by :mod:`workbench.fileformat` (the container) and every method
family's file part (:class:`workbench.core.families.FilePart`), so that a bad
field in any part of the file fails the same way: ``"<file>: <JSON path>:
expected <what>, got <value>"``, before anything is built.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

#: name -> (dtype, shape, description); a dimension is an int or a symbol bound by the first array using it
Spec = tuple[str, tuple[int | str, ...], str]


class WorkbenchFileError(ValueError):
    """A saved workbench file that cannot be loaded; the message names file and field."""

    def __init__(self, path: str | os.PathLike[str], field: str, problem: str) -> None:
        self.path = str(path)
        self.field = field
        super().__init__(f"{self.path}: {field}: {problem}")


#: Largest count or array dimension a manifest may declare (keeps all size maths exact).
_MAX_COUNT = 2**53
_REQUIRED: Any = object()
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
SHA256 = re.compile(r"[0-9a-f]{64}\Z")


def json_path(base: str, key: str) -> str:
    """JSON path of ``key`` inside the object at ``base`` (``shapes[3].mask``, ``weights["a b"]``)."""
    part = key if _IDENT.match(key) else f"[{json.dumps(key)}]"
    if not base:
        return part
    return f"{base}{part}" if part.startswith("[") else f"{base}.{part}"


def show_json(value: Any) -> str:
    """A short description of a JSON value for error messages: its JSON type and text."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        kind = "a boolean"
    elif isinstance(value, int | float):
        kind = "a number"
    elif isinstance(value, str):
        kind = "a string"
    elif isinstance(value, list):
        kind = "a list"
    elif isinstance(value, dict):
        kind = "an object"
    else:  # pragma: no cover - json.loads gives only the types above
        kind = type(value).__name__
    try:
        text = json.dumps(value)
    except (ValueError, TypeError, RecursionError):  # pragma: no cover
        return kind
    return f"{kind} {text if len(text) <= 40 else text[:37] + '...'}"


class Checker:
    """Typed reads of parsed manifest JSON; every failure names the file and the JSON path."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, field: str, problem: str) -> NoReturn:
        raise WorkbenchFileError(self.path, field, problem)

    def expect(self, field: str, what: str, got: Any) -> NoReturn:
        self.fail(field, f"expected {what}, got {show_json(got)}")

    def key(self, obj: Mapping[str, Any], base: str, key: str, default: Any = _REQUIRED) -> Any:
        if key in obj:
            return obj[key]
        if default is _REQUIRED:
            self.fail(json_path(base, key), "missing")
        return default

    def obj(self, value: Any, field: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            self.expect(field, "an object", value)
        return value

    def lst(self, value: Any, field: str, length: int | None = None, why: str = "") -> list[Any]:
        if not isinstance(value, list):
            self.expect(field, "a list", value)
        if length is not None and len(value) != length:
            self.fail(field, f"expected {length} entries{why}, got {len(value)}")
        return value

    def string(self, value: Any, field: str, nonempty: bool = False) -> str:
        if not isinstance(value, str) or (nonempty and not value.strip()):
            self.expect(field, "a non-empty string" if nonempty else "a string", value)
        return value

    def boolean(self, value: Any, field: str) -> bool:
        if not isinstance(value, bool):
            self.expect(field, "true or false", value)
        return value

    def number(self, value: Any, field: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.expect(field, "a number", value)
        try:
            x = float(value)
        except OverflowError:
            x = math.inf
        if not math.isfinite(x):
            self.expect(field, "a finite number", value)
        return x

    def integer(self, value: Any, field: str, lo: int = 0, hi: int = _MAX_COUNT) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            what = f"an integer >= {lo}" if hi == _MAX_COUNT else f"an integer in {lo}..{hi}"
            self.expect(field, what, value)
        return value

    def strings(
        self, value: Any, field: str, length: int | None = None, why: str = "",
        unique: bool = False, nonempty: bool = False,
    ) -> list[str]:
        out = [self.string(s, f"{field}[{i}]", nonempty) for i, s in enumerate(self.lst(value, field, length, why))]
        if unique and len(set(out)) != len(out):
            i = next(i for i, s in enumerate(out) if s in out[:i])
            self.fail(f"{field}[{i}]", f"duplicate name {out[i]!r}")
        return out

    def numeric(self, value: Any, field: str, depth: int = 0) -> None:
        """A number or a (nested, at most 2 deep) list of numbers (a timeline value)."""
        if isinstance(value, list) and depth < 2:
            for i, x in enumerate(value):
                self.numeric(x, f"{field}[{i}]", depth + 1)
        elif isinstance(value, bool) or not isinstance(value, int | float):
            self.expect(field, "a number or a list of numbers", value)
        else:
            self.number(value, field)

    def in_range(self, arrays: dict[str, np.ndarray], name: str, lo: int, hi: int, what: str) -> None:
        """Fail unless every value of array ``name`` (when present) is in ``lo..hi``."""
        a = arrays.get(name)
        if a is not None and a.size and (a.min() < lo or a.max() > hi):
            flat = a.reshape(-1)
            bad = int(np.flatnonzero((flat < lo) | (flat > hi))[0])
            self.fail(json_path("arrays", name), f"{what} must be in {lo}..{hi}, got {flat[bad]} at flat index {bad}")
