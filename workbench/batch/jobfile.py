"""The batch job file: characters × takes × steps in TOML, checked before anything runs.

A job file (read with the standard library's :mod:`tomllib`) looks like::

    output = "out"                 # folder for the results, relative to the job file

    [[characters]]
    name = "head"                  # the folder name under output/
    rig = "head.fwb"               # a .fwb or anything workbench.load reads
    vertex_map = "markers.json"    # optional: marker -> vertex map for `track`
    units = "cm"                   # optional: the rig's length unit (as `workbench rig --units`)

    [[takes]]
    name = "take1"                 # the file name stem of the outputs
    path = "take1.csv"             # an animation (weights CSV, Live Link, glTF, FBX, USD, Alembic)
                                   # or, with a `track` step, markers (C3D, marker CSV, NPY/NPZ)
    vertex_map = "take1_map.json"  # optional: this take's marker map (wins over the character's)
    fps = 30                       # optional: the take's frame rate (wins over the file's)
    units = "mm"                   # optional: the markers' unit (wins over the file's)

    [[steps]]
    kind = "export"
    formats = ["glb", "usdc"]

:data:`STEP_FIELDS` lists every step kind and its fields. Every problem —
a TOML syntax error, an unknown table or field, a value of the wrong type,
a file that does not exist — raises :class:`JobFileError` naming the file,
the line and the field, e.g. ``jobs.toml line 9: [[steps]] kind = "exprot":
expected one of track, transfer_rig, retime, enhance, clone, export``. Paths are resolved against the job
file's folder.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = [
    "STEP_FIELDS",
    "Character",
    "JobFile",
    "JobFileError",
    "Step",
    "Take",
    "load_jobs",
    "parse_jobs",
]


class JobFileError(ValueError):
    """A malformed job file; the message names the file, the line and the field."""


#: per step kind: field -> (accepted Python types, required, what it means)
STEP_FIELDS: dict[str, dict[str, tuple[tuple[type, ...], bool, str]]] = {
    "track": {
        "l1": ((int, float), False, "sparsity λ of the tracker"),
        "temporal": ((int, float), False, "temporal smoothness λ of the tracker"),
        "adapt": ((bool,), False, "adapt the rig to the actor"),
        "tolerance": ((int, float), False, "key reduction tolerance when keying the result"),
    },
    "transfer_rig": {
        "template": ((str,), False, "the template rig: a file or a bundled sample name (default head)"),
        "landmarks": ((str,), False, "CSV of template_vertex,target_vertex pairs"),
    },
    "retime": {
        "t0": ((int, float), True, "start of the transition, seconds"),
        "t1": ((int, float), True, "end of the transition, seconds"),
        "database": ((list,), True, "performance takes whose timing is matched"),
        "n_frames": ((int,), False, "in-betweens including both ends"),
        "extend": ((bool,), False, "let the match extend beyond the key pair"),
        "method": ((str,), False, "where the timing comes from: auto, closest or take"),
    },
    "enhance": {
        "database": ((str,), True, "a saved PerformanceDatabase (.npz)"),
    },
    "clone": {
        "onto": ((str,), True, "the face to play the take on (any topology and units; expression cloning)"),
        "landmarks": ((str,), False, "CSV of character_vertex,target_vertex pairs"),
    },
    "export": {
        "formats": ((list,), True, "file suffixes: glb, gltf, usdc, usda, usd, fbx, abc, pc2, mdd, csv, obj"),
        "fps": ((int, float), False, "frame rate of baked/per-frame formats"),
        "bake": ((bool,), False, "per-frame values instead of keys / blend shapes"),
        "style": ((str,), False, "CSV layout: plain or livelink"),
    },
}

_CHARACTER_FIELDS: dict[str, tuple[tuple[type, ...], bool]] = {
    "name": ((str,), True), "rig": ((str,), True), "vertex_map": ((str,), False), "units": ((str,), False),
}
_TAKE_FIELDS: dict[str, tuple[tuple[type, ...], bool]] = {
    "name": ((str,), True), "path": ((str,), True), "vertex_map": ((str,), False),
    "fps": ((int, float), False), "units": ((str,), False),
}
_TOP_FIELDS = ("output", "characters", "takes", "steps")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_EXPORT_SUFFIXES = ("glb", "gltf", "usdc", "usda", "usd", "fbx", "abc", "pc2", "mdd", "csv", "obj")


@dataclass(frozen=True)
class Character:
    """A rig to animate: ``name`` (its output folder), ``rig`` (absolute path), optional marker map."""

    name: str
    rig: Path
    vertex_map: Path | None = None
    units: str | None = None


@dataclass(frozen=True)
class Take:
    """A performance: ``name`` (output stem), ``path`` (absolute), optional marker map, fps, units."""

    name: str
    path: Path
    vertex_map: Path | None = None
    fps: float | None = None
    units: str | None = None


@dataclass(frozen=True)
class Step:
    """One step applied to every (character, take): ``kind`` and its options (paths made absolute)."""

    kind: str
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class JobFile:
    """A checked job file: every (character, take) pair runs ``steps`` in order."""

    source: Path
    output: Path
    characters: tuple[Character, ...]
    takes: tuple[Take, ...]
    steps: tuple[Step, ...]

    @property
    def n_tasks(self) -> int:
        """(character, take, step) tasks: one Dask task each."""
        return len(self.characters) * len(self.takes) * len(self.steps)


class _Locator:
    """Line numbers of tables and keys in the TOML text (tomllib keeps none)."""

    def __init__(self, text: str) -> None:
        self.lines = text.splitlines()
        self.headers: list[tuple[int, str]] = []  # (0-based line, "[[steps]]" / "[x]")
        for i, line in enumerate(self.lines):
            s = line.strip()
            if s.startswith("["):
                self.headers.append((i, s.split("#", 1)[0].strip()))

    def _block(self, table: str | None, index: int) -> tuple[int, int] | None:
        if table is None:
            return 0, self.headers[0][0] if self.headers else len(self.lines)
        found = [k for k, (_, h) in enumerate(self.headers) if h.replace(" ", "") == f"[[{table}]]"]
        if index >= len(found):
            return None
        k = found[index]
        end = self.headers[k + 1][0] if k + 1 < len(self.headers) else len(self.lines)
        return self.headers[k][0], end

    def line_of(self, table: str | None, index: int, key: str | None) -> tuple[int, str]:
        """1-based line and the ``key = value`` text as written (or the header line)."""
        block = self._block(table, index)
        if block is None:  # inline array of tables: point at "table ="
            for i, line in enumerate(self.lines):
                if re.match(rf"\s*{re.escape(table or '')}\s*=", line):
                    return i + 1, line.strip()
            return 1, ""
        a, b = block
        if key is not None:
            for i in range(a, b):
                if re.match(rf"\s*\"?{re.escape(key)}\"?\s*=", self.lines[i]):
                    return i + 1, self.lines[i].split("#", 1)[0].strip()
        return a + 1, self.lines[a].strip() if a < len(self.lines) else ""


class _Checker:
    def __init__(self, source: Path, text: str) -> None:
        self.source, self.where = source, _Locator(text)
        self.base = source.parent

    def fail(self, table: str | None, index: int, key: str | None, problem: str) -> JobFileError:
        line, written = self.where.line_of(table, index, key)
        prefix = f"[[{table}]] " if table else ""
        if key is not None and written and not written.startswith("["):
            what = f"{prefix}{written}"
        elif key is not None:
            what = f"{prefix}{key}"
        else:
            what = prefix.strip() or "top level"
        return JobFileError(f"{self.source.name} line {line}: {what}: {problem}")

    def fields(self, table: str | None, index: int, data: dict[str, Any],
               spec: dict[str, tuple[tuple[type, ...], bool]]) -> None:
        for key, value in data.items():
            if key not in spec:
                raise self.fail(table, index, key, f"unknown field {key!r}; expected one of {', '.join(spec)}")
            types = spec[key][0]
            ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
            if not ok:
                want = " or ".join(_type_name(t) for t in types)
                raise self.fail(table, index, key, f"expected {want}, got {_type_name(type(value))}")
        for key, (_, required) in spec.items():
            if required and key not in data:
                raise self.fail(table, index, None, f"missing field {key!r}")

    def existing(self, table: str, index: int, key: str, value: str) -> Path:
        p = Path(value).expanduser()
        p = p if p.is_absolute() else self.base / p
        if not p.exists():
            raise self.fail(table, index, key, f"no such file {p}")
        return p.resolve()

    def name(self, table: str, index: int, value: str, seen: set[str]) -> str:
        if not _NAME.match(value):
            raise self.fail(table, index, "name", "names are letters, digits, '_', '.', '-' (a folder/file name)")
        if value in seen:
            raise self.fail(table, index, "name", f"{value!r} is used twice")
        seen.add(value)
        return value


def _type_name(t: type) -> str:
    return {str: "a string", int: "an integer", float: "a number", bool: "true/false", list: "an array",
            dict: "a table"}.get(t, t.__name__)


def _tables(c: _Checker, data: dict[str, Any], key: str) -> list[dict[str, Any]]:
    items = data.get(key)
    if not isinstance(items, list) or not items or not all(isinstance(x, dict) for x in items):
        raise c.fail(None, 0, key if key in data else None,
                     f"needs at least one [[{key}]] table" if key not in data else f"expected [[{key}]] tables")
    return items


def _step(c: _Checker, i: int, raw: dict[str, Any], suffixes_seen: set[str]) -> Step:
    kind = raw.get("kind")
    if not isinstance(kind, str) or kind not in STEP_FIELDS:
        raise c.fail("steps", i, "kind" if "kind" in raw else None,
                     f"expected one of {', '.join(STEP_FIELDS)}" if "kind" in raw else "missing field 'kind'")
    spec = {k: (types, req) for k, (types, req, _) in STEP_FIELDS[kind].items()}
    spec["kind"] = ((str,), True)
    c.fields("steps", i, raw, spec)
    options = {k: v for k, v in raw.items() if k != "kind"}
    if kind == "export":
        formats = options["formats"]
        if not formats or not all(isinstance(f, str) for f in formats):
            raise c.fail("steps", i, "formats", "expected a non-empty array of strings")
        for f in formats:
            s = f.lower().lstrip(".")
            if s not in _EXPORT_SUFFIXES:
                raise c.fail("steps", i, "formats", f"unknown format {f!r}; expected some of {', '.join(_EXPORT_SUFFIXES)}")
            if s in suffixes_seen:
                raise c.fail("steps", i, "formats", f"{f!r} is exported twice (the outputs would collide)")
            suffixes_seen.add(s)
        options["formats"] = [f.lower().lstrip(".") for f in formats]
        if options.get("style") not in (None, "plain", "livelink"):
            raise c.fail("steps", i, "style", "expected plain or livelink")
    elif kind == "retime":
        db = options["database"]
        if not db or not all(isinstance(x, str) for x in db):
            raise c.fail("steps", i, "database", "expected a non-empty array of take files")
        options["database"] = [str(c.existing("steps", i, "database", x)) for x in db]
        if not options["t1"] > options["t0"]:
            raise c.fail("steps", i, "t1", f"must be greater than t0 = {options['t0']}")
        if options.get("method", "auto") not in ("auto", "closest", "take"):
            raise c.fail("steps", i, "method", f"expected auto, closest or take, got {options['method']!r}")
    elif kind == "enhance":
        options["database"] = str(c.existing("steps", i, "database", options["database"]))
    elif kind == "clone":
        options["onto"] = str(c.existing("steps", i, "onto", options["onto"]))
        if "landmarks" in options:
            options["landmarks"] = str(c.existing("steps", i, "landmarks", options["landmarks"]))
    elif kind == "transfer_rig":
        template = options.get("template", "head")
        looks_like_file = any(ch in template for ch in "/\\.")
        # a path, or a bundled sample's name (checked when it loads)
        options["template"] = str(c.existing("steps", i, "template", template)) if looks_like_file else template
        if "landmarks" in options:
            options["landmarks"] = str(c.existing("steps", i, "landmarks", options["landmarks"]))
    return Step(kind, options)


def parse_jobs(text: str, source: str | Path = "jobs.toml") -> JobFile:
    """Check the TOML ``text`` of a job file (paths relative to ``source``'s folder).

    Raises
    ------
    JobFileError
        Naming the line and the field of the first problem.
    """
    src = Path(source).absolute()
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = re.search(r"at line (\d+)", msg)
        line = m.group(1) if m else "?"
        raise JobFileError(f"{src.name} line {line}: TOML syntax error: {re.sub(r' ?[(]at line.*[)]', '', msg)}") from None
    c = _Checker(src, text)
    for key in data:
        if key not in _TOP_FIELDS:
            raise c.fail(None, 0, key, f"unknown field {key!r}; expected one of {', '.join(_TOP_FIELDS)}")
    if not isinstance(data.get("output"), str):
        raise c.fail(None, 0, "output" if "output" in data else None,
                     "expected a string (the output folder)" if "output" in data else "missing field 'output'")
    out = Path(data["output"]).expanduser()
    out = (out if out.is_absolute() else c.base / out).resolve()
    characters, names = [], set[str]()
    for i, raw in enumerate(_tables(c, data, "characters")):
        c.fields("characters", i, raw, _CHARACTER_FIELDS)
        vmap = raw.get("vertex_map")
        characters.append(Character(
            c.name("characters", i, raw["name"], names), c.existing("characters", i, "rig", raw["rig"]),
            None if vmap is None else c.existing("characters", i, "vertex_map", vmap), raw.get("units")))
    takes, names = [], set[str]()
    for i, raw in enumerate(_tables(c, data, "takes")):
        c.fields("takes", i, raw, _TAKE_FIELDS)
        vmap = raw.get("vertex_map")
        fps = raw.get("fps")
        if fps is not None and not fps > 0:
            raise c.fail("takes", i, "fps", "must be positive")
        takes.append(Take(
            c.name("takes", i, raw["name"], names), c.existing("takes", i, "path", raw["path"]),
            None if vmap is None else c.existing("takes", i, "vertex_map", vmap),
            None if fps is None else float(fps), raw.get("units")))
    suffixes: set[str] = set()
    steps = [_step(c, i, raw, suffixes) for i, raw in enumerate(_tables(c, data, "steps"))]
    kinds = [s.kind for s in steps]
    if "track" in kinds:
        i = kinds.index("track")
        if kinds.count("track") > 1:
            raise c.fail("steps", kinds.index("track", i + 1), "kind", "track can run once per take")
        before = [k for k in kinds[:i] if k != "transfer_rig"]
        if before:
            raise c.fail("steps", i, "kind", f"track must come before {before[0]} (it creates the animation)")
        for j, t in enumerate(takes):
            if t.vertex_map is None and any(ch.vertex_map is None for ch in characters):
                raise c.fail("takes", j, None, "a track step needs a vertex_map (marker -> vertex) on the take "
                             "or on every character")
    return JobFile(src, out, tuple(characters), tuple(takes), tuple(steps))


def load_jobs(path: str | os.PathLike[str]) -> JobFile:
    """Read and check a job file; see :func:`parse_jobs`."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise JobFileError(f"{p}: cannot read the job file: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise JobFileError(f"{p.name}: not UTF-8 text ({exc.reason})") from None
    return parse_jobs(text, p)
