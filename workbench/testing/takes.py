"""Capture takes that behave like a real phone take: dense, co-articulated, asymmetric, noisy.

A tracker tuned on clean generated takes (a few shapes active at a time, every
weight 0 at rest, transitions eased exactly into their keys) can lose to naive
baselines on a real performance. The generator here follows the measured facts
of a real ARKit take (``shared/notes/what-real-takes-look-like.md``, kept in
:data:`REAL_TAKE`) for any rig:

* **dense co-articulation** — an expression moves many shapes at once (a few
  latent "expression factors" load on every shape), about 33 of 52 shapes sit
  above 0.05 in a frame;
* **a rest pose that is not zero** — about a quarter of the shapes sit at 0.05–0.25
  when the face is at rest; peaks are moderate (median ≈ 0.5) and a few shapes
  barely move at all;
* **asymmetry** — left/right pairs (:func:`workbench.arkit.mirror_name`) share a
  level but split it unevenly (mean ``|L − R|`` ≈ 0.57 of the mean level);
* **transitions** 4–28 frames long (median ≈ 12), each shape reaching half of its
  change at its own time (staggered onsets), stopping short of the key or settling
  towards it during the hold that follows, rarely overshooting; some onsets are fast;
* **phone-like noise** — temporally correlated jitter on every weight, clipped to the
  sliders (as a phone clips at 0), so the jitter is of the real take's order.

:func:`realistic_weights` makes the weights only; :func:`take_markers` observes any
weights as markers on the rig (noisy, under head motion) through
:func:`workbench.capture.synthetic_performance`; :func:`realistic_take` does both.
:func:`take_statistics` measures a take the way the notes' table does, so a test
can check a generated take against :data:`REAL_TAKE`. Everything is deterministic
given its seed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.arkit import mirror_name
from workbench.capture.rig import ExpressionSpace
from workbench.capture.synthetic import SyntheticPerformance, synthetic_performance

if TYPE_CHECKING:
    from collections.abc import Sequence

    from workbench.capture.expression_calibration import CalibrationPrompt, ExpressionCalibration
    from workbench.core.state import FaceState

__all__ = ["REAL_TAKE", "TakeStatistics", "calibration_head_motion", "calibration_session", "realistic_take", "realistic_weights",
           "take_markers", "take_statistics"]

#: The real phone take's statistics (52 ARKit weights, 335 frames at 30 fps), from the notes:
#: name → (measured value, low, high) where low..high is the range a generated take should land in.
REAL_TAKE: dict[str, tuple[float, float, float]] = {
    "active_share": (33 / 52, 29 / 52, 36 / 52),  # median share of shapes above 0.05 per frame (p10–p90 29–36)
    "strong_share": (16 / 52, 10 / 52, 24 / 52),  # median share above 0.2 per frame
    "rest_share": (12 / 52, 8 / 52, 16 / 52),  # share of shapes whose 5th percentile is above 0.05
    "rest_max": (0.25, 0.12, 0.4),  # the highest 5th percentile
    "peak_median": (0.52, 0.38, 0.66),  # median over shapes of the peak weight
    "still_share": (4 / 52, 1 / 52, 8 / 52),  # share of shapes that never exceed 0.1
    "change_median": (0.016, 0.008, 0.035),  # median over frames of the largest per-frame change
    "change_p95": (0.27, 0.12, 0.45),  # its 95th percentile (fast onsets)
    "jitter": (6.8e-4, 2e-4, 2e-3),  # mean squared second difference
    "transitions_per_second": (12 / 11.1, 0.6, 1.8),  # monotone transitions of the expression magnitude > 0.25
    "transition_frames": (12.0, 6.0, 22.0),  # their median length (4–28)
    "onset_spread": (0.31, 0.15, 0.5),  # median spread of the shapes' half-change times / transition length
    "asymmetry": (0.57, 0.35, 0.8),  # mean |L − R| over the mean level of the pairs
}


# ------------------------------------------------------------------ the weights
def _pairs(names: tuple[str, ...], plain: NDArray[np.intp]) -> list[tuple[int, ...]]:
    """The plain shapes grouped into units: mirror pairs ``(left, right)`` and single shapes ``(j,)``."""
    index = {names[j]: int(j) for j in plain}
    seen: set[int] = set()
    units: list[tuple[int, ...]] = []
    for j in plain:
        j = int(j)
        if j in seen:
            continue
        other = mirror_name(names[j])
        o = index.get(other) if other is not None else None
        if o is not None and o != j and o not in seen:
            units.append((j, o))
            seen.update((j, o))
        else:
            units.append((j,))
            seen.add(j)
    return units


def _ramp(u: NDArray[np.float64], centre: NDArray[np.float64], half: NDArray[np.float64]) -> NDArray[np.float64]:
    """(L, k) smoothstep from 0 to 1 centred at ``centre`` with half-width ``half`` (both (k,)), for u in [0, 1]."""
    x = np.clip((u[:, None] - (centre - half)) / (2.0 * half), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def realistic_weights(
    model: FaceState,
    T: int,
    *,
    fps: float = 30.0,
    seed: int = 0,
    factors: int = 6,
    noise: float = 0.004,
    repeat: float = 0.0,
) -> NDArray[np.float64]:
    """Weights ``(T, k)`` like a real phone take (see the module docstring), in ``model.shape_names`` order.

    Parameters
    ----------
    model : FaceModel
        Any rig with blendshapes; pairs are found by :func:`~workbench.arkit.mirror_name`
        (ARKit, ``_L``/``_R``, ``Left``/``Right`` ...). Muted shapes stay 0; derived
        (corrective) shapes play their drivers' product.
    T : int
        Frames (≥ 1).
    fps : float
        Frame rate; hold and transition lengths are in seconds of a 30 fps take.
    seed : int
    factors : int
        Latent expression factors the shapes co-articulate on (≥ 1).
    noise : float
        Standard deviation of the phone-like jitter on each weight (temporally correlated).
    repeat : float
        Chance that a transition returns to an expression the take showed before
        (varied: its reach, L/R split and a few shapes differ), as talking revisits
        visemes and an actor repeats a smile; 0 (default) makes every expression new,
        the hardest case for methods that look for similar moments in a take.

    Returns
    -------
    (T, k) float
        Clipped to the shapes' slider ranges.
    """
    if isinstance(T, bool) or not isinstance(T, int | np.integer) or T < 1:
        raise ValueError(f"T must be an int ≥ 1, got {T!r}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    if int(factors) < 1:
        raise ValueError(f"factors must be ≥ 1, got {factors!r}")
    if not (np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise must be a number ≥ 0, got {noise!r}")
    if not (np.isfinite(repeat) and 0.0 <= repeat <= 1.0):
        raise ValueError(f"repeat must be a number in [0, 1], got {repeat!r}")
    if not model.shapes:
        raise ValueError("model: it has no blendshapes to animate")
    rng = np.random.default_rng(seed)
    T = int(T)
    space = ExpressionSpace.from_model(model)
    names = space.shape_names
    units = _pairs(names, space.plain)
    nu = len(units)
    k = len(names)
    rate = float(fps) / 30.0  # lengths below are frames of a 30 fps take

    # per unit: rest level, reach, co-articulation loadings
    sizes = np.array([len(m) for m in units])
    order = rng.permutation(nu)
    at_rest = np.zeros(nu, bool)  # about 23 % of the shapes sit above 0.05 at rest
    at_rest[order[np.cumsum(sizes[order]) <= round(0.23 * sizes.sum())]] = True
    rest_u = np.where(at_rest, rng.uniform(0.07, 0.24, nu), rng.uniform(0.0, 0.02, nu))
    peak_u = np.clip(rng.lognormal(np.log(0.6), 0.35, nu), 0.2, 1.0)
    still = np.zeros(nu, bool)  # a few shapes barely move (about 8 % of them)
    still[rng.choice(nu, max(1, round(0.06 * nu)), replace=False)] = True
    peak_u[still] = rng.uniform(0.05, 0.09, int(still.sum()))
    rest_u = np.minimum(rest_u, 0.8 * peak_u)
    load = rng.gamma(0.5, 1.0, (nu, int(factors)))
    load /= np.maximum(load.sum(1, keepdims=True), 1e-12)

    # per shape (a pair's sides differ a little at rest)
    col_of: list[int] = []
    unit_of: list[int] = []
    for u, members in enumerate(units):
        for j in members:
            col_of.append(j)
            unit_of.append(u)
    cols = np.array(col_of, np.intp)
    uo = np.array(unit_of, np.intp)
    ks = cols.size
    rest = rest_u[uo] * np.exp(rng.normal(0.0, 0.25, ks))
    peak = peak_u[uo]
    side = np.zeros(ks)  # +1 left member of a pair, −1 right, 0 single
    pos = 0
    for members in units:
        if len(members) == 2:
            side[pos], side[pos + 1] = 1.0, -1.0
        pos += len(members)

    def key_state() -> NDArray[np.float64]:
        """Target weights of one expression: the factors' activations spread over every unit, then split L/R."""
        f = rng.gamma(0.8, 1.0, int(factors))
        score = load @ f / max(float(f.max(initial=0.0)), 1e-12) + rng.normal(0.0, 0.1, nu)
        # the share of the face this expression moves (co-articulation: the units the factors load on most)
        n_on = round(rng.uniform(0.45, 0.65) * nu)
        on = np.argsort(-score)[:n_on]
        z = np.zeros(nu)
        z[on] = rng.beta(2.2, 2.0, n_on)
        a = np.clip(rng.normal(0.0, 0.4, nu), -0.9, 0.9)  # the L/R split of what the expression adds
        out = rest + ((peak_u - rest_u) * z)[uo] * (1.0 + side * a[uo])
        out = np.where(still[uo], np.minimum(out, 0.8 * peak), out)
        return np.asarray(np.clip(out, 0.0, 1.0))

    W = np.empty((T, ks))
    v = rest.copy()
    visited: list[NDArray[np.float64]] = []
    t = 0
    while t < T:
        # a transition into a new expression: per-shape onsets, stopping short (rarely overshooting)
        fast = rng.random() < 0.3  # a fast onset (a jaw drop, a blink)
        L = int(np.clip(round((rng.uniform(3.0, 6.0) if fast else rng.lognormal(np.log(13.0), 0.45)) * rate),
                        max(2, round(3 * rate)), round(28 * rate)))
        if visited and repeat > 0.0 and rng.random() < repeat:
            seen_key = visited[int(rng.integers(len(visited)))]
            varied = rest + (seen_key - rest) * rng.uniform(0.8, 1.1) + rng.normal(0.0, 0.03, ks)
            target = np.clip(varied, 0.0, 1.0)
        else:
            target = key_state() if rng.random() < 0.8 else rest.copy() + rng.normal(0.0, 0.02, ks)
            visited.append(target)
        reach = 1.0 - rng.uniform(0.0, 0.3, ks)
        over = rng.random(ks) < 0.04
        reach[over] = 1.0 + rng.uniform(0.03, 0.1, int(over.sum()))
        centre = np.clip(0.5 + rng.normal(0.0, 0.18, ks), 0.15, 0.85)
        half = np.minimum(centre, 1.0 - centre) * rng.uniform(0.5, 1.0, ks)
        prog = np.arange(1, L + 1) / L
        start = v.copy()
        end = start + (target - start) * reach
        seg = start + (end - start) * _ramp(prog, centre, half)
        n = min(L, T - t)
        W[t : t + n] = seg[:n]
        t += n
        v = seg[-1]
        # a hold: some shapes settle towards the key, the face drifts a little
        H = round(rng.uniform(4.0, 26.0) * rate)
        if t >= T or H <= 0:
            continue
        tau = rng.uniform(3.0, 10.0) * rate
        settle = rng.random(ks) < 0.5
        s = np.arange(1, H + 1)[:, None]
        goal = np.where(settle, target, v)
        drift = np.cumsum(rng.normal(0.0, 0.002, (H, ks)), axis=0)
        hold = goal + (v - goal) * np.exp(-s / tau) + drift
        n = min(H, T - t)
        W[t : t + n] = hold[:n]
        t += n
        v = hold[-1]

    # phone-like jitter: AR(1) noise, correlated over a few frames
    if noise > 0:
        rho = 0.3
        e = rng.normal(0.0, noise * np.sqrt(1.0 - rho * rho), (T, ks))
        x = np.empty_like(e)
        x[0] = rng.normal(0.0, noise, ks)
        for f in range(1, T):
            x[f] = rho * x[f - 1] + e[f]
        W += x
    plain = np.zeros((T, k))
    plain[:, cols] = W
    plain[:, space.plain] = np.clip(plain[:, space.plain], space.lo, space.hi)
    return np.asarray(space.full_weights(plain[:, space.plain]))


