"""Constants and helpers shared by the viewport's modules (no widget state here).

The bundle loader, the brush defaults other panels use (:func:`face_height`,
:func:`default_brush_radius`, :func:`brush_radius_slider`), the neutral-mesh
bounds the front end frames the camera on, and the binary encoders of the
transfer protocol (see :mod:`widgets.viewport.sync`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import ipywidgets
import numpy as np

_STATIC = Path(__file__).resolve().parent.parent / "static"
BUNDLE = _STATIC / "viewport.js"

#: Below this fraction of changed vertices an update is sent as (ids, values).
SPARSE_FRACTION = 1.0 / 3.0

#: During an interaction, vertices that moved less than this fraction of the mesh's
#: bounding-box diagonal are not re-sent (about 1/40 pixel at the default framing,
#: 1/4 pixel zoomed in 10x); the interaction's final update is exact.
DRAG_TOLERANCE = 5e-5

FALLOFFS = ("smooth", "linear", "constant", "sphere")
BRUSH_MODES = ("add", "subtract", "smooth")

#: Default brush radius as a fraction of the face height (the skin's extent along up).
BRUSH_RADIUS_FRACTION = 0.03

#: Most dabs one "stroke" message may carry (the front end sends at most 8).
MAX_DABS_PER_MESSAGE = 32

#: Relative stretch drawn in full colour by the feature-graph overlay (±20 %).
STRAIN_RANGE = 0.2

#: A strain update is sent only when some edge changed by more than this (0.01 %).
STRAIN_TOLERANCE = 1e-4

#: path -> ((path, mtime_ns, size), text) of every bundle read
_bundle_cache: dict[str, tuple[tuple[str, int, int], str]] = {}


def read_bundle(path: Path, missing: str) -> str:
    """The text of a built front-end bundle, re-read only when it changes on disk.

    ``missing`` is the FileNotFoundError message when the file is not there.
    """
    try:
        stat = path.stat()
    except FileNotFoundError:
        raise FileNotFoundError(missing) from None
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    hit = _bundle_cache.get(key[0])
    if hit is None or hit[0] != key:
        hit = (key, path.read_text(encoding="utf-8"))
        _bundle_cache[key[0]] = hit
    return hit[1]


def load_bundle(path: Path = BUNDLE) -> str:
    """The viewport's ESM bundle (three.js included), re-read when it changes on disk.

    Raises
    ------
    FileNotFoundError
        When the bundle was not built (``widgets/static/`` is not committed).
    """
    return read_bundle(
        path,
        f"the viewport's JavaScript bundle {path} is missing: it is built from "
        "widgets/js (three.js + esbuild). Run the README test/run command or "
        "`npm --prefix widgets/js ci && npm --prefix widgets/js run build`.",
    )


def scene_key(model: Any) -> str:
    """A key naming ``model`` in the browser (the ``_scene`` trait of its widgets).

    The front end's playback registry (``widgets/js/src/shared/playback.js``) keys
    playing timelines by it, so a timeline puts only the viewports of its own face
    model in draft resolution.
    """
    return f"fwb-{id(model):x}"


def f32_bytes(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype="<f4").tobytes()


def u32_bytes(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype="<u4").tobytes()


def as_ids(value: Any, n: int, what: str) -> np.ndarray:
    ids = np.asarray(value if value is not None else [], dtype=np.int64).reshape(-1)
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise ValueError(f"Viewport.{what}: vertex ids must be in 0..{n - 1}")
    return ids.astype(np.uint32)


def face_height(model: Any) -> float:
    """Extent of the skin (or of the whole mesh) along the model's up axis, model units."""
    V = np.asarray(model.vertices)
    if not V.size:
        return 1.0
    names = list(getattr(model, "component_names", []) or [])
    labels = np.asarray(getattr(model, "component_labels", np.zeros(0)))
    roles = list(getattr(model, "part_roles", None) or names)  # the skin by role, else by name
    if "skin" in roles and labels.size == V.shape[0]:
        skin = V[np.isin(labels, [i for i, r in enumerate(roles) if r == "skin"])]
        V = skin if skin.size else V
    up = str(getattr(getattr(model, "metadata", None), "up_axis", "+y") or "+y")
    axis = {"x": 0, "y": 1, "z": 2}.get(up[-1:].lower(), 1)
    h = float(np.ptp(V[:, axis]))
    return h if h > 0 else float(np.linalg.norm(np.ptp(V, axis=0))) or 1.0


