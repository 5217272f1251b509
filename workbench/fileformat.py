"""The saved workbench file (``.fwb``): an open, documented container.

Layout (a plain zip, members stored uncompressed so large arrays load fast)::

    manifest.json          JSON, see below
    arrays/<name>.npy      numpy .npy arrays (never pickled objects)

``manifest.json``::

    {
      "format": "face-workbench",
      "schema_version": 1,
      "writer": "face-workbench 0.1.0",
      "metadata": {"name", "units", "up_axis", "front_axis", "provenance": [...]},
      "mesh": {"n_vertices", "n_faces", "n_polygons"},
      "components": ["skin", "eye_left", ...],
      "shapes": [{"name", "slider_min", "slider_max", "mute", "mask": bool}, ...],
      "weights": {"jawOpen": 0.25, ...},
      "handles": {"names": [...], "stiffness": [k_s, k_b]},        (stiffness: since 0.2)
      "expressions": [{"name", "weights", "n_handles"}, ...],      (schema >= 2)
      "paint": ["smile", ...],                                      (schema >= 2)
      "tracks": {"fps", "start", "end", "tracks": {...}},           (schema >= 2)
      "regions": null | {"level", "threshold", "threshold_value", "overlap_rings",
                  "n_levels", "names", "kinds", "drivers",
                  "weights": null | {"level", "region_names", "shape_names"}},  (schema >= 2)
      "wrinkles": null | {the fit's inputs; refitted on load},      (optional)
      "correctives": [{"name", "drivers": [...]}, ...],             (optional)
      "arrays": {"neutral": {"file", "dtype", "shape", "sha256"}, ...}
    }

Arrays: ``neutral`` (n,3) <f8, ``faces`` (m,3) <i4, ``polygon_indices`` (s,) <i4,
``polygon_offsets`` (p+1,) <i8, ``component_labels`` (n,) <i4, ``deltas`` (k,n,3) <f4,
``masks`` (k_masked, n) <f4 in the order of shapes with ``mask: true``,
``handle_vertices`` (h,) <i4, ``handle_offsets`` (h,3) <f4, ``handle_mirror`` (h,) <i4;
schema 2 adds ``expression_displacements`` (E,n,3) <f4, ``expression_handle_vertices``
(sum of n_handles,) <i4 and ``expression_handle_offsets`` (sum of n_handles, 3) <f4
(expressions in manifest order), and ``paint_maps`` (P,n) <f4 in the order of ``paint``.
The timeline is JSON in the manifest (:meth:`workbench.animation.tracks.Timeline.to_json`).
Regions (schema 2): ``regions_deformation`` (n,) <f4 and, per level ``l``,
``regions_labels_l``, ``regions_weight_rows_l``, ``regions_weight_cols_l`` <i4,
``regions_weight_vals_l``, ``regions_background_l`` <f4, ``regions_parents_l``
(levels 0..L-2) <i4; per-region weights ``regions_weight_values`` (R,k) <f4.

Who writes what: this module is the container (zip, manifest, checksums,
metadata, mesh, components, shapes and weights); every other key and its
arrays belong to a method family's file part
(:class:`workbench.core.families.FilePart`): ``handles`` to
:mod:`workbench.methods.handles.family`, ``expressions`` and ``paint`` to
:mod:`workbench.methods.paint.family`, ``regions`` to
:mod:`workbench.methods.regions.family`, ``wrinkles`` to
:mod:`workbench.methods.wrinkles.family`, ``correctives`` to
:mod:`workbench.methods.shapes.family`, ``tracks`` to
:mod:`workbench.animation.family`. A new family adds its keys there, not here;
a file without a family's keys loads with that family's defaults.

Guarantees: saving writes a temporary file ``.<name>.<pid>.<random>.tmp``
beside the target, fsyncs it and renames it over the target, so a crash
mid-save leaves the previous good file; the next save or load of the file
removes temporaries whose writer no longer runs (:func:`remove_stale_temporaries`).
Loading checks every manifest field's JSON type, range and cross-references
(counts against declared array shapes, names against shapes) and every array's
sha256, documented dtype, shape and value range; unknown arrays are refused.
It reads ``.npy`` with ``allow_pickle=False``, checks declared sizes against the
member sizes and the ``.npy`` header against the manifest before allocating, and
builds the model only after everything verified (nothing half-loaded). Any
problem raises :class:`WorkbenchFileError` ``"<file>: <JSON path>: <expected>"``. Older schema versions are upgraded by the
functions in ``_MIGRATIONS``; newer ones are refused with a clear error.

Why hand-written: ``np.savez`` gives no checksums, no atomic write and no
manifest, and we want the format readable from any language without numpy.
"""