def _session_schedule(
    model: FaceState, prompts: Sequence[CalibrationPrompt] | None, seconds: float, fps: float
) -> tuple[ExpressionCalibration, int, NDArray[np.float64]]:
    """The tracker's schedule of a guided session on ``model``: (its calibration, frames per prompt,
    a prompt's frame times (n,))."""
    from workbench.capture.expression_calibration import ExpressionCalibration

    if not (np.isfinite(seconds) and seconds > 0 and np.isfinite(fps) and fps > 0):
        raise ValueError(f"seconds and fps must be numbers > 0, got {seconds!r}, {fps!r}")
    cal = ExpressionCalibration(list(model.shape_names), prompts, seconds=seconds)
    n = max(1, round(seconds * fps))
    return cal, n, np.arange(n) / float(fps)


def calibration_session(
    model: FaceState,
    prompts: Sequence[CalibrationPrompt] | None = None,
    *,
    seconds: float = 2.0,
    fps: float = 15.0,
    seed: int = 0,
) -> NDArray[np.float64]:
    """Weights ``(T, k)`` of an actor following a guided calibration session, in ``model.shape_names`` order.

    Each prompt (:data:`~workbench.capture.expression_calibration.DEFAULT_PROMPTS` by
    default; the ones the rig cannot show are skipped, as the tracker skips them) lasts
    ``seconds``: the actor reacts late (12–25 % of it: 0.25–0.5 s of a 2 s prompt), eases in
    over 10–20 % of it to 0.85–1.0 of the expression (each shape 0.9–1.0 of that), holds, and
    lets go before the next prompt — not the exact 1 the calibration assumes.
    """
    cal, n, t = _session_schedule(model, prompts, seconds, fps)
    rng = np.random.default_rng(seed)
    W = np.zeros((n * len(cal.prompts_), len(cal.shape_names)))
    for i, cols in enumerate(cal.columns_):
        on, up = seconds * rng.uniform(0.12, 0.25), seconds * rng.uniform(0.1, 0.2)
        off = seconds * (1.0 - rng.uniform(0.18, 0.35))
        env = np.clip((t - on) / up, 0.0, 1.0) * np.clip(1.0 - (t - off) / (0.125 * seconds), 0.0, 1.0)
        env = env * env * (3.0 - 2.0 * env)
        level = rng.uniform(0.85, 1.0)
        for j in cols:
            W[i * n : (i + 1) * n, j] = level * rng.uniform(0.9, 1.0) * env
    return W


