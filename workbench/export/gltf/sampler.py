"""The weights, translation and rotation samplers: curves merged onto glTF's one key list, exactly.

Sampler construction (exact, no resampling unless ``bake=True``)
-----------------------------------------------------------------
glTF has one sampler for all morph weights, so the key times of every weight
track are merged. The sampler's interpolation is ``STEP`` if every segment is
step, ``CUBICSPLINE`` if any is Bézier, else ``LINEAR``. At every merged time
the value and the left/right derivatives of each curve are written; since our
Bézier segments are cubic polynomials of ``t`` (:mod:`workbench.animation.curves`),
splitting one at an extra time with the true derivatives reproduces it
exactly, and a linear segment is a cubic with both tangents equal to its
slope. glTF ``CUBICSPLINE`` stores per key ``(a_k, v_k, b_k)`` with
``p(t) = h00 v_k + h10 Δ b_k + h01 v_{k+1} + h11 Δ a_{k+1}`` (spec, Appendix C),
so ``b_k`` = our out-slope and ``a_{k+1}`` = our in-slope (value per second).
A *step* segment inside a LINEAR/CUBICSPLINE sampler is written as a hold
followed by a ramp over the last ``ε = min(1e-4 s, gap/4)`` before the next
key (glTF cannot jump inside a non-STEP sampler); that ramp is the only place
the file differs from :meth:`Timeline.evaluate`. Times are float32 seconds.
Negative key times are rejected (glTF animations start at 0 or later).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.animation.curves import Track
from workbench.export.base import ExportError
from workbench.export.encoding import crossing_times

_STEP_EPS = 1e-4


@dataclass(frozen=True, eq=False)
class Curve:
    """One scalar curve for a sampler: a component (or a linear combination) of a track, or a constant.

    ``value(t) = scale * track.sample(t)[:, component] + offset``, or with
    ``coeffs`` ``scale * track.sample(t) @ coeffs + offset``; without a track
    ``scale * constant``. ``clamp`` = ``(lo, hi)`` clips the written values
    (used only where values are resampled at frames). With ``factors`` the
    curve is their product (a corrective shape's weight), then clamped.
    """

    track: Track | None
    component: int = 0
    constant: float = 0.0
    scale: float = 1.0
    coeffs: NDArray[np.float64] | None = None
    offset: float = 0.0
    clamp: tuple[float, float] | None = None
    factors: tuple[Curve, ...] = ()

    def leaves(self) -> list[Curve]:
        """The curves this one is made of (itself, or its factors')."""
        return [leaf for f in self.factors for leaf in f.leaves()] if self.factors else [self]

    def _combine(self, arr: NDArray[np.float64]) -> NDArray[np.float64]:
        col = arr @ self.coeffs if self.coeffs is not None else arr[:, self.component]
        return self.scale * col

    def sample(self, times: NDArray[np.float64]) -> NDArray[np.float64]:
        """Values at ``times`` (clamped if ``clamp``)."""
        ts = np.asarray(times, np.float64).reshape(-1)
        if self.factors:
            # the same operations, in the same order, as workbench.core.families.derive_weights
            w: NDArray[np.float64] = np.ones(ts.size)
            for f in self.factors:
                w = w * f.sample(ts)
            return w if self.clamp is None else np.clip(w, *self.clamp)
        if self.track is None:
            return np.full(ts.size, self.scale * self.constant)
        v = self._combine(self.track.sample(ts)) + self.offset
        return v if self.clamp is None else np.clip(v, *self.clamp)


@dataclass(frozen=True)
class SamplerData:
    """Arrays of one glTF animation sampler.

    Attributes
    ----------
    times : (K,) float
    interpolation : {"STEP", "LINEAR", "CUBICSPLINE"}
    values, in_tangents, out_tangents : (K, m) float
        Per key and curve (tangents are per second; used for CUBICSPLINE).
    """

    times: NDArray[np.float64]
    interpolation: str
    values: NDArray[np.float64]
    in_tangents: NDArray[np.float64]
    out_tangents: NDArray[np.float64]

    def output(self) -> NDArray[np.float32]:
        """Flat float32 sampler output in glTF order (with in/out tangents for CUBICSPLINE)."""
        if self.interpolation == "CUBICSPLINE":
            out = np.stack([self.in_tangents, self.values, self.out_tangents], axis=1)
            return out.astype(np.float32).reshape(-1)
        return self.values.astype(np.float32).reshape(-1)


def _segment_codes(tr: Track) -> set[str]:
    # the last key's interpolation governs no segment
    return set(tr.interpolations[:-1]) if len(tr) > 1 else set()


def merge_curves(
    curves: list[Curve],
    *,
    bake_times: NDArray[np.float64] | None = None,
    rotation_track: Track | None = None,
    knots: NDArray[np.float64] | None = None,
) -> SamplerData | None:
    """Merge scalar curves onto one glTF sampler (see module docstring).

    Parameters
    ----------
    curves : list of Curve
        The sampler's output columns.
    bake_times : (F,) float, optional
        Resample at these times with LINEAR instead of merging keys.
    knots : (F,) float, optional
        Extra key times (the frames) when a product curve (``factors``) is
        animated and the sampler is not STEP: the product is exact there.
    rotation_track : Track, optional
        If given, ``curves`` are its quaternion components: interpolation is
        STEP or LINEAR (glTF slerps rotations, like :class:`Track`).

    Returns
    -------
    SamplerData or None
        None when no curve is animated.
    """
    leaves = [leaf for c in curves for leaf in c.leaves()]
    tracks: dict[int, Track] = {id(c.track): c.track for c in leaves if c.track is not None}
    if not tracks:
        return None
    animated_products = any(c.factors and any(leaf.track is not None for leaf in c.leaves()) for c in curves)
    if bake_times is not None:
        times = np.asarray(bake_times, np.float64)
        mode = "LINEAR"
    else:
        orig = set().union(*(_segment_codes(t) for t in tracks.values()))
        codes = orig
        if rotation_track is not None:
            codes = {"step"} if codes <= {"step"} else {"linear"}
        if not codes or codes == {"step"}:
            mode = "STEP"
        elif "bezier" in codes:
            mode = "CUBICSPLINE"
        else:
            mode = "LINEAR"
        times = np.unique(np.concatenate([t.times for t in tracks.values()]))
        if mode != "STEP" and animated_products and knots is not None and knots.size:
            lo, hi = times[0], times[-1]
            fr = np.asarray(knots, np.float64)
            # frames inside the keyed range (outside it every track holds its end value)
            times = np.unique(np.concatenate([times, fr[(fr > lo) & (fr < hi)]]))
            times = _drop_close(times, np.unique(np.concatenate([t.times for t in tracks.values()])))
        if mode != "STEP":
            times = _add_crossings(times, leaves)
        if mode != "STEP" and "step" in orig:
            # hold-then-ramp knots just before the end of every step segment
            gaps = np.diff(times)
            eps = min(_STEP_EPS, float(gaps.min()) / 4.0) if gaps.size else _STEP_EPS
            extra = [
                tr.times[i + 1] - eps
                for tr in tracks.values()
                for i in range(len(tr) - 1)
                if tr.keys[i].interpolation == "step"
            ]
            times = np.unique(np.concatenate([times, np.asarray(extra)]))
    if times.size and times[0] < 0:
        raise ExportError(f"glTF animation times must be >= 0; the first key is at {times[0]:g} s")
    K, m = times.size, len(curves)
    V = np.zeros((K, m))
    A = np.zeros((K, m))
    B = np.zeros((K, m))
    cache: dict[int, tuple[NDArray[np.float64], ...]] = {}
    for j, c in enumerate(curves):
        V[:, j], A[:, j], B[:, j] = _column(c, times, mode, cache)
    return SamplerData(times, mode, V, A, B)


def _column(
    c: Curve, times: NDArray[np.float64], mode: str, cache: dict[int, tuple[NDArray[np.float64], ...]]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Values, in-slopes and out-slopes of one curve at ``times`` (clamped where it clamps)."""
    K = times.size
    if c.factors:
        # product rule, factor by factor: (v f)' = v' f + v f'; values as derive_weights multiplies
        v, a, b = np.ones(K), np.zeros(K), np.zeros(K)
        for f in c.factors:
            fv, fa, fb = _column(f, times, mode, cache)
            a, b, v = a * fv + v * fa, b * fv + v * fb, v * fv
        if c.clamp is not None:
            _clamp_column(v, a, b, *c.clamp)
        return v, a, b
    if c.track is None:
        return np.full(K, c.scale * c.constant), np.zeros(K), np.zeros(K)
    key = id(c.track)
    if key not in cache:
        tr = c.track
        vals = tr.sample(times)
        if mode == "CUBICSPLINE":
            left, right = tr.derivatives(times, "left"), tr.derivatives(times, "right")
            left, right = _step_ramps(tr, times, vals, left, right)
        else:
            left = right = np.zeros_like(vals)
        cache[key] = (vals, left, right)
    vals, left, right = cache[key]
    v = c._combine(vals) + c.offset
    a = c._combine(left)
    b = c._combine(right)
    if c.clamp is not None:
        _clamp_column(v, a, b, *c.clamp)
    return v, a, b


def _drop_close(times: NDArray[np.float64], keys: NDArray[np.float64]) -> NDArray[np.float64]:
    """``times`` without the added knots that float32 cannot tell from the previous knot (keys win)."""
    f32 = times.astype(np.float32)
    orig = np.isin(times, keys)
    kept: list[int] = []
    for i in range(times.size):
        if kept and f32[i] <= f32[kept[-1]]:
            if not orig[i]:
                continue
            if not orig[kept[-1]]:
                kept.pop()
        kept.append(i)
    return times[kept]


def _add_crossings(times: NDArray[np.float64], curves: list[Curve]) -> NDArray[np.float64]:
    """``times`` plus the times where a clamped curve crosses its bounds.

    With a knot at every crossing, each piece between knots is either inside
    the range (the curve itself) or outside (the constant bound), so clamping
    is exact in a LINEAR/CUBICSPLINE sampler. Crossings closer than float32
    resolution to another knot are dropped (times are stored as float32).
    """
    extra: list[float] = []
    for c in curves:
        if c.clamp is not None and c.track is not None and c.coeffs is None and c.track.values.shape[1] == 1:
            lo, hi = ((x - c.offset) / c.scale for x in c.clamp)
            extra += crossing_times(c.track, (lo, hi))
    if not extra:
        return times
    out = np.unique(np.concatenate([times, np.asarray(extra)]))
    f32 = out.astype(np.float32)
    orig = np.isin(out, times)
    kept: list[int] = []
    for i in range(out.size):
        if kept and f32[i] <= f32[kept[-1]]:
            if not orig[i]:
                continue  # a crossing on top of the previous knot
            if not orig[kept[-1]]:
                kept.pop()  # the previous one was a crossing: the key wins
        kept.append(i)
    return out[kept]


def _clamp_column(
    v: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64], lo: float, hi: float
) -> None:
    """Clamp one sampler column in place: values to ``[lo, hi]``, tangents 0 on the clamped side."""
    tol = 1e-9 * max(1.0, abs(lo), abs(hi))
    above, below = v > hi + tol, v < lo - tol
    at_hi, at_lo = np.abs(v - hi) <= tol, np.abs(v - lo) <= tol
    # at the upper bound the curve is inside on the left if it comes up (a >= 0),
    # and on the right if it goes down (b <= 0); mirrored at the lower bound
    a[:] = np.where(above | below, 0.0, np.where(at_hi, np.maximum(a, 0.0), np.where(at_lo, np.minimum(a, 0.0), a)))
    b[:] = np.where(above | below, 0.0, np.where(at_hi, np.minimum(b, 0.0), np.where(at_lo, np.maximum(b, 0.0), b)))
    v[:] = np.clip(v, lo, hi)


def _step_ramps(
    tr: Track,
    times: NDArray[np.float64],
    vals: NDArray[np.float64],
    left: NDArray[np.float64],
    right: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tangents of the short linear ramp that ends each step segment in a cubic sampler."""
    left, right = left.copy(), right.copy()
    for i in range(len(tr) - 1):
        if tr.keys[i].interpolation != "step":
            continue
        end = int(np.searchsorted(times, tr.times[i + 1]))
        if end == 0:
            continue
        start = end - 1  # the knot just before the key (inserted by merge_curves)
        slope = (vals[end] - vals[start]) / (times[end] - times[start])
        right[start] = slope
        left[end] = slope
    return left, right
