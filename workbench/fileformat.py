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
      "handles": {"names": [...]},
      "expressions": [{"name", "weights", "n_handles"}, ...],      (schema >= 2)
      "paint": ["smile", ...],                                      (schema >= 2)
      "tracks": {"fps", "start", "end", "tracks": {...}},           (schema >= 2)
      "regions": null | {"level", "threshold", "threshold_value", "overlap_rings",
                  "n_levels", "names", "kinds", "drivers",
                  "weights": null | {"level", "region_names", "shape_names"}},  (schema >= 2)
      "arrays": {"neutral": {"file", "dtype", "shape", "sha256"}, ...}
    }

Arrays: ``neutral`` (n,3) <f8, ``faces`` (m,3) <i4, ``polygon_indices`` (s,) <i4,
``polygon_offsets`` (p+1,) <i8, ``component_labels`` (n,) <i4, ``deltas`` (k,n,3) <f4,
``masks`` (k_masked, n) <f4 in the order of shapes with ``mask: true``,
``handle_vertices`` (h,) <i4, ``handle_offsets`` (h,3) <f4, ``handle_mirror`` (h,) <i4;
schema 2 adds ``expression_displacements`` (E,n,3) <f4, ``expression_handle_vertices``
(sum of n_handles,) <i4 and ``expression_handle_offsets`` (sum of n_handles, 3) <f4
(expressions in manifest order), and ``paint_maps`` (P,n) <f4 in the order of ``paint``.
The timeline is JSON in the manifest (:meth:`workbench.tracks.Timeline.to_json`).
Regions (schema 2): ``regions_deformation`` (n,) <f4 and, per level ``l``,
``regions_labels_l``, ``regions_weight_rows_l``, ``regions_weight_cols_l`` <i4,
``regions_weight_vals_l``, ``regions_background_l`` <f4, ``regions_parents_l``
(levels 0..L-2) <i4; per-region weights ``regions_weight_values`` (R,k) <f4.

Guarantees: saving writes a temporary file beside the target, fsyncs it and
renames it over the target, so a crash mid-save leaves the previous good file.
Loading checks every array's sha256, dtype and shape against the manifest,
reads ``.npy`` with ``allow_pickle=False``, checks declared sizes against the
member sizes before allocating, and builds the model only after everything
verified (nothing half-loaded). Older schema versions are upgraded by the
functions in ``_MIGRATIONS``; newer ones are refused with a clear error.

Why hand-written: ``np.savez`` gives no checksums, no atomic write and no
manifest, and we want the format readable from any language without numpy.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.expressions import expressions_to_json
from workbench.polygons import Polygons

if TYPE_CHECKING:
    from workbench.model import FaceModel

FORMAT_NAME = "face-workbench"
SCHEMA_VERSION = 2
SUFFIX = ".fwb"
_MAX_MANIFEST_BYTES = 64 * 2**20


class WorkbenchFileError(ValueError):
    """A saved workbench file that cannot be loaded; the message names file and field."""

    def __init__(self, path: str | os.PathLike[str], field: str, problem: str) -> None:
        self.path = str(path)
        self.field = field
        super().__init__(f"{self.path}: {field}: {problem}")


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


def _model_arrays(model: FaceModel) -> dict[str, np.ndarray]:
    masked = [s.vertex_mask for s in model.shapes if s.vertex_mask is not None]
    h = model.handles
    n = model.n_vertices
    exprs = list(model.expressions.values())
    paint = model.paint_layers
    return {
        "expression_displacements": (
            np.stack([e.displacement for e in exprs]).astype("<f4") if exprs else np.zeros((0, n, 3), "<f4")
        ),
        "expression_handle_vertices": np.concatenate(
            [np.zeros(0, "<i4")] + [e.handle_vertices.astype("<i4") for e in exprs]
        ),
        "expression_handle_offsets": np.concatenate(
            [np.zeros((0, 3), "<f4")] + [e.handle_offsets.astype("<f4") for e in exprs]
        ),
        **_region_arrays(model),
        "paint_maps": (
            np.stack([paint[k] for k in paint]).astype("<f4") if len(paint) else np.zeros((0, n), "<f4")
        ),
        "neutral": model.vertices.astype("<f8"),
        "faces": model.faces.astype("<i4"),
        "polygon_indices": model.polygons.indices.astype("<i4"),
        "polygon_offsets": model.polygons.offsets.astype("<i8"),
        "component_labels": model.component_labels.astype("<i4"),
        "deltas": model.deltas.astype("<f4"),
        "masks": (
            np.stack(masked).astype("<f4") if masked else np.zeros((0, model.n_vertices), "<f4")
        ),
        "handle_vertices": h.vertices.astype("<i4"),
        "handle_offsets": h.offsets.astype("<f4"),
        "handle_mirror": h.mirror.astype("<i4"),
    }


