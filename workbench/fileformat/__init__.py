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

Who writes what: this package is the container (zip, manifest, checksums,
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

Guarantees: saving is atomic, a crash mid-save leaves the previous good file
(:mod:`~workbench.fileformat.saving`); what killed saves leave behind is removed
by the next save or load (:mod:`~workbench.fileformat.temporaries`); loading
checks every manifest field (:mod:`~workbench.fileformat.schema`, which also
upgrades older schema versions) and every array before it builds the model
(:mod:`~workbench.fileformat.loading`). Any problem raises
:class:`WorkbenchFileError` ``"<file>: <JSON path>: <expected>"``.

Why hand-written: ``np.savez`` gives no checksums, no atomic write and no
manifest, and we want the format readable from any language without numpy.
"""

from __future__ import annotations

from workbench.core.manifest import WorkbenchFileError
from workbench.fileformat.container import FORMAT_NAME, SCHEMA_VERSION, SUFFIX
from workbench.fileformat.loading import load_model, read_manifest
from workbench.fileformat.saving import ModelSnapshot, save_model, snapshot_model, write_snapshot
from workbench.fileformat.temporaries import logger as logger
from workbench.fileformat.temporaries import remove_stale_temporaries

__all__ = [
    "FORMAT_NAME",
    "SCHEMA_VERSION",
    "SUFFIX",
    "ModelSnapshot",
    "WorkbenchFileError",
    "load_model",
    "read_manifest",
    "remove_stale_temporaries",
    "save_model",
    "snapshot_model",
    "write_snapshot",
]