from __future__ import annotations

import glob
import hashlib
import io
import json
import logging
import math
import os
import tempfile
import time
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench._version import __version__
from workbench.core import families
from workbench.core.manifest import (
    SHA256,
    Checker,
    Spec,
    WorkbenchFileError,
    json_path,
)
from workbench.core.polygons import Polygons
from workbench.core.shapes import AXES, UNIT_TO_METRES, BlendShape, ModelError, ModelMetadata

if TYPE_CHECKING:
    from workbench.core.state import FaceState

logger = logging.getLogger(__name__)

FORMAT_NAME = "face-workbench"
SCHEMA_VERSION = 2
SUFFIX = ".fwb"
_MAX_MANIFEST_BYTES = 64 * 2**20


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


def _container_arrays(model: FaceState) -> dict[str, np.ndarray]:
    masked = [s.vertex_mask for s in model.shapes if s.vertex_mask is not None]
    return {
        "neutral": model.vertices.astype("<f8"),
        "faces": model.faces.astype("<i4"),
        "polygon_indices": model.polygons.indices.astype("<i4"),
        "polygon_offsets": model.polygons.offsets.astype("<i8"),
        "component_labels": model.component_labels.astype("<i4"),
        "deltas": model.deltas.astype("<f4"),
        "masks": np.stack(masked).astype("<f4") if masked else np.zeros((0, model.n_vertices), "<f4"),
    }


def _parts() -> list[families.FilePart]:
    """The file parts of the registered method families, in family order."""
    return [f.file_part for f in families.families() if f.file_part is not None]


