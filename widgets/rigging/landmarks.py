"""``LandmarkPicker``: the template and the target side by side, linked, to click landmark pairs.

Two :class:`~widgets.viewport.Viewport` s in one ``camera_group`` (orbit or zoom
one and the other follows, in the browser). A click on one face's surface marks a
point there (highlighted); a click on the other face completes the pair, which
goes to :meth:`workbench.rigging.RigSession.add_landmark` (with *Mirror*, its
mirror pair too: one undo step). The pairs are drawn as markers on both faces;
picking a pair in the list, or dragging its marker, highlights it on both. A drag
moves that end of the pair to the vertex nearest where it is dropped
(``session.move_landmark``); Alt-click on a marker removes its pair. *Suggest*
adds automatic pairs (named template points placed where the non-rigid fit puts
them, :meth:`~workbench.rigging.RigSession.suggest_landmarks`).

The views never edit the models they show: clicks and drags go to the picker
(``viewport.pick_handler`` / ``drag_handler``), which edits the session.
"""

from __future__ import annotations

import html
import uuid
from typing import Any

import ipywidgets as W
import numpy as np
from scipy.spatial import cKDTree

from widgets.panels.base import ModelPanel, button
from widgets.panels.progress import ProgressRow
from widgets.viewport import Viewport

__all__ = ["LandmarkPicker"]

SIDES = ("template", "target")


class _Clicks:
    """``viewport.pick_handler`` of one side: surface clicks and marker Alt-clicks."""

    def __init__(self, picker: LandmarkPicker, side: str) -> None:
        self.picker, self.side = picker, side

    def pick(self, vertex: int) -> None:
        self.picker.pick(self.side, vertex)

    def remove(self, index: int, vertex: int | None = None) -> None:
        self.picker.remove_marker(self.side, index)


class _Drag:
    """``viewport.drag_handler`` of one side: a marker dragged to another vertex."""

    def __init__(self, picker: LandmarkPicker, side: str) -> None:
        self.picker, self.side = picker, side
        self.index = -1
        self.position: Any = None

    def begin(self, index: int, vertex: int | None) -> None:
        self.index, self.position = int(index), None
        self.picker.select(self.index)

    def move(self, index: int, position: Any) -> float:
        self.position = position
        return 0.0

    def end(self) -> None:
        if self.position is not None:
            self.picker.drop(self.side, self.index, self.position)
        self.index, self.position = -1, None

    def cancel(self) -> None:
        self.index, self.position = -1, None
        self.picker.refresh()


