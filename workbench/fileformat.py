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
The timeline is JSON in the manifest (:meth:`workbench.animation.tracks.Timeline.to_json`).
Regions (schema 2): ``regions_deformation`` (n,) <f4 and, per level ``l``,
``regions_labels_l``, ``regions_weight_rows_l``, ``regions_weight_cols_l`` <i4,
``regions_weight_vals_l``, ``regions_background_l`` <f4, ``regions_parents_l``
(levels 0..L-2) <i4; per-region weights ``regions_weight_values`` (R,k) <f4.

Guarantees: saving writes a temporary file beside the target, fsyncs it and
renames it over the target, so a crash mid-save leaves the previous good file.
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

import hashlib
import io
import json
import math
import os
import re
import tempfile
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from workbench.methods.paint.expressions import expressions_to_json
from workbench.core.polygons import Polygons

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

#: Largest count or array dimension a manifest may declare (keeps all size maths exact).
_MAX_COUNT = 2**53
_REQUIRED: Any = object()
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_SHA256 = re.compile(r"[0-9a-f]{64}\Z")


def _join(base: str, key: str) -> str:
    """JSON path of ``key`` inside the object at ``base`` (``shapes[3].mask``, ``weights["a b"]``)."""
    part = key if _IDENT.match(key) else f"[{json.dumps(key)}]"
    if not base:
        return part
    return f"{base}{part}" if part.startswith("[") else f"{base}.{part}"


def _show(value: Any) -> str:
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


