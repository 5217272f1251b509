"""``RigGallery``: before / after pictures of chosen shapes: template, transferred, refined.

One row per shape: the template at weight 1, the same shape transferred onto
your face and, after the refinement, refined; all front views framed on the
face the shapes move (:func:`widgets.gallery.cached_thumbnails`, offscreen
pyvista: a picture is rendered once per shape and result). The shapes are the
ones picked in the quality report (flagged shapes first) plus a few that show a
face best (jaw, smile, blink, brows); *Render* redraws after a stage.
"""

from __future__ import annotations

import html
from typing import Any

import ipywidgets as W

from widgets.gallery import cached_thumbnails
from widgets.panels.base import ModelPanel, button

__all__ = ["DEFAULT_SHAPES", "RigGallery"]

#: shapes shown by default (those the template has)
DEFAULT_SHAPES = ("jawOpen", "mouthSmileLeft", "eyeBlinkLeft", "browInnerUp")


class RigGallery(ModelPanel):
    """Before / after thumbnails (see the module docstring).

    Parameters
    ----------
    session : workbench.rigging.RigSession
    errors : ipywidgets.Output or ErrorSink, optional
    size : (int, int)
        Thumbnail size in pixels.
    max_shapes : int
        Rows kept (the most recently picked shapes first).

    Attributes
    ----------
    shapes : list of str
    grid : ipywidgets.GridBox
    """

    def __init__(self, session: Any, *, errors: Any = None, size: tuple[int, int] = (150, 150),
                 max_shapes: int = 6) -> None:
        super().__init__(session, errors=errors, layout=W.Layout(width="100%"))
        self.session = session
        self.size = size
        self.max_shapes = max_shapes
        names = set(session.template.shape_names)
        self.shapes: list[str] = [n for n in DEFAULT_SHAPES if n in names] or list(session.template.shape_names[:4])
        self.grid = W.GridBox(layout=W.Layout(grid_template_columns=f"160px repeat(3, {size[0] + 8}px)"))
        self.grid.add_class("fwb-rig-gallery")
        self.render_button = button("Render", "fwb-rig-render", "Draw the pictures of the current results", "image")
        self.render_button.on_click(self.guard("render gallery")(lambda _b: self.render()))
        self.children = [self.render_button, self.grid]
        self.listen(session.events.stages, self.render, "gallery")
        self.render()

    def add_shape(self, name: str, *, render: bool = True) -> None:
        """Show ``name`` first (keeping at most ``max_shapes`` rows)."""
        if name not in self.session.template.shape_names:
            raise KeyError(f"the template has no shape {name!r}")
        self.shapes = [name, *[n for n in self.shapes if n != name]][: self.max_shapes]
        if render:
            self.render()

    def columns(self) -> list[tuple[str, Any]]:
        """(title, model) of each column: the template, then every stage's rig so far."""
        s = self.session
        cols: list[tuple[str, Any]] = [("template", s.template)]
        if s.state.transferred is not None:
            cols.append(("transferred", s.state.transferred))
        if s.refined is not None:
            cols.append(("refined", s.refined.model))
        return cols

    def render(self) -> None:
        """Draw every row of every column (cached pictures are reused)."""
        cols = self.columns()
        pictures = [cached_thumbnails(m, self.shapes, self.size, camera="face") for _, m in cols]
        cells: list[W.Widget] = [W.HTML("")]
        for title, _ in cols:
            cells.append(W.HTML(f"<b>{html.escape(title)}</b>"))
        cells += [W.HTML("") for _ in range(3 - len(cols))]
        for name in self.shapes:
            cells.append(W.HTML(html.escape(name)))
            for pics in pictures:
                img = W.Image(value=pics[name], format="png", width=self.size[0], height=self.size[1])
                img.add_class("fwb-rig-thumb")
                cells.append(img)
            cells += [W.HTML("") for _ in range(3 - len(cols))]
        self.grid.children = cells