def neutral_bounds(model: Any) -> dict[str, Any]:
    """``{"min": [x, y, z], "max": [x, y, z], "radius": r}`` of the neutral mesh (``model.vertices``).

    ``radius``: the largest distance of a vertex from the box centre (what
    three.js's ``computeBoundingSphere`` gives). The front end frames the camera
    on this box and sizes the markers by this radius, so neither depends
    on the pose shown when the view opened.
    """
    V = np.asarray(model.vertices, dtype=np.float64).reshape(-1, 3)
    if not V.size or not np.isfinite(V).all():
        return {}
    lo, hi = V.min(axis=0), V.max(axis=0)
    r = float(np.sqrt(((V - (lo + hi) / 2) ** 2).sum(axis=1).max()))
    return {"min": lo.tolist(), "max": hi.tolist(), "radius": r}


def default_brush_radius(model: Any) -> float:
    """:data:`BRUSH_RADIUS_FRACTION` of the face height (about a third of the mouth width)."""
    return BRUSH_RADIUS_FRACTION * face_height(model)


def brush_radius_slider(
    model: Any, viewport: Any, description: str, **kwargs: Any
) -> ipywidgets.FloatSlider:
    """The brush-radius slider every brush (a stroke tool, a stroke handler) shows.

    Starts at the viewport's brush radius (or :func:`default_brush_radius`) and
    spans 0.5 %–30 % of the face height; ``kwargs`` go to the slider (style, layout).
    """
    H = face_height(model)
    r0 = float(getattr(viewport, "brush_radius", 0.0) or default_brush_radius(model))
    return ipywidgets.FloatSlider(
        value=r0,
        min=0.005 * H,
        max=0.3 * H,
        step=0.001 * H,
        readout_format=".3f",
        description=description,
        **kwargs,
    )


def changed_rows(new: np.ndarray, old: np.ndarray, tolerance: float) -> np.ndarray:
    """Rows (vertices) of (n, 3) ``new`` that differ from ``old`` by more than ``tolerance``.

    Column-wise ORs instead of ``.any(axis=1)``: numpy's axis reduction over a
    short last axis was half of the kernel's time per drag frame at 100k vertices.
    """
    if tolerance > 0:
        d = np.abs(new - old)
        mask = d[:, 0] > tolerance
        mask |= d[:, 1] > tolerance
        mask |= d[:, 2] > tolerance
    else:
        mask = new[:, 0] != old[:, 0]
        mask |= new[:, 1] != old[:, 1]
        mask |= new[:, 2] != old[:, 2]
    return np.flatnonzero(mask)


# ------------------------------------------------------------------ silent traits
# A trait the page gets changes of as messages (patches, GPU parameters) is kept current
# in Python without syncing it (store_silently): a reloaded page reads it whole. Python's
# value is then newer than the page's copy of the trait, and traitlets does not send an
# assignment of an equal value: a full update must go through assign_synced, or the page
# would read its stale copy (a picture from before the patches).
_UNSENT = object()


def store_silently(widget: Any, **values: Any) -> None:
    """Keep these traits current in Python only (the page got the change as a message)."""
    for name, value in values.items():
        widget._trait_values[name] = value


def assign_synced(widget: Any, **values: Any) -> None:
    """Assign traits so that every one reaches the page, equal to Python's value or not.

    Call inside ``widget.hold_sync()`` to send them with the rest of a full update in one
    message.
    """
    for name, value in values.items():
        old = widget._trait_values.get(name, _UNSENT)
        widget._trait_values[name] = _UNSENT  # any value is a change from this
        try:
            setattr(widget, name, value)
        except Exception:
            widget._trait_values[name] = old
            raise
