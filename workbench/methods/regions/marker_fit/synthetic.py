"""A synthetic marker performance from known weight curves, to measure a fit against the truth."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.methods.regions.blend.evaluate import _mute, _vertex_ids
from workbench.methods.regions.hierarchy import RegionError
from workbench.methods.regions.marker_fit.rbf import _ro

if TYPE_CHECKING:
    from workbench.core.state import FaceState as FaceModel


@dataclass(frozen=True, eq=False)
class SyntheticPerformance:
    """A marker performance generated from known weight curves.

    The truth has different weights in four smooth quadrants of the face
    (subject's left/right × upper/lower), so it is *more expressive than one
    global weight set*, as the paper's captured motion is.

    Attributes
    ----------
    markers : (M,) int
    marker_positions : (T, M, 3) float32
        Measured positions (truth + Gaussian noise).
    quadrant_weights : (T, Q, k) float32
        True weights of each quadrant per frame (Q = 4).
    masks : (n, Q) float32
        Smooth quadrant masks, summing to 1 at every vertex.
    noise : float
        Standard deviation of the noise per coordinate (model units).
    """

    markers: NDArray[np.intp]
    marker_positions: NDArray[np.float32]
    quadrant_weights: NDArray[np.float32]
    masks: NDArray[np.float32]
    noise: float

    @property
    def n_frames(self) -> int:
        return int(self.marker_positions.shape[0])

    def vertex_weights(self, frame: int) -> NDArray[np.float64]:
        """(n, k) true per-vertex weights of one frame."""
        return self.masks.astype(np.float64) @ self.quadrant_weights[frame].astype(np.float64)

    def positions(self, model: FaceModel, frame: int) -> NDArray[np.float64]:
        """(n, 3) true (noise-free) vertex positions of one frame."""
        W = self.vertex_weights(frame) * _mute(model)[None, :]
        D = model.effective_deltas.astype(np.float64)
        return model.vertices + np.einsum("nk,knc->nc", W, D)


def _smooth_curves(rng: np.random.Generator, T: int, k: int, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T, k) sums of Gaussian bumps (each shape ~0.8 bumps), clipped to [lo, hi]."""
    t = np.arange(T, dtype=np.float64)
    out = np.zeros((T, k))
    for j in range(k):
        for _ in range(rng.poisson(0.8)):
            c = rng.uniform(0, T)
            w = rng.uniform(0.04, 0.15) * T
            out[:, j] += rng.uniform(0.2, 0.9) * np.exp(-0.5 * ((t - c) / w) ** 2)
    return np.clip(out, lo, hi)


def generate_synthetic_marker_performance(
    model: FaceModel,
    markers: ArrayLike,
    n_frames: int = 120,
    seed: int = 0,
    noise: float = 0.0,
    *,
    asymmetry: float = 0.5,
) -> SyntheticPerformance:
    """Marker tracks from known smooth weight curves plus noise.

    Parameters
    ----------
    model : FaceModel
    markers : (M,) int
        Marker vertex ids (e.g. ``default_face_handles(model).vertices``).
    n_frames : int
        >= 1.
    seed : int
        Random seed (the result is a pure function of the arguments).
    noise : float
        >= 0, Gaussian noise per coordinate in model units.
    asymmetry : float
        In [0, 1]: 0 = one weight set for the whole face (a global blend can
        explain it), 1 = independent curves per quadrant.

    Returns
    -------
    SyntheticPerformance
    """
    ids = _vertex_ids(model, markers, "markers")
    if ids.size == 0:
        raise RegionError("markers: need at least one marker vertex")
    if not isinstance(n_frames, int | np.integer) or isinstance(n_frames, bool) or n_frames < 1:
        raise RegionError(f"n_frames must be an int >= 1, got {n_frames!r}")
    nz = float(noise)
    if not (np.isfinite(nz) and nz >= 0):
        raise RegionError(f"noise must be a finite number >= 0, got {noise!r}")
    a = float(asymmetry)
    if not (np.isfinite(a) and 0 <= a <= 1):
        raise RegionError(f"asymmetry must be in [0, 1], got {asymmetry!r}")
    if not model.shapes:
        raise RegionError("model has no blendshapes to animate")
    rng = np.random.default_rng(seed)
    k = len(model.shapes)
    lo = np.array([s.slider_min for s in model.shapes])
    hi = np.array([s.slider_max for s in model.shapes])
    T = int(n_frames)
    base = _smooth_curves(rng, T, k, lo, hi)
    Q = 4
    qw = np.stack([np.clip((1 - a) * base + a * _smooth_curves(rng, T, k, lo, hi), lo, hi) for _ in range(Q)], axis=1)
    # smooth quadrant masks around the centre of the face's motion
    V = model.vertices
    D = model.effective_deltas
    mag = np.sqrt(np.einsum("knc,knc->n", D, D, dtype=np.float64))
    w = mag / max(float(mag.sum()), 1e-30)
    cx, cy = float(w @ V[:, 0]), float(w @ V[:, 1])
    size = float(np.sqrt(w @ ((V[:, 0] - cx) ** 2 + (V[:, 1] - cy) ** 2)))
    s = 0.25 * max(size, 1e-12)
    sx = 1.0 / (1.0 + np.exp(-(V[:, 0] - cx) / s))
    sy = 1.0 / (1.0 + np.exp(-(V[:, 1] - cy) / s))
    masks = np.stack([sx * sy, (1 - sx) * sy, sx * (1 - sy), (1 - sx) * (1 - sy)], axis=1)
    perf0 = SyntheticPerformance(ids, np.zeros((T, ids.size, 3), np.float32), qw.astype(np.float32), masks.astype(np.float32), nz)
    mute = _mute(model)
    Dm = D[:, ids].astype(np.float64)
    pos = np.empty((T, ids.size, 3))
    Mm = masks[ids]
    for t in range(T):
        Wt = (Mm @ qw[t]) * mute[None, :]
        pos[t] = V[ids] + np.einsum("mk,kmc->mc", Wt, Dm)
    pos += rng.normal(0.0, nz, pos.shape) if nz > 0 else 0.0
    return SyntheticPerformance(
        _ro(ids), _ro(pos.astype(np.float32)), _ro(perf0.quadrant_weights), _ro(perf0.masks), nz
    )
