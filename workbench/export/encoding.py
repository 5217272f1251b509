"""What every exporter writes: ``model.evaluate_at(t)`` split into linear parts and baked layers.

:meth:`FaceModel.evaluate` is the blend plus every registered layer. Each
layer says what it is (:mod:`workbench.core.linear`): a linear one gives its
gain (the share of the motion below it each vertex keeps), its constant and
its keyed linear controls, so with ``Δ_k`` the effective (masked) delta of
shape ``k`` (muted shapes at weight 0, keyed weights clamped to the slider
range as :meth:`FaceModel.set_time` does), :func:`workbench.core.linear.decompose`
composes them in pipeline order into::

    x(t) = neutral + C + Σ_k g_k(t) G Δ_k + Σ_c G_c A_c(u_c(t)) + Σ_b G_b N_b(t)

``G`` the product of every linear layer's gain, ``C`` the constants (each
times the gains of the layers above it), ``A_c`` a controls layer's linear
map of its keyed parameters ``u_c`` (the handle shell of the offsets),
``N_b(t)`` a baked layer's own displacement and ``G_c``, ``G_b`` the gains of
the linear layers above them. The layers' own docstrings give their terms
(the region blend: constant ``Σ_k (Σ_r W_r w_rk) Δ_k``, gain ``1 − Σ_r W_r``;
painted expressions: constant ``Σ_e W_e D_e``, gain ``1 − Σ_e W_e``). That is
what :class:`MeshEncoding` holds:

``shape_targets``
    ``G Δ_k``, one per shape, driven by the shape's own weight.
``static``
    ``C`` plus ``G_c A_c(u_c)`` of controls that are not keyed: one target at
    weight 1 (instead of one per parameter).
``controls``
    Per controls layer whose parameters are keyed (:class:`EncodedControls`):
    the key values and tangents of its track span a subspace of the
    parameters; with an orthonormal basis ``q_i`` of it (SVD; usually a few
    vectors, at most ``3 × keys``), ``u(t) = Σ_i a_i(t) q_i`` and
    ``a_i(t) = q_i · u(t)`` is the same piecewise cubic/linear/step curve as
    the keys (any interpolation carries over exactly). Each ``a_i`` is mapped
    affinely onto ``[0, 1]`` over its exact range (extremes of every Bézier
    segment included), the offset going into ``static``, so consumers that
    clamp morph weights to ``[0, 1]`` (Blender) play it too. Target ``i`` is
    ``(hi_i − lo_i) G_c A_c(q_i)``, named ``"<prefix>:basis<i>"``.
``baked_layers``
    Layers that are not linear in the keyed quantities (pose-space wrinkles,
    anything that does not describe itself), and linear ones that say a
    timeline makes them so (keyed region weights): each format bakes their sum
    ``Σ_b G_b N_b(t)`` per frame (:meth:`baked`, through
    :meth:`FaceModel.layers_at`). A baked sum that is the same at every frame
    is folded into ``static``. Their reports say why.

**Corrective (combination) shapes** (:mod:`workbench.methods.shapes.correctives`)
are ordinary shape targets whose weight is not keyed but derived: the product
of their drivers' played weights, clamped to their own range
(:func:`workbench.core.families.derive_weights`, the function the model's
views use). :attr:`MeshEncoding.weight_products` names them and their drivers,
and :meth:`MeshEncoding.weights` gives the derived weight at every time, so
per-frame writers (USD, CSV) are exact at every frame; the glTF writer, whose
sampler interpolates keys, writes the product as its own curve with knots
at every frame (:mod:`workbench.export.gltf`).

The head pose is applied after all layers (a rigid transform, as in
:meth:`FaceModel.evaluate_at`); formats write it on the node / root prim.
Units are model units here; writers scale by ``metadata.metres_per_unit``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.core.families import derive_weights, weight_products
from workbench.core.linear import Controls, decompose, is_linear
from workbench.export import ExportError, LayerReport

if TYPE_CHECKING:
    from workbench.animation.curves import Track
    from workbench.animation.tracks import Timeline
    from workbench.model import FaceModel

__all__ = ["EncodedControls", "MeshEncoding", "crossing_times", "curve_range", "segment_polynomials"]

#: singular values below this fraction of the largest are dropped from a controls basis
_RANK_TOL = 1e-9


def segment_polynomials(
    track: Track, coeffs: NDArray[np.float64]
) -> list[tuple[float, float, str, NDArray[np.float64]]]:
    """Every segment of ``a(t) = track(t) @ coeffs`` as a polynomial in ``u = (t - t0) / (t1 - t0)``.

    Returns ``(t0, t1, interpolation, c)`` per segment with ``c`` (4, r): the
    coefficients of ``1, u, u², u³`` (a step segment is its held value).
    """
    T = track.times
    if T.size < 2:
        return []
    vals = track.values @ coeffs
    right = track.derivatives(T, "right") @ coeffs
    left = track.derivatives(T, "left") @ coeffs
    out: list[tuple[float, float, str, NDArray[np.float64]]] = []
    for i, key in enumerate(track.keys[:-1]):
        dt = T[i + 1] - T[i]
        v0, v1 = vals[i], vals[i + 1]
        c = np.zeros((4, vals.shape[1]))
        c[0] = v0
        if key.interpolation == "linear":
            c[1] = v1 - v0
        elif key.interpolation == "bezier":
            m0, m1 = right[i] * dt, left[i + 1] * dt
            c[1] = m0
            c[2] = -3 * v0 - 2 * m0 + 3 * v1 - m1
            c[3] = 2 * v0 + m0 - 2 * v1 + m1
        out.append((float(T[i]), float(T[i + 1]), key.interpolation, c))
    return out


def _roots_in_unit(c: NDArray[np.float64]) -> list[float]:
    """Real roots in (0, 1) of ``c[0] + c[1] u + c[2] u² + c[3] u³``."""
    poly = np.trim_zeros(c[::-1], "f")
    if poly.size < 2:
        return []
    return [float(r.real) for r in np.roots(poly) if abs(r.imag) < 1e-12 and 0.0 < r.real < 1.0]


def curve_range(track: Track, coeffs: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Exact ``(lo, hi)`` of ``a(t) = track(t) @ coeffs`` over all ``t`` (one per column).

    Tracks hold their end values outside the keyed range, step and linear
    segments reach their extremes at keys, and a Bézier segment is a cubic
    whose interior extremes are the roots of its derivative.
    """
    vals = track.values @ coeffs
    lo, hi = vals.min(axis=0).copy(), vals.max(axis=0).copy()
    for _, _, interp, c in segment_polynomials(track, coeffs):
        if interp != "bezier":
            continue
        for j in range(c.shape[1]):
            for u in _roots_in_unit(np.array([c[1, j], 2 * c[2, j], 3 * c[3, j], 0.0])):
                p = c[0, j] + c[1, j] * u + c[2, j] * u * u + c[3, j] * u**3
                lo[j], hi[j] = min(lo[j], p), max(hi[j], p)
    return lo, hi


