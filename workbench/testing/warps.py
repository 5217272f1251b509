"""Smooth maps of 3-D space that turn one face into another with a known answer.

A warp ``w`` is any callable ``(..., 3) -> (..., 3)``. Applied to a rig, the
neutral becomes ``w(V)`` and every shape ``w(V + delta) - w(V)``: the shapes a
method should find on the new face are known exactly.

* :class:`SmoothWarp` — Gaussian bumps, an anisotropic scale, a rotation and a
  change of units (the rigging tests' warp);
* :class:`LocalScale` — grow or shrink parts (the eyes, the jaw) about their
  centres, exactly inside an inner radius and fading to nothing at an outer one;
* :func:`compose` — one warp after another;
* :func:`random_warp` — a :class:`SmoothWarp` drawn from a seed, sized to a mesh;
* :func:`sample_head_warp` — the fixed warp of the rigging tests and benchmarks.

Only numpy: nothing here knows about :class:`~workbench.model.FaceModel`
(:mod:`workbench.testing.faces` applies warps to models).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Composed",
    "LocalScale",
    "SmoothWarp",
    "Warp",
    "compose",
    "identity",
    "random_warp",
    "sample_head_warp",
    "unit_factor",
]

#: what every function here accepts as a warp: points in, points out (same shape)
Warp = Callable[[Any], NDArray[np.float64]]


def identity(P: ArrayLike) -> NDArray[np.float64]:
    """The identity warp (a float64 copy of ``P``)."""
    return np.array(P, np.float64)


def unit_factor(warp: Warp) -> float:
    """Factor a warp changes the units by: its ``unit`` attribute, else 1 (a plain callable keeps them)."""
    return float(getattr(warp, "unit", 1.0))


@dataclass(frozen=True)
class SmoothWarp:
    """``p -> R (S (p + sum_i a_i exp(-|p - c_i|^2 / r_i^2))) * unit + t``: bumps, anisotropic scale, rotation, units.

    Parameters
    ----------
    centres, radii, amplitudes
        Gaussian bumps in the input units: ``(b, 3)``, ``(b,)``, ``(b, 3)``.
    scale : (3,) float
        Anisotropic scale after the bumps.
    rotation : (3, 3) float
        Rotation after the scale.
    unit : float
        Factor to the output units (10 for dm -> cm).
    translation : (3,) float
        In the output units.

    Notes
    -----
    With no bumps, ``scale = 1``, ``rotation = I``, ``unit = 1`` and
    ``translation = 0`` (the defaults) it is the identity. Bumps much smaller
    than their radius keep it one-to-one (its Jacobian is ``I`` plus terms of
    order ``|a| / r``).
    """

    centres: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    radii: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    amplitudes: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    scale: NDArray[np.float64] = field(default_factory=lambda: np.ones(3))
    rotation: NDArray[np.float64] = field(default_factory=lambda: np.eye(3))
    unit: float = 1.0
    translation: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))

    def __call__(self, P: ArrayLike) -> NDArray[np.float64]:
        P = np.asarray(P, np.float64)
        Q = P.copy()
        for c, r, a in zip(np.asarray(self.centres), np.asarray(self.radii), np.asarray(self.amplitudes), strict=True):
            Q += np.exp(-((P - c) ** 2).sum(-1) / r**2)[..., None] * a
        Q = Q * np.asarray(self.scale)
        return (Q @ np.asarray(self.rotation).T) * self.unit + np.asarray(self.translation)

    @staticmethod
    def rotation_xyz(degrees: ArrayLike) -> NDArray[np.float64]:
        """``Rz @ Ry @ Rx`` for angles about x, y, z in degrees."""
        ax, ay, az = np.radians(np.asarray(degrees, np.float64))
        rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
        ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
        rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
        return rz @ ry @ rx


@dataclass(frozen=True)
class LocalScale:
    """``p -> p + sum_i (f_i - 1) g_i(|p - c_i|) (p - c_i)``: parts grown or shrunk about their centres.

    ``g_i`` is 1 up to ``inner_i`` (there the map is exactly a uniform scale by
    ``f_i`` about ``c_i``), falls smoothly (C¹, a smoothstep) to 0 at
    ``outer_i`` and is 0 beyond (there nothing moves).

    Parameters
    ----------
    centres : (b, 3) float
    inner, outer : (b,) float
        ``0 <= inner < outer``.
    factors : (b,) float
        Scale of each part; keep ``|f - 1| <= 0.3`` with ``outer >= 2 inner``
        so the map stays one-to-one. Regions should not overlap where a part
        must scale exactly.
    """

    centres: NDArray[np.float64]
    inner: NDArray[np.float64]
    outer: NDArray[np.float64]
    factors: NDArray[np.float64]

    def __post_init__(self) -> None:
        inner, outer = np.asarray(self.inner, np.float64), np.asarray(self.outer, np.float64)
        if np.any(inner < 0) or np.any(outer <= inner):
            raise ValueError(f"LocalScale: need 0 <= inner < outer, got {inner} and {outer}")

    def weight(self, P: ArrayLike) -> NDArray[np.float64]:
        """``(..., b)``: ``g_i`` at every point."""
        P = np.asarray(P, np.float64)
        d = np.linalg.norm(P[..., None, :] - np.asarray(self.centres, np.float64), axis=-1)
        inner, outer = np.asarray(self.inner, np.float64), np.asarray(self.outer, np.float64)
        s = np.clip((d - inner) / (outer - inner), 0.0, 1.0)
        return np.asarray(1.0 - s * s * (3.0 - 2.0 * s))

    def __call__(self, P: ArrayLike) -> NDArray[np.float64]:
        P = np.asarray(P, np.float64)
        g = self.weight(P) * (np.asarray(self.factors, np.float64) - 1.0)  # (..., b)
        off = P[..., None, :] - np.asarray(self.centres, np.float64)  # (..., b, 3)
        return np.asarray(P + (g[..., None] * off).sum(-2))


@dataclass(frozen=True)
class Composed:
    """``warps[-1](... warps[0](p))``; :attr:`unit` is the product of the parts' unit factors."""

    warps: tuple[Warp, ...]

    def __call__(self, P: ArrayLike) -> NDArray[np.float64]:
        Q = np.asarray(P, np.float64)
        for w in self.warps:
            Q = np.asarray(w(Q), np.float64)
        return Q

    @property
    def unit(self) -> float:
        return float(np.prod([unit_factor(w) for w in self.warps]))


