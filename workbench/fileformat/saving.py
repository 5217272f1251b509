"""Saving: a snapshot of the model (manifest + ``.npy`` payloads) written atomically.

Saving writes a temporary file ``.<name>.<pid>.<random>.tmp`` beside the
target, fsyncs it and renames it over the target, so a crash mid-save leaves
the previous good file.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench._version import __version__
from workbench.fileformat.container import FORMAT_NAME, SCHEMA_VERSION, _parts, _sha256
from workbench.fileformat.temporaries import remove_stale_temporaries

if TYPE_CHECKING:
    from workbench.core.state import FaceState


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
