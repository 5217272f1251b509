"""The Regions panel's "Edit regions" box: rename, merge, split, paint.

Each edit is one ``model.regions`` call and one undo step on the selected
region of the shown level (see :mod:`workbench.methods.regions.edits` for the
rules): *Rename* (text + button); *Merge* with a touching region chosen in a
dropdown (the merged region keeps the larger one's name and weights);
*Split…*: markers spread over the region, click two and the region is cut
halfway between them along the surface (geodesic Voronoi; on coarser levels
whole finer regions are grouped); *Paint region*: markers over and around
the region, drag from one and a round brush (radius slider, "erase" to take
vertices out) assigns the skin under it to the region, one undo step per
stroke.

Split seeds and brush strokes come through the viewport's marker-drag hook
(:class:`~widgets.regions.tools.RegionSeedPicker`,
:class:`~widgets.regions.tools.RegionBrushHandler`): the viewport has no hook
that reports a plain click on the surface without adding a model handle;
:meth:`RegionEdits.pick_seed` and :meth:`RegionEdits.paint_at` take a vertex
id for when it has.
"""

from __future__ import annotations

import html
from typing import TYPE_CHECKING, Any

import ipywidgets as W
import numpy as np

from widgets.regions.tools import RegionBrushHandler, RegionSeedPicker

if TYPE_CHECKING:
    from widgets.regions.panel import RegionsPanel

#: Markers shown over the selected region in split mode (click two of them).
SPLIT_MARKERS = 24

#: Markers shown over and around the selected region in paint mode (drag from one).
PAINT_MARKERS = 40


def _default_brush_radius(model: Any) -> float:
    from widgets.viewport import default_brush_radius

    try:
        return float(default_brush_radius(model))
    except Exception:  # a degenerate mesh
        return 0.05


