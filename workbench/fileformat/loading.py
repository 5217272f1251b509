"""Loading: the zip and its manifest, every array checked, then the model built.

It reads ``.npy`` with ``allow_pickle=False``, checks declared sizes against the
member sizes, each array's sha256 and the ``.npy`` header against the manifest
before allocating, then the value ranges, and builds the model only after
everything verified (nothing half-loaded).
"""

from __future__ import annotations

import io
import json
import math
import os
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core import families
from workbench.core.manifest import Checker, WorkbenchFileError, json_path
from workbench.core.polygons import Polygons
from workbench.core.shapes import BlendShape, ModelError, ModelMetadata
from workbench.fileformat.container import (
    _MAX_MANIFEST_BYTES,
    FORMAT_NAME,
    SCHEMA_VERSION,
    _parts,
    _sha256,
)
from workbench.fileformat.schema import _MIGRATIONS, _check_manifest
from workbench.fileformat.temporaries import remove_stale_temporaries


def _read_member(zf: zipfile.ZipFile, path: Path, member: str | zipfile.ZipInfo, field: str) -> bytes:
    try:
        return zf.read(member)
    except (zipfile.BadZipFile, EOFError, OSError, RuntimeError, NotImplementedError, zlib.error) as exc:
        raise WorkbenchFileError(path, field, f"cannot read the zip member ({exc})") from None


def _read_npy(zf: zipfile.ZipFile, path: Path, name: str, entry: dict[str, Any]) -> np.ndarray:
    """One array, its entry already checked by :func:`_check_arrays`."""
    f = json_path("arrays", name)
    member = entry["file"]
    try:
        info = zf.getinfo(member)
    except KeyError:
        raise WorkbenchFileError(path, f"{f}.file", f"member {member!r} is missing") from None
    if info.file_size > 8 * 2**30:
        raise WorkbenchFileError(path, f, "member larger than 8 GiB")
    expected_shape = tuple(entry["shape"])
    dtype = np.dtype(entry["dtype"])  # one of the fixed dtype strings of _array_specs
    declared = math.prod(expected_shape) * dtype.itemsize
    if declared > info.file_size:
        raise WorkbenchFileError(
            path,
            f"{f}.shape",
            f"declares {expected_shape} ({declared} bytes) but the member holds only "
            f"{info.file_size} bytes",
        )
    data = _read_member(zf, path, info, f)
    if _sha256(data) != entry["sha256"]:
        raise WorkbenchFileError(path, f, "checksum mismatch (file corrupted or edited)")
    # read the .npy header first: np.load allocates whatever shape the header declares
    fp = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(fp)
        if version == (1, 0):
            shape, _fortran, dt = np.lib.format.read_array_header_1_0(fp)
        elif version == (2, 0):
            shape, _fortran, dt = np.lib.format.read_array_header_2_0(fp)
        else:
            raise ValueError(f"unsupported .npy version {version}")
        if shape != expected_shape or dt != dtype:
            raise WorkbenchFileError(
                path, f, f"holds {dt.str}{shape}, manifest says {dtype.str}{expected_shape}"
            )
        a = np.load(io.BytesIO(data), allow_pickle=False)
    except WorkbenchFileError:
        raise
    except (ValueError, OSError, EOFError, SyntaxError, TypeError) as exc:
        raise WorkbenchFileError(path, f, f"not a valid .npy array ({exc})") from None
    if a.shape != expected_shape or a.dtype != dtype:  # pragma: no cover - the header said so
        raise WorkbenchFileError(path, f, f"holds {a.dtype.str}{a.shape}, manifest says {dtype.str}{expected_shape}")
    return a


