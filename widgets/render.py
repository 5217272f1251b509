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

The conversion, the colours and the camera are in :mod:`widgets.rendering`
(:mod:`~widgets.rendering.convert`, :mod:`~widgets.rendering.colors`,
:mod:`~widgets.rendering.camera`); their public names are importable from here.
"""

from __future__ import annotations

import hashlib
import io
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

from widgets.rendering.camera import CAMERAS, screen_positions, setup_camera

# under its old name: widgets.wrinkles.thumbnails imports it from here
from widgets.rendering.camera import model_axes as _model_axes
from widgets.rendering.colors import COMPONENT_COLORS, vertex_colors
from widgets.rendering.convert import from_pyvista, to_pyvista
from workbench import FaceModel
from workbench.converters import register_mesh_converter
from workbench.geometry.normals import vertex_normals

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
        setup_camera(pl.camera, model, np.asarray(model.vertices), camera, w / h)
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