def calibration_head_motion(
    model: FaceState,
    prompts: Sequence[CalibrationPrompt] | None = None,
    *,
    seconds: float = 2.0,
    fps: float = 15.0,
    seed: int = 0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Yaw and pitch ``(T,)`` in radians of the actor's head through a guided session.

    Frames as :func:`calibration_session` (same prompts, ``seconds``, ``fps``). The head
    drifts a little throughout (±3° yaw, ±2° pitch, as a person holding still in front of a
    camera does); in a prompt whose ``head`` is ``"turn"`` the actor, after the same late
    reaction, turns left and right once (12–18°), in a ``"nod"`` prompt nods down and up
    once (6–10°).
    """
    cal, n, t = _session_schedule(model, prompts, seconds, fps)
    rng = np.random.default_rng(seed)
    ts = np.arange(n * len(cal.prompts_)) / float(fps)
    phase = rng.uniform(0.0, 2 * np.pi, 2)
    yaw = np.deg2rad(3.0) * np.sin(2 * np.pi * 0.3 * ts + phase[0])
    pitch = np.deg2rad(2.0) * np.sin(2 * np.pi * 0.2 * ts + phase[1])
    for i, p in enumerate(cal.prompts_):
        if p.head == "still":
            continue
        on = seconds * rng.uniform(0.12, 0.25)
        u = np.clip((t - on) / (0.9 * seconds - on), 0.0, 1.0)  # back to the front before the next prompt
        sweep = np.sin(2 * np.pi * u)
        if p.head == "turn":
            yaw[i * n : (i + 1) * n] += np.deg2rad(rng.uniform(12.0, 18.0)) * sweep
        else:
            pitch[i * n : (i + 1) * n] += np.deg2rad(rng.uniform(6.0, 10.0)) * sweep
    return yaw, pitch


# ------------------------------------------------------------------ markers
def take_markers(
    model: FaceState,
    weights: ArrayLike,
    *,
    fps: float = 30.0,
    seed: int = 0,
    markers: int | ArrayLike = 120,
    noise_mm: float = 0.5,
    max_degrees: float = 10.0,
    occlusion: float = 0.0,
) -> SyntheticPerformance:
    """Markers of the rig playing ``weights``, with head motion and noise (via :func:`synthetic_performance`).

    Parameters
    ----------
    model : FaceModel
    weights : (T, k) float
        In ``model.shape_names`` order (e.g. :func:`realistic_weights`).
    fps : float
    seed : int
    markers : int or (m,) int
        A count spread over the face, or vertex ids.
    noise_mm : float
        Gaussian noise per coordinate in millimetres (converted with ``metadata.metres_per_unit``).
    max_degrees : float
        The head turns up to this many degrees (yaw; pitch 0.6×, roll 0.4× of it) and drifts.
    occlusion : float
        In [0, 1): probability that a marker observation is NaN.

    Returns
    -------
    SyntheticPerformance
        ``weights`` as played (muted 0, derived from drivers), poses, meshes, markers; no landmarks.
    """
    W = np.asarray(weights, np.float64)
    if W.ndim != 2:
        raise ValueError(f"weights must be (T, k), got shape {W.shape}")
    mpu = float(getattr(model.metadata, "metres_per_unit", 1.0) or 1.0)
    if not (np.isfinite(noise_mm) and noise_mm >= 0):
        raise ValueError(f"noise_mm must be a number ≥ 0, got {noise_mm!r}")
    if not (np.isfinite(max_degrees) and max_degrees >= 0):
        raise ValueError(f"max_degrees must be a number ≥ 0, got {max_degrees!r}")
    return synthetic_performance(model, W.shape[0], fps=fps, seed=seed, markers=markers, landmarks=0,
                                 noise=1e-3 * float(noise_mm) / mpu, occlusion=occlusion,
                                 head_motion=float(max_degrees) / 15.0, weights=W)


def realistic_take(
    model: FaceState,
    T: int,
    *,
    fps: float = 30.0,
    seed: int = 0,
    markers: int | ArrayLike = 120,
    noise_mm: float = 0.5,
    max_degrees: float = 10.0,
    occlusion: float = 0.0,
) -> SyntheticPerformance:
    """A realistic take (:func:`realistic_weights`) observed as markers (:func:`take_markers`).

    The parameters are those of the two functions; both use ``seed``.
    """
    W = realistic_weights(model, T, fps=fps, seed=seed)
    return take_markers(model, W, fps=fps, seed=seed, markers=markers, noise_mm=noise_mm, max_degrees=max_degrees,
                        occlusion=occlusion)


# ------------------------------------------------------------------ statistics
@dataclass(frozen=True)
class TakeStatistics:
    """A take measured as the notes' table does (names as in :data:`REAL_TAKE`; shares are of the shapes).

    Attributes
    ----------
    active_share, strong_share : float
        Median share of the shapes above 0.05 / 0.2 per frame.
    rest_share, rest_max : float
        Share of shapes whose 5th percentile is above 0.05; the highest 5th percentile.
    peak_median, still_share : float
        Median peak weight; share of shapes that never exceed 0.1.
    change_median, change_p95 : float
        Median and 95th percentile over frames of the largest per-frame change of any weight.
    jitter : float
        Mean squared second difference.
    transitions_per_second, transition_frames : float
        Monotone transitions of the expression magnitude by more than 0.25, per second; their median length.
    onset_spread : float
        Median over transitions of the spread of the shapes' half-change times, as a share of the transition.
    asymmetry : float
        Mean ``|L − R|`` over the mean level, over the mirror pairs.
    """

    active_share: float
    strong_share: float
    rest_share: float
    rest_max: float
    peak_median: float
    still_share: float
    change_median: float
    change_p95: float
    jitter: float
    transitions_per_second: float
    transition_frames: float
    onset_spread: float
    asymmetry: float

    def outside(self, ranges: dict[str, tuple[float, float, float]] = REAL_TAKE) -> dict[str, float]:
        """The statistics outside their ``(value, low, high)`` range (empty: the take looks real)."""
        return {n: float(getattr(self, n)) for n, (_v, lo, hi) in ranges.items()
                if not lo <= float(getattr(self, n)) <= hi}


def _transitions(W: NDArray[np.float64], rest: NDArray[np.float64]) -> list[tuple[int, int]]:
    """Monotone runs ``(a, b)`` of the expression magnitude ``||w − rest||₂`` (over 3 frames) changing by > 0.25."""
    T = W.shape[0]
    if T < 4:
        return []
    mag = np.linalg.norm(W - rest, axis=1)
    mag = np.convolve(np.pad(mag, 1, mode="edge"), np.ones(3) / 3.0, mode="valid")
    d = np.diff(mag)
    runs: list[tuple[int, int]] = []
    a = 0
    for f in range(1, d.size + 1):
        if f == d.size or np.sign(d[f]) != np.sign(d[a]):
            if abs(mag[f] - mag[a]) > 0.25:
                runs.append((a, f))
            a = f
    return runs


def take_statistics(weights: ArrayLike, shape_names: tuple[str, ...] | list[str], *, fps: float = 30.0,
                    shapes: ArrayLike | None = None) -> TakeStatistics:
    """Measure a ``(T, k)`` take (see :class:`TakeStatistics`); ``shapes`` limits it to some columns (default all)."""
    W_all = np.asarray(weights, np.float64)
    names = list(shape_names)
    cols = np.arange(W_all.shape[1]) if shapes is None else np.asarray(shapes, np.intp)
    W = W_all[:, cols]
    T, k = W.shape
    p5 = np.percentile(W, 5, axis=0)
    peak = W.max(0)
    change = np.abs(np.diff(W, axis=0)).max(1) if T > 1 else np.zeros(1)
    jitter = float(np.mean(np.diff(W, 2, axis=0) ** 2)) if T > 2 else 0.0
    runs = _transitions(W, p5)
    spreads = []
    for a, b in runs:
        delta = W[b] - W[a]
        moving = np.flatnonzero(np.abs(delta) > 0.1)
        if moving.size < 2 or b - a < 3:
            continue
        seg = (W[a : b + 1, moving] - W[a, moving]) / delta[moving]
        half = np.argmax(seg >= 0.5, axis=0).astype(np.float64)
        spreads.append(float(np.percentile(half, 90) - np.percentile(half, 10)) / (b - a))
    sel = [names[c] for c in cols]
    index = {n: i for i, n in enumerate(sel)}
    diffs, levels = [], []
    for i, n in enumerate(sel):
        o = mirror_name(n)
        j = index.get(o) if o is not None else None
        if j is not None and j > i:
            diffs.append(np.abs(W[:, i] - W[:, j]).mean())
            levels.append(0.5 * (W[:, i] + W[:, j]).mean())
    return TakeStatistics(
        active_share=float(np.median((W > 0.05).sum(1))) / k,
        strong_share=float(np.median((W > 0.2).sum(1))) / k,
        rest_share=float((p5 > 0.05).sum()) / k,
        rest_max=float(p5.max()),
        peak_median=float(np.median(peak)),
        still_share=float((peak <= 0.1).sum()) / k,
        change_median=float(np.median(change)),
        change_p95=float(np.percentile(change, 95)),
        jitter=jitter,
        transitions_per_second=len(runs) / (T / float(fps)),
        transition_frames=float(np.median([b - a for a, b in runs])) if runs else 0.0,
        onset_spread=float(np.median(spreads)) if spreads else 0.0,
        asymmetry=float(np.sum(diffs) / max(np.sum(levels), 1e-12)) if diffs else 0.0,
    )
