"""Pictures of a tracked take: weight curves and fit error over time (matplotlib, Agg, PNG bytes).

The busiest shapes get a curve each (the rest are summed into "others"), the
fit error is drawn under them, and a vertical line marks the current frame;
frames held for lack of visible points are shaded. Drawn offscreen so the
Capture tab can show them in an ``ipywidgets.Image``.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

__all__ = ["take_plot_png"]


def take_plot_png(
    result: Any,
    *,
    frame: int | None = None,
    window: tuple[int, int] | None = None,
    top: int = 6,
    size: tuple[float, float] = (6.4, 3.6),
    dpi: int = 90,
    units: str = "",
) -> bytes:
    """PNG of ``result``'s weights (top ``top`` shapes by peak weight) and fit error.

    Parameters
    ----------
    result : workbench.capture.TrackResult
    frame : int, optional
        The current frame (a vertical line).
    window : (first, last), optional
        Frames to draw (inclusive); default all.
    top : int
        Shapes drawn with their own curve.
    units : str
        The model's length unit, for the error axis.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    W = np.asarray(result.weights)
    T = W.shape[0]
    a, b = (0, T - 1) if window is None else (max(0, int(window[0])), min(T - 1, int(window[1])))
    t = np.arange(a, b + 1)
    Wv = W[a : b + 1]
    order = np.argsort(-Wv.max(axis=0))[:top] if Wv.size else np.zeros(0, int)
    fig = Figure(figsize=size, dpi=dpi)
    ax, ax2 = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    for j in order:
        if Wv[:, j].max() > 0:
            ax.plot(t, Wv[:, j], lw=1.4, label=result.shape_names[j])
    rest = np.delete(Wv, order, axis=1).sum(axis=1) if Wv.shape[1] > len(order) else np.zeros(len(t))
    if rest.max(initial=0.0) > 0:
        ax.plot(t, rest, lw=1.0, color="0.6", ls="--", label="others (sum)")
    ax.set_ylabel("weight")
    ax.set_ylim(-0.02, max(1.02, float(Wv.max(initial=0.0)) + 0.02))
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, ncol=2, loc="upper right", framealpha=0.8)
    held = np.asarray(result.held)[a : b + 1]
    for k in np.flatnonzero(held):
        for axis in (ax, ax2):
            axis.axvspan(t[k] - 0.5, t[k] + 0.5, color="#f4c7c3", lw=0)
    err = np.asarray(result.errors)[a : b + 1]
    ax2.plot(t, err, color="#b5442c", lw=1.2)
    ax2.set_ylabel(f"error{f' ({units})' if units else ''}", fontsize=8)
    ax2.set_xlabel(f"frame ({result.fps:g} fps)")
    if frame is not None and a <= frame <= b:
        for axis in (ax, ax2):
            axis.axvline(frame, color="k", lw=1.0)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
