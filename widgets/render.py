"""Bridge between :class:`workbench.FaceModel` and pyvista, plus offscreen pictures.

The headless core (``workbench/``) never imports pyvista or VTK; everything that
needs them lives here.  Three things are offered:

* :func:`to_pyvista` / :func:`from_pyvista` convert meshes both ways (component
  labels travel as point data, component names as field data).
* :func:`render_png` draws one offscreen picture of a model (optionally with
  blendshape weights or per-vertex scalars) and returns PNG bytes.
* :func:`expression_thumbnails` draws one small picture per blendshape with a
  single plotter: the scene is built once and only the points (and normals) are
  replaced between screenshots, which is what makes 52 thumbnails cheap.

Why parts are hand-written instead of using pyvista's helpers:

* Vertex normals are computed here in numpy (area-weighted face normals summed
  per vertex) instead of ``add_mesh(smooth_shading=True)``: pyvista's smooth
  shading runs ``compute_normals`` on a *copy* of the mesh, so later point
  updates on our mesh would no longer reach the renderer.
* The camera is placed from the model's own axes (metadata up axis, face toward
  +z) and the extent of the points seen from that direction, because
  ``reset_camera`` frames a bounding sphere and leaves faces small and off
  centre in portrait-shaped heads.
* Colours are per-vertex RGB chosen from the components' part roles (skin,
  eyeballs, teeth, ...: ``model.part_roles``, from the names or else the
  geometry); eyeballs get a procedural iris/pupil from their vertex
  directions, since the sample has no textures.

Rendering is CPU-only (Mesa llvmpipe through EGL, no display needed) and
deterministic: a fresh plotter with fixed lights and camera gives the same
pixels for the same input.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast

# Must be set before vtk is first imported: skips the X11 attempt (and its
# warning) on machines without a display and goes straight to EGL/llvmpipe.
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import numpy as np
import pyvista as pv
from numpy.typing import ArrayLike, NDArray
from PIL import Image

from workbench import FaceModel, ModelMetadata
from workbench.converters import register_mesh_converter
from workbench.core.polygons import Polygons
from workbench.geometry.axes import face_axes
from workbench.geometry.normals import vertex_normals
from workbench.geometry.parts import model_part_roles, part_material

__all__ = [
    "CAMERAS",
    "COMPONENT_COLORS",
    "delta_hash",
    "expression_thumbnails",
    "from_pyvista",
    "png_to_array",
    "render_png",
    "screen_positions",
    "to_pyvista",
    "vertex_colors",
]

#: Camera presets accepted by :func:`render_png`.
#: ``face`` is a front view framed on the vertices the blendshapes move
#: (the face itself, without neck and skull), used for thumbnails.
CAMERAS = ("front", "three_quarter", "side", "face")

#: sRGB colours (0-255) by part material (:func:`workbench.geometry.parts.part_material`
#: of the component's role); unrecognised parts use ``skin``.
COMPONENT_COLORS: dict[str, tuple[int, int, int]] = {
    "skin": (226, 178, 152),
    "eye": (242, 240, 235),  # sclera; iris and pupil are added procedurally
    "iris": (86, 112, 78),
    "pupil": (18, 16, 16),
    # the lashes are cards meant for an alpha texture; drawn opaque, a soft
    # brown reads as a lash line instead of a heavy black band
    "eyelashes": (128, 92, 76),
    "eyebrows": (70, 50, 38),
    "teeth": (238, 232, 212),
    "tongue": (196, 96, 100),
    "gums": (190, 104, 104),
}

_LABEL_ARRAY = "component"
_NAMES_FIELD = "component_names"
_VIEW_ANGLE = 24.0  # degrees, vertical field of view: a mild "portrait lens"


# --------------------------------------------------------------------------- conversion


def _polygon_cell_array(indices: NDArray[np.int32], offsets: NDArray[np.int64]) -> NDArray:
    """Legacy VTK cell array ``[n0, i.., n1, i.., ...]`` from CSR polygons."""
    sizes = np.diff(offsets)
    out = np.empty(indices.size + sizes.size, dtype=np.int64)
    # polygon k's size sits at offsets[k] + k; its corners follow it
    size_pos = offsets[:-1] + np.arange(sizes.size)
    out[size_pos] = sizes
    mask = np.ones(out.size, dtype=bool)
    mask[size_pos] = False
    out[mask] = indices
    return out


def to_pyvista(
    model: FaceModel,
    points: ArrayLike | None = None,
    *,
    polygons: bool = False,
    scalars: ArrayLike | None = None,
    scalars_name: str = "scalars",
) -> pv.PolyData:
    """Convert a face model to a :class:`pyvista.PolyData`.

    Parameters
    ----------
    model : FaceModel
    points : (n, 3) float, optional
        Vertex positions to use instead of the neutral ``model.vertices``
        (e.g. ``model.evaluate()``).
    polygons : bool
        Write the original polygons (quads, n-gons) instead of the triangles.
    scalars : (n,) or (n, c) array, optional
        Extra point data, stored under ``scalars_name`` and made active.

    Returns
    -------
    pyvista.PolyData
        Point data ``"component"`` (n,) int32 holds ``model.component_labels``;
        field data ``"component_names"`` holds the names.
    """
    n = model.n_vertices
    pts = np.asarray(model.vertices if points is None else points, dtype=np.float64)
    if pts.shape != (n, 3):
        raise ValueError(f"to_pyvista: points must have shape ({n}, 3), got {pts.shape}")
    if polygons:
        poly = model.polygons
        mesh = pv.PolyData(pts.copy(), faces=_polygon_cell_array(poly.indices, poly.offsets))
    else:
        faces: Any = np.asarray(model.faces, dtype=np.int64)  # pyvista's stubs want int, not int64
        mesh = pv.PolyData.from_regular_faces(pts.copy(), faces)
    mesh.point_data[_LABEL_ARRAY] = np.asarray(model.component_labels, dtype=np.int32)
    mesh.field_data[_NAMES_FIELD] = np.asarray(list(model.component_names), dtype=str)
    if scalars is not None:
        s = np.asarray(scalars)
        if s.shape[:1] != (n,):
            raise ValueError(f"to_pyvista: scalars must have {n} rows, got shape {s.shape}")
        mesh.point_data[scalars_name] = s
        mesh.point_data.active_scalars_name = scalars_name
    return mesh


def from_pyvista(
    mesh: pv.DataSet,
    name: str | None = None,
    *,
    units: str = "m",
    up_axis: str = "+y",
    front_axis: str = "+z",
) -> FaceModel:
    """Build a :class:`workbench.FaceModel` (no blendshapes) from a pyvista mesh.

    Parameters
    ----------
    mesh : pyvista.DataSet
        Any surface-like dataset; non-PolyData is passed through
        ``extract_surface``. Polygons are kept as ``model.polygons`` and
        fan-triangulated for ``model.faces``; lines, vertices and strips are
        ignored.
    name : str, optional
        Model name (``metadata.name``), also recorded in the provenance entry
        ``{"source": "pyvista", "name": ...}``.
    units, up_axis, front_axis : str
        Metadata; a pyvista mesh carries no units or orientation of its own.

    Returns
    -------
    FaceModel
        ``"component"`` point data (if present) become component labels, with
        names from the ``"component_names"`` field data.
    """
    if not isinstance(mesh, pv.PolyData):
        mesh = mesh.extract_surface()
    if mesh.GetNumberOfPolys() == 0:
        raise ValueError("from_pyvista: mesh has no polygon faces (only points/lines?)")
    cells = mesh.GetPolys()
    offsets = pv.convert_array(cells.GetOffsetsArray()).astype(np.int64)
    indices = pv.convert_array(cells.GetConnectivityArray()).astype(np.int32)
    polygons = Polygons(indices, offsets)
    faces, _ = polygons.triangulate()
    labels = names = None
    if _LABEL_ARRAY in mesh.point_data:
        labels = np.asarray(mesh.point_data[_LABEL_ARRAY], dtype=np.int32)
        if _NAMES_FIELD in mesh.field_data:
            names = [str(s) for s in mesh.field_data[_NAMES_FIELD]]
    provenance: dict[str, Any] = {"source": "pyvista"}
    if name is not None:
        provenance["name"] = name
    metadata = ModelMetadata(
        name=name or "",
        units=units,
        up_axis=up_axis,
        front_axis=front_axis,
        provenance=(provenance,),
    )
    return FaceModel(
        np.asarray(mesh.points, dtype=np.float64),
        faces,
        polygons=polygons,
        component_labels=labels,
        component_names=names,
        metadata=metadata,
    )


# --------------------------------------------------------------------------- shading helpers


def vertex_colors(model: FaceModel, front: ArrayLike = (0.0, 0.0, 1.0)) -> NDArray[np.uint8]:
    """Per-vertex RGB colours from the components' part roles (``model.part_roles``).

    The roles come from the names, else from the geometry
    (:func:`workbench.geometry.parts.component_roles`), so an unnamed eyeball is
    still drawn as an eye. Eyeballs get a sclera/iris/pupil pattern: a vertex's
    direction from its eyeball's centre is compared with the face direction
    ``front``.

    Returns
    -------
    (n, 3) uint8
    """
    n = model.n_vertices
    out = np.empty((n, 3), dtype=np.uint8)
    out[:] = COMPONENT_COLORS["skin"]
    labels = np.asarray(model.component_labels)
    names = list(model.component_names)
    roles = model_part_roles(model)
    v = np.asarray(model.vertices, dtype=np.float64)
    fwd = np.asarray(front, dtype=np.float64)
    fwd = fwd / np.linalg.norm(fwd)
    for idx, cname in enumerate(names):
        sel = labels == idx
        if not np.any(sel):
            continue
        key = part_material(roles[idx], cname)
        out[sel] = COMPONENT_COLORS[key]
        if key == "eye":
            ids = np.flatnonzero(sel)
            for piece in _connected_pieces(model.faces, ids):  # both eyes may be one component
                p = v[piece]
                d = p - p.mean(axis=0)
                d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
                cos = d @ fwd
                rgb = np.empty((len(p), 3), dtype=np.uint8)
                rgb[:] = COMPONENT_COLORS["eye"]
                rgb[cos > math.cos(math.radians(36))] = COMPONENT_COLORS["iris"]
                rgb[cos > math.cos(math.radians(17))] = COMPONENT_COLORS["pupil"]
                out[piece] = rgb
    return out


def _connected_pieces(faces: ArrayLike, ids: NDArray[np.intp]) -> list[NDArray[np.intp]]:
    """The vertex ids ``ids`` split into the connected pieces of the faces among them."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    local = np.full(int(max(F.max(initial=0), ids.max(initial=0))) + 1, -1, np.int64)
    local[ids] = np.arange(ids.size)
    Fl = local[F]
    Fl = Fl[(Fl >= 0).all(axis=1)]
    m = ids.size
    adj = coo_matrix((np.ones(Fl.size), (np.repeat(Fl[:, 0], 3), Fl.ravel())), shape=(m, m))
    k, lab = connected_components(adj + adj.T, directed=False)
    return [ids[lab == i] for i in range(k)]


