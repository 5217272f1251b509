"""``ProgressRow``: a progress bar and a message under it, for long kernel work.

The row is itself the ``progress(fraction, message)`` callback the core's long
operations take (``model.handles.set_progress(row)``,
``model.regions.segment(t, progress=row)``): below 1 the bar shows the fraction
and the label the message; at 1 the bar hides and the label empties. The bar
keeps its place while hidden (``visibility``, not ``display``), so the panel
does not jump.
"""

from __future__ import annotations

import html

import ipywidgets as W

__all__ = ["ProgressRow"]


class ProgressRow(W.VBox):
    """A hidden-until-needed progress bar with a message label.

    Parameters
    ----------
    bar_class : str
        CSS class of the bar (tests and browser tests select by it).
    label_class : str, optional
        CSS class of the label.
    template : str
        HTML of the label while running; ``{message}`` is the callback's message.

    Attributes
    ----------
    bar : ipywidgets.FloatProgress
    label : ipywidgets.HTML
    """

    def __init__(
        self,
        bar_class: str = "fwb-progress",
        label_class: str | None = None,
        *,
        template: str = "<i>{message}</i>",
    ) -> None:
        self.template = template
        self.bar = W.FloatProgress(
            value=0.0,
            min=0.0,
            max=1.0,
            description="",
            bar_style="info",
            layout=W.Layout(width="98%", visibility="hidden"),
        )
        self.bar.add_class(bar_class)
        self.label = W.HTML("")
        if label_class:
            self.label.add_class(label_class)
        super().__init__([self.bar, self.label], layout=W.Layout(width="100%"))

    @property
    def visible(self) -> bool:
        return self.bar.layout.visibility == "visible"

    def __call__(self, fraction: float, message: str = "") -> None:
        """Show ``fraction`` (0..1) and ``message``; at 1 (or more) hide the bar and clear the label."""
        done = fraction >= 1.0
        self.bar.bar_style = "info"
        self.bar.value = min(max(float(fraction), 0.0), 1.0)
        self.bar.layout.visibility = "hidden" if done else "visible"
        self.label.value = "" if done else self.template.format(message=message)

    def start(self, text: str) -> None:
        """Show an empty bar and ``text`` (HTML) as the label."""
        self.bar.bar_style = "info"
        self.bar.value = 0.0
        self.bar.layout.visibility = "visible"
        self.label.value = text

    def finish(self, text: str = "") -> None:
        """Hide the bar; ``text`` (HTML) stays as the label (e.g. what was done, how fast)."""
        self.bar.layout.visibility = "hidden"
        self.label.value = text

    def fail(self, text: str) -> None:
        """Leave the bar visible in red and say what failed (plain text)."""
        self.bar.bar_style = "danger"
        self.label.value = f"<span style='color:#b00'>{html.escape(text)}</span>"
