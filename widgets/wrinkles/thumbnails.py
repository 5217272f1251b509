"""Small pictures of the wrinkle examples: the detailed mesh shaded, its grooves tinted.

:func:`example_thumbnail` renders one example (pyvista, offscreen);
:class:`ExampleThumbnails` keeps one PNG per example and re-renders only the
examples whose details or weights changed (a scale or erase edit of one example
leaves the others' pictures alone).
"""

from __future__ import annotations

import hashlib
import threading
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["THUMB_SIZE", "ExampleThumbnails", "example_thumbnail"]

#: thumbnail size in pixels
THUMB_SIZE = (96, 96)
#: groove depth (as a fraction of the face height) tinted in full colour
_TINT_DEPTH = 0.003
_GROOVE = np.array([0.32, 0.2, 0.66])  # violet: furrow
_CREST = np.array([1.0, 0.95, 0.88])  # pale: the skin bulging between furrows


def example_thumbnail(
    model: Any,
    blend: NDArray[np.float64],
    detailed: NDArray[np.float64],
    size: tuple[int, int] = THUMB_SIZE,
    scene: Any = None,
) -> bytes:
    """PNG of a detailed example: shaded, grooves tinted violet (wrinkles are sub-pixel at 96 px).

    Parameters
    ----------
    model : workbench.FaceModel
    blend, detailed : (n, 3) float
        The example's large-scale and detailed meshes
        (:meth:`model.wrinkles.example_detailed <workbench.methods.wrinkles.facet.WrinklesFacet.example_detailed>`).
    size : (width, height)
    scene : widgets.render._Scene, optional
        Built for ``model`` with RGB scalars: renders without building a
        plotter. Default: :func:`widgets.render.render_png`.
    """
    from widgets.render import _model_axes, render_png, vertex_colors
    from widgets.viewport import face_height
    from workbench.methods.wrinkles.features import vertex_normals

    _, front = _model_axes(model)
    base = vertex_colors(model, front).astype(np.float64) / 255.0
    h = np.sum((detailed - blend) * vertex_normals(blend, model.faces), axis=1)
    a = np.clip(np.abs(h) / (_TINT_DEPTH * face_height(model)), 0.0, 1.0)[:, None] * 0.85
    tint = np.where(h[:, None] < 0, _GROOVE, _CREST)
    rgb = np.clip((base * (1 - a) + a * tint) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if scene is None:
        return render_png(model, points=detailed, scalars=rgb, size=size, camera="face")
    scene.mesh.point_data["rgb"] = rgb
    scene.set_points(detailed)
    return bytes(scene.png())


class ExampleThumbnails:
    """One PNG per fitted example of ``model.wrinkles``, cached by the example's details and weights.

    VTK renders on the main thread only: called from another thread (an edit
    from a timer or a kernel subshell), examples that need a new picture keep
    their old one (or none) until the next call on the main thread.
    """

    def __init__(self, model: Any) -> None:
        self.model = model
        self._cache: dict[str, tuple[str, bytes]] = {}

    def _key(self, j: int) -> str:
        w = self.model.wrinkles
        ps = w.pose_space
        h = hashlib.blake2b(np.ascontiguousarray(ps.train_values[j]).tobytes(), digest_size=12)
        h.update(repr(sorted(w.example_weights[j].items())).encode())
        return h.hexdigest()

    def render(self, names: list[str]) -> dict[str, bytes]:
        """PNG of each example in ``names`` (fitted ones), re-rendered only where it changed."""
        out: dict[str, bytes] = {}
        todo = []
        main = threading.current_thread() is threading.main_thread()
        fitted = self.model.wrinkles.example_names
        for n in names:
            j = fitted.index(n)
            key = self._key(j)
            hit = self._cache.get(n)
            if hit is not None and (hit[0] == key or not main):
                out[n] = hit[1]
            elif main:
                todo.append((n, key))
        if todo:
            self._render(todo, out)
        return out

    def _render(self, todo: list[tuple[str, str]], out: dict[str, bytes]) -> None:
        from widgets.render import _Scene

        model = self.model
        blank = np.zeros((model.n_vertices, 3), np.uint8)
        scene = _Scene(model, np.asarray(model.vertices), size=THUMB_SIZE, camera="face",
                       scalars=blank, cmap=None, clim=None, background="white")
        try:
            for n, key in todo:
                X, D = model.wrinkles.example_detailed(n)
                png = example_thumbnail(model, X, D, scene=scene)
                self._cache[n] = (key, png)
                out[n] = png
        finally:
            scene.close()