# --------------------------------------------------------------------------- camera


def _model_axes(model: FaceModel) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(up, front) unit vectors from the model metadata (:func:`workbench.geometry.axes.face_axes`)."""
    axes = face_axes(model)
    return axes[1], axes[2]


def _rotate(vec: NDArray, axis: NDArray, degrees: float) -> NDArray:
    """Rodrigues rotation of ``vec`` about unit ``axis``."""
    t = math.radians(degrees)
    return (
        vec * math.cos(t)
        + np.cross(axis, vec) * math.sin(t)
        + axis * float(axis @ vec) * (1 - math.cos(t))
    )


def _face_region(model: FaceModel) -> NDArray[np.bool_] | None:
    """(n,) bool: vertices moved by any blendshape, or None if there are none."""
    if not model.shapes:
        return None
    biggest = np.zeros(model.n_vertices)
    for shape in model.shapes:
        d = shape.effective_delta()
        np.maximum(biggest, np.abs(d).max(axis=1), out=biggest)
    # Many shapes drag the scalp and neck a hair's width; only clearly moved
    # vertices (1% of the model size) outline the face itself.
    v = np.asarray(model.vertices, dtype=np.float64)
    size = float(np.linalg.norm(np.ptp(v, axis=0)))
    for threshold in (0.01 * size, 1e-9):
        moved = biggest > threshold
        if moved.sum() >= 3:
            return moved
    return None


def _camera_for(
    model: FaceModel, points: NDArray, camera: str, aspect: float
) -> tuple[tuple, tuple, tuple]:
    """Camera (position, focal point, view up) framing ``points`` for a preset."""
    if camera not in CAMERAS:
        raise ValueError(f"render_png: camera must be one of {CAMERAS}, got {camera!r}")
    up, front = _model_axes(model)
    pts = np.asarray(points, dtype=np.float64)
    if camera == "face":
        region = _face_region(model)
        if region is not None:
            pts = pts[region]
    direction = front
    if camera == "three_quarter":
        # turn toward the subject's left (viewer's right) and look down a little
        direction = _rotate(front, up, 35.0)
    elif camera == "side":
        direction = _rotate(front, up, 90.0)
    right = np.cross(up, direction)
    right /= np.linalg.norm(right)
    true_up = np.cross(direction, right)
    if camera in ("three_quarter", "side"):
        direction = _rotate(direction, right, -8.0)
        true_up = np.cross(direction, right)
    # extents in the view frame
    x, y, z = pts @ right, pts @ true_up, pts @ direction
    cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
    half_w, half_h = 0.5 * np.ptp(x), 0.5 * np.ptp(y)
    margin = 1.08 if camera != "face" else 1.12
    tan_v = math.tan(math.radians(_VIEW_ANGLE / 2))
    dist = margin * max(half_h / tan_v, half_w / (tan_v * aspect))
    focal = cx * right + cy * true_up + float(z.mean()) * direction
    position = focal + direction * (dist + (z.max() - z.mean()))
    return tuple(position), tuple(focal), tuple(true_up)


def _setup_camera(cam: Any, model: FaceModel, points: NDArray, camera: str, aspect: float) -> None:
    pos, focal, up = _camera_for(model, points, camera, aspect)
    cam.position, cam.focal_point, cam.up = pos, focal, up
    cam.view_angle = _VIEW_ANGLE


def screen_positions(
    model: FaceModel,
    xyz: ArrayLike,
    *,
    size: tuple[int, int] = (480, 480),
    camera: str = "front",
) -> NDArray[np.float64]:
    """Pixel coordinates of 3D points in a :func:`render_png` picture.

    Uses the same camera as ``render_png(model, ..., size=size, camera=camera)``
    (framed on the neutral mesh, so it does not depend on weights). Handy for
    tests (which pixels show the mouth?) and for aiming the mouse in browser
    tests.

    Parameters
    ----------
    xyz : (k, 3) float
        World positions.

    Returns
    -------
    (k, 2) float
        ``(column, row)`` with the origin at the top-left pixel corner.
    """
    w, h = int(size[0]), int(size[1])
    cam = pv.Camera()
    _setup_camera(cam, model, np.asarray(model.vertices), camera, w / h)
    m = np.array(
        [
            [
                cam.GetCompositeProjectionTransformMatrix(w / h, -1, 1).GetElement(i, j)
                for j in range(4)
            ]
            for i in range(4)
        ]
    )
    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    hom = np.c_[p, np.ones(len(p))] @ m.T
    ndc = hom[:, :2] / hom[:, 3:4]
    return np.c_[(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h]


# --------------------------------------------------------------------------- rendering


def _points_for(model: FaceModel, weights: Mapping[str, float] | None) -> NDArray[np.float64]:
    """Deformed points for explicit ``weights`` (unnamed shapes at 0), or the model's own."""
    if weights is None:
        return np.asarray(model.evaluate(), dtype=np.float64)
    names = list(model.shape_names)
    index = {n: i for i, n in enumerate(names)}
    unknown = [k for k in weights if k not in index]
    if unknown:
        raise KeyError(f"render_png: unknown blendshape name(s) {unknown}; model has {names}")
    pts = np.array(model.vertices, dtype=np.float64)
    for name, w in weights.items():
        shape = model.shapes[index[name]]
        if w and not shape.mute:
            pts += float(w) * shape.effective_delta().astype(np.float64)
    return pts