#: a temporary file of a writer whose pid cannot be read is stale after this many seconds
_STALE_AFTER_S = 600.0


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def remove_stale_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Delete what killed saves of ``path`` left beside it; returns the removed files.

    A save writes ``.<name>.<pid>.<random>.tmp`` and renames it over ``path``;
    killed mid-write (SIGKILL, power loss) the partial file stays. It is stale
    when its writer's process no longer runs (or, for a name without a pid,
    when it is older than ten minutes); a save in progress elsewhere is left
    alone. Called by every save and load of ``path``.
    """
    path = Path(path)
    removed: list[Path] = []
    try:
        candidates = list(path.parent.glob(f".{glob.escape(path.name)}.*.tmp"))
    except OSError:
        return removed
    now = time.time()
    for tmp in candidates:
        rest = tmp.name[len(path.name) + 2 : -len(".tmp")]
        pid_text = rest.split(".", 1)[0]
        try:
            if pid_text.isdigit() and "." in rest:
                stale = not _pid_alive(int(pid_text))
            else:
                stale = now - tmp.stat().st_mtime > _STALE_AFTER_S
            if stale:
                tmp.unlink()
                removed.append(tmp)
        except OSError:
            continue
    if removed:
        logger.info("%s: removed %d temporary file(s) left by interrupted saves", path.name, len(removed))
    return removed


@dataclass(frozen=True)
class ModelSnapshot:
    """Everything a save writes, taken at one instant: the manifest and each array as ``.npy`` bytes.

    :func:`snapshot_model` takes it on the thread that edits the model (under its
    lock); :func:`write_snapshot` writes it from any thread (autosave writes on
    its own thread while the user goes on editing).
    """

    manifest: dict[str, Any]
    #: array name -> (.npy bytes, dtype string, shape)
    payloads: dict[str, tuple[bytes, str, list[int]]]


def save_model(model: FaceState, path: str | os.PathLike[str]) -> Path:
    """Write ``model`` to ``path`` atomically (temp file + fsync + rename).

    Returns the path written. The suffix ``.fwb`` is recommended, not enforced.
    """
    return write_snapshot(snapshot_model(model), path)


def snapshot_model(model: FaceState) -> ModelSnapshot:
    """The model as a save would write it, now (arrays serialised, so later edits cannot reach it)."""
    with model.lock:
        arrays = _container_arrays(model)
        manifest: dict[str, Any] = {
            "format": FORMAT_NAME,
            "schema_version": SCHEMA_VERSION,
            "writer": f"face-workbench {__version__}",
            "metadata": model.metadata.to_json(),
            "mesh": {
                "n_vertices": model.n_vertices,
                "n_faces": len(model.faces),
                "n_polygons": len(model.polygons),
            },
            "components": model.component_names,
            "shapes": [
                {
                    "name": s.name,
                    "slider_min": s.slider_min,
                    "slider_max": s.slider_max,
                    "mute": s.mute,
                    "mask": s.vertex_mask is not None,
                }
                for s in model.shapes
            ],
            "weights": dict(model.weights),
        }
        for part in _parts():  # each method family writes its own keys and arrays
            entries, part_arrays = part.save(model)
            manifest.update(entries)
            arrays.update(part_arrays)
        payloads = {name: (_npy_bytes(a), a.dtype.str, list(a.shape)) for name, a in arrays.items()}
        # a deep copy: the families' entries may share lists with the live model
        manifest = json.loads(json.dumps(manifest))
    return ModelSnapshot(manifest, payloads)


def write_snapshot(snapshot: ModelSnapshot, path: str | os.PathLike[str]) -> Path:
    """Write a :class:`ModelSnapshot` to ``path`` atomically (temp file + fsync + rename); any thread."""
    path = Path(path)
    manifest = dict(snapshot.manifest)
    manifest["arrays"] = {}
    payloads = {}
    for name, (data, dtype, shape) in snapshot.payloads.items():
        payloads[name] = data
        manifest["arrays"][name] = {
            "file": f"arrays/{name}.npy",
            "dtype": dtype,
            "shape": shape,
            "sha256": _sha256(data),
        }
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    # the writer's pid in the name tells a later save or load whether the writer still lives
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    try:
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; saved files follow the umask
        with os.fdopen(fd, "wb") as fh:
            with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED) as zf:
                zf.writestr("manifest.json", json.dumps(manifest, indent=1, sort_keys=True))
                for name, data in payloads.items():
                    zf.writestr(manifest["arrays"][name]["file"], data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    try:  # make the rename itself durable
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass
    return path


# -------------------------------------------------------------------- loading
def _migrate_1_to_2(manifest: dict[str, Any]) -> dict[str, Any]:
    """Schema 2 added saved expressions, paint layers, the timeline and regions: start them empty."""
    out = dict(manifest)
    out.update(schema_version=2, expressions=[], paint=[], tracks=None, regions=None)
    return out


#: schema_version -> function upgrading a manifest to schema_version + 1.
#: tests/data/schema_v1_tiny.fwb (written by schema 1) proves old files still load.
_MIGRATIONS: dict[int, Callable[[dict[str, Any]], dict[str, Any]]] = {1: _migrate_1_to_2}

def _check_metadata(c: Checker, value: Any) -> dict[str, Any]:
    f = "metadata"
    meta = c.obj(value, f)
    units = c.string(c.key(meta, f, "units"), "metadata.units")
    if units not in UNIT_TO_METRES:
        c.fail("metadata.units", f"expected one of {sorted(UNIT_TO_METRES)}, got {units!r}")
    axes = {}
    for ax in ("up_axis", "front_axis"):
        axes[ax] = c.string(c.key(meta, f, ax), f"metadata.{ax}")
        if axes[ax] not in AXES:
            c.fail(f"metadata.{ax}", f"expected one of {list(AXES)}, got {axes[ax]!r}")
    prov = c.lst(c.key(meta, f, "provenance", []), "metadata.provenance")
    return {
        "name": c.string(c.key(meta, f, "name", ""), "metadata.name"),
        "units": units,
        **axes,
        "provenance": [c.obj(p, f"metadata.provenance[{i}]") for i, p in enumerate(prov)],
    }


def _check_shapes(c: Checker, value: Any) -> list[dict[str, Any]]:
    shapes = []
    seen: set[str] = set()
    for i, sj in enumerate(c.lst(value, "shapes")):
        f = f"shapes[{i}]"
        sj = c.obj(sj, f)
        name = c.string(c.key(sj, f, "name"), f"{f}.name", nonempty=True)
        if name in seen:
            c.fail(f"{f}.name", f"duplicate blendshape name {name!r}")
        seen.add(name)
        lo = c.number(c.key(sj, f, "slider_min"), f"{f}.slider_min")
        hi = c.number(c.key(sj, f, "slider_max"), f"{f}.slider_max")
        if not lo < hi:
            c.fail(f"{f}.slider_max", f"expected a number greater than slider_min ({lo}), got {hi}")
        shapes.append({
            "name": name,
            "slider_min": lo,
            "slider_max": hi,
            "mute": c.boolean(c.key(sj, f, "mute"), f"{f}.mute"),
            "mask": c.boolean(c.key(sj, f, "mask", False), f"{f}.mask"),
        })
    return shapes


def _check_weights(c: Checker, value: Any, field: str, shape_names: list[str] | None) -> dict[str, float]:
    out = {}
    for name, w in c.obj(value, field).items():
        if shape_names is not None and name not in shape_names:
            c.fail(json_path(field, name), f"not a shape name; the shapes are {shape_names[:8]}")
        out[name] = c.number(w, json_path(field, name))
    return out


def _array_specs(m: dict[str, Any], entries: dict[str, Any]) -> tuple[dict[str, Spec], set[str]]:
    """Expected dtype and shape of every array the manifest implies, and which must be present."""
    mesh = m["mesh"]
    n, nf, npoly = mesh["n_vertices"], mesh["n_faces"], mesh["n_polygons"]
    k = len(m["shapes"])
    km = sum(s["mask"] for s in m["shapes"])
    specs: dict[str, Spec] = {
        "neutral": ("<f8", (n, 3), "(mesh.n_vertices, 3)"),
        "faces": ("<i4", (nf, 3), "(mesh.n_faces, 3)"),
        "polygon_indices": ("<i4", ("s",), "(corners,)"),
        "polygon_offsets": ("<i8", (npoly + 1,), "(mesh.n_polygons + 1,)"),
        "component_labels": ("<i4", (n,), "(mesh.n_vertices,)"),
        "deltas": ("<f4", (k, n, 3), "(len(shapes), mesh.n_vertices, 3)"),
        "masks": ("<f4", (km, n), "(shapes with mask true, mesh.n_vertices)"),
    }
    required = set(specs)
    present = set(entries)
    for part in _parts():
        part_specs, part_required = part.specs(m, present)
        specs.update(part_specs)
        required |= part_required
    return specs, required


def _check_arrays(c: Checker, m: dict[str, Any], value: Any) -> dict[str, dict[str, Any]]:
    entries = c.obj(value, "arrays")
    specs, required = _array_specs(m, entries)
    for name in sorted(required):
        if name not in entries:
            c.fail(json_path("arrays", name), "missing")
    bound: dict[str, int] = {}
    out = {}
    for name, e in entries.items():
        f = json_path("arrays", name)
        if name not in specs:
            why = " while regions is null or has fewer levels" if name.startswith("regions_") else ""
            c.fail(f, f"unknown array (schema {SCHEMA_VERSION} has no such array{why})")
        dtype, dims, desc = specs[name]
        e = c.obj(e, f)
        member = c.string(c.key(e, f, "file"), f"{f}.file", nonempty=True)
        dt = c.string(c.key(e, f, "dtype"), f"{f}.dtype")
        if dt != dtype:
            c.fail(f"{f}.dtype", f"expected {dtype!r}, got {dt!r}")
        shape = tuple(c.integer(x, f"{f}.shape[{i}]") for i, x in enumerate(c.lst(c.key(e, f, "shape"), f"{f}.shape")))
        if len(shape) != len(dims):
            c.fail(f"{f}.shape", f"declares {list(shape)} but expected {len(dims)} dimensions {desc}")
        expected = tuple(
            bound.setdefault(d, s) if isinstance(d, str) else d for d, s in zip(dims, shape, strict=True)
        )
        if shape != expected:
            c.fail(f"{f}.shape", f"declares {list(shape)} but expected {desc} = {list(expected)}")
        sha = c.string(c.key(e, f, "sha256"), f"{f}.sha256")
        if not SHA256.match(sha):
            c.expect(f"{f}.sha256", "64 lowercase hex digits", sha)
        out[name] = {"file": member, "dtype": dt, "shape": list(shape), "sha256": sha}
    return out


def _check_manifest(c: Checker, manifest: dict[str, Any]) -> dict[str, Any]:
    """Check every field's JSON type, range and cross-reference; return a normalized copy.

    Fields that are optional (absent in older writers) get their defaults. Nothing
    below the checks needs to guard against malformed JSON again.
    """
    m = dict(manifest)
    m["writer"] = c.string(c.key(manifest, "", "writer", ""), "writer")
    m["metadata"] = _check_metadata(c, c.key(manifest, "", "metadata"))
    mesh = c.obj(c.key(manifest, "", "mesh"), "mesh")
    m["mesh"] = {
        "n_vertices": c.integer(c.key(mesh, "mesh", "n_vertices"), "mesh.n_vertices", lo=1),
        "n_faces": c.integer(c.key(mesh, "mesh", "n_faces"), "mesh.n_faces"),
        "n_polygons": c.integer(c.key(mesh, "mesh", "n_polygons"), "mesh.n_polygons"),
    }
    m["components"] = c.strings(c.key(manifest, "", "components"), "components")
    if not m["components"]:
        c.fail("components", "expected at least one component name")
    m["shapes"] = shapes = _check_shapes(c, c.key(manifest, "", "shapes"))
    shape_names = [s["name"] for s in shapes]
    m["weights"] = _check_weights(c, c.key(manifest, "", "weights", {}), "weights", shape_names)
    for part in _parts():  # each method family checks its own keys
        m.update(part.check(c, manifest, m))
    m["arrays"] = _check_arrays(c, m, c.key(manifest, "", "arrays"))
    return m


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