class _Checker:
    """Typed reads of parsed manifest JSON; every failure names the file and the JSON path."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, field: str, problem: str) -> NoReturn:
        raise WorkbenchFileError(self.path, field, problem)

    def expect(self, field: str, what: str, got: Any) -> NoReturn:
        self.fail(field, f"expected {what}, got {_show(got)}")

    def key(self, obj: dict[str, Any], base: str, key: str, default: Any = _REQUIRED) -> Any:
        if key in obj:
            return obj[key]
        if default is _REQUIRED:
            self.fail(_join(base, key), "missing")
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


def _check_metadata(c: _Checker, value: Any) -> dict[str, Any]:
    from workbench.model import AXES, UNIT_TO_METRES

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


def _check_shapes(c: _Checker, value: Any) -> list[dict[str, Any]]:
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


def _check_weights(c: _Checker, value: Any, field: str, shape_names: list[str] | None) -> dict[str, float]:
    out = {}
    for name, w in c.obj(value, field).items():
        if shape_names is not None and name not in shape_names:
            c.fail(_join(field, name), f"not a shape name; the shapes are {shape_names[:8]}")
        out[name] = c.number(w, _join(field, name))
    return out


def _check_expressions(c: _Checker, value: Any) -> list[dict[str, Any]]:
    out = []
    seen: set[str] = set()
    for i, ej in enumerate(c.lst(value, "expressions")):
        f = f"expressions[{i}]"
        ej = c.obj(ej, f)
        name = c.string(c.key(ej, f, "name"), f"{f}.name", nonempty=True)
        if name in seen:
            c.fail(f"{f}.name", f"duplicate expression name {name!r}")
        seen.add(name)
        out.append({
            "name": name,
            "weights": _check_weights(c, c.key(ej, f, "weights"), f"{f}.weights", None),
            "n_handles": c.integer(c.key(ej, f, "n_handles"), f"{f}.n_handles"),
        })
    return out


def _check_tracks(c: _Checker, value: Any) -> dict[str, Any] | None:
    """Structure of the timeline JSON; :meth:`Timeline.from_json` checks the meaning."""
    from workbench.animation.tracks import INTERPOLATIONS, TANGENT_MODES

    if value is None:
        return None
    t = c.obj(value, "tracks")
    for fld in ("fps", "start", "end"):
        if fld in t:
            c.number(t[fld], f"tracks.{fld}")
    for name, keys in c.obj(c.key(t, "tracks", "tracks", {}), "tracks.tracks").items():
        tf = _join("tracks.tracks", name)
        for i, key in enumerate(c.lst(keys, tf)):
            f = f"{tf}[{i}]"
            k = c.obj(key, f)
            c.number(c.key(k, f, "time"), f"{f}.time")
            c.numeric(c.key(k, f, "value"), f"{f}.value")
            for tan in ("in_tangent", "out_tangent"):
                if k.get(tan) is not None:
                    c.numeric(k[tan], f"{f}.{tan}")
            for opt, allowed in (("interpolation", INTERPOLATIONS), ("tangent_mode", TANGENT_MODES)):
                if opt in k and k[opt] not in allowed:
                    c.expect(f"{f}.{opt}", f"one of {list(allowed)}", k[opt])
    return t


def _check_regions(c: _Checker, value: Any) -> dict[str, Any] | None:
    if value is None:
        return None
    f = "regions"
    r = c.obj(value, f)
    L = c.integer(c.key(r, f, "n_levels"), "regions.n_levels", lo=1, hi=1000)
    per_level = f" (one per level, regions.n_levels = {L})"
    names = [
        c.strings(x, f"regions.names[{lv}]", unique=True)
        for lv, x in enumerate(c.lst(c.key(r, f, "names"), "regions.names", L, per_level))
    ]
    kinds = [
        c.strings(x, f"regions.kinds[{lv}]", len(names[lv]), f" (one per name in regions.names[{lv}])")
        for lv, x in enumerate(c.lst(c.key(r, f, "kinds"), "regions.kinds", L, per_level))
    ]
    drivers = []
    for lv, x in enumerate(c.lst(c.key(r, f, "drivers"), "regions.drivers", L, per_level)):
        lf = f"regions.drivers[{lv}]"
        regs = c.lst(x, lf, len(names[lv]), f" (one per name in regions.names[{lv}])")
        drivers.append([c.strings(d, f"{lf}[{j}]") for j, d in enumerate(regs)])
    weights = None
    weights_json = c.key(r, f, "weights", None)
    if weights_json is not None:
        wf = "regions.weights"
        wj = c.obj(weights_json, wf)
        wl = c.integer(c.key(wj, wf, "level"), f"{wf}.level", hi=L - 1)
        weights = {
            "level": wl,
            "region_names": c.strings(
                c.key(wj, wf, "region_names"), f"{wf}.region_names", len(names[wl]),
                f" (one per region of level {wl})",
            ),
            "shape_names": c.strings(c.key(wj, wf, "shape_names"), f"{wf}.shape_names"),
        }
    return {
        "level": c.integer(c.key(r, f, "level"), "regions.level", hi=L - 1),
        "n_levels": L,
        "threshold": c.number(c.key(r, f, "threshold"), "regions.threshold"),
        "threshold_value": c.number(c.key(r, f, "threshold_value"), "regions.threshold_value"),
        "overlap_rings": c.integer(c.key(r, f, "overlap_rings"), "regions.overlap_rings"),
        "names": names,
        "kinds": kinds,
        "drivers": drivers,
        "weights": weights,
    }


#: name -> (dtype, shape); a dimension is an int or a symbol bound by the first array using it.
_Spec = tuple[str, tuple[int | str, ...], str]


def _array_specs(m: dict[str, Any], entries: dict[str, Any]) -> tuple[dict[str, _Spec], set[str]]:
    """Expected dtype and shape of every array the manifest implies, and which must be present."""
    mesh = m["mesh"]
    n, nf, npoly = mesh["n_vertices"], mesh["n_faces"], mesh["n_polygons"]
    k = len(m["shapes"])
    km = sum(s["mask"] for s in m["shapes"])
    h = len(m["handles"]["names"])
    E = len(m["expressions"])
    H = sum(e["n_handles"] for e in m["expressions"])
    P = len(m["paint"])
    specs: dict[str, _Spec] = {
        "neutral": ("<f8", (n, 3), "(mesh.n_vertices, 3)"),
        "faces": ("<i4", (nf, 3), "(mesh.n_faces, 3)"),
        "polygon_indices": ("<i4", ("s",), "(corners,)"),
        "polygon_offsets": ("<i8", (npoly + 1,), "(mesh.n_polygons + 1,)"),
        "component_labels": ("<i4", (n,), "(mesh.n_vertices,)"),
        "deltas": ("<f4", (k, n, 3), "(len(shapes), mesh.n_vertices, 3)"),
        "masks": ("<f4", (km, n), "(shapes with mask true, mesh.n_vertices)"),
        "handle_vertices": ("<i4", (h,), "(len(handles.names),)"),
        "handle_offsets": ("<f4", (h, 3), "(len(handles.names), 3)"),
        "handle_mirror": ("<i4", (h,), "(len(handles.names),)"),
        "expression_displacements": ("<f4", (E, n, 3), "(len(expressions), mesh.n_vertices, 3)"),
        "expression_handle_vertices": ("<i4", (H,), "(sum of expressions[].n_handles,)"),
        "expression_handle_offsets": ("<f4", (H, 3), "(sum of expressions[].n_handles, 3)"),
        "paint_maps": ("<f4", (P, n), "(len(paint), mesh.n_vertices)"),
    }
    required = {"neutral", "faces", "polygon_indices", "polygon_offsets", "component_labels", "deltas", "masks"}
    handle_arrays = {"handle_vertices", "handle_offsets", "handle_mirror"}
    if h or handle_arrays & set(entries):  # handles: all three arrays or none (schema 1 and 2 write all)
        required |= handle_arrays
    # optional arrays default to empty ones, so they must be present when not empty
    required |= {name for name in ("expression_displacements", "paint_maps") if specs[name][1][0]}
    if H:
        required |= {"expression_handle_vertices", "expression_handle_offsets"}
    rj = m["regions"]
    if rj is not None:
        L = rj["n_levels"]
        specs["regions_deformation"] = ("<f4", (n,), "(mesh.n_vertices,)")
        for lv in range(L):
            R = len(rj["names"][lv])
            nnz = f"nnz{lv}"
            specs[f"regions_labels_{lv}"] = ("<i4", (n,), "(mesh.n_vertices,)")
            specs[f"regions_background_{lv}"] = ("<f4", (n,), "(mesh.n_vertices,)")
            for fld, dt in (("rows", "<i4"), ("cols", "<i4"), ("vals", "<f4")):
                specs[f"regions_weight_{fld}_{lv}"] = (dt, (nnz,), f"(nnz,) like regions_weight_rows_{lv}")
            if lv < L - 1:
                specs[f"regions_parents_{lv}"] = ("<i4", (R,), f"(len(regions.names[{lv}]),)")
        wj = rj["weights"]
        if wj is not None:
            specs["regions_weight_values"] = (
                "<f4",
                (len(wj["region_names"]), len(wj["shape_names"])),
                "(len(regions.weights.region_names), len(regions.weights.shape_names))",
            )
        required |= {name for name in specs if name.startswith("regions_")}
    return specs, required


def _check_arrays(c: _Checker, m: dict[str, Any], value: Any) -> dict[str, dict[str, Any]]:
    entries = c.obj(value, "arrays")
    specs, required = _array_specs(m, entries)
    for name in sorted(required):
        if name not in entries:
            c.fail(_join("arrays", name), "missing")
    bound: dict[str, int] = {}
    out = {}
    for name, e in entries.items():
        f = _join("arrays", name)
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
        if not _SHA256.match(sha):
            c.expect(f"{f}.sha256", "64 lowercase hex digits", sha)
        out[name] = {"file": member, "dtype": dt, "shape": list(shape), "sha256": sha}
    return out


def _check_manifest(c: _Checker, manifest: dict[str, Any]) -> dict[str, Any]:
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
    handles = c.obj(c.key(manifest, "", "handles", {}), "handles")
    m["handles"] = {"names": c.strings(c.key(handles, "handles", "names", []), "handles.names")}
    m["expressions"] = exprs = _check_expressions(c, c.key(manifest, "", "expressions", []))
    m["paint"] = paint = c.strings(c.key(manifest, "", "paint", []), "paint", unique=True)
    known = {e["name"] for e in exprs} | set(shape_names)
    for i, p in enumerate(paint):
        if p not in known:
            c.fail(f"paint[{i}]", f"paints {p!r}, which is neither a saved expression nor a shape")
    m["tracks"] = _check_tracks(c, c.key(manifest, "", "tracks", None))
    m["regions"] = _check_regions(c, c.key(manifest, "", "regions", None))
    m["arrays"] = _check_arrays(c, m, c.key(manifest, "", "arrays"))
    return m


def _read_member(zf: zipfile.ZipFile, path: Path, member: str | zipfile.ZipInfo, field: str) -> bytes:
    try:
        return zf.read(member)
    except (zipfile.BadZipFile, EOFError, OSError, RuntimeError, NotImplementedError, zlib.error) as exc:
        raise WorkbenchFileError(path, field, f"cannot read the zip member ({exc})") from None


def _read_npy(zf: zipfile.ZipFile, path: Path, name: str, entry: dict[str, Any]) -> np.ndarray:
    """One array, its entry already checked by :func:`_check_arrays`."""
    f = _join("arrays", name)
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


def _check_values(c: _Checker, m: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Value ranges of the arrays (shapes and dtypes are already known to be right)."""
    n = m["mesh"]["n_vertices"]

    def in_range(name: str, lo: int, hi: int, what: str) -> None:
        a = arrays.get(name)
        if a is not None and a.size and (a.min() < lo or a.max() > hi):
            bad = int(np.flatnonzero((a.reshape(-1) < lo) | (a.reshape(-1) > hi))[0])
            c.fail(
                _join("arrays", name),
                f"{what} must be in {lo}..{hi}, got {a.reshape(-1)[bad]} at flat index {bad}",
            )

    for name, a in arrays.items():
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            bad = int(np.flatnonzero(~np.isfinite(a.reshape(-1)))[0])
            c.fail(_join("arrays", name), f"NaN or infinity at flat index {bad}")
    in_range("faces", 0, n - 1, "vertex ids")
    in_range("polygon_indices", 0, n - 1, "vertex ids")
    off = arrays["polygon_offsets"]
    if off[0] != 0 or off[-1] != arrays["polygon_indices"].size or np.any(np.diff(off) < 3):
        c.fail(
            "arrays.polygon_offsets",
            "offsets must start at 0, end at len(polygon_indices) and give >= 3 corners per polygon",
        )
    in_range("component_labels", 0, len(m["components"]) - 1, "labels (indices into components)")
    for name in ("masks", "paint_maps"):
        w = arrays.get(name)
        if w is not None and w.size and (w.min() < 0.0 or w.max() > 1.0):
            c.fail(_join("arrays", name), "values must be in [0, 1]")
    pm = arrays.get("paint_maps")
    if pm is not None and pm.size and pm.sum(axis=0, dtype=np.float64).max() > 1.0 + 1e-3:
        c.fail("arrays.paint_maps", "painted weights must sum to <= 1 at every vertex")
    in_range("handle_vertices", 0, n - 1, "vertex ids")
    in_range("handle_mirror", -1, len(m["handles"]["names"]) - 1, "mirror handle indices (-1 = none)")
    in_range("expression_handle_vertices", 0, n - 1, "vertex ids")
    rj = m["regions"]
    if rj is not None:
        L = rj["n_levels"]
        for lv in range(L):
            R = len(rj["names"][lv])
            in_range(f"regions_labels_{lv}", -1, R - 1, f"labels (-1 or regions of level {lv})")
            in_range(f"regions_weight_rows_{lv}", 0, n - 1, "vertex ids")
            in_range(f"regions_weight_cols_{lv}", 0, R - 1, f"regions of level {lv}")
            if lv < L - 1:
                in_range(f"regions_parents_{lv}", 0, len(rj["names"][lv + 1]) - 1, f"regions of level {lv + 1}")


