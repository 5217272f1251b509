"""The composed app: one viewport beside the tabs of panels, the timeline, undo/redo and a status line.

:class:`Workbench` builds the panels over one :class:`workbench.FaceModel`
and wires them to the shared viewport; :func:`show_workbench` displays it.
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import Any

import ipywidgets as W
import traitlets

from widgets._iopub import keep_every_iopub_message
from widgets._threading import ErrorSink, UiScheduler, close_interactions
from widgets.gallery import ExpressionGallery
from widgets.panels import ExpressionPanel, UndoRedoButtons
from widgets.tabs import TabSpec, tab_specs
from widgets.timeline import TimelineWidget
from widgets.viewport import Viewport

__all__ = ["PALETTE_COLUMNS", "PALETTE_THUMB_SIZE", "TAB_TITLES", "Workbench", "show_workbench"]

#: the registered tabs' titles, in order (:mod:`widgets.tabs`)
TAB_TITLES = tuple(spec.title for spec in tab_specs())
#: thumbnail size and columns of the expression palette (Paint tab, timeline chips)
PALETTE_THUMB_SIZE = (72, 72)
PALETTE_COLUMNS = 7


class Workbench(W.VBox):
    """The composed app: one viewport over one model, tabs of tools, timeline, status line.

    Layout: a top bar (Undo / Redo, a *Wireframe* checkbox — view state linked
    to ``viewport.wireframe``, not an undoable edit — and the status line), then the viewport
    beside a tab of panels ("Shapes", "Sculpt", "Regions", "Paint", "Export"),
    the :class:`TimelineWidget` under the viewport, and the shared error
    Output at the bottom (every panel reports callback errors there).

    The Shapes tab holds the :class:`ExpressionPanel` (blendshape sliders) and,
    under it, the :class:`~widgets.panels.shape_tools.ShapeToolsPanel` (split
    L/R with a preview on the viewport, mirror, corrective shapes), whose shape
    follows the last slider touched; leaving the tab ends the split preview.

    Selecting "Sculpt" switches the viewport to its sculpt tool (drag handle
    markers), "Paint" to its paint tool (brush strokes); the other tabs orbit.
    The Sculpt tab holds the :class:`SculptPanel` and, under it, the
    :class:`WrinklePanel` (pose-space wrinkles while dragging; its *Erase
    wrinkles* toggle brushes with the paint tool without leaving the tab).
    "Regions" activates its panel (colour overlay, and the pin drag mode, which
    itself switches the viewport to the sculpt tool without leaving the tab)
    and deactivates it when another tab is selected. The Regions and Paint
    panels are built the first time their tab is opened (segmentation and the
    palette thumbnails take seconds), or when :attr:`regions` / :attr:`paint`
    is read.

    The expression palette (:attr:`gallery`, thumbnails of the saved
    expressions and blendshapes) is rendered once and shared: the Paint tab
    shows it and the timeline's expression chips show its pictures (drag one
    onto the timeline to key it; the timeline's "Key selected expression"
    button keys the palette's pick). In a kernel it is built right after the
    cell that made the workbench (on the kernel's event loop, so the app shows
    at once and the chips get their pictures a moment later); without a
    running event loop it is built when :attr:`gallery` or :attr:`paint` is
    first read, and until then the chips are text.

    Parameters
    ----------
    model : workbench.FaceModel
    autosave : str, optional
        Session name: creates a :class:`workbench.autosave.Autosaver` saving the
        model atomically a few seconds after each edit; :meth:`close` stops it.
    autosave_delay : float
        Seconds of quiet before an autosave.
    autosave_folder : path, optional
        Default: the recovery folder (``$WORKBENCH_RECOVERY_DIR``).
    height : int
        Viewport height in pixels.

    Attributes
    ----------
    panel : ExpressionPanel
    shape_tools : ShapeToolsPanel
    wrinkles : WrinklePanel
    gallery : ExpressionGallery
        The expression palette (built on first use, see above).
    wireframe : ipywidgets.Checkbox
        Top-bar toggle of the viewport's triangle-edge overlay (``viewport.wireframe``).
    status : ipywidgets.HTML
        "N vertices · last drag X ms (Y updates/s) · undo depth D · saved 12:03:04".
    autosaver : workbench.autosave.Autosaver or None
    """

    def __init__(
        self,
        model: Any,
        *,
        autosave: str | None = None,
        autosave_delay: float = 2.0,
        autosave_folder: Any = None,
        height: int = 520,
    ) -> None:
        self.model = model
        keep_every_iopub_message()  # about 1,500 messages follow; a page that connected late
        self.errors = W.Output(layout=W.Layout(max_height="160px", overflow="auto"))
        self.errors.add_class("fwb-errors")
        self.sink = ErrorSink(self.errors)
        self.viewport = Viewport(model, height=height, errors=self.errors)
        # its own height in the column: growing with a tall tool panel only left a gap
        # between the canvas and the timeline
        self.viewport.layout = W.Layout(flex="0 0 auto", min_width="320px")
        self.panel = ExpressionPanel(
            model, errors=self.errors, max_height=f"{max(height - 200, 240)}px"
        )
        # the page plays the shape sliders at once (GPU path), before the kernel answers
        self.viewport.follow_sliders(self.panel.sliders)
        self.panel.observe(lambda _ch: self.viewport.follow_sliders(self.panel.sliders), "sliders_version")
        self.timeline = TimelineWidget(model, errors=self.errors)
        self._gallery: ExpressionGallery | None = None
        self._switching = False
        # the tabs, from the registry: eager ones built now, lazy ones when shown or read
        self.tab_specs: tuple[TabSpec, ...] = tab_specs()
        #: every built panel by attribute name (``wb.regions`` reads it)
        self.panels: dict[str, Any] = {}
        self._built: set[str] = set()
        self._slots: dict[str, W.VBox] = {}
        children = []
        for spec in self.tab_specs:
            if spec.lazy:
                slot = W.VBox([W.HTML(f"<i>{spec.lazy}</i>")])
                self._slots[spec.title] = slot
                children.append(slot)
            else:
                children.append(self._build_tab(spec))
        self.tabs = W.Tab(
            children=children,
            titles=[spec.title for spec in self.tab_specs],
            layout=W.Layout(flex="0 0 650px", width="650px"),
        )
        self.tabs.add_class("fwb-tabs")

        g = self.sink.guard
        self.history_buttons = UndoRedoButtons(
            model,
            on_undo=self.undo,
            on_redo=self.redo,
            classes=("fwb-wb-undo", "fwb-wb-redo"),
            width="auto",
            errors=self.sink,
            where="Workbench",
        )
        self.undo_button, self.redo_button = self.history_buttons.buttons
        # View state, not a model edit (no undo step): linked to the viewport's trait.
        self.wireframe = W.Checkbox(
            value=bool(self.viewport.wireframe),
            description="Wireframe",
            indent=False,
            tooltip="Draw the triangle edges over the shaded surface",
            layout=W.Layout(width="auto"),
        )
        self.wireframe.add_class("fwb-wb-wireframe")
        self._wireframe_link = traitlets.link(
            (self.wireframe, "value"), (self.viewport, "wireframe")
        )
        self.status = W.HTML()
        self.status.add_class("fwb-wb-status")
        # what the (built) tabs show over the viewport too, e.g. the Enhanced preview box (one widget, two views)
        extra = [w for spec in self.tab_specs if spec.topbar is not None and spec.title in self._built
                 for w in spec.topbar(self)]
        top = W.HBox(
            [self.undo_button, self.redo_button, self.wireframe, *extra, self.status],
            layout=W.Layout(width="100%", align_items="center", grid_gap="6px"),
        )
        top.add_class("fwb-topbar")

        self.autosaver: Any = None
        if autosave is not None:
            from workbench.autosave import Autosaver

            # timer and snapshot on the kernel's loop, state changes back on the UI thread
            self.autosaver = Autosaver(
                model, autosave, delay=autosave_delay, folder=autosave_folder, scheduler=UiScheduler()
            )
            self._cb_autosave = g("Workbench autosave status")(self._on_autosave)
            self.autosaver.changed.connect(self._cb_autosave)

        self.tabs.observe(g("switching tabs")(self._on_tab), "selected_index")
        self.viewport.observe(g("viewport tool")(self._on_tool), "tool")
        self._cb_history = g("Workbench history")(self.update_status)
        model.events.history.connect(self._cb_history)
        self._cb_drag = g("Workbench drag stats")(self._on_drag)
        self.viewport.drag_listeners.append(self._cb_drag)

        left = W.VBox(
            [self.viewport, self.timeline], layout=W.Layout(flex="1 1 auto", min_width="320px")
        )
        row = W.HBox([left, self.tabs], layout=W.Layout(width="100%"))
        super().__init__([top, row, self.errors], layout=W.Layout(width="100%"))
        self.add_class("fwb-workbench")
        self.update_status()
        self._schedule_gallery()

    # ------------------------------------------------------------ tabs and their panels
    def _build_tab(self, spec: TabSpec) -> Any:
        keep_every_iopub_message()  # a tab's panel is a burst of its own
        widget, panels = spec.build(self)
        self.panels.update(panels)
        self._built.add(spec.title)
        return widget

    def _ensure_built(self, spec: TabSpec) -> None:
        if spec.title not in self._built:
            self._slots[spec.title].children = [self._build_tab(spec)]

    def panel_built(self, name: str) -> bool:
        """Whether the tab holding panel ``name`` (``"regions"``) has been built yet."""
        return name in self.panels

    def __getattr__(self, name: str) -> Any:
        # a tab's panel by name (wb.regions, wb.paint, wb.capture ...): a lazy tab is built on first read
        if not name.startswith("_") and "tab_specs" in self.__dict__:
            panels = self.__dict__["panels"]
            if name in panels:
                return panels[name]
            for spec in self.__dict__["tab_specs"]:
                if name in spec.attrs:
                    self._ensure_built(spec)
                    return panels[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def gallery(self) -> ExpressionGallery:
        """The expression palette shared by the Paint tab and the timeline's chips (built once)."""
        if self._gallery is None:
            self._gallery = ExpressionGallery(
                self.model,
                size=PALETTE_THUMB_SIZE,
                columns=PALETTE_COLUMNS,
                expressions=True,
                label_size="10px",
            )
            self.timeline.set_gallery(self._gallery)
        return self._gallery

    def _schedule_gallery(self) -> None:
        # In a kernel: render the palette once the current cell is done (the app is
        # already on screen), so the timeline chips get their pictures without the
        # Paint tab being opened and without delaying the workbench itself.
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return  # no event loop (a script, a test): built on first use

        def build() -> None:
            if not getattr(self, "_closed", False):
                self.gallery  # noqa: B018 - builds the palette

        loop.call_soon(self.sink.guard("rendering the expression thumbnails")(build))

    # ------------------------------------------------------------ tabs <-> tool
    def _on_tab(self, change: dict) -> None:
        self._switching = True  # tool changes made here must not move the tab again
        try:
            # the page gets the tool the switch ends with, not the tab's default on the way
            # (Regions in drag mode: orbit, then sculpt) - one message, no flicker
            with self.viewport.hold_sync():
                self._switch_tab(change["old"], change["new"])
        finally:
            self._switching = False

    def _switch_tab(self, old: int | None, new: int | None) -> None:
        specs = self.tab_specs
        if old is not None and 0 <= old < len(specs):
            spec = specs[old]
            if spec.on_hide is not None and spec.title in self._built:
                spec.on_hide(self)
        if new is None or not 0 <= new < len(specs):
            return
        spec = specs[new]
        self.viewport.tool = spec.tool
        try:
            self._ensure_built(spec)
            if spec.on_show is not None:
                spec.on_show(self)
        except Exception as exc:
            self.sink.report(f"building the {spec.title} tab", exc)

    def _on_tool(self, change: dict) -> None:
        # The tool changed from elsewhere (front end, code, a tab's own mode): follow
        # it with the tab, unless the current tab already explains it.
        i = self.tabs.selected_index
        specs = self.tab_specs
        if self._switching or i is None or not 0 <= i < len(specs):
            return
        spec = specs[i]
        if spec.tool == change["new"] or (spec.owns_tool is not None and spec.owns_tool(self, change["new"])):
            return
        for j, other in enumerate(specs):
            if other.tool == change["new"]:
                self.tabs.selected_index = j
                return

    # ------------------------------------------------------------ undo / redo
    def undo(self) -> str | None:
        """Undo the model's last step (the top bar's Undo); its label, or None.

        ``model.undo`` refuses to run inside an interaction: every open one ends
        first (slider bursts of all panels, a handle drag or paint stroke, a
        region pin drag).
        """
        close_interactions(self.model)
        return self.model.undo() if self.model.can_undo else None

    def redo(self) -> str | None:
        """Redo the model's last undone step (the top bar's Redo); its label, or None."""
        close_interactions(self.model)
        return self.model.redo() if self.model.can_redo else None

    # ------------------------------------------------------------ status line
    def _on_drag(self, _stats: dict) -> None:
        self.update_status()

    def _on_autosave(self, _state: str) -> None:
        self.update_status()

    def autosave_text(self) -> str:
        """ "saved 12:03:04", "pending", "error: ...", "not saved yet" or "off"."""
        a = self.autosaver
        if a is None:
            return "off"
        state = a.state
        if state == "saved" and a.last_saved is not None:
            return "saved " + time.strftime("%H:%M:%S", time.localtime(a.last_saved))
        if state == "idle":
            return "no edits yet"
        return str(state)

    def status_text(self) -> str:
        """The status line as plain text (also what :attr:`status` shows)."""
        parts = [f"{self.model.n_vertices} vertices"]
        drag = getattr(self.viewport, "last_drag", None) or {}
        if drag:
            ms, ups = drag.get("last_ms", math.nan), drag.get("updates_per_s", math.nan)
            fps = f" ({ups:.0f} updates/s)" if math.isfinite(ups) else ""
            parts.append(f"last drag {ms:.1f} ms{fps}")
        else:
            parts.append("last drag –")
        parts.append(f"undo depth {len(self.model.history.undo_labels)}")
        parts.append(f"autosave: {self.autosave_text()}")
        return " · ".join(parts)

    def update_status(self) -> None:
        """Recompute :attr:`status` (called on history, drag and autosave events)."""
        text = self.status_text()
        colour = "#b00" if "error" in text else "#555"
        self.status.value = f"<span style='color:{colour};font-size:12px'>{text}</span>"

    # ------------------------------------------------------------ closing
    def close(self, *, discard_autosave: bool = False) -> None:
        """Disconnect everything and close the widgets.

        The autosaver is stopped after a last save of pending edits, and its
        recovery file is kept unless ``discard_autosave`` (the user saved the
        model properly).
        """
        if getattr(self, "_closed", False):
            return
        self._closed = True
        a = self.autosaver
        if a is not None:
            a.changed.disconnect(self._cb_autosave)
            if a.state == "pending" and not discard_autosave:
                a.save_now()
            a.close(discard=discard_autosave)
        self.model.events.history.disconnect(self._cb_history)
        self.history_buttons.close()
        self._wireframe_link.unlink()
        if self._cb_drag in self.viewport.drag_listeners:
            self.viewport.drag_listeners.remove(self._cb_drag)
        for spec in self.tab_specs:
            if spec.close is not None and spec.title in self._built:
                spec.close(self)
        for panel in self.panels.values():
            panel.close()
        self.timeline.close()
        if self._gallery is not None:
            self._gallery.close()
        self.viewport.close()
        self.panel.close()
        self.errors.close()
        super().close()


def show_workbench(model: Any, **kwargs: Any) -> Workbench:
    """Display a :class:`Workbench` for ``model`` and return it.

    Assign the result (``wb = show_workbench(m)``): as the last bare expression
    of a cell it would be displayed a second time.
    """
    from IPython.display import display

    wb = Workbench(model, **kwargs)
    display(wb)
    return wb