def compose(*warps: Warp) -> Composed:
    """Apply ``warps`` in order (the first one first)."""
    return Composed(tuple(warps))


def random_warp(
    points: ArrayLike, *, seed: int = 0, bumps: int = 3, strength: float = 0.02, radius: tuple[float, float] = (0.15, 0.3),
    anisotropy: float = 0.05, degrees: float = 0.0, unit: float = 1.0, symmetric: bool = False, side_axis: int = 0,
) -> SmoothWarp:
    """A :class:`SmoothWarp` drawn from ``seed``, sized to ``points`` (a face it is meant for).

    Parameters
    ----------
    points : (n, 3) float
        The mesh the warp is for: bumps are centred on some of its points, and
        sizes are shares of its bounding-box diagonal ``D``.
    seed : int
        The same seed gives the same warp.
    bumps : int
        Number of Gaussian bumps (with ``symmetric``, of mirrored pairs).
    strength : float
        Largest push of a bump, as a share of ``D`` (each is 0.5-1 of it).
    radius : (float, float)
        Range of the bumps' radii, as shares of ``D``.
    anisotropy : float
        Each axis is scaled by ``1 +- anisotropy`` (about the bounding-box centre).
    degrees : float
        Largest rotation about each axis (about the origin of the output).
    unit : float
        Factor to the output units.
    symmetric : bool
        Mirror every bump across the plane through the bounding-box centre
        normal to ``side_axis`` (a symmetric face stays symmetric when
        ``degrees`` is 0).
    side_axis : int
        The left-right axis (0 for the sample head: the subject's left is +x).

    Returns
    -------
    SmoothWarp
        ``strength = 0``, ``anisotropy = 0``, ``degrees = 0``, ``unit = 1``: the identity.
    """
    P = np.asarray(points, np.float64).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    lo, hi = P.min(0), P.max(0)
    size = float(np.linalg.norm(hi - lo))
    middle = 0.5 * (lo + hi)
    centres = P[rng.choice(P.shape[0], bumps, replace=bumps > P.shape[0])]
    radii = rng.uniform(*radius, bumps) * size
    direction = rng.normal(size=(bumps, 3))
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    amplitudes = direction * (rng.uniform(0.5, 1.0, bumps) * strength * size)[:, None]
    if symmetric:
        flip = np.ones(3)
        flip[side_axis] = -1.0
        mirrored = centres.copy()
        mirrored[:, side_axis] = 2.0 * middle[side_axis] - centres[:, side_axis]
        centres = np.concatenate([centres, mirrored])
        radii = np.concatenate([radii, radii])
        amplitudes = np.concatenate([amplitudes, amplitudes * flip])
    scale = 1.0 + rng.uniform(-anisotropy, anisotropy, 3)
    R = SmoothWarp.rotation_xyz(rng.uniform(-degrees, degrees, 3))
    # scale about the box centre: t = unit R (m - S m)
    translation = unit * (R @ (middle - scale * middle))
    return SmoothWarp(centres=centres, radii=radii, amplitudes=amplitudes, scale=scale, rotation=R, unit=unit,
                      translation=translation)