def crossing_times(track: Track, bounds: tuple[float, float]) -> list[float]:
    """Times where the scalar ``track`` crosses ``bounds[0]`` or ``bounds[1]`` inside a segment."""
    if track.values.shape[1] != 1:
        raise ValueError(f"crossing_times needs a scalar track, {track.name!r} is not")
    out = []
    for t0, t1, interp, c in segment_polynomials(track, np.ones((1, 1))):
        if interp == "step":
            continue
        for b in bounds:
            cc = c[:, 0].copy()
            cc[0] -= b
            out += [t0 + u * (t1 - t0) for u in _roots_in_unit(cc)]
    return out


@dataclass(frozen=True)
class EncodedControls:
    """One controls layer's keyed parameters as morph targets (see the module docstring).

    Target ``i``'s weight is ``u(t).ravel() @ coeffs[:, i] + shift[i]``, ``u(t)``
    the values of ``track``; exporters name it ``"<prefix>:basis<i>"``.
    """

    layer: str
    prefix: str
    targets: NDArray[np.float32]
    track: Track | None
    coeffs: NDArray[np.float64]
    shift: NDArray[np.float64]


class MeshEncoding:
    """The animated mesh of ``model`` under ``timeline`` as exportable parts (module docstring).

    Parameters
    ----------
    model : FaceModel
    timeline : Timeline
        Checked against the model; the exported animation (it need not be
        ``model.tracks``: :meth:`FaceModel.evaluate_at` takes it too).

    Attributes
    ----------
    neutral : (n, 3) float32
    shape_names : list of str
    shape_targets : (k, n, 3) float32
    static : (n, 3) float32 or None
        The constant target (weight 1); None when it is zero.
    controls : list of EncodedControls
        One per layer with keyed linear controls (the handle offsets): its basis
        targets, their weights' coefficients and the track that keys them.
    baked_layers : tuple of str
        Layers baked per frame (see :meth:`baked`); empty when all are linear.
    weight_products : dict of str to tuple of str
        Corrective shapes and their drivers: the shape's weight is the product
        of the drivers' (see the module docstring); empty without correctives.
    layers : list of LayerReport
        One per registered layer: ``"linear"``, ``"baked"`` or ``"inactive"``.
    """

    def __init__(self, model: FaceModel, timeline: Timeline) -> None:
        timeline.check_model(model)
        self.model = model
        self.timeline = timeline
        with model.lock:
            n = model.n_vertices
            self.n_vertices = n
            self.neutral = np.asarray(model.vertices, np.float64).astype(np.float32)
            shapes = model.shapes
            self.shape_names = [s.name for s in shapes]
            self.muted = np.array([s.mute for s in shapes], bool)
            self.slider_range = np.array([[s.slider_min, s.slider_max] for s in shapes]).reshape(-1, 2)
            self.static_weights = np.array([model.weights[nm] for nm in self.shape_names], np.float64)
            self._shapes = shapes
            view = model.view()
            self._slots = dict(view.slots)
            names = set(self.shape_names)
            self.weight_products = {
                nm: drivers for nm, drivers in weight_products(self._slots).items() if nm in names
            }
            eff = (
                np.stack([s.effective_delta() for s in shapes])
                if shapes
                else np.zeros((0, n, 3), np.float32)
            )
            layers = model.pipeline.layers
            # a nonlinear layer that says it is off for this model (nothing fitted yet) is not baked
            silent = {
                layer.name for layer in layers
                if not is_linear(layer) and hasattr(layer, "active") and not layer.active(view)
            }
            try:
                dec = decompose(layers, view, timeline, n=n, skip=lambda layer: layer.name in silent)
            except ExportError:
                raise
            except ValueError as exc:  # a layer refusing this timeline (tracks its state cannot play)
                raise ExportError(str(exc)) from exc
            reports: dict[str, LayerReport] = {nm: LayerReport(nm, "inactive", "off for this model")
                                               for nm in silent}
            const = dec.constant
            has_const = dec.has_constant
            for name, terms in dec.terms.items():
                if not terms.baked and terms.controls is None:
                    reports[name] = LayerReport(name, "linear" if not terms.empty else "inactive", terms.detail)

            # --- controls layers: constant when not keyed, else a basis of their keyed span
            self.controls: list[EncodedControls] = []
            for name, ctl, gain in dec.controls:
                keep = None if np.all(gain == 1.0) else gain[:, None]

                def disp(u: NDArray[np.float64], ctl: Controls = ctl, keep: NDArray[np.float64] | None = keep,
                         ) -> NDArray[np.float64]:
                    d = np.asarray(ctl.apply(u.reshape(ctl.values.shape)), np.float64)
                    return d if keep is None else d * keep

                tr = ctl.track
                m = ctl.values.size
                coeffs_l: list[NDArray[np.float64]] = []
                shift: list[float] = []
                targets: list[NDArray[np.float64]] = []
                if tr is None:
                    if np.any(ctl.values):
                        const = const + disp(ctl.values)
                        has_const = True
                        reports[name] = LayerReport(name, "linear", f"{ctl.label}, not keyed: one constant target")
                    else:
                        reports[name] = LayerReport(name, "inactive", f"{ctl.label}, all zero")
                else:
                    Q = _row_basis(np.concatenate([tr.values, tr.derivatives(tr.times, "left"),
                                                   tr.derivatives(tr.times, "right")]))
                    if Q.shape[1]:
                        lo, hi = curve_range(tr, Q)
                        for i in range(Q.shape[1]):
                            d = disp(Q[:, i])
                            span = hi[i] - lo[i]
                            if lo[i] != 0.0:
                                const = const + lo[i] * d
                                has_const = True
                            if span <= 1e-12 * max(1.0, abs(lo[i])):
                                continue  # constant along q_i: folded into the static target
                            targets.append(span * d)
                            coeffs_l.append(Q[:, i] / span)
                            shift.append(-lo[i] / span)
                        reports[name] = LayerReport(
                            name, "linear",
                            f"{ctl.label} keyed ({len(tr)} keys): {len(targets)} basis targets "
                            "(weights in [0, 1]) + constant target",
                        )
                    else:
                        reports[name] = LayerReport(name, "inactive", f"{ctl.label}, keyed values all zero")
                self.controls.append(EncodedControls(
                    name, ctl.prefix,
                    np.stack(targets).astype(np.float32) if targets else np.zeros((0, n, 3), np.float32),
                    tr if targets else None,
                    np.stack(coeffs_l, axis=1) if coeffs_l else np.zeros((m, 0)),
                    np.array(shift),
                ))

            scale = dec.shape_gain
            self.shape_targets = eff if np.all(scale == 1.0) else (eff * scale[None, :, None].astype(np.float32))
            # baked layers, each times the gain of the linear layers above it
            self.baked_layers = tuple(name for name, _, _ in dec.baked)
            self._baked_gain = {
                name: g.astype(np.float32)[:, None] for name, g, _ in dec.baked if not np.all(g == 1.0)
            }
            reasons = {name: why for name, _, why in dec.baked}
            for name in self.baked_layers:
                reports[name] = LayerReport(name, "baked", reasons[name])
            self._baked_reasons = reasons
            self.layers = [reports[layer.name] for layer in layers if layer.name in reports]
        self._const = const
        self._has_const = has_const
        self.static: NDArray[np.float32] | None = const.astype(np.float32) if has_const else None
        self._baked_cache: dict[float, NDArray[np.float32] | None] = {}
        self._folded = False

    # ------------------------------------------------------------------ weights
    @property
    def n_shapes(self) -> int:
        return len(self.shape_names)

    def raw_weights(self, times: ArrayLike) -> NDArray[np.float64]:
        """(F, k) weights as the keys give them (unclamped), unkeyed shapes at their current value."""
        ts = np.asarray(times, np.float64).reshape(-1)
        W = np.repeat(self.static_weights[None, :], ts.size, axis=0)
        index = {nm: i for i, nm in enumerate(self.shape_names)}
        for s, tr in self.timeline.weight_tracks.items():
            W[:, index[s]] = tr.sample(ts)[:, 0]
        return W

    def weights(self, times: ArrayLike) -> NDArray[np.float64]:
        """(F, k) weights the model plays: clamped to each slider range, correctives derived, muted shapes 0."""
        W = self.raw_weights(times)
        if W.size:
            W = np.clip(W, self.slider_range[:, 0], self.slider_range[:, 1])
        if self.weight_products and W.size:
            derived = derive_weights(self._shapes, {nm: W[:, k] for k, nm in enumerate(self.shape_names)},
                                     self._slots)
            for k, nm in enumerate(self.shape_names):
                if nm in self.weight_products:
                    W[:, k] = derived[nm]
        W[:, self.muted] = 0.0
        return W

    def clamping_shapes(self, times: ArrayLike) -> list[str]:
        """Unmuted keyed shapes whose keys leave the slider range at some of ``times``."""
        W = self.raw_weights(times)
        out = []
        for k, nm in enumerate(self.shape_names):
            if self.muted[k] or nm not in self.timeline.weight_tracks or nm in self.weight_products:
                continue
            lo, hi = self.slider_range[k]
            if np.any(W[:, k] < lo) or np.any(W[:, k] > hi):
                out.append(nm)
        return out

    def control_weights(self, controls: EncodedControls, times: ArrayLike) -> NDArray[np.float64]:
        """(F, r) weights of ``controls.targets`` (in [0, 1])."""
        ts = np.asarray(times, np.float64).reshape(-1)
        r = controls.targets.shape[0]
        if r == 0 or controls.track is None:
            return np.zeros((ts.size, r))
        return controls.track.sample(ts) @ controls.coeffs + controls.shift[None, :]

    # ------------------------------------------------------------------ baked layers
    def baked(self, time: float) -> NDArray[np.float32] | None:
        """(n, 3) float32 sum of :attr:`baked_layers` at ``time`` (None: zero)."""
        if not self.baked_layers or self._folded:
            return None
        t = float(time)
        if t not in self._baked_cache:
            parts = self.model.layers_at(t, self.baked_layers, self.timeline)
            for name, gain in self._baked_gain.items():
                d = parts.get(name)
                if d is not None:
                    parts[name] = d * gain
            arrs = [p for p in parts.values() if p is not None]
            total: NDArray[np.float32] | None = None
            if arrs:
                total = np.sum(np.stack(arrs), axis=0, dtype=np.float32) if len(arrs) > 1 else arrs[0]
                if not np.any(total):
                    total = None
            self._baked_cache[t] = total
        return self._baked_cache[t]

    def fold_constant_baked(self, times: ArrayLike) -> bool:
        """If the baked layers give the same displacement at every time, move it into :attr:`static`.

        Returns True when folded (then :meth:`baked` is None everywhere).
        """
        if not self.baked_layers:
            return False
        ts = np.asarray(times, np.float64).reshape(-1)
        frames = [self.baked(float(t)) for t in ts]
        first = frames[0]
        for f in frames:
            if (f is None) != (first is None):
                return False
            if f is not None and first is not None and not np.array_equal(f, first):
                return False
        if first is not None:
            self._const = self._const + first.astype(np.float64)
            self._has_const = True
            self.static = self._const.astype(np.float32)
        self._baked_cache = {float(t): None for t in ts}
        self._folded = True
        return True

    def baked_report(self, times: ArrayLike, how: str) -> None:
        """Fill in how the baked layers were written (after the writer baked them)."""
        if not self.baked_layers:
            return
        ts = np.asarray(times, np.float64).reshape(-1)
        moving = sum(self.baked(float(t)) is not None for t in ts)
        folded = self._folded
        for i, rep in enumerate(self.layers):
            if rep.name not in self.baked_layers:
                continue
            if folded and self.static is not None and moving == 0:
                detail = "the same at every frame: folded into the constant target"
                enc = "linear"
            elif moving == 0:
                detail, enc = "zero at every exported frame", "inactive"
            else:
                detail, enc = f"{how} ({moving} of {ts.size} frames non-zero)", "baked"
            self.layers[i] = LayerReport(rep.name, enc, f"{self._baked_reasons[rep.name]}; {detail}")

    def all_baked_report(self, how: str) -> None:
        """Every active layer went into per-frame positions (point caches, ``bake=True``)."""
        for i, rep in enumerate(self.layers):
            if rep.encoding in ("linear", "baked"):
                self.layers[i] = LayerReport(rep.name, "baked", f"{how}; {rep.detail}")

    # ------------------------------------------------------------------ positions
    def local_points(self, times: ArrayLike) -> NDArray[np.float32]:
        """(F, n, 3) float32 mesh without the head pose (model units): the pipeline at each time."""
        ts = np.asarray(times, np.float64).reshape(-1)
        n = self.n_vertices
        out = np.empty((ts.size, n, 3), np.float32)
        self.timeline.prefetch_weights(ts)
        try:
            for f, t in enumerate(ts):
                out[f] = self.model.evaluation_at(float(t), self.timeline).mesh
        finally:
            self.timeline.forget_prefetched()
        return out

    def points(self, times: ArrayLike) -> NDArray[np.float32]:
        """(F, n, 3) float32 mesh with the head pose (model units): ``model.evaluate_at(t, timeline)``, bit for bit."""
        ts = np.asarray(times, np.float64).reshape(-1)
        n = self.n_vertices
        out = np.empty((ts.size, n, 3), np.float32)
        self.timeline.prefetch_weights(ts)
        try:
            for f, t in enumerate(ts):
                out[f] = self.model.evaluate_at(float(t), self.timeline)
        finally:
            self.timeline.forget_prefetched()
        return out


def _row_basis(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """(d, r) orthonormal basis of the span of ``rows`` (SVD, relative tolerance ``_RANK_TOL``)."""
    if rows.size == 0 or not np.any(rows):
        return np.zeros((rows.shape[1], 0))
    _, s, vt = np.linalg.svd(rows, full_matrices=False)
    r = int(np.count_nonzero(s > _RANK_TOL * s[0]))
    Q = vt[:r].T
    # a deterministic sign: the largest component of every basis vector is positive
    sign = np.sign(Q[np.argmax(np.abs(Q), axis=0), np.arange(r)])
    return Q * np.where(sign == 0, 1.0, sign)[None, :]
