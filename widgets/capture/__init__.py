"""The Capture tab: drive the face from a performance (issue 17)."""

from widgets.capture.panel import CapturePanel
from widgets.capture.plots import take_plot_png

__all__ = ["CapturePanel", "take_plot_png"]
