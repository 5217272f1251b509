"""The manifest's schema: upgrades of older versions, and the check of every field and array entry.

Loading checks every manifest field's JSON type, range and cross-references
(counts against declared array shapes, names against shapes) and every array
entry's documented dtype and shape; unknown arrays are refused. Older schema
versions are upgraded by the functions in ``_MIGRATIONS``; newer ones are
refused with a clear error.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from workbench.core.manifest import SHA256, Checker, Spec, json_path
from workbench.core.shapes import AXES, UNIT_TO_METRES
from workbench.fileformat.container import SCHEMA_VERSION, _parts


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