def _load_regions(path: Path, rj: dict[str, Any], arrays: dict[str, np.ndarray]) -> Any:
    """The regions slot from checked JSON and arrays (:func:`_array_specs` made sure all exist)."""
    from workbench.methods.regions.blend import RegionState, RegionWeights
    from workbench.methods.regions.segmentation import Regions

    L = rj["n_levels"]
    regions = Regions(
        **{f: tuple(arrays[f"regions_{f}_{lv}"] for lv in range(L)) for f in _REGION_LEVEL_FIELDS},
        names=tuple(tuple(x) for x in rj["names"]),
        parents=tuple(arrays[f"regions_parents_{lv}"] for lv in range(L - 1)),
        kinds=tuple(tuple(x) for x in rj["kinds"]),
        drivers=tuple(tuple(tuple(d) for d in x) for x in rj["drivers"]),
        deformation=arrays["regions_deformation"],
        threshold=rj["threshold"],
        threshold_value=rj["threshold_value"],
        overlap_rings=rj["overlap_rings"],
    )
    wj = rj["weights"]
    weights = None
    if wj is not None:
        weights = RegionWeights(
            wj["level"], tuple(wj["shape_names"]), tuple(wj["region_names"]), arrays["regions_weight_values"]
        )
    return RegionState(regions, rj["level"], weights)


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
    c = _Checker(path)
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