_REGION_LEVEL_FIELDS = ("labels", "weight_rows", "weight_cols", "weight_vals", "background")


def _region_arrays(model: FaceModel) -> dict[str, np.ndarray]:
    st = model.regions
    if st is None:
        return {}
    r = st.regions
    out: dict[str, np.ndarray] = {"regions_deformation": r.deformation.astype("<f4")}
    for f in _REGION_LEVEL_FIELDS:
        for lv, a in enumerate(getattr(r, f)):
            out[f"regions_{f}_{lv}"] = a.astype("<f4" if a.dtype.kind == "f" else "<i4")
    for lv, a in enumerate(r.parents):
        out[f"regions_parents_{lv}"] = a.astype("<i4")
    if st.weights is not None:
        out["regions_weight_values"] = st.weights.values.astype("<f4")
    return out


def _regions_json(model: FaceModel) -> dict[str, Any] | None:
    st = model.regions
    if st is None:
        return None
    r = st.regions
    w = st.weights
    return {
        "level": st.level,
        "n_levels": r.n_levels,
        "threshold": r.threshold,
        "threshold_value": r.threshold_value,
        "overlap_rings": r.overlap_rings,
        "names": [list(x) for x in r.names],
        "kinds": [list(x) for x in r.kinds],
        "drivers": [[list(d) for d in x] for x in r.drivers],
        "weights": None
        if w is None
        else {"level": w.level, "region_names": list(w.region_names), "shape_names": list(w.shape_names)},
    }


def _load_regions(path: Path, rj: dict[str, Any], arrays: dict[str, np.ndarray]) -> Any:
    from workbench.region_blend import RegionState, RegionWeights
    from workbench.regions import Regions

    L = int(rj["n_levels"])

    def get(name: str) -> np.ndarray:
        if name not in arrays:
            raise WorkbenchFileError(path, f"arrays.{name}", "missing (regions are incomplete)")
        return arrays[name]

    regions = Regions(
        **{f: tuple(get(f"regions_{f}_{lv}") for lv in range(L)) for f in _REGION_LEVEL_FIELDS},
        names=tuple(tuple(x) for x in rj["names"]),
        parents=tuple(get(f"regions_parents_{lv}") for lv in range(L - 1)),
        kinds=tuple(tuple(x) for x in rj["kinds"]),
        drivers=tuple(tuple(tuple(d) for d in x) for x in rj["drivers"]),
        deformation=get("regions_deformation"),
        threshold=float(rj["threshold"]),
        threshold_value=float(rj["threshold_value"]),
        overlap_rings=int(rj["overlap_rings"]),
    )
    wj = rj.get("weights")
    weights = None
    if wj is not None:
        weights = RegionWeights(
            int(wj["level"]), tuple(wj["shape_names"]), tuple(wj["region_names"]), get("regions_weight_values")
        )
    return RegionState(regions, int(rj["level"]), weights)


def save_model(model: FaceModel, path: str | os.PathLike[str]) -> Path:
    """Write ``model`` to ``path`` atomically (temp file + fsync + rename).

    Returns the path written. The suffix ``.fwb`` is recommended, not enforced.
    """
    from workbench import __version__

    path = Path(path)
    with model.lock:
        arrays = _model_arrays(model)
        meta = model.metadata.to_json()
        manifest: dict[str, Any] = {
            "format": FORMAT_NAME,
            "schema_version": SCHEMA_VERSION,
            "writer": f"face-workbench {__version__}",
            "metadata": meta,
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
            "handles": {"names": list(model.handles.names)},
            "expressions": expressions_to_json(model.expressions),
            "paint": list(model.paint_layers),
            "tracks": model.tracks.to_json(),
            "regions": _regions_json(model),
            "arrays": {},
        }
    payloads = {}
    for name, a in arrays.items():
        data = _npy_bytes(a)
        payloads[name] = data
        manifest["arrays"][name] = {
            "file": f"arrays/{name}.npy",
            "dtype": a.dtype.str,
            "shape": list(a.shape),
            "sha256": _sha256(data),
        }
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
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


