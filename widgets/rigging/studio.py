"""``RigStudio``: rig your face from the template in one widget (issue 16's Rig tab).

Top: Undo / Redo of the rigging session (each landmark edit, example edit and
stage is one step) and *Open in Workbench*. Then the two linked views to click
landmark pairs (:class:`~widgets.rigging.landmarks.LandmarkPicker`), and tabs:

* **Stages** — Transfer, Refine, Carry wrinkles, each with its progress bar
  (:class:`~widgets.rigging.stages.StagePanel`);
* **Report** — the per-shape quality table, flagged shapes first
  (:class:`~widgets.rigging.report_view.QualityReport`); picking a shape shows
  it in the gallery;
* **Gallery** — before / after pictures: template, transferred, refined
  (:class:`~widgets.rigging.gallery.RigGallery`);
* **Examples** — the example poses with their rough-weight sliders
  (:class:`~widgets.rigging.examples.ExamplesPanel`).

*Open in Workbench* puts a :class:`~widgets.app.Workbench` over a copy of the
latest rig under the studio (:attr:`RigStudio.workbench`): every tool works
on it, and the rigging session is not changed by what you do there.
"""

from __future__ import annotations

from typing import Any

import ipywidgets as W

from widgets._iopub import keep_every_iopub_message
from widgets._threading import ErrorSink
from widgets.panels.base import ModelPanel, button
from widgets.rigging.examples import ExamplesPanel
from widgets.rigging.gallery import RigGallery
from widgets.rigging.landmarks import LandmarkPicker
from widgets.rigging.report_view import QualityReport
from widgets.rigging.stages import StagePanel

__all__ = ["RIG_TABS", "RigStudio", "show_rig_studio"]

RIG_TABS = ("Stages", "Report", "Gallery", "Examples")


class RigStudio(ModelPanel):
    """Landmarks, stages, report, gallery and examples over one rigging session.

    Parameters
    ----------
    session : workbench.rigging.RigSession, or a template FaceModel
        With a template, ``target`` is required and a new session is made.
    target : FaceModel or path, optional
    height : int
        Height of each landmark view in pixels.

    Attributes
    ----------
    session : workbench.rigging.RigSession
    landmarks : LandmarkPicker
    stages : StagePanel
    report : QualityReport
    gallery : RigGallery
    examples : ExamplesPanel
    tabs : ipywidgets.Tab
    workbench : widgets.Workbench or None
        The last rig opened with *Open in Workbench*.
    """

    def __init__(self, session: Any, target: Any = None, *, height: int = 360) -> None:
        from workbench.rigging import RigSession

        keep_every_iopub_message()  # the studio is a burst of widgets (widgets._iopub)
        if not isinstance(session, RigSession):
            if target is None:
                raise TypeError("RigStudio: give a RigSession, or a template FaceModel and a target")
            session = RigSession(session, target)
        output = W.Output(layout=W.Layout(max_height="160px", overflow="auto"))
        output.add_class("fwb-errors")
        super().__init__(session, errors=ErrorSink(output), layout=W.Layout(width="100%"))
        self.session = session
        self.workbench: Any = None
        sink = self.errors
        self.landmarks = LandmarkPicker(session, errors=sink, height=height)
        self.stages = StagePanel(session, errors=sink)
        self.gallery = RigGallery(session, errors=sink)
        self.report = QualityReport(session, errors=sink, on_show=self._show_shape)
        self.examples = ExamplesPanel(session, errors=sink)
        for part in (self.landmarks, self.stages, self.gallery, self.report, self.examples):
            self.on_close(part.close)
        self.tabs = W.Tab(children=[self.stages, self.report, self.gallery, self.examples])
        for i, title in enumerate(RIG_TABS):
            self.tabs.set_title(i, title)
        self.tabs.add_class("fwb-rig-tabs")
        undo_redo = self.undo_redo_buttons("fwb-rig-undo", "fwb-rig-redo")
        self.open_button = button("Open in Workbench", "fwb-rig-open", "Edit, animate and export the rig", "external-link")
        self.open_button.on_click(self.guard("open in workbench")(lambda _b: self.open_in_workbench()))
        self.status = W.HTML()
        self.status.add_class("fwb-rig-status")
        self.opened = W.VBox()
        self.opened.add_class("fwb-rig-opened")
        self.listen(session.events.history, self.refresh, "rig status")
        self.children = [
            W.HBox([*undo_redo.buttons, self.open_button, self.status]),
            self.landmarks,
            self.tabs,
            output,
            self.opened,
        ]
        self.refresh()

    def _show_shape(self, name: str) -> None:
        self.gallery.add_shape(name)
        self.tabs.selected_index = RIG_TABS.index("Gallery")

    def refresh(self) -> None:
        s = self.session
        done = s.stages_done
        self.open_button.disabled = not done
        steps = s.history.undo_labels
        last = f" \u00b7 last step: {steps[-1]}" if steps else ""
        self.status.value = (
            f"<b>{s.target.metadata.name or 'your face'}</b>: {s.target.n_vertices} vertices \u00b7 "
            f"{len(s.landmarks)} landmark pairs \u00b7 {len(s.examples)} examples \u00b7 "
            f"done: {', '.join(done) or 'nothing yet'}{last}"
        )

    def open_in_workbench(self, **kwargs: Any) -> Any:
        """A :class:`~widgets.app.Workbench` over a copy of the latest rig, shown under the studio."""
        from widgets.app import Workbench

        rig = self.session.result()
        if self.workbench is not None:
            self.workbench.close()
        self.workbench = Workbench(rig, **kwargs)
        self.opened.children = [W.HTML("<h3>Your rig in the Workbench</h3>"), self.workbench]
        return self.workbench

    def close(self) -> None:
        if self.workbench is not None:
            self.workbench.close()
            self.workbench = None
        super().close()


def show_rig_studio(template: Any, target: Any, **kwargs: Any) -> RigStudio:
    """Make a :class:`RigStudio` for ``template`` and ``target``, display it and return it."""
    from IPython.display import display

    studio = RigStudio(template, target, **kwargs)
    display(studio)
    return studio