class LandmarkPicker(ModelPanel):
    """Click landmark pairs on two linked views (see the module docstring).

    Parameters
    ----------
    session : workbench.rigging.RigSession
    errors : ipywidgets.Output or ErrorSink, optional
    height : int
        Height of each view in pixels.

    Attributes
    ----------
    views : dict of str to Viewport
        ``"template"`` and ``"target"``.
    pending : dict of str to int or None
        The point clicked on a side whose partner is still to be clicked.
    mirror : ipywidgets.Checkbox
    pairs : ipywidgets.Select
        One line per pair; the selected one is highlighted on both faces.
    hint : ipywidgets.HTML
    progress : ProgressRow
        The *Suggest* set-up's progress.
    """

    def __init__(self, session: Any, *, errors: Any = None, height: int = 360) -> None:
        super().__init__(session, errors=errors, layout=W.Layout(width="100%"))
        self.session = session
        group = f"rig-{uuid.uuid4().hex[:8]}"
        self.views: dict[str, Viewport] = {}
        self.pending: dict[str, int | None] = {s: None for s in SIDES}
        self._trees: dict[str, cKDTree] = {}
        self._selected = -1
        for side, model in zip(SIDES, (session.template, session.target), strict=True):
            vp = Viewport(model, height=height, errors=self.errors.output, tool="sculpt", add_on_click=True,
                          camera_group=group)
            vp.add_class(f"fwb-rig-{side}-view")
            vp.layout = W.Layout(width="50%", min_width="240px")
            vp.pick_handler = _Clicks(self, side)
            vp.drag_handler = _Drag(self, side)
            self.views[side] = vp
            self.on_close(vp.close)
        self.mirror = W.Checkbox(value=True, description="Mirror", indent=False, layout=W.Layout(width="auto"),
                                 tooltip="Also add the mirror pair (the other side of both faces)")
        self.mirror.add_class("fwb-rig-mirror")
        self.pairs = W.Select(options=[], rows=6, layout=W.Layout(width="100%"))
        self.pairs.add_class("fwb-rig-pairs")
        self.remove_button = button("Remove", "fwb-rig-remove", "Remove the selected pair", "minus")
        self.clear_button = button("Clear", "fwb-rig-clear", "Remove every pair", "trash")
        self.suggest_button = button("Suggest", "fwb-rig-suggest",
                                     "Add automatic pairs (eye corners, mouth corners, nose tip, ...)", "magic")
        self.hint = W.HTML()
        self.hint.add_class("fwb-rig-hint")
        self.progress = ProgressRow("fwb-rig-suggest-progress")
        g = self.guard
        self.remove_button.on_click(g("remove landmark")(lambda _b: self._remove_selected()))
        self.clear_button.on_click(g("clear landmarks")(lambda _b: self.session.clear_landmarks()))
        self.suggest_button.on_click(g("suggest landmarks")(lambda _b: self.suggest()))
        self.pairs.observe(g("select landmark")(self._on_list), "index")
        titles = W.HBox([W.HTML("<b>Template</b>", layout=W.Layout(width="50%")),
                         W.HTML("<b>Your face</b>", layout=W.Layout(width="50%"))])
        self.children = [
            titles,
            W.HBox([self.views["template"], self.views["target"]], layout=W.Layout(width="100%")),
            self.hint,
            W.HBox([self.mirror, self.suggest_button, self.remove_button, self.clear_button]),
            self.pairs,
            self.progress,
        ]
        self.listen(session.events.landmarks, self.refresh, "landmarks")
        self.refresh()

    # ------------------------------------------------------------------ picking
    def pick(self, side: str, vertex: int) -> None:
        """A click on ``side``'s surface at ``vertex``: completes a pair, or waits for the other side."""
        other = SIDES[1 - SIDES.index(side)]
        partner = self.pending[other]
        if partner is None:
            self.pending[side] = int(vertex)
            self.refresh()
            return
        pair = {side: int(vertex), other: partner}
        self.pending = {s: None for s in SIDES}
        added = self.session.add_landmark(pair["template"], pair["target"], mirror=self.mirror.value)
        self.select(len(self.session.landmarks) - added)

    def remove_marker(self, side: str, index: int) -> None:
        """Alt-click on marker ``index`` of ``side``: remove its pair (or the pending point)."""
        n = len(self.session.landmarks)
        if index < n:
            self.session.remove_landmark(index)
        else:
            self.pending[side] = None
            self.refresh()

    def drop(self, side: str, index: int, position: Any) -> None:
        """Marker ``index`` of ``side`` dropped at ``position``: that end moves to the nearest vertex."""
        tree = self._trees.get(side)
        model = self.session.template if side == "template" else self.session.target
        if tree is None:
            tree = self._trees[side] = cKDTree(np.asarray(model.vertices, np.float64))
        v = int(tree.query(np.asarray(position, np.float64).reshape(3))[1])
        if index < len(self.session.landmarks):
            self.session.move_landmark(index, side, v)
            self.select(index)
        else:
            self.pending[side] = v
            self.refresh()

    def select(self, index: int) -> None:
        """Highlight pair ``index`` on both faces and in the list (-1: none)."""
        n = len(self.session.landmarks)
        self._selected = index if 0 <= index < n else -1
        self.refresh()

    def suggest(self) -> int:
        """Add automatic pairs (runs the fit when needed); returns how many were added."""
        self.progress.start("<i>fitting the template to your face ...</i>")
        try:
            added = self.session.suggest_landmarks(progress=self.progress)
        except Exception as exc:
            self.progress.fail(str(exc))
            raise
        self.progress.finish(f"{added} pairs suggested: drag a marker to correct it")
        return added

    def _remove_selected(self) -> None:
        if self._selected >= 0:
            self.session.remove_landmark(self._selected)

    def _on_list(self, change: dict[str, Any]) -> None:
        idx = change["new"]
        # refresh() setting the list's options moves its index too: not the person's choice
        if getattr(self, "_refreshing", False):
            return
        if idx is not None and idx != self._selected:
            self.select(int(idx))

    # ------------------------------------------------------------------ display
    def refresh(self) -> None:
        """Markers, list and hint from the session and the pending points."""
        lm = self.session.landmarks
        if self._selected >= len(lm):
            self._selected = -1
        for k, side in enumerate(SIDES):
            ids = [p[k] for p in lm]
            pend = self.pending[side]
            vp = self.views[side]
            vp.markers = [*ids, pend] if pend is not None else ids
            vp.selected_marker = len(ids) if pend is not None else self._selected
        names = [f"{i + 1}. template {a} \u2194 face {b}" for i, (a, b) in enumerate(lm)]
        self._refreshing = True
        try:
            with self.pairs.hold_trait_notifications():
                self.pairs.options = names
                self.pairs.index = self._selected if self._selected >= 0 else None
        finally:
            self._refreshing = False
        if self.pending["template"] is not None:
            hint = "Now click the same point on <b>your face</b>."
        elif self.pending["target"] is not None:
            hint = "Now click the same point on the <b>template</b>."
        else:
            hint = ("Click a point on either face, then the same point on the other. Drag a marker to move it, "
                    "Alt-click it to remove its pair.")
        stale = " <span style='color:#b60'>(changed since the transfer: run it again)</span>" \
            if "transfer" in self.session.stale else ""
        self.hint.value = f"{html.escape(str(len(lm)))} pairs. {hint}{stale}"
