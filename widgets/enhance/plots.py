"""The timing plot of a retimed transition, after Bermano et al. 2014, Fig. 7 (matplotlib, Agg, PNG bytes).

Time against the weight of the shape that changes most between the two keys:
linear interpolation (red), the in-betweens keyed from the matched take (cyan,
or purple when extended to the full matched motion) and the matched database
motion itself (blue): its progress along its own chord ``β(τ0) → β(τ1)`` —
what the retimed progress ``s`` follows — over the same span, drawn on the
keys' scale. Drawn offscreen for an
``ipywidgets.Image`` and for the tutorial.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["retime_plot_png"]


def _progress(beta: np.ndarray, tau0: float, tau1: float, samples: int = 200) -> np.ndarray:
    """Progress of a take between continuous times ``tau0`` and ``tau1`` along its own chord."""
    tau = np.linspace(tau0, tau1, samples)
    j = np.minimum(np.floor(tau).astype(int), beta.shape[0] - 2)
    f = (tau - j)[:, None]
    path = (1 - f) * beta[j] + f * beta[j + 1]
    chord = path[-1] - path[0]
    return np.asarray((path - path[0]) @ chord / max(float(chord @ chord), 1e-12))


def retime_plot_png(
    result: Any,
    takes: Sequence[ArrayLike],
    t0: float,
    t1: float,
    *,
    shape: int,
    name: str = "",
    extended: bool = False,
    size: tuple[float, float] = (6.0, 3.4),
    dpi: int = 90,
) -> bytes:
    """PNG of one shape's weight over ``t0``–``t1`` (seconds) for a :class:`~workbench.enhance.RetimeResult`.

    Parameters
    ----------
    result : RetimeResult
        Of a weight-space retime (``frames`` (n, k)).
    takes : list of (T_i, k) arrays
        The database the result was timed by (``result.matched[0]`` and ``result.sources`` index it).
    shape : int
        Column of the shape to draw.
    extended : bool
        The retime was extended to the full matched motion (purple) or not (cyan).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    frames = np.asarray(result.frames, np.float64)
    n = frames.shape[0]
    t = np.linspace(t0, t1, n)
    a, b = frames[0, shape], frames[-1, shape]
    fig = Figure(figsize=size, dpi=dpi)
    ax = fig.subplots()
    choice = getattr(result, "choice", "match")
    if choice == "match":
        beta = np.asarray(takes[int(result.matched[0])], np.float64)
        ax.plot(np.linspace(t0, t1, 200), a + _progress(beta, *result.span) * (b - a), color="#1f3a93", lw=2.0,
                label="database motion")
        label = "retimed (extended)" if extended else "retimed (matched sub-sequence)"
    elif choice == "take":
        top = max((w for *_, w in result.sources), default=1.0)
        for k, (i, first, last, w) in enumerate(result.sources):
            beta = np.asarray(takes[int(i)], np.float64)
            ax.plot(np.linspace(t0, t1, 200), a + _progress(beta, float(first), float(last)) * (b - a),
                    color="#1f3a93", lw=1.0, alpha=0.15 + 0.6 * w / top,
                    label="the take's transitions (darker: more weight)" if k == 0 else None)
        label = f"retimed (blend of {len(result.sources)} transitions of the take)"
    else:
        label = "retimed (ease: the take has no transition to learn from)"
    ax.plot([t0, t1], [a, b], color="#d62728", lw=1.4, ls="--", label="linear")
    ax.plot(t, frames[:, shape], color="#8e44ad" if extended else "#17becf", lw=1.8, marker="o", ms=3, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"weight{f' of {name}' if name else ''}")
    ax.legend(fontsize=7, loc="best", framealpha=0.8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