class _Scene:
    """One offscreen plotter holding one model; points can be swapped cheaply."""

    def __init__(
        self,
        model: FaceModel,
        points: NDArray,
        *,
        size: tuple[int, int],
        camera: str,
        scalars: ArrayLike | None,
        cmap: str | None,
        clim: tuple[float, float] | None,
        background: Any,
        antialias: bool = True,
        show_edges: bool = False,
    ) -> None:
        w, h = int(size[0]), int(size[1])
        if w < 8 or h < 8:
            raise ValueError(f"render_png: size must be at least (8, 8), got {size}")
        self.faces = np.asarray(model.faces, dtype=np.int64)
        faces: Any = self.faces  # pyvista's stubs want int, not int64
        self.mesh = pv.PolyData.from_regular_faces(np.asarray(points, np.float64).copy(), faces)
        self._set_normals(points)
        pl = pv.Plotter(off_screen=True, window_size=[w, h], lighting="light kit")
        pl.set_background(background)
        if antialias:
            # SSAA: FXAA is not supported by VTK's EGL/OSMesa builds (it warns and
            # falls back to SSAA anyway); pixels stay deterministic.
            pl.enable_anti_aliasing("ssaa")
        prop: dict[str, Any] = dict(ambient=0.12, diffuse=0.85, specular=0.12, specular_power=18.0)
        if show_edges:
            prop.update(show_edges=True, edge_color=(0.35, 0.22, 0.18), line_width=0.5)
        if scalars is None:
            _, front = _model_axes(model)
            self.mesh.point_data["rgb"] = vertex_colors(model, front)
            actor = pl.add_mesh(self.mesh, scalars="rgb", rgb=True, **prop)
        else:
            s = np.asarray(scalars)
            if s.shape[:1] != (model.n_vertices,):
                raise ValueError(
                    f"render_png: scalars must have {model.n_vertices} rows, got {s.shape}"
                )
            if s.ndim == 2 and s.shape[1] in (3, 4):
                rgb = s if s.dtype == np.uint8 else np.clip(s * 255.0 + 0.5, 0, 255)
                self.mesh.point_data["rgb"] = rgb.astype(np.uint8)
                actor = pl.add_mesh(self.mesh, scalars="rgb", rgb=True, **prop)
            else:
                self.mesh.point_data["scalars"] = s.astype(np.float64)
                actor = pl.add_mesh(
                    self.mesh,
                    scalars="scalars",
                    cmap=cast(Any, cmap or "viridis"),  # stubs list names as a Literal
                    clim=clim,
                    show_scalar_bar=False,
                    **prop,
                )
        # our own per-vertex normals + Gouraud/Phong = smooth shading
        actor.prop.interpolation = "phong"
        _setup_camera(pl.camera, model, np.asarray(model.vertices), camera, w / h)
        pl.reset_camera_clipping_range()
        self.plotter = pl

    def _set_normals(self, points: NDArray) -> None:
        # float32: what VTK shades with
        self.mesh.point_data["Normals"] = vertex_normals(points, self.faces).astype(np.float32)
        self.mesh.point_data.active_normals_name = "Normals"

    def set_points(self, points: NDArray) -> None:
        self.mesh.points = np.asarray(points, dtype=np.float64)
        self._set_normals(points)

    def png(self) -> bytes:
        self.plotter.render()
        img = self.plotter.screenshot(return_img=True, transparent_background=False)
        return _encode_png(np.asarray(img))

    def close(self) -> None:
        self.plotter.close()