def _read_npy(
    zf: zipfile.ZipFile, path: Path, name: str, entry: dict[str, Any]
) -> np.ndarray:
    member = entry.get("file")
    if not isinstance(member, str):
        raise WorkbenchFileError(path, f"arrays.{name}.file", "missing member name")
    try:
        info = zf.getinfo(member)
    except KeyError:
        raise WorkbenchFileError(path, f"arrays.{name}", f"member {member!r} is missing") from None
    if info.file_size > 8 * 2**30:
        raise WorkbenchFileError(path, f"arrays.{name}", "member larger than 8 GiB")
    expected_shape = tuple(int(x) for x in entry.get("shape", ()))
    dtype = np.dtype(entry.get("dtype", "|V0"))
    if dtype.hasobject:
        raise WorkbenchFileError(path, f"arrays.{name}.dtype", "object arrays are not allowed")
    declared = int(np.prod(expected_shape, dtype=np.int64)) * dtype.itemsize
    if declared > info.file_size:
        raise WorkbenchFileError(
            path,
            f"arrays.{name}.shape",
            f"declares {expected_shape} ({declared} bytes) but the member holds only "
            f"{info.file_size} bytes",
        )
    data = zf.read(member)
    if _sha256(data) != entry.get("sha256"):
        raise WorkbenchFileError(
            path, f"arrays.{name}", "checksum mismatch (file corrupted or edited)"
        )
    try:
        a = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise WorkbenchFileError(path, f"arrays.{name}", f"not a valid .npy array ({exc})") from None
    if a.shape != expected_shape or a.dtype != dtype:
        raise WorkbenchFileError(
            path,
            f"arrays.{name}",
            f"holds {a.dtype.str}{a.shape}, manifest says {dtype.str}{expected_shape}",
        )
    return a


