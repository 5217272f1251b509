"""``StagePanel``: run the rigging stages, each with its progress bar and one undo step.

*Transfer* (correspondence + deformation transfer of every template shape),
*Refine* (Li et al. 2010 §3 from the examples, with its iteration count) and
*Carry details* (the template's wrinkle examples, Bickel et al. 2008 §5.4) call
:class:`workbench.rigging.RigSession`'s stages. A button is enabled when its
stage can run; its row says what the last run did and how long it took, or in
red what failed (the session is unchanged then: a stage is all or nothing).
The stages run in the kernel while the bar moves (ipywidgets sends the bar's
updates as they are made).
"""

from __future__ import annotations

import html
import time
from collections.abc import Callable
from typing import Any

import ipywidgets as W
import numpy as np

from widgets.panels.base import ModelPanel, button
from widgets.panels.progress import ProgressRow

__all__ = ["StagePanel"]


class StagePanel(ModelPanel):
    """The three stage buttons with their progress rows (see the module docstring).

    Parameters
    ----------
    session : workbench.rigging.RigSession
    errors : ipywidgets.Output or ErrorSink, optional
    on_done : callable, optional
        Called with the stage name after a stage ran (the studio refreshes its gallery).

    Attributes
    ----------
    buttons : dict of str to ipywidgets.Button
    rows : dict of str to ProgressRow
    iterations : ipywidgets.BoundedIntText
    """

    def __init__(self, session: Any, *, errors: Any = None, on_done: Callable[[str], Any] | None = None) -> None:
        super().__init__(session, errors=errors, layout=W.Layout(width="100%"))
        self.session = session
        self.on_done = on_done
        self.buttons = {
            "transfer": button("Transfer shapes", "fwb-rig-transfer",
                               "Fit the template to your face and carry every shape over", "share", "170px"),
            "refine": button("Refine from examples", "fwb-rig-refine",
                             "Li et al. 2010: adapt the shapes to your example poses", "sliders", "170px"),
            "details": button("Carry wrinkles", "fwb-rig-details",
                              "Carry the template's wrinkle details and fit them on the rig", "paint-brush", "170px"),
        }
        self.rows = {k: ProgressRow(f"fwb-rig-{k}-progress", f"fwb-rig-{k}-status") for k in self.buttons}
        self.iterations = W.BoundedIntText(value=10, min=1, max=50, description="iterations",
                                           layout=W.Layout(width="150px"))
        self.iterations.add_class("fwb-rig-iterations")
        for k, b in self.buttons.items():
            b.on_click(self.guard(f"{k} stage")(lambda _b, k=k: self.run(k)))
        line = {"transfer": [], "refine": [self.iterations], "details": []}
        self.children = [W.VBox([W.HBox([self.buttons[k], *line[k]]), self.rows[k]]) for k in self.buttons]
        self.listen(session.events.stages, self.refresh, "stages")
        self.listen(session.events.examples, self.refresh, "examples")
        self.listen(session.events.landmarks, self.refresh, "landmarks")
        self.refresh()

    def run(self, stage: str) -> Any:
        """Run ``stage`` ("transfer", "refine" or "details") with its progress row; returns its result."""
        row = self.rows[stage]
        s = self.session
        row.start(f"<i>{html.escape(stage)} ...</i>")
        for b in self.buttons.values():
            b.disabled = True
        t0 = time.perf_counter()
        try:
            if stage == "transfer":
                report = s.transfer(progress=row)
                worst = report.worst
                text = (f"{len(report.shapes)} shapes in {time.perf_counter() - t0:.1f} s; "
                        f"fit coverage {report.registration.get('coverage', 0):.0%}"
                        + (f"; worst stretch {worst.max_stretch:.2f} ({html.escape(worst.name)})" if worst else ""))
                out: Any = report
            elif stage == "refine":
                res = s.refine(iterations=int(self.iterations.value), progress=row)
                before, after = float(np.mean(res.initial_errors)), float(np.mean(res.errors[:, -1]))
                text = (f"{len(s.examples)} examples, {res.errors.shape[1]} iterations in "
                        f"{time.perf_counter() - t0:.1f} s; example error {before:.3g} \u2192 {after:.3g} "
                        f"{html.escape(s.target.metadata.units)}")
                out = res
            elif stage == "details":
                rig = s.carry_details(progress=row)
                text = (f"{len(rig.wrinkles.example_names)} wrinkle examples fitted in "
                        f"{time.perf_counter() - t0:.1f} s")
                out = rig
            else:
                raise ValueError(f"unknown stage {stage!r}; expected transfer, refine or details")
        except Exception as exc:
            row.fail(f"{stage} failed: {exc}")
            raise
        finally:
            self.refresh()
        row.finish(text)
        if self.on_done is not None:
            self.on_done(stage)
        return out

    def refresh(self) -> None:
        """Enable the stages that can run; say which results are stale."""
        s = self.session
        done = s.stages_done
        self.buttons["transfer"].disabled = False
        self.buttons["refine"].disabled = "transfer" not in done or not s.examples
        self.buttons["details"].disabled = "transfer" not in done
        self.buttons["refine"].tooltip = (
            "Add example poses first (Examples)" if not s.examples
            else "Li et al. 2010: adapt the shapes to your example poses")
        for k, row in self.rows.items():
            if k not in done and not row.visible and "failed" not in row.label.value:
                row.label.value = ""
            if k in s.stale:
                row.label.value = "<span style='color:#b60'>inputs changed since this ran: run it again</span>"