class RegionEdits:
    """The edit controls of a :class:`~widgets.regions.panel.RegionsPanel` (see the module docstring).

    Uses the panel's ``model``, ``errors``, ``selected()``, ``select_index()``,
    ``flush()``, ``active``, ``marker_mode``, ``drag_mode`` and
    ``update_status()``.
    """

    def __init__(self, panel: RegionsPanel) -> None:
        self.panel = panel
        model = panel.model
        self.model = model
        #: split seeds are picked, and the region brush painted, through the viewport's
        #: marker-drag hook, as the pin drags are (markers over the region)
        self.seed_picker = RegionSeedPicker(self.pick_seed, lambda: self.markers)
        self.brush_handler = RegionBrushHandler(model, self._brush_target)
        #: (m,) int vertex ids of the split / paint markers shown
        self.markers = np.zeros(0, np.int64)
        #: the last message of the edit status line (plain text)
        self.message = ""
        self._split_seeds: list[int] = []

        def button(desc: str, cls: str, tip: str) -> W.Button:
            b = W.Button(description=desc, tooltip=tip, layout=W.Layout(width="auto"))
            b.add_class(cls)
            return b

        self.rename_text = W.Text(value="", placeholder="new name", layout=W.Layout(width="180px"), disabled=True)
        self.rename_text.add_class("fwb-region-rename-text")
        self.rename_button = button("Rename", "fwb-region-rename", "Rename the selected region")
        self.merge_with = W.Dropdown(options=[], description="merge with", style={"description_width": "80px"},
                                     layout=W.Layout(width="260px"), disabled=True)  # fmt: skip
        self.merge_with.add_class("fwb-region-merge-with")
        self.merge_button = button(
            "Merge", "fwb-region-merge", "Merge the selected region with the touching one chosen"
        )
        self.split_mode = W.ToggleButton(value=False, description="Split…", icon="scissors",
                                         tooltip="Click two markers on the selected region: it is "
                                         "cut halfway between them along the surface",
                                         layout=W.Layout(width="110px"))  # fmt: skip
        self.split_mode.add_class("fwb-region-split")
        self.paint_mode = W.ToggleButton(value=False, description="Paint region", icon="paint-brush",
                                         tooltip="Drag from a marker to paint the selected region "
                                         "over the face (one undo step per stroke)",
                                         layout=W.Layout(width="130px"))  # fmt: skip
        self.paint_mode.add_class("fwb-region-paint")
        r0 = _default_brush_radius(model)
        self.paint_radius = W.FloatSlider(
            value=r0, min=r0 / 4, max=r0 * 4, step=r0 / 20, description="radius",
            readout_format=".3f", continuous_update=False,
            style={"description_width": "50px"}, layout=W.Layout(width="230px"),
        )  # fmt: skip
        self.paint_radius.add_class("fwb-region-paint-radius")
        self.paint_erase = W.Checkbox(value=False, description="erase", indent=False, layout=W.Layout(width="80px"))
        self.paint_erase.add_class("fwb-region-paint-erase")
        self.status = W.HTML("")
        self.status.add_class("fwb-region-edit-status")
        self.box = W.VBox(
            [
                W.HTML("<b>Edit regions</b> (the selected region, on the shown level)"),
                W.HBox([self.rename_text, self.rename_button]),
                W.HBox([self.merge_with, self.merge_button]),
                W.HBox([self.split_mode, self.paint_mode, self.paint_radius, self.paint_erase]),
                self.status,
            ],
            layout=W.Layout(width="100%", border="1px solid #ddd", padding="4px"),
        )
        self.box.add_class("fwb-region-edit")
        g = panel.errors.guard
        self.rename_button.on_click(g("rename region")(lambda _b: self.rename()))
        self.merge_button.on_click(g("merge regions")(lambda _b: self.merge()))
        self.split_mode.observe(g("split mode")(self._on_split_mode), "value")
        self.paint_mode.observe(g("paint mode")(self._on_paint_mode), "value")
        self.paint_radius.observe(g("brush radius")(self._on_brush_options), "value")
        self.paint_erase.observe(g("brush erase")(self._on_brush_options), "value")
        self.brush_handler.listeners.append(g("region brush stats")(self._on_stroke_end))

    # ------------------------------------------------------------ state
    @property
    def mode(self) -> str | None:
        """"split", "paint" or None (the pointer mode of this box)."""
        return "split" if self.split_mode.value else "paint" if self.paint_mode.value else None

    def set_disabled(self, disabled: bool) -> None:
        for w in (self.rename_text, self.rename_button, self.merge_with, self.merge_button,
                  self.split_mode, self.paint_mode):  # fmt: skip
            w.disabled = disabled

    def installed(self) -> bool:
        """True while the seed picker or the brush has the viewport's marker drags."""
        return self.panel.marker_mode.installed(self.seed_picker, self.brush_handler)

    def _brush_target(self) -> tuple[int, str] | None:
        sel = self.panel.selected()
        if sel is None:
            return None
        R, lv, r = sel
        return lv, R.names[lv][r]

    def say(self, text: str, error: bool = False) -> None:
        """Show ``text`` in the edit status line (red for an error)."""
        self.message = text
        esc = html.escape(text, quote=False)
        self.status.value = f"<span style='color:#b00020'>{esc}</span>" if error else esc

    def refresh(self) -> None:
        """Merge candidates, rename placeholder and edit-mode markers for the selection."""
        from workbench.methods.regions.topology import adjacent_regions

        self._split_seeds = []
        sel = self.panel.selected()
        if sel is None:
            self.merge_with.options = []
            self.merge_button.disabled = True
            self.rename_text.placeholder = "new name"
        else:
            R, lv, r = sel
            topo = self.model.regions.topology
            nb = adjacent_regions(R, topo, lv, r) if R.kinds[lv][r] == "skin" else []
            self.merge_with.options = [(R.names[lv][i], i) for i in nb]
            self.merge_with.value = nb[0] if nb else None
            self.merge_button.disabled = not nb
            self.rename_text.placeholder = R.names[lv][r]
        self.refresh_markers()

    # ------------------------------------------------------------ edits
    def rename(self, name: str | None = None) -> None:
        """Rename the selected region to ``name`` (default: the text box); one undo step."""
        sel = self.panel.selected()
        new = (self.rename_text.value if name is None else name).strip()
        if sel is None or not new:
            self.say("select a region and type its new name", error=True)
            return
        R, lv, r = sel
        self.panel.flush()
        try:
            self.model.regions.rename(lv, r, new)
        except ValueError as exc:
            self.say(str(exc), error=True)
            return
        self.rename_text.value = ""
        self.panel.select_index(r)
        self.say(f"renamed {R.names[lv][r]} to {new}")

    def merge(self, other: int | str | None = None) -> None:
        """Merge the selected region with ``other`` (default: the "merge with" choice); one undo step.

        The merged region keeps the lower index and the name and weights of the
        larger of the two (``model.regions.merge``).
        """
        sel = self.panel.selected()
        b = self.merge_with.value if other is None else other
        if sel is None or b is None:
            self.say("select a region and a touching region to merge with", error=True)
            return
        R, lv, r = sel
        self.panel.flush()
        try:
            bi = R.region_index(lv, b)
            st = self.model.regions.merge(lv, r, bi)
        except ValueError as exc:
            self.say(str(exc), error=True)
            return
        keep = min(r, bi)
        self.panel.select_index(keep)
        self.say(f"merged {R.names[lv][r]} and {R.names[lv][bi]} into {st.regions.names[lv][keep]}")

    def split(self, seed_a: int, seed_b: int) -> None:
        """Split the selected region between two vertices (geodesic Voronoi); one undo step."""
        sel = self.panel.selected()
        if sel is None:
            self.say("select a region to split", error=True)
            return
        R, lv, r = sel
        self.panel.flush()
        try:
            st = self.model.regions.split(lv, r, int(seed_a), int(seed_b))
        except ValueError as exc:
            self.say(str(exc), error=True)
            return
        self.panel.select_index(r)
        names = st.regions.names[lv]
        self.say(f"split {R.names[lv][r]} into {names[r]} and {names[r + 1]}")
        self.split_mode.value = False

    def pick_seed(self, vertex: int) -> None:
        """A click on the face in split mode: the first picks seed A, the second splits.

        What a press on a split-mode marker does (and what a future viewport
        click hook would call with the vertex under the pointer).
        """
        sel = self.panel.selected()
        if sel is None:
            self.say("select a region to split", error=True)
            return
        R, lv, r = sel
        v = int(vertex)
        if R.labels[lv][v] != r:
            self.say(f"vertex {v} is not in {R.names[lv][r]}: click a marker on it", error=True)
            return
        if self._split_seeds and self._split_seeds[0] == v:
            return  # the same marker again
        self._split_seeds.append(v)
        if len(self._split_seeds) == 1:
            self.say(f"split {R.names[lv][r]}: first point at vertex {v}; click a second marker")
            return
        a, b = self._split_seeds[:2]
        self._split_seeds = []
        self.split(a, b)

    def paint_at(self, vertex: int) -> int:
        """One dab of the region brush at ``vertex`` (its own undo step outside a stroke).

        Returns the number of vertices whose label changed; a refused dab shows
        its reason in the edit status and returns 0.
        """
        self.panel.flush()
        h = self.brush_handler
        changed = h.dab(int(vertex))
        if h.last_error:
            self.say(h.last_error, error=True)
        else:
            tgt = self._brush_target()
            verb = "erased from" if h.erase else "painted into"
            self.say(f"{changed} vertices {verb} {tgt[1] if tgt else '?'}")
        return changed

    def _on_stroke_end(self, stats: dict[str, Any]) -> None:
        verb = "erased from" if stats["erase"] else "painted into"
        msg = f"{stats['changed']} vertices {verb} {stats['name']} ({stats['dabs']} dabs)"
        if stats["error"]:
            self.say(f"{msg}; last dab refused: {stats['error']}", error=True)
        else:
            self.say(msg)
        st = self.model.regions.state
        if st is not None and stats["name"] in st.regions.names[st.level]:
            self.panel.select_index(st.regions.names[st.level].index(stats["name"]))
        self.refresh_markers()

    def _on_brush_options(self, _change: Any = None) -> None:
        self.brush_handler.radius = float(self.paint_radius.value)
        self.brush_handler.erase = bool(self.paint_erase.value)
        self.refresh_markers()

    # ------------------------------------------------------------ pointer modes
    def refresh_markers(self) -> None:
        """Markers of the current mode over (and, painting, around) the selected region."""
        from workbench.methods.regions.drag import region_markers

        mode = self.mode
        if mode is None or self.brush_handler.dragging:
            return  # (markers never change under a stroke: the drag addresses them by index)
        sel = self.panel.selected()
        if sel is None:
            self.markers = np.zeros(0, np.int64)
        elif mode == "split":
            self.markers = region_markers(self.model, sel[1], sel[2], SPLIT_MARKERS)
        else:  # the region and a band of three brush radii around it
            band = 3.0 * float(self.paint_radius.value)
            self.markers = region_markers(self.model, sel[1], sel[2], PAINT_MARKERS, band=band)
        if self.installed():
            self.panel.marker_mode.show(self.markers)
        self.panel.update_status()

    def _on_split_mode(self, change: Any) -> None:
        if change["new"]:
            self.panel.drag_mode.value = False  # one pointer mode at a time
            self.paint_mode.value = False
            self._split_seeds = []
            sel = self.panel.selected()
            if sel is not None:
                R, lv, r = sel
                self.say(f"split {R.names[lv][r]}: click two markers on it")
            self.enter()
        else:
            self._split_seeds = []
            if not self.paint_mode.value:
                self.leave()

    def _on_paint_mode(self, change: Any) -> None:
        if change["new"]:
            self.panel.drag_mode.value = False
            self.split_mode.value = False
            self._on_brush_options()
            self.say("drag from a marker to paint the selected region (tick erase to remove)")
            self.enter()
        elif not self.split_mode.value:
            self.leave()

    def enter(self) -> None:
        """Hand the viewport's marker drags to the seed picker or the brush (if the panel is active)."""
        if self.mode is None:
            return
        handler = self.seed_picker if self.mode == "split" else self.brush_handler
        self.refresh_markers()
        if not self.panel.active:
            return
        self.panel.marker_mode.install(handler, self.markers, before=self.panel.flush)
        self.panel.update_status()

    def leave(self) -> None:
        """End an open stroke and give the viewport back."""
        self.brush_handler.end()
        if self.installed():
            self.panel.marker_mode.release()
            self.panel.update_status()