def read_manifest(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and upgrade the manifest of a workbench file without loading arrays."""
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
    try:
        info = zf.getinfo("manifest.json")
    except KeyError:
        raise WorkbenchFileError(path, "manifest.json", "missing") from None
    if info.file_size > _MAX_MANIFEST_BYTES:
        raise WorkbenchFileError(path, "manifest.json", "larger than 64 MiB")
    try:
        manifest = json.loads(zf.read(info).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, zipfile.BadZipFile) as exc:
        raise WorkbenchFileError(path, "manifest.json", f"not valid JSON ({exc})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT_NAME:
        raise WorkbenchFileError(path, "manifest.format", f"expected {FORMAT_NAME!r}")
    version = manifest.get("schema_version")
    if not isinstance(version, int) or version < 1:
        raise WorkbenchFileError(path, "manifest.schema_version", f"invalid value {version!r}")
    if version > SCHEMA_VERSION:
        raise WorkbenchFileError(
            path,
            "manifest.schema_version",
            f"file has schema {version}, this workbench reads up to {SCHEMA_VERSION}; "
            "upgrade face-workbench to open it",
        )
    while version < SCHEMA_VERSION:
        manifest = _MIGRATIONS[version](manifest)
        version = manifest["schema_version"]
    return manifest


def load_model(path: str | os.PathLike[str]) -> FaceModel:
    """Load a workbench file written by :func:`save_model` (any supported schema version)."""
    from workbench.expressions import Expression
    from workbench.model import BlendShape, FaceModel, HandleSet, ModelError, ModelMetadata
    from workbench.paint import PaintMix
    from workbench.tracks import Timeline, TrackError

    path = Path(path)
    with _open_zip(path) as zf:
        manifest = _manifest(zf, path)
        entries = manifest.get("arrays")
        if not isinstance(entries, dict):
            raise WorkbenchFileError(path, "manifest.arrays", "missing")
        required = (
            "neutral", "faces", "polygon_indices", "polygon_offsets",
            "component_labels", "deltas", "masks",
        )
        for name in required:
            if name not in entries:
                raise WorkbenchFileError(path, f"arrays.{name}", "missing from manifest")
        arrays = {name: _read_npy(zf, path, name, entries[name]) for name in entries}
    try:
        shapes_json = manifest["shapes"]
        deltas = arrays["deltas"]
        if deltas.ndim != 3 or deltas.shape[0] != len(shapes_json):
            raise WorkbenchFileError(
                path, "arrays.deltas", f"expected {len(shapes_json)} shapes, got {deltas.shape}"
            )
        masks = iter(arrays["masks"])
        shapes = []
        for i, sj in enumerate(shapes_json):
            mask = next(masks) if sj.get("mask") else None
            shapes.append(
                BlendShape(
                    sj["name"], deltas[i], sj["slider_min"], sj["slider_max"], sj["mute"], mask
                )
            )
        meta_json = manifest["metadata"]
        metadata = ModelMetadata(
            name=meta_json.get("name", ""),
            units=meta_json["units"],
            up_axis=meta_json["up_axis"],
            front_axis=meta_json["front_axis"],
            provenance=tuple(meta_json.get("provenance", ())),
        )
        model = FaceModel(
            arrays["neutral"],
            arrays["faces"],
            shapes,
            polygons=Polygons(arrays["polygon_indices"], arrays["polygon_offsets"]),
            component_labels=arrays["component_labels"],
            component_names=manifest["components"],
            metadata=metadata,
            weights=manifest.get("weights", {}),
            handles=HandleSet(
                arrays["handle_vertices"],
                arrays["handle_offsets"],
                tuple(manifest.get("handles", {}).get("names", ())),
                arrays["handle_mirror"],
            )
            if "handle_vertices" in arrays
            else None,
        )
        n = model.n_vertices
        exprs = manifest.get("expressions", [])
        disp = arrays.get("expression_displacements", np.zeros((0, n, 3), "<f4"))
        hv = arrays.get("expression_handle_vertices", np.zeros(0, "<i4"))
        ho = arrays.get("expression_handle_offsets", np.zeros((0, 3), "<f4"))
        if disp.shape != (len(exprs), n, 3):
            raise WorkbenchFileError(path, "arrays.expression_displacements", f"expected ({len(exprs)}, {n}, 3), got {disp.shape}")
        library, start = {}, 0
        for i, ej in enumerate(exprs):
            stop = start + int(ej["n_handles"])
            if stop > len(hv) or stop > len(ho):
                raise WorkbenchFileError(path, f"expressions[{i}].n_handles", "more handles than stored")
            library[ej["name"]] = Expression(ej["name"], disp[i], ej["weights"], hv[start:stop], ho[start:stop])
            start = stop
        paint_names = manifest.get("paint", [])
        pm = arrays.get("paint_maps", np.zeros((0, n), "<f4"))
        if pm.shape != (len(paint_names), n):
            raise WorkbenchFileError(path, "arrays.paint_maps", f"expected ({len(paint_names)}, {n}), got {pm.shape}")
        tracks_json = manifest.get("tracks")
        # the loaded state is the starting point, not an edit: install without history
        if library:
            model._slots["expressions"] = MappingProxyType(library)
        if paint_names:
            bad = [p for p in paint_names if p not in library and p not in model.shape_names]
            if bad:
                raise WorkbenchFileError(path, "paint", f"paints unknown expressions {bad}")
            maps = {p: pm[i].copy() for i, p in enumerate(paint_names)}
            for w in maps.values():
                w.setflags(write=False)
            model._slots["paint_layers"] = PaintMix(maps)
        regions_json = manifest.get("regions")
        if regions_json:
            from workbench.regions import RegionError

            try:
                model._slots["regions"] = _load_regions(path, regions_json, arrays)
            except RegionError as exc:
                raise WorkbenchFileError(path, "regions", str(exc)) from None
        if tracks_json:
            try:
                timeline = Timeline.from_json(tracks_json)
                timeline.check_model(model)
            except TrackError as exc:
                raise WorkbenchFileError(path, "tracks", str(exc)) from None
            model._slots["tracks"] = timeline
    except WorkbenchFileError:
        raise
    except (KeyError, TypeError) as exc:
        raise WorkbenchFileError(path, "manifest", f"missing or malformed field {exc}") from None
    except (ModelError, ValueError) as exc:
        raise WorkbenchFileError(path, "content", str(exc)) from None
    return model