def _encode_png(img: NDArray[np.uint8]) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img[..., :3])).save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def render_png(
    model: FaceModel,
    weights: Mapping[str, float] | None = None,
    *,
    size: tuple[int, int] = (480, 480),
    camera: str = "front",
    scalars: ArrayLike | None = None,
    cmap: str | None = None,
    clim: tuple[float, float] | None = None,
    background: Any = "white",
    points: ArrayLike | None = None,
    antialias: bool = True,
    show_edges: bool = False,
) -> bytes:
    """Render a face model offscreen and return PNG bytes.

    Parameters
    ----------
    model : FaceModel
    weights : dict[str, float], optional
        Blendshape weights to show; shapes not named are at 0 and the model is
        not changed. ``None`` shows the model's current ``evaluate()``.
    size : (width, height) int
    camera : {"front", "three_quarter", "side", "face"}
        View preset; the model's up axis (metadata) points up on screen and the
        camera looks at the face (+z). ``"face"`` is a front view framed on the
        region the blendshapes move. The camera is framed on the neutral mesh,
        so pictures of different expressions line up pixel for pixel.
    scalars : (n,) float or (n, 3) colours, optional
        Colour the surface by these values (with ``cmap``, default viridis, and
        optional ``clim``) instead of the component colours. (n, 3) uint8 or
        float in [0, 1] are used as RGB directly.
    background : colour
        Any pyvista colour.
    points : (n, 3) float, optional
        Explicit vertex positions (overrides ``weights``).
    antialias : bool
        Smooth edges with VTK's SSAA (about 1.5x the render time).
    show_edges : bool
        Draw the triangle edges (to show mesh density).

    Returns
    -------
    bytes
        PNG image of ``size``. The same input gives the same bytes.
    """
    pts = _points_for(model, weights) if points is None else np.asarray(points, np.float64)
    if pts.shape != (model.n_vertices, 3):
        raise ValueError(
            f"render_png: points must have shape ({model.n_vertices}, 3), got {pts.shape}"
        )
    scene = _Scene(
        model,
        pts,
        size=size,
        camera=camera,
        scalars=scalars,
        cmap=cmap,
        clim=clim,
        background=background,
        antialias=antialias,
        show_edges=show_edges,
    )
    try:
        return scene.png()
    finally:
        scene.close()