def load_model(path: str | os.PathLike[str]) -> FaceModel:
    """Load a workbench file written by :func:`save_model` (any supported schema version).

    Every problem with the file raises :class:`WorkbenchFileError` naming the file
    and the field; the model is built only after all checks passed.
    """
    from workbench.methods.paint.expressions import Expression
    from workbench.model import BlendShape, FaceModel, HandleSet, ModelError, ModelMetadata
    from workbench.methods.paint.painting import PaintMix
    from workbench.methods.regions.segmentation import RegionError
    from workbench.animation.tracks import Timeline, TrackError

    path = Path(path)
    c = _Checker(path)
    with _open_zip(path) as zf:
        m = _manifest(zf, path)
        arrays = {name: _read_npy(zf, path, name, e) for name, e in m["arrays"].items()}
    _check_values(c, m, arrays)
    n = m["mesh"]["n_vertices"]
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
            name=meta["name"],
            units=meta["units"],
            up_axis=meta["up_axis"],
            front_axis=meta["front_axis"],
            provenance=tuple(meta["provenance"]),
        )
        model = FaceModel(
            arrays["neutral"],
            arrays["faces"],
            shapes,
            polygons=Polygons(arrays["polygon_indices"], arrays["polygon_offsets"]),
            component_labels=arrays["component_labels"],
            component_names=m["components"],
            metadata=metadata,
            weights=m["weights"],
            handles=HandleSet(
                arrays["handle_vertices"],
                arrays["handle_offsets"],
                tuple(m["handles"]["names"]),
                arrays["handle_mirror"],
            )
            if "handle_vertices" in arrays
            else None,
        )
        disp = arrays.get("expression_displacements", np.zeros((0, n, 3), "<f4"))
        hv = arrays.get("expression_handle_vertices", np.zeros(0, "<i4"))
        ho = arrays.get("expression_handle_offsets", np.zeros((0, 3), "<f4"))
        library, start = {}, 0
        for i, ej in enumerate(m["expressions"]):
            stop = start + ej["n_handles"]
            library[ej["name"]] = Expression(ej["name"], disp[i], ej["weights"], hv[start:stop], ho[start:stop])
            start = stop
        pm = arrays.get("paint_maps", np.zeros((0, n), "<f4"))
    except (ModelError, ValueError) as exc:
        raise WorkbenchFileError(path, "content", str(exc)) from None
    regions = None
    if m["regions"] is not None:
        try:
            regions = _load_regions(path, m["regions"], arrays)
        except (RegionError, ValueError) as exc:
            raise WorkbenchFileError(path, "regions", str(exc)) from None
    timeline = None
    if m["tracks"] is not None:
        try:
            timeline = Timeline.from_json(m["tracks"])
            timeline.check_model(model)
        except (TrackError, ValueError) as exc:
            raise WorkbenchFileError(path, "tracks", str(exc)) from None
    # the loaded state is the starting point, not an edit: install without history
    if library:
        model._slots["expressions"] = MappingProxyType(library)
    if m["paint"]:
        maps = {p: pm[i].copy() for i, p in enumerate(m["paint"])}
        for w in maps.values():
            w.setflags(write=False)
        model._slots["paint_layers"] = PaintMix(maps)
    if regions is not None:
        model._slots["regions"] = regions
    if timeline is not None:
        model._slots["tracks"] = timeline
    return model