def _check_values(c: Checker, m: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Value ranges of the arrays (shapes and dtypes are already known to be right)."""
    n = m["mesh"]["n_vertices"]

    def in_range(name: str, lo: int, hi: int, what: str) -> None:
        a = arrays.get(name)
        if a is not None and a.size and (a.min() < lo or a.max() > hi):
            bad = int(np.flatnonzero((a.reshape(-1) < lo) | (a.reshape(-1) > hi))[0])
            c.fail(
                json_path("arrays", name),
                f"{what} must be in {lo}..{hi}, got {a.reshape(-1)[bad]} at flat index {bad}",
            )

    for name, a in arrays.items():
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            bad = int(np.flatnonzero(~np.isfinite(a.reshape(-1)))[0])
            c.fail(json_path("arrays", name), f"NaN or infinity at flat index {bad}")
    in_range("faces", 0, n - 1, "vertex ids")
    in_range("polygon_indices", 0, n - 1, "vertex ids")
    off = arrays["polygon_offsets"]
    if off[0] != 0 or off[-1] != arrays["polygon_indices"].size or np.any(np.diff(off) < 3):
        c.fail(
            "arrays.polygon_offsets",
            "offsets must start at 0, end at len(polygon_indices) and give >= 3 corners per polygon",
        )
    in_range("component_labels", 0, len(m["components"]) - 1, "labels (indices into components)")
    masks = arrays.get("masks")
    if masks is not None and masks.size and (masks.min() < 0.0 or masks.max() > 1.0):
        c.fail("arrays.masks", "values must be in [0, 1]")
    for part in _parts():
        part.check_values(c, m, arrays)


def read_manifest(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read, upgrade and check the manifest of a workbench file without loading arrays.

    Raises :class:`WorkbenchFileError` naming the field if any field has the wrong
    JSON type or disagrees with another; optional fields are filled with defaults.
    """
    path = Path(path)
    with _open_zip(path) as zf:
        return _manifest(zf, path)


def _open_zip(path: Path) -> zipfile.ZipFile:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such workbench file")
    if path.stat().st_size == 0:
        raise WorkbenchFileError(path, "file", "is empty")
    try:
        return zipfile.ZipFile(path, "r")
    except zipfile.BadZipFile as exc:
        raise WorkbenchFileError(path, "file", f"not a workbench file (bad zip: {exc})") from None


def _manifest(zf: zipfile.ZipFile, path: Path) -> dict[str, Any]:
    c = Checker(path)
    try:
        info = zf.getinfo("manifest.json")
    except KeyError:
        raise WorkbenchFileError(path, "manifest.json", "missing") from None
    if info.file_size > _MAX_MANIFEST_BYTES:
        raise WorkbenchFileError(path, "manifest.json", "larger than 64 MiB")
    raw = _read_member(zf, path, info, "manifest.json")
    try:
        manifest = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise WorkbenchFileError(path, "manifest.json", f"not valid JSON ({exc})") from None
    if not isinstance(manifest, dict):
        c.expect("manifest.json", "a JSON object", manifest)
    if manifest.get("format") != FORMAT_NAME:
        c.expect("format", repr(FORMAT_NAME), manifest.get("format"))
    version = c.key(manifest, "", "schema_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        c.expect("schema_version", "an integer >= 1", version)
    if version > SCHEMA_VERSION:
        raise WorkbenchFileError(
            path,
            "schema_version",
            f"file has schema {version}, this workbench reads up to {SCHEMA_VERSION}; "
            "upgrade face-workbench to open it",
        )
    while version < SCHEMA_VERSION:
        manifest = _MIGRATIONS[version](manifest)
        version = manifest["schema_version"]
    return _check_manifest(c, manifest)


def load_model(path: str | os.PathLike[str]) -> Any:
    """Load a workbench file written by :func:`save_model` (any supported schema version).

    Every problem with the file raises :class:`WorkbenchFileError` naming the file
    and the field; the model is built only after all checks passed, and each
    method family's slots are installed from its part (no undo history).
    """
    path = Path(path)
    c = Checker(path)
    remove_stale_temporaries(path)
    with _open_zip(path) as zf:
        m = _manifest(zf, path)
        arrays = {name: _read_npy(zf, path, name, e) for name, e in m["arrays"].items()}
    _check_values(c, m, arrays)
    model_class = families.hook("model_class")
    try:
        masks = iter(arrays["masks"])  # one row per shape with mask true (checked by _array_specs)
        shapes = [
            BlendShape(
                sj["name"], arrays["deltas"][i], sj["slider_min"], sj["slider_max"], sj["mute"],
                next(masks) if sj["mask"] else None,
            )
            for i, sj in enumerate(m["shapes"])
        ]
        meta = m["metadata"]
        metadata = ModelMetadata(
            name=meta["name"], units=meta["units"], up_axis=meta["up_axis"],
            front_axis=meta["front_axis"], provenance=tuple(meta["provenance"]),
        )
        model = model_class(
            arrays["neutral"],
            arrays["faces"],
            shapes,
            polygons=Polygons(arrays["polygon_indices"], arrays["polygon_offsets"]),
            component_labels=arrays["component_labels"],
            component_names=m["components"],
            metadata=metadata,
            weights=m["weights"],
        )
    except (ModelError, ValueError) as exc:
        raise WorkbenchFileError(path, "content", str(exc)) from None
    for fam in families.families():
        part = fam.file_part
        if part is None:
            continue
        try:
            model.restore_slots(part.load(model, m, arrays))
        except (ModelError, ValueError, KeyError) as exc:
            field = part.keys[0] if part.keys else fam.name
            raise WorkbenchFileError(path, field, str(exc)) from None
    return model
