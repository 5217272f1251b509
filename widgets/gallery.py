"""Expression gallery: a grid of blendshape thumbnails to pick from.

Each blendshape is shown as a small offscreen render (see
:func:`widgets.render.expression_thumbnails`) with a button carrying its name;
clicking the button selects the shape. The selection is a traitlet
(``gallery.selected``) so other widgets can ``observe`` or ``link`` to it, and
:meth:`ExpressionGallery.on_select` takes plain callbacks. Later tools use the
gallery as the paint palette and the timeline's shape source.

Why hand-written: ipywidgets has no image-grid picker, and ``ipywidgets.Image``
has no click event (ipyevents would add a front-end extension); a button under
each picture works in every Jupyter front end and in Voila.

Thumbnails are cached in-process by (shape name, delta hash, neutral-mesh hash,
size, camera), so rebuilding the gallery or editing one shape re-renders only
what changed.

With ``expressions=True`` (the paint palette of :class:`widgets.PaintPanel`) the
gallery shows every *expression* (:func:`workbench.methods.paint.expressions.expression_names`):
the saved expressions first, then the blendshapes, and follows
``model.events.expressions`` so an expression saved from any cell appears at once.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any

import ipywidgets as ipw
import numpy as np
import traitlets

from widgets.render import delta_hash, expression_thumbnails, render_png
from workbench import FaceModel
from workbench.methods.paint.expressions import expression_names

__all__ = ["ExpressionGallery", "cached_thumbnails", "clear_thumbnail_cache"]

_CACHE_LIMIT = 4096
_CACHE: OrderedDict[tuple, bytes] = OrderedDict()


def _mesh_key(model: FaceModel) -> str:
    """Hash of what a thumbnail depends on besides the delta: neutral, faces, components."""
    h = hashlib.blake2b(digest_size=12)
    for arr in (model.vertices, model.faces, model.component_labels):
        h.update(np.ascontiguousarray(arr).tobytes())
    h.update("\0".join(model.component_names).encode())
    h.update(f"{model.metadata.up_axis}{model.metadata.front_axis}".encode())
    return h.hexdigest()


def clear_thumbnail_cache() -> None:
    """Forget all cached thumbnails."""
    _CACHE.clear()


def cached_thumbnails(
    model: FaceModel,
    names: Sequence[str] | None = None,
    size: tuple[int, int] = (96, 96),
    *,
    camera: str = "face",
    progress: bool = False,
) -> dict[str, bytes]:
    """Like :func:`widgets.render.expression_thumbnails`, but cached.

    Only shapes whose (name, effective delta) were not rendered before for this
    neutral mesh, size and camera are rendered (with one plotter).

    Returns
    -------
    dict[str, bytes]
        Name to PNG bytes, in the order of ``names`` (default all shapes).
    """
    wanted = list(model.shape_names) if names is None else list(names)
    mesh_key = _mesh_key(model)
    keys = {}
    for name in wanted:
        shape = model.shape(name)
        keys[name] = (
            name,
            delta_hash(shape.effective_delta()),
            mesh_key,
            tuple(size),
            camera,
        )
    missing = [n for n in wanted if keys[n] not in _CACHE]
    if missing:
        fresh = expression_thumbnails(model, missing, size=size, camera=camera, progress=progress)
        for name, png in fresh.items():
            _CACHE[keys[name]] = png
    out = {}
    for name in wanted:
        _CACHE.move_to_end(keys[name])
        out[name] = _CACHE[keys[name]]
    while len(_CACHE) > _CACHE_LIMIT:
        _CACHE.popitem(last=False)
    return out


def saved_expression_thumbnails(
    model: FaceModel,
    names: Sequence[str],
    size: tuple[int, int] = (96, 96),
    *,
    camera: str = "face",
) -> dict[str, bytes]:
    """Cached thumbnails of saved expressions (``model.expressions``), in the order of ``names``.

    Rendered like the blendshape thumbnails (same camera framed on the neutral,
    same lights), from the expression's stored displacement.
    """
    mesh_key = _mesh_key(model)
    neutral = np.asarray(model.vertices, dtype=np.float64)
    out = {}
    for name in names:
        disp = model.expressions[name].displacement
        key = ("expression:" + name, delta_hash(disp), mesh_key, tuple(size), camera)
        if key not in _CACHE:
            _CACHE[key] = render_png(
                model, points=neutral + disp.astype(np.float64), size=size, camera=camera
            )
        _CACHE.move_to_end(key)
        out[name] = _CACHE[key]
    while len(_CACHE) > _CACHE_LIMIT:
        _CACHE.popitem(last=False)
    return out


class ExpressionGallery(ipw.VBox):
    """Grid of blendshape thumbnails; click a name to select that shape.

    Parameters
    ----------
    model : FaceModel
    size : (width, height) int
        Thumbnail size in pixels.
    columns : int
        Thumbnails per row.
    names : sequence of str, optional
        Shapes to show (default: all, in model order, following shape edits).
    camera : str
        Camera preset for the thumbnails (see :func:`widgets.render.render_png`).
    label_size : str, optional
        CSS font size of the name buttons (e.g. ``"10px"`` so long names fit
        small thumbnails); default the theme's.
    expressions : bool
        Also show the saved expressions (first, marked with a star) and follow
        ``model.events.expressions``; ``names`` may then name them too.

    Attributes
    ----------
    selected : str or None
        Name of the selected shape (a traitlet: ``observe``/``link`` it).
    thumbnails : dict[str, bytes]
        The PNG bytes currently shown (a traitlet, not synced: ``observe`` it to
        follow new pictures, as the timeline's expression chips do).
    """

    selected = traitlets.Unicode(None, allow_none=True)
    thumbnails = traitlets.Dict(value_trait=traitlets.Bytes())

    def __init__(
        self,
        model: FaceModel,
        *,
        size: tuple[int, int] = (96, 96),
        columns: int = 8,
        names: Sequence[str] | None = None,
        camera: str = "face",
        expressions: bool = False,
        label_size: str | None = None,
        **kwargs: Any,
    ) -> None:
        if columns < 1:
            raise ValueError(f"ExpressionGallery: columns must be >= 1, got {columns}")
        self.model = model
        self.size = (int(size[0]), int(size[1]))
        self.columns = int(columns)
        self.camera = camera
        self.expressions = bool(expressions)
        self.label_size = label_size
        self._names_fixed = list(names) if names is not None else None
        self._cells: dict[str, tuple[ipw.Image, ipw.Button]] = {}
        self._tiles: dict[str, ipw.VBox] = {}
        self._handlers: dict[Callable, Callable] = {}
        self._title = ipw.HTML("<b>Expressions</b>")
        self._grid = ipw.GridBox(
            layout=ipw.Layout(
                grid_template_columns=f"repeat({self.columns}, {self.size[0] + 8}px)",
                grid_gap="4px",
            )
        )
        super().__init__([self._title, self._grid], **kwargs)
        self.add_class("fw-expression-gallery")
        self.refresh()
        # shape edits (added/removed/renamed/new deltas) re-render what changed
        model.events.shapes.connect(self.refresh)
        if self.expressions:
            model.events.expressions.connect(self.refresh)

    # ---------------------------------------------------------------- public
    @property
    def names(self) -> list[str]:
        """Shape names shown, in grid order."""
        return list(self._cells)

    def refresh(self) -> None:
        """Re-read the model's shapes and rebuild the grid (cached thumbnails are reused)."""
        model = self.model
        available = expression_names(model) if self.expressions else list(model.shape_names)
        names = self._names_fixed
        if names is None:
            names = available
        else:
            names = [n for n in names if n in available]
        saved = [n for n in names if self.expressions and n in model.expressions]
        shapes = [n for n in names if n not in saved]
        pngs = cached_thumbnails(model, shapes, self.size, camera=self.camera)
        if saved:
            pngs.update(saved_expression_thumbnails(model, saved, self.size, camera=self.camera))
        self.thumbnails = {n: pngs[n] for n in names}
        # Reuse the tiles of names still shown (a saved expression must not re-send
        # every picture to the browser); only new or changed pictures are sent.
        old_cells, old_tiles = self._cells, self._tiles
        cells = []
        self._cells, self._tiles = {}, {}
        w, h = self.size
        for name, png in self.thumbnails.items():
            label = f"★ {name}" if name in saved else name
            if name in old_tiles and old_cells[name][1].description == label:
                img, btn = old_cells[name]
                tile = old_tiles[name]
                if img.value != png:
                    img.value = png
            else:
                img = ipw.Image(value=png, format="png", width=w, height=h)
                img.layout = ipw.Layout(
                    width=f"{w}px", height=f"{h}px", border="2px solid transparent"
                )
                tip = f"saved expression {name}" if name in saved else name
                btn = ipw.Button(
                    description=label,
                    tooltip=tip,
                    layout=ipw.Layout(
                        width=f"{w + 4}px", padding="0 2px" if self.label_size else None
                    ),
                )
                if self.label_size:
                    btn.style.font_size = self.label_size
                btn.add_class("fw-thumb-button")
                btn.on_click(lambda _b, n=name: self.select(n))
                tile = ipw.VBox([img, btn], layout=ipw.Layout(align_items="center"))
            self._cells[name] = (img, btn)
            self._tiles[name] = tile
            cells.append(tile)
        self._grid.children = cells
        self._title.value = f"<b>Expressions</b> ({len(cells)})"
        if self.selected is not None and self.selected not in self._cells:
            self.selected = None
        self._highlight(self.selected)

    def select(self, name: str | None) -> None:
        """Select a shape by name (``None`` clears the selection)."""
        if name is not None and name not in self._cells:
            raise KeyError(f"ExpressionGallery.select: {name!r} is not shown; shown: {self.names}")
        self.selected = name

    def on_select(self, callback: Callable[[str | None], Any], remove: bool = False) -> None:
        """Call ``callback(name)`` whenever the selection changes (``remove=True`` unregisters)."""
        handler = self._handlers.get(callback)
        if remove:
            if handler is not None:
                self.unobserve(handler, names="selected")
                del self._handlers[callback]
            return
        if handler is None:

            def handler(change: dict[str, Any]) -> None:
                callback(change["new"])

            self._handlers[callback] = handler
            self.observe(handler, names="selected")

    def close(self) -> None:
        self.model.events.shapes.disconnect(self.refresh)
        if self.expressions:
            self.model.events.expressions.disconnect(self.refresh)
        super().close()

    # --------------------------------------------------------------- private
    @traitlets.observe("selected")
    def _on_selected(self, change: dict[str, Any]) -> None:
        self._highlight(change["new"])

    def _highlight(self, name: str | None) -> None:
        for n, (img, btn) in self._cells.items():
            on = n == name
            btn.button_style = "info" if on else ""
            img.layout.border = "2px solid #2196f3" if on else "2px solid transparent"