def capture_actor_warp(vertices: ArrayLike) -> SmoothWarp:
    """The actor of the capture benchmarks: the sample head in place and in its units, another face.

    Three Gaussian bumps of up to 0.06 units (6 mm on the decimetre sample: mid-face,
    upper left, lower right) and an anisotropic scale (1.05, 0.96, 1.03) about the
    centre of ``vertices``' bounding box. Shared by ``bench_capture.py``'s adaptation
    table and ``bench_capture_clouds_realistic.py``.
    """
    V = np.asarray(vertices, np.float64)
    centre = 0.5 * (V.min(0) + V.max(0))
    scale = np.array([1.05, 0.96, 1.03])
    return SmoothWarp(centres=np.array([[0.0, 7.0, 1.5], [0.35, 7.4, 1.2], [-0.3, 6.3, 1.2]]),
                      radii=np.array([0.35, 0.3, 0.35]),
                      amplitudes=np.array([[0.0, 0.0, 0.06], [0.03, 0.03, 0.03], [-0.03, -0.02, 0.03]]),
                      scale=scale, translation=centre - scale * centre)


def sample_head_warp() -> SmoothWarp:
    """The warp of the rigging tests and benchmarks, for the sample head (dm in, cm out).

    Three Gaussian bumps (up to 9 mm: the left eye, by the mouth, the forehead),
    an anisotropic scale (1.08, 0.95, 1.04), a rotation of (8, 15, -5) degrees
    and a change of units to centimetres, with the head moved off the origin.
    """
    return SmoothWarp(
        centres=np.array([[0.4, 7.3, 1.2], [-0.3, 6.4, 1.3], [0.0, 8.0, 0.5]]),
        radii=np.array([0.35, 0.4, 0.6]),
        amplitudes=np.array([[0.05, 0.04, 0.08], [-0.04, 0.0, 0.06], [0.0, 0.08, 0.05]]),
        scale=np.array([1.08, 0.95, 1.04]),
        rotation=SmoothWarp.rotation_xyz([8, 15, -5]),
        unit=10.0,
        translation=np.array([3.0, -60.0, 5.0]),
    )
