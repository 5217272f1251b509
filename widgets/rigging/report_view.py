"""``QualityReport``: the transfer's per-shape quality as a table, problems first.

One row per transferred shape (:class:`workbench.rigging.ShapeQuality`): the
largest and median stretch on your face beside the template's own largest
stretch, flipped triangles and new self-intersections (the template's in
brackets), and what is flagged: a shape that stretches your face much more than
it stretches the template, turns triangles over or pushes the surface through
itself where the template's shape does not
(:meth:`workbench.rigging.ShapeQuality.concerns`, the rule of the report's summary). Flagged rows come first and are
tinted; above the table, the fit's coverage and residuals and the transfer's
warnings. Clicking *Show* on a row picks the shape for the before/after gallery.
"""

from __future__ import annotations

import html
from collections.abc import Callable
from typing import Any

import ipywidgets as W

from widgets.panels.base import ModelPanel

__all__ = ["QualityReport", "shape_flags"]

_OK = "\u2713"


def shape_flags(q: Any) -> list[str]:
    """Why a :class:`~workbench.rigging.ShapeQuality` needs a look (empty: fine); its own rule, :meth:`concerns`."""
    return list(q.concerns())


class QualityReport(ModelPanel):
    """The last transfer's report as a table (see the module docstring).

    Parameters
    ----------
    session : workbench.rigging.RigSession
    errors : ipywidgets.Output or ErrorSink, optional
    on_show : callable, optional
        Called with a shape name when its row's *Show* is picked.

    Attributes
    ----------
    summary : ipywidgets.HTML
    table : ipywidgets.HTML
    show : ipywidgets.Dropdown
        The shapes, flagged first; picking one calls ``on_show``.
    flagged : list of str
        Names of the flagged shapes of the shown report.
    """

    def __init__(self, session: Any, *, errors: Any = None, on_show: Callable[[str], Any] | None = None) -> None:
        super().__init__(session, errors=errors, layout=W.Layout(width="100%"))
        self.session = session
        self.on_show = on_show
        self.flagged: list[str] = []
        self.summary = W.HTML()
        self.summary.add_class("fwb-rig-summary")
        self.show = W.Dropdown(options=[], description="Show", layout=W.Layout(width="320px"))
        self.show.add_class("fwb-rig-show")
        self.table = W.HTML(layout=W.Layout(max_height="320px", overflow="auto"))
        self.table.add_class("fwb-rig-report")
        self.show.observe(self.guard("show shape")(self._on_show), "value")
        self.children = [self.summary, self.show, self.table]
        self.listen(session.events.stages, self.refresh, "report")
        self.refresh()

    def _on_show(self, change: dict[str, Any]) -> None:
        if change["new"] and self.on_show is not None:
            self.on_show(str(change["new"]))

    def refresh(self) -> None:
        rep = self.session.report
        if rep is None:
            self.flagged = []
            self.summary.value = "<i>No transfer yet.</i>"
            self.table.value = ""
            self.show.options = []
            return
        reg = rep.registration
        rows = [(shape_flags(q), q) for q in rep.shapes]
        rows.sort(key=lambda r: (not r[0], -r[1].max_stretch))
        self.flagged = [q.name for f, q in rows if f]
        warn = "".join(f"<li style='color:#b60'>{html.escape(w)}</li>" for w in rep.warnings)
        self.summary.value = (
            f"<b>{len(rep.shapes)} shapes</b>, {len(self.flagged)} flagged \u00b7 fit coverage "
            f"{reg.get('coverage', 0):.0%} ({reg.get('over_holes', 0):.0%} over holes), residual median "
            f"{reg.get('median_residual', 0):.3g} / p95 "
            f"{reg.get('p95_residual', 0):.3g} {html.escape(self.session.target.metadata.units)} \u00b7 "
            f"aligned by {html.escape(str(rep.alignment.get('method', '?')))} \u00b7 set-up "
            f"{rep.timings.get('setup', 0):.1f} s, transfer {rep.timings.get('transfer', 0):.2f} s"
            + (f"<ul>{warn}</ul>" if warn else "")
        )
        head = ("<tr><th>shape</th><th>stretch max / median</th><th>template</th><th>flipped</th>"
                "<th>intersecting</th><th>flag</th></tr>")
        body = []
        for flags, q in rows:
            tint = " style='background:#fde8e0'" if flags else ""
            inter = int(getattr(q, "intersecting", 0))
            src_inter = int(getattr(q, "source_intersecting", 0))
            body.append(
                f"<tr class='{'fwb-flagged' if flags else 'fwb-ok'}'{tint}><td>{html.escape(q.name)}</td>"
                f"<td>{q.max_stretch:.2f} / {q.median_stretch:.2f}</td><td>{q.source_max_stretch:.2f}</td>"
                f"<td>{q.flipped} ({q.source_flipped})</td><td>{inter} ({src_inter})</td>"
                f"<td>{html.escape('; '.join(flags)) or _OK}</td></tr>"
            )
        self.table.value = (
            "<table style='border-collapse:collapse;font-size:12px' class='fwb-rig-table'>"
            f"{head}{''.join(body)}</table>"
        )
        self.show.options = ["", *(q.name for _, q in rows)]
        self.show.value = ""