def delta_hash(delta: ArrayLike) -> str:
    """Short content hash of a blendshape delta, for thumbnail caches."""
    arr = np.ascontiguousarray(delta, dtype=np.float32)
    return hashlib.blake2b(arr.tobytes(), digest_size=12).hexdigest()


def expression_thumbnails(
    model: FaceModel,
    names: Iterable[str] | None = None,
    size: tuple[int, int] = (128, 128),
    progress: bool = True,
    *,
    camera: str = "face",
    background: Any = "white",
    weight: float = 1.0,
    antialias: bool = True,
    timings: dict[str, float] | None = None,
) -> dict[str, bytes]:
    """One PNG per blendshape (at ``weight``, others 0), rendered with one plotter.

    Parameters
    ----------
    model : FaceModel
    names : iterable of str, optional
        Shapes to draw, default all ``model.shape_names`` in order.
    size : (width, height) int
    progress : bool
        Show a tqdm progress bar.
    camera : str
        Camera preset (see :func:`render_png`); fixed for all thumbnails and
        framed on the neutral face so thumbnails line up.
    weight : float
        Weight of the shown shape (1 = full expression).
    antialias : bool
        Smooth edges (SSAA).
    timings : dict, optional
        If given, receives ``{"setup": s, "per_thumbnail": s, "total": s}``.

    Returns
    -------
    dict[str, bytes]
        Name to PNG bytes, in the order requested.
    """
    t0 = time.perf_counter()
    all_names = list(model.shape_names)
    wanted = all_names if names is None else list(names)
    missing = [n for n in wanted if n not in all_names]
    if missing:
        raise KeyError(f"expression_thumbnails: unknown blendshape name(s) {missing}")
    neutral = np.asarray(model.vertices, dtype=np.float64)
    index = {n: i for i, n in enumerate(all_names)}
    scene = _Scene(
        model,
        neutral,
        size=size,
        camera=camera,
        scalars=None,
        cmap=None,
        clim=None,
        background=background,
        antialias=antialias,
    )
    t_setup = time.perf_counter() - t0
    out: dict[str, bytes] = {}
    iterator: Sequence[str] | Any = wanted
    if progress and wanted:
        from tqdm.auto import tqdm

        iterator = tqdm(wanted, desc="thumbnails", leave=False)
    try:
        for name in iterator:
            delta = model.shapes[index[name]].effective_delta().astype(np.float64)
            scene.set_points(neutral + weight * delta)
            out[name] = scene.png()
    finally:
        scene.close()
    total = time.perf_counter() - t0
    if timings is not None:
        timings.update(
            setup=t_setup,
            per_thumbnail=(total - t_setup) / max(len(wanted), 1),
            total=total,
        )
    return out


def png_to_array(png: bytes) -> NDArray[np.uint8]:
    """Decode PNG bytes to an (h, w, 3) uint8 array (for tests and contact sheets)."""
    with Image.open(io.BytesIO(png)) as im:
        return np.asarray(im.convert("RGB"))


# FaceModel.to_pyvista() / FaceModel.from_pyvista() find these (workbench.converters)
register_mesh_converter("pyvista", to_pyvista, from_pyvista, provider=__name__)
