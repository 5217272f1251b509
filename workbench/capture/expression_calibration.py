"""Expression calibration: a short guided session of known expressions corrects what the tracker reads.

On camera frames FaceMesh reads an expression short and mixed with others: on the
rendered takes of ``benchmarks/bench_live.py`` the smiles reach half to two thirds
of their truth, the outer brows nearly nothing, a turned head reads as ``browDownLeft``
and the parting lips are explained partly by ``mouthLowerDown*`` and ``mouthPucker``. Much of that is systematic — the same
expression gives the same misreading — so it can be measured once per actor and
camera, the way face-capture tools calibrate (a neutral face, then a handful of
prompted expressions held for a moment):

* the actor follows :data:`DEFAULT_PROMPTS` (relax, jaw wide open, eyes closed,
  smile, brows up, frown, pucker, "oo", then a relaxed face turning left and right
  and nodding), :data:`SECONDS_PER_PROMPT` each;
* in each prompt, the frames where the prompted shapes' tracked weight is
  within :data:`HOLD` of its highest are the hold (the actor's reaction and
  release are left out); they are taken to show the prompted shapes at 1 and
  every other shape at 0 (the neutral, turning and nodding prompts: every frame,
  all shapes 0);
* a linear map ``C`` (k × k, the rig's plain shapes) from the tracked weights to
  those targets is fitted by ridge regression towards the identity
  (:func:`fit_weight_map`), and every later frame's weights become
  ``clip(w C)``.

The ridge keeps what the session did not show as it was: a shape that neither
moved nor was prompted keeps its own weight. The turning and nodding prompts are
there because the tracker misreads a turned head as expression: on a neutral face
its ``browDownLeft`` follows the yaw (correlation +0.69 on the rendered take),
``browDownRight`` and ``browOuterUpLeft`` against it (−0.61, −0.52); a map fitted
only on a still head kept those readings. Measured on the rendered takes
(``bench_live.py``, table 6, the live defaults, 2026-12-01 with the head pose a
similarity): the whole take's RMSE over the face shapes falls from 0.107 to 0.079 on
the sample head and from 0.112 to 0.086 on a foreign face (before the inner lips were
parted and the depth left the tracker's fit: 0.113 -> 0.087 and 0.125 -> 0.081); left
out of the session, any one prompt still leaves it at or below 0.087 / 0.101; on dense
co-articulated takes, most of whose shapes no prompt shows, it changes little (0.188 ->
0.187, 0.180 -> 0.175, 0.186 -> 0.189, 0.180 -> 0.180); on a held-out take of ten other
expressions 0.113 -> 0.091 and 0.104 -> 0.093 (all-zero weights 0.095). The jaw's level
over the truth goes from 0.74 to 0.86 on the sample head and from 0.98 to 1.12 on the
foreign face (0.61 and 0.90 before the lips and the depth). Tried and not kept (at l1 = 0.01): the head's yaw and pitch (and their squares)
as inputs of the map besides the weights (0.087 / 0.084 on the same frames against
0.088 / 0.085 without: the misreading is mostly a pattern of weights no expression
makes, which the weights alone cancel); each prompt weighing the same instead of
each frame (0.094 / 0.087, jaw 0.68 / 0.90).

Hand-written: a small ridge regression in numpy and a prompt schedule; no kept
library does either for a face rig.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.arkit import canonical_arkit_name

__all__ = ["DEFAULT_PROMPTS", "HEAD_MOTIONS", "HOLD", "RIDGE", "SECONDS_PER_PROMPT", "WEAK_READING", "CalibrationPrompt",
           "ExpressionCalibration", "fit_weight_map", "held_frames"]

#: seconds each prompt shows (a reaction, about a second held, a release)
SECONDS_PER_PROMPT = 2.0
#: a prompt's hold: its frames within this fraction of the prompted shapes' highest tracked weight
HOLD = 0.8
#: the ridge towards the identity, per frame (the fit term is a mean over the session's frames):
#: 0.003–0.03 gave the same RMSE on the rendered takes within 0.01; lower let one prompt's frames
#: decide too much (one prompt left out: up to 0.143)
RIDGE = 0.01


#: a prompted expression read below this (its shapes' mean tracked weight over the hold) is named in
#: :meth:`ExpressionCalibration.summary`: the map can only scale up what the tracker reads, so a
#: shape read this weakly, or not at all, stays unreliable (on the rendered sessions of
#: ``benchmarks/bench_live.py`` the sample head's "oo" was never read and the foreign face's frown
#: 0.0; the others 0.2-0.9)
WEAK_READING = 0.15

#: what the head may do during a prompt
HEAD_MOTIONS = ("still", "turn", "nod")


@dataclass(frozen=True)
class CalibrationPrompt:
    """One prompt of the session: what the actor is asked to do and which ARKit shapes it shows at 1.

    ``head`` is what the head does meanwhile: ``"still"``, or a slow ``"turn"`` (left and right)
    or ``"nod"`` (up and down) with a relaxed face, so that the fit sees what the tracker reads
    on a neutral face as the head turns (the fit treats those frames like the neutral's: every
    shape 0; :func:`workbench.testing.calibration_head_motion` moves a generated actor so).
    """

    instruction: str
    shapes: tuple[str, ...] = ()
    head: str = "still"

    def __post_init__(self) -> None:
        if self.head not in HEAD_MOTIONS:
            raise ValueError(f"CalibrationPrompt.head: expected one of {HEAD_MOTIONS}, got {self.head!r}")


#: the session: a neutral face, the expressions a camera reads worst or most often, then the
#: relaxed face turning and nodding (what the tracker misreads as the head turns)
DEFAULT_PROMPTS: tuple[CalibrationPrompt, ...] = (
    CalibrationPrompt("Relax: your neutral face, eyes open"),
    CalibrationPrompt("Open your jaw wide", ("jawOpen",)),
    CalibrationPrompt("Close your eyes", ("eyeBlinkLeft", "eyeBlinkRight")),
    CalibrationPrompt("Smile wide", ("mouthSmileLeft", "mouthSmileRight")),
    CalibrationPrompt("Raise your brows", ("browInnerUp", "browOuterUpLeft", "browOuterUpRight")),
    CalibrationPrompt("Frown: brows down", ("browDownLeft", "browDownRight")),
    CalibrationPrompt("Pucker your lips (a kiss)", ("mouthPucker",)),
    CalibrationPrompt("Round your lips: say 'oo'", ("mouthFunnel",)),
    CalibrationPrompt("Relax your face and turn your head slowly left and right", head="turn"),
    CalibrationPrompt("Relax your face and nod slowly, up and down", head="nod"),
)


def fit_weight_map(raw: ArrayLike, target: ArrayLike, *, ridge: float = RIDGE) -> NDArray[np.float64]:
    """The linear map from tracked to true weights, pulled towards the identity.

    Minimises ``(1/m) ||raw C − target||² + ridge ||C − I||²``.

    Parameters
    ----------
    raw : (m, k) float
        Tracked weights of the session's frames.
    target : (m, k) float
        What those frames showed.
    ridge : float
        ≥ 0; 0 is plain least squares (needs ``raw`` of full column rank).

    Returns
    -------
    (k, k) float
        ``C``: calibrated weights are ``w @ C``. The identity when ``target == raw``.
    """
    R = np.asarray(raw, np.float64)
    Y = np.asarray(target, np.float64)
    if R.ndim != 2 or Y.shape != R.shape or R.shape[0] == 0:
        raise ValueError(f"raw and target must be (m, k) alike with m ≥ 1, got {R.shape} and {Y.shape}")
    if not (np.isfinite(R).all() and np.isfinite(Y).all()):
        raise ValueError("raw and target must be finite")
    if not (np.isfinite(ridge) and ridge >= 0):
        raise ValueError(f"ridge must be a number ≥ 0, got {ridge!r}")
    m, k = R.shape
    eye = np.eye(k)
    return np.asarray(np.linalg.solve(R.T @ R / m + ridge * eye, R.T @ Y / m + ridge * eye))


def held_frames(raw: ArrayLike, columns: Sequence[int], *, hold: float = HOLD) -> NDArray[np.bool_]:
    """Which frames of one prompt hold the expression: the prompted columns' mean within ``hold`` of its peak.

    Parameters
    ----------
    raw : (m, k) float
        The prompt's tracked weights.
    columns : sequence of int
        The prompted shapes (empty: the neutral prompt, every frame holds).
    hold : float
        In (0, 1].

    Returns
    -------
    (m,) bool
        None when the prompted shapes never rose above 0 (nothing was shown).
    """
    R = np.asarray(raw, np.float64)
    if not columns:
        return np.ones(R.shape[0], bool)
    s = R[:, list(columns)].mean(1)
    top = float(s.max(initial=0.0))
    if top <= 0.0:
        return np.zeros(R.shape[0], bool)
    return np.asarray(s >= hold * top)


class ExpressionCalibration:
    """One guided session on a rig: its schedule, the frames it collects and the map it fits.

    Parameters
    ----------
    shape_names : sequence of str
        The shapes the tracker solves (a rig's plain shapes), in its order.
    prompts : sequence of CalibrationPrompt
        The session (default :data:`DEFAULT_PROMPTS`); the first should be the neutral.
        A prompt none of whose shapes the rig has (by ARKit name, any spelling:
        :func:`~workbench.arkit.canonical_arkit_name`) is skipped.
    seconds : float
        Per prompt.
    ridge, hold : float
        See :func:`fit_weight_map` and :func:`held_frames`.

    Attributes
    ----------
    prompts_ : tuple of CalibrationPrompt
        The prompts kept for this rig.
    columns_ : tuple of tuple of int
        Each kept prompt's shapes as columns of ``shape_names``.
    weight_map_ : (k, k) float or None
        ``C`` once :meth:`fit` ran.
    held_ : (n_prompts,) int or None
        Frames held per prompt in the fit.
    readings_ : (n_prompts,) float or None
        Each prompted expression's tracked level over its hold (its shapes' mean weight, before
        the map; 0 when they never rose): what the tracker sees of it. NaN for the neutral and
        head prompts and for prompts not reached or left out.
    """

    def __init__(self, shape_names: Sequence[str], prompts: Sequence[CalibrationPrompt] | None = None, *,
                 seconds: float = SECONDS_PER_PROMPT, ridge: float = RIDGE, hold: float = HOLD) -> None:
        if not (np.isfinite(seconds) and seconds > 0):
            raise ValueError(f"seconds must be a number > 0, got {seconds!r}")
        if not (np.isfinite(hold) and 0.0 < hold <= 1.0):
            raise ValueError(f"hold must be in (0, 1], got {hold!r}")
        if not (np.isfinite(ridge) and ridge >= 0):
            raise ValueError(f"ridge must be a number ≥ 0, got {ridge!r}")
        self.shape_names = list(shape_names)
        self.seconds = float(seconds)
        self.ridge = float(ridge)
        self.hold = float(hold)
        by_arkit: dict[str, int] = {}
        for j, n in enumerate(self.shape_names):
            arkit = canonical_arkit_name(n)
            if arkit is not None:
                by_arkit.setdefault(arkit, j)
        kept: list[CalibrationPrompt] = []
        cols: list[tuple[int, ...]] = []
        for p in DEFAULT_PROMPTS if prompts is None else prompts:
            if not isinstance(p, CalibrationPrompt):
                raise ValueError(f"prompts: each must be a CalibrationPrompt, got {p!r}")
            shown = tuple(by_arkit[s] for s in p.shapes if s in by_arkit)
            if p.shapes and not shown:
                continue  # the rig cannot show it
            kept.append(p)
            cols.append(shown)
        if sum(1 for c in cols if c) < 1:
            raise ValueError("prompts: the rig has none of the prompted shapes (ARKit names: "
                             + ", ".join(sorted({s for p in (prompts or DEFAULT_PROMPTS) for s in p.shapes})) + ")")
        self.prompts_ = tuple(kept)
        self.columns_ = tuple(cols)
        self.weight_map_: NDArray[np.float64] | None = None
        self.held_: NDArray[np.intp] | None = None
        self.readings_: NDArray[np.float64] | None = None
        self._start: float | None = None
        self._frames: list[tuple[int, NDArray[np.float64]]] = []

    @property
    def duration(self) -> float:
        """Seconds the whole session lasts."""
        return self.seconds * len(self.prompts_)

    def prompt_index(self, t: float) -> int | None:
        """The prompt showing at time ``t`` (seconds, the frames' clock), None after the session.

        The session starts at the first frame :meth:`add` receives (0 before it).
        """
        if self._start is None:
            return 0
        i = int((float(t) - self._start) // self.seconds)
        return i if 0 <= i < len(self.prompts_) else None

    def add(self, t: float, weights: ArrayLike) -> int | None:
        """Record one tracked frame's weights ((k,)) at time ``t``; returns its prompt (None: the session is over)."""
        w = np.asarray(weights, np.float64)
        if w.shape != (len(self.shape_names),):
            raise ValueError(f"weights must be ({len(self.shape_names)},), got shape {w.shape}")
        if self._start is None:
            self._start = float(t)
        i = self.prompt_index(t)
        if i is not None:
            self._frames.append((i, w.copy()))
        return i

    def neutral_window(self) -> tuple[float, float] | None:
        """``(start, end)`` seconds of the session's first prompt if it is a still neutral face, else None.

        None too before the session's first frame. :class:`~workbench.capture.LiveTracker`
        takes the actor's neutral from these frames when the prompt ends.
        """
        first = self.prompts_[0]
        if self._start is None or self.columns_[0] or first.head != "still":
            return None
        return self._start, self._start + self.seconds

    def reread(self, index: int, weights: ArrayLike) -> None:
        """Replace the frames recorded for prompt ``index`` by ``weights`` ((n, k)): the same frames read again.

        The tracker reads the neutral prompt's frames again once it has taken its neutral
        from them, so that the fit sees them as read from then on.
        """
        W = np.asarray(weights, np.float64).reshape(-1, len(self.shape_names))
        if not 0 <= index < len(self.prompts_):
            raise ValueError(f"index must be a prompt of the session (0–{len(self.prompts_) - 1}), got {index!r}")
        self._frames = [(i, w) for i, w in self._frames if i != index] + [(index, w.copy()) for w in W]

    def done(self, t: float) -> bool:
        """The session is over at time ``t``."""
        return self._start is not None and self.prompt_index(t) is None

    def fit(self, *, leave_out: Sequence[int] = ()) -> NDArray[np.float64]:
        """Fit ``C`` on the frames recorded so far (prompts not reached are left out).

        ``leave_out``: indices into :attr:`prompts_` fitted without (what a session missing
        them would give: ``benchmarks/bench_live.py`` leaves each out in turn).

        Raises
        ------
        ValueError
            No frame of the neutral prompt, or no prompted expression was held.
        """
        k = len(self.shape_names)
        rows: list[NDArray[np.float64]] = []
        targets: list[NDArray[np.float64]] = []
        held = np.zeros(len(self.prompts_), np.intp)
        readings = np.full(len(self.prompts_), np.nan)
        for i, cols in enumerate(self.columns_):
            R = np.array([w for p, w in self._frames if p == i]).reshape(-1, k)
            if R.shape[0] == 0 or i in leave_out:
                continue
            sel = held_frames(R, cols, hold=self.hold)
            if cols:
                readings[i] = float(R[sel][:, list(cols)].mean()) if sel.any() else 0.0
            y = np.zeros(k)
            y[list(cols)] = 1.0
            rows.append(R[sel])
            targets.append(np.tile(y, (int(sel.sum()), 1)))
            held[i] = int(sel.sum())
        neutral = [i for i, c in enumerate(self.columns_) if not c]
        if neutral and not held[neutral].any():
            raise ValueError("calibration: no frame of the neutral face was tracked")
        if not any(held[i] for i, c in enumerate(self.columns_) if c):
            raise ValueError("calibration: no prompted expression was tracked (was a face in view?)")
        self.weight_map_ = fit_weight_map(np.vstack(rows), np.vstack(targets), ridge=self.ridge)
        self.held_ = held
        self.readings_ = readings
        return self.weight_map_

    def weak_prompts(self) -> list[int]:
        """Indices into :attr:`prompts_` of the prompted expressions read below :data:`WEAK_READING` (after :meth:`fit`)."""
        if self.readings_ is None:
            return []
        return [i for i, r in enumerate(self.readings_) if np.isfinite(r) and r < WEAK_READING]

    def summary(self) -> str:
        """One line on the fit: ``"calibrated: 7 expressions held (96 frames)"``, and the expressions read weakly.

        E.g. ``"…; read weakly: mouthFunnel 0.00, browDownLeft/browDownRight 0.08"`` (the prompted
        shapes' mean tracked weight over the hold, before the map).
        """
        if self.held_ is None or self.readings_ is None:
            return "not calibrated yet"
        shown = sum(1 for i, c in enumerate(self.columns_) if c and self.held_[i])
        text = (f"calibrated: {shown} expression{'' if shown == 1 else 's'} held "
                f"({int(self.held_.sum())} frames)")
        weak = self.weak_prompts()
        if weak:
            text += "; read weakly: " + ", ".join(
                f"{'/'.join(self.shape_names[j] for j in self.columns_[i])} {self.readings_[i]:.2f}" for i in weak)
        return text

    def apply(self, weights: ArrayLike) -> NDArray[np.float64]:
        """``weights @ C`` (unclipped; (k,) or (T, k)); unchanged before :meth:`fit`."""
        w = np.asarray(weights, np.float64)
        return w if self.weight_map_ is None else w @ self.weight_map_
