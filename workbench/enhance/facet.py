"""``model.enhance``: *Retime from performance* on the model's timeline (Bermano et al. 2014 §6.2).

:meth:`EnhanceFacet.retime` takes two times on the timeline (a key pair), reads
the weights there, finds the transition between them in a database of takes
(:func:`workbench.enhance.retime`: segment projection and the monotone matching
of eq. 5–6 over every take) and keys the in-betweens with the matched take's
timing — linear keys on every frame between the two times, for the shapes that
change between them — as one undo step. The database is any sequence of takes:
(T, k) weight arrays in ``model.shape_names`` order, tracked takes
(:class:`workbench.capture.TrackResult`) or timelines (sampled at their frames).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.animation.tracks import Timeline, add_keys
from workbench.core.shapes import ModelError
from workbench.enhance.retime import RetimeResult, retime

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["EnhanceFacet", "weight_takes"]


def weight_takes(database: Any, shape_names: Sequence[str]) -> list[NDArray[np.float64]]:
    """(T_i, k) weight arrays in ``shape_names`` order from arrays, tracked takes or timelines."""
    items = [database] if isinstance(database, Timeline) or hasattr(database, "shape_names") else list(database)
    if not items:
        raise ModelError("retime: the database has no takes")
    names = list(shape_names)
    out = []
    for i, item in enumerate(items):
        if isinstance(item, Timeline):
            W = item.weight_matrix(names, item.frame_times())
        elif hasattr(item, "shape_names") and hasattr(item, "weights"):
            index = {n: j for j, n in enumerate(item.shape_names)}
            missing = [n for n in names if n not in index]
            if missing:
                raise ModelError(f"retime: database[{i}] has no weights for {missing[:5]}")
            W = np.asarray(item.weights, np.float64)[:, [index[n] for n in names]]
        else:
            W = np.asarray(item, np.float64)
            if W.ndim != 2 or W.shape[1] != len(names):
                raise ModelError(f"retime: database[{i}] must be (T, {len(names)}) weights, got {W.shape}")
        out.append(W)
    return out


class EnhanceFacet:
    """Performance enhancement on one model (see the module docstring); keeps nothing of its own."""

    def __init__(self, model: FaceState) -> None:
        self._model = model

    def __repr__(self) -> str:
        return "<enhance: retime(t0, t1, database) keys a transition with a take's timing>"

    def retime(self, t0: float, t1: float, database: Any, *, n_frames: int | None = None, extend: bool = False,
               label: str | None = None) -> RetimeResult:
        """Key the in-betweens of ``t0`` → ``t1`` with the timing of the best-matching take (one undo step).

        Parameters
        ----------
        t0, t1 : float
            Seconds, ``t0 < t1`` (usually two keys).
        database : sequence of takes
            See :func:`weight_takes`.
        n_frames : int, optional
            In-betweens including both ends; default one per frame of the timeline's fps.
        extend : bool
            See :func:`workbench.enhance.retime`.

        Returns
        -------
        RetimeResult
        """
        m = self._model
        a, b = float(t0), float(t1)
        if not (np.isfinite(a) and np.isfinite(b) and b > a):
            raise ModelError(f"retime: need finite t0 < t1, got {t0!r}, {t1!r}")
        derived = set(m.shape_tools.correctives)  # type: ignore[attr-defined]
        names = [n for n in m.shape_names if n not in derived]
        tl: Timeline = m.slot("tracks")
        n = round((b - a) * tl.fps) + 1 if n_frames is None else int(n_frames)
        if n < 3:
            raise ModelError(f"retime: {t0:g}–{t1:g} s holds fewer than 3 frames at {tl.fps:g} fps (n_frames={n})")
        W = tl.weight_matrix(names, [a, b])
        changed = np.flatnonzero(np.abs(W[1] - W[0]) > 1e-9)
        if changed.size == 0:
            raise ModelError(f"retime: the weights at {a:g} s and {b:g} s are the same: nothing to retime")
        res = retime(weight_takes(database, names), W[0], W[1], n, extend=extend)
        times = np.linspace(a, b, n)[1:-1]
        new = tl
        for j in changed:
            track = f"weights/{names[j]}"
            new = add_keys(new, track, times, res.frames[1:-1, j], interpolation="linear")
            # the key at t0 governs the segment after it: linear, so the in-betweens play as keyed;
            # the key at t1 stays as it was (it governs what follows), or is added when missing
            new = add_keys(new, track, [a], W[:1, j], interpolation="linear")
            old = tl.tracks.get(track)
            if old is None or not np.any(np.abs(old.times - b) <= 1e-9):
                new = add_keys(new, track, [b], W[1:, j], interpolation="linear")
        m.timeline.set(new, label or f"Retime {a:g}–{b:g} s from performance")  # type: ignore[attr-defined]
        return res
